"""The encoder's forward + backward as the GPU compiler optimises it: write the optimised HLO.

    python3 experiments/gpu/encoder_hlo.py --impl fused_bf16 --out /tmp/out/encoder_hlo.txt

Compiles the grad of encoder_bench's scalar loss of ``networks.encode`` wrt the params (the
stair layout, the default NetworkConfig, ``--batch`` maps) for one conv_impl and writes
``compiled.as_text()``, so the kernels a profile names (``loop_convert_fusion`` ...) can be read
back to their ops.
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
from encoder_bench import LAYOUT, default_params, encoder_loss  # this folder, on sys.path

from mjx_stairs import atomic


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--impl", default="fused_bf16")
    ap.add_argument("--batch", type=int, default=49152)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    obs = jnp.zeros((args.batch, LAYOUT.obs_size), jnp.float32)
    loss = encoder_loss(args.impl)
    text = jax.jit(jax.grad(loss)).lower(default_params(), obs).compile().as_text()
    atomic.write_text(args.out, text)
    print(f"wrote {args.out} ({len(text)} chars)")


if __name__ == "__main__":
    main()
