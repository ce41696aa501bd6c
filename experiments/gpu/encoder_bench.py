"""Time the height-map encoder's forward + backward for each conv implementation.

    python3 experiments/gpu/encoder_bench.py --batch 49152 --out /tmp/out/encoder_bench.json

For conv_impl 'xla' (lax.conv, cuDNN on a GPU), jits the grad of a scalar loss of
``networks.encode`` wrt the params (float32, the stair layout: 49 vec floats + a 21x21 map,
default NetworkConfig) and reports the median ms of ``--repeats`` calls after warm-up, in the
default matmul precision and in float32. 'fused' (the conv stack with its written-out backward
pass) is timed in the default precision and in float32, 'fused_bf16' (the same storing its
activations in bfloat16) in the default; its gradient difference says what the rounding costs.
(The row-Toeplitz encoders 'row' and 'row_bf16' of earlier measurements were retired in issue
20.)
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import jax
import jax.numpy as jnp

from mjx_stairs import atomic
from mjx_stairs.rl import networks
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout

LAYOUT = ObsLayout(49, (21, 21))  # env.N_VEC, the 21 x 21 height scan


def default_params():
    """The default NetworkConfig's params for the stair layout (12 actions)."""
    return networks.init_params(jax.random.PRNGKey(0), NetworkConfig(), LAYOUT.n_vec,
                                LAYOUT.map_shape, 12)


def encoder_loss(impl: str):
    """A scalar loss of the encoder's features, ``loss(params, obs)``, for one conv_impl."""

    def loss(p, o):
        return jnp.sum(jnp.sin(networks.encode(p, o, LAYOUT, conv_impl=impl)))

    return loss


def time_ms(fn, args, repeats: int) -> float:
    """Median milliseconds of fn(*args) over ``repeats`` calls after compile and one warm-up."""
    jax.block_until_ready(fn(*args))  # compile + warm-up
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=49152, help="maps per call")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--out", required=True, help="JSON file to write")
    args = ap.parse_args()

    params = default_params()
    obs = jax.random.normal(jax.random.PRNGKey(1), (args.batch, LAYOUT.obs_size), jnp.float32)

    def make(impl):
        loss = encoder_loss(impl)
        return jax.jit(jax.grad(loss)), jax.jit(loss)

    grads, rows = {}, {}
    for name, impl, precision in (("xla", "xla", None),
                                  ("xla_fp32", "xla", "float32"),
                                  ("fused", "fused", None),
                                  ("fused_fp32", "fused", "float32"),
                                  ("fused_bf16", "fused_bf16", None)):
        with jax.default_matmul_precision(precision):  # None: the default
            g, f = make(impl)  # jit inside the context: precision is fixed at trace time
            ms = time_ms(g, (params, obs), args.repeats)
            fwd = time_ms(f, (params, obs), args.repeats)
            grads[name] = g(params, obs)
        rows[name] = {"conv_impl": impl, "matmul_precision": precision or "default",
                      "fwd_bwd_ms": round(ms, 3), "fwd_ms": round(fwd, 3)}
        print(f"{name:9s} fwd+bwd {ms:8.3f} ms   fwd {fwd:8.3f} ms", flush=True)

    def max_rel_diff(a, b):
        return max(float(jnp.max(jnp.abs(x - y)) / (jnp.max(jnp.abs(y)) + 1e-30))
                   for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b),
                                   strict=True))

    result = {
        "device": jax.devices()[0].device_kind,
        "backend": jax.default_backend(),
        "jax": jax.__version__,
        "batch": args.batch,
        "layout": {"n_vec": LAYOUT.n_vec, "map_shape": list(LAYOUT.map_shape)},
        "repeats": args.repeats,
        "timings": rows,
        # grads vs the float32 lax.conv: how far each variant is from full precision
        "grad_max_rel_diff_vs_xla_fp32": {k: max_rel_diff(g, grads["xla_fp32"])
                                          for k, g in grads.items()},
    }
    atomic.write_text(args.out, json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
