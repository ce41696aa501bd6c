"""Ship a policy: ONE ONNX graph (normaliser -> CNN encoder -> actor MLP) and a JSON sidecar.

The graph maps the raw observation `obs` [batch, 490] (the layout of mjx_stairs.env, no noise
added) to the mean action `action` [batch, 12], exactly as `policy.policy_action` does:

    x = clip((obs - mean) / (std + 0.01), -clip, clip)               # the actor's normaliser
    vec, map = x[:, :49], x[:, 49:].reshape(batch, 1, 21, 21)      # rows = y, columns = x
    3 x (Conv 3x3 pads 1 -> Elu), MaxPool 2 after all but the last   # 21 -> 10 -> 5
    adaptive average pool to 2 x 2 (torch bins, overlapping: rows/cols [0:3] and [2:5])
    NCHW -> NHWC flatten -> Gemm -> Elu = latent [batch, 128]
    actor MLP on concat(latent, vec): Gemm + Elu per hidden layer, Gemm out

Built with onnx.helper at opset 17 (Sub, Div, Clip, Slice, Reshape, Conv, Elu, MaxPool,
ReduceMean, Concat, Transpose, Flatten, Gemm). The sidecar (`<file>.json`,
mjx_stairs.tools.sidecar) is what a robot-side runner needs beside the graph: the observation
layout with units, scales and clips, the joint orders (ours and the Go2 SDK's), the nominal pose,
the action -> PD target rule, PD gains, torque limits, rates, the height-map geometry, the goal
convention and the versions.
Both files are written through a temporary file and os.replace.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Sequence

import jax
import numpy as np

from mjx_stairs import atomic
from mjx_stairs.config import ConfigError, to_dict
from mjx_stairs.env.config import env_config_from
from mjx_stairs.rl.policy import (
    Policy,
    load_policy,
    normaliser_constants,
    policy_action,
    saved_config,
)
from mjx_stairs.tools import sidecar as sidecar_lib

OPSET = sidecar_lib.OPSET

class ExportError(RuntimeError):
    """The policy cannot be exported (missing onnx, unsupported layout)."""


def _onnx():
    try:
        import onnx
        from onnx import helper, numpy_helper
    except ImportError:
        raise ExportError("ONNX export needs the onnx package: pip install 'mjx_stairs[export]'"
                          ) from None
    return onnx, helper, numpy_helper


def _adaptive_bins(n: int, out: int) -> list[tuple[int, int]]:
    """torch AdaptiveAvgPool bins, as networks._adaptive_avg_pool computes them."""
    return [((i * n) // out, -((-(i + 1) * n) // out)) for i in range(out)]


def build_onnx(policy: Policy, opset: int = OPSET):
    """The policy's normaliser, encoder and actor as an onnx.ModelProto (checked).

    Long: the graph node by node, in the order networks.encode computes it.
    """
    onnx, helper, numpy_helper = _onnx()
    from onnx import TensorProto

    params = jax.tree_util.tree_map(lambda x: np.asarray(x, np.float32), policy.params)
    layout = policy.layout
    D, A = layout.obs_size, policy.action_size
    nodes, inits = [], []
    counter = [0]

    def name(prefix: str) -> str:
        counter[0] += 1
        return f"{prefix}_{counter[0]}"

    def const(prefix: str, value) -> str:
        n = name(prefix)
        inits.append(numpy_helper.from_array(np.asarray(value), n))
        return n

    def node(op: str, inputs: list[str], out: str | None = None, **attrs) -> str:
        out = out or name(op.lower())
        nodes.append(helper.make_node(op, inputs, [out], name=name(f"n_{op}"), **attrs))
        return out

    x = "obs"
    norm = normaliser_constants(policy)
    if norm is not None:
        mean, denom, clip = norm
        x = node("Sub", [x, const("norm_mean", mean)])
        x = node("Div", [x, const("norm_std_plus_eps", denom)])
        if clip > 0:
            x = node("Clip", [x, const("clip_lo", np.float32(-clip)),
                              const("clip_hi", np.float32(clip))])

    if layout.map_shape:
        H, W = (int(s) for s in layout.map_shape)
        i64 = lambda v: np.asarray(v, np.int64)
        vec = node("Slice", [x, const("s0", i64([0])), const("s1", i64([layout.n_vec])),
                             const("ax", i64([1]))])
        m = node("Slice", [x, const("s0", i64([layout.n_vec])), const("s1", i64([D])),
                           const("ax", i64([1]))])
        m = node("Reshape", [m, const("shape", i64([-1, 1, H, W]))])
        convs = params["encoder"]["conv"]
        h, w = H, W
        for i, p in enumerate(convs):
            k = p["w"].shape[0]
            if p["w"].shape[1] != k or k % 2 == 0:
                raise ExportError(f"conv {i}: only odd square kernels are supported")
            wt = np.ascontiguousarray(np.transpose(p["w"], (3, 2, 0, 1)))  # HWIO -> OIHW
            pad = (k - 1) // 2
            m = node("Conv", [m, const(f"conv{i}_w", wt), const(f"conv{i}_b", p["b"])],
                     kernel_shape=[k, k], pads=[pad] * 4, strides=[1, 1])
            m = node("Elu", [m], alpha=1.0)
            if i < len(convs) - 1:
                m = node("MaxPool", [m], kernel_shape=[2, 2], strides=[2, 2])
                h, w = h // 2, w // 2
        c = int(convs[-1]["w"].shape[-1])
        n_flat = int(params["encoder"]["proj"]["w"].shape[0])
        side = int(round((n_flat // c) ** 0.5))
        if side * side * c != n_flat:
            raise ExportError(f"encoder projection expects {n_flat} inputs, not a square pool")
        rows = []
        for r0, r1 in _adaptive_bins(h, side):
            cols = []
            for c0, c1 in _adaptive_bins(w, side):
                cell = node("Slice", [m, const("s0", i64([r0, c0])), const("s1", i64([r1, c1])),
                                      const("ax", i64([2, 3]))])
                cols.append(node("ReduceMean", [cell], axes=[2, 3], keepdims=1))
            rows.append(node("Concat", cols, axis=3))
        pooled = node("Concat", rows, axis=2)  # [N, C, side, side]
        pooled = node("Transpose", [pooled], perm=[0, 2, 3, 1])  # NHWC, as networks.encode
        flat = node("Flatten", [pooled], axis=1)
        proj = params["encoder"]["proj"]
        latent = node("Gemm", [flat, const("proj_w", proj["w"]), const("proj_b", proj["b"])])
        latent = node("Elu", [latent], alpha=1.0)
        x = node("Concat", [latent, vec], axis=1)

    layers = params["actor"]
    for i, p in enumerate(layers):
        last = i == len(layers) - 1
        x = node("Gemm", [x, const(f"actor{i}_w", p["w"]), const(f"actor{i}_b", p["b"])],
                 out="action" if last else None)
        if not last:
            x = node("Elu", [x], alpha=1.0)

    graph = helper.make_graph(
        nodes, "mjx_stairs_policy",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", D])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", A])],
        initializer=inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)],
                              producer_name="mjx_stairs", producer_version="0.1.0")
    model.ir_version = min(model.ir_version, 8)  # opset 17 <-> IR 8: loadable by older runtimes
    model.doc_string = ("raw observation [batch, %d] -> mean action [batch, %d]; see the JSON "
                        "sidecar for the layout" % (D, A))
    meta = policy.metadata
    for k, v in (("iteration", meta.get("iteration")), ("env_steps", meta.get("env_steps"))):
        if v is not None:
            entry = model.metadata_props.add()
            entry.key, entry.value = k, str(v)
    onnx.checker.check_model(model)
    return model


def sidecar(policy: Policy, onnx_bytes: bytes | None = None) -> dict[str, Any]:
    """The JSON sidecar of the policy (mjx_stairs.tools.sidecar)."""
    try:
        return sidecar_lib.sidecar(policy, onnx_bytes)
    except sidecar_lib.SidecarError as e:
        raise ExportError(str(e)) from None


def export(checkpoint: str | os.PathLike, onnx_path: str | os.PathLike) -> dict[str, Any]:
    """Write `onnx_path` and `onnx_path + '.json'`; returns the sidecar."""
    policy = load_policy(checkpoint)
    return export_policy(policy, onnx_path)


def export_policy(policy: Policy, onnx_path: str | os.PathLike) -> dict[str, Any]:
    onnx_path = Path(onnx_path)
    data = build_onnx(policy).SerializeToString()
    side = sidecar(policy, data)
    atomic.write_bytes(onnx_path, data)
    atomic.write_text(sidecar_path(onnx_path), json.dumps(side, indent=2) + "\n")
    return side


def sidecar_path(onnx_path: str | os.PathLike) -> Path:
    p = Path(onnx_path)
    return p.with_name(p.name + ".json")


def verify(policy: Policy, onnx_path: str | os.PathLike, n: int = 64,
           seed: int = 0) -> float:
    """The largest difference between onnxruntime and JAX over `n` random observations (normal,
    std 3: many beyond the normaliser's clip) in the action a robot applies, clipped to the
    sidecar's `action.clip` as the env and the sidecar's rule clip it, relative to the largest raw
    action (at least 1). Random observations drive some policies' raw outputs to hundreds (the
    paper-setting stage-2 policies: up to 400), and float32's roundoff grows with the magnitudes
    the network computes: 5e-5 absolute inside the clip there, 1e-7 of the largest output."""
    try:
        import onnxruntime as ort
    except ImportError:
        raise ExportError("verifying needs onnxruntime: pip install 'mjx_stairs[export]'"
                          ) from None
    rng = np.random.default_rng(seed)
    obs = (3.0 * rng.standard_normal((n, policy.layout.obs_size))).astype(np.float32)
    sess = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    got = sess.run(["action"], {"obs": obs})[0]
    want = np.asarray(jax.jit(lambda o: policy_action(policy, o))(obs))
    try:
        c = float(json.loads(sidecar_path(onnx_path).read_text())["action"]["clip"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ExportError(f"{sidecar_path(onnx_path)}: no readable action.clip ({e})") from None
    diff = float(np.max(np.abs(np.clip(got, -c, c) - np.clip(want, -c, c))))
    return diff / max(1.0, float(np.max(np.abs(want))))


# What a robot's perception gives the policy without changing the network's input: settings of
# the observation that `export --observation` may change (the wall rule: docs/deploy.md,
# "Nothing behind a wall"; docs/results.md 8x: a policy trained without it does better with it).
OBSERVATION_KEYS = ("height_map.occlusion_samples", "height_map.sensor_height")
# What the robot's joint controller sets: `export --pd kd=VALUE`, the PD's damping gain, which
# adds to the joints' own damping, and `kd_per_delay=VALUE`, its rise per second of the robot's
# action delay (docs/deploy.md, "The PD's damping for a measured latency").
PD_KEYS = ("kd", "kd_per_delay")


def _with_env(policy: Policy, overrides: Sequence[str], flag: str, meta_key: str,
              **first: Any) -> Policy:
    """The policy with its saved env config changed by `overrides` (checked by the caller),
    listed in its metadata under `meta_key`, and each `first` entry set where the metadata has
    none yet; a value the config refuses is an ExportError."""
    try:
        cfg = env_config_from(saved_config(policy, "env"), overrides)
    except ConfigError as e:
        raise ExportError(f"{flag}: {e}") from None
    meta = dict(policy.metadata)
    meta["config"] = {**meta.get("config", {}), "env": to_dict(cfg)}
    meta[meta_key] = [*meta.get(meta_key, []), *overrides]
    return policy._replace(metadata={**first, **meta})


def with_observation(policy: Policy, overrides: Sequence[str]) -> Policy:
    """The policy with its saved env config's observation settings changed (KEY=VALUE, KEY in
    OBSERVATION_KEYS), the change listed in its metadata (`observation_overrides`) so that the
    sidecar says it was not trained with it; a bad item is an ExportError."""
    if not overrides:
        return policy
    for item in overrides:
        if item.partition("=")[0].strip() not in OBSERVATION_KEYS or "=" not in item:
            raise ExportError(f"--observation '{item}': expected KEY=VALUE with KEY one of "
                              f"{', '.join(OBSERVATION_KEYS)}")
    return _with_env(policy, overrides, "--observation", "observation_overrides")


def with_pd(policy: Policy, items: Sequence[str]) -> Policy:
    """The policy with its PD gains changed for the robot (KEY=VALUE, KEY in PD_KEYS, a finite
    value >= 0), listed in its metadata (`pd_overrides`, as `robot.KEY=VALUE`) beside the gains
    it trained with (`pd_trained`), which the sidecar reports; a bad item is an ExportError."""
    if not items:
        return policy
    overrides = []
    for item in items:
        key, eq, value = (part.strip() for part in item.partition("="))
        if key not in PD_KEYS or not eq:
            raise ExportError(f"--pd '{item}': expected KEY=VALUE with KEY one of "
                              f"{', '.join(PD_KEYS)}")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if not (np.isfinite(number) and number >= 0):
            raise ExportError(f"--pd '{item}': {key} must be a finite number >= 0")
        overrides.append(f"robot.{key}={number}")
    trained = env_config_from(saved_config(policy, "env")).robot
    return _with_env(policy, overrides, "--pd", "pd_overrides",
                     pd_trained=sidecar_lib.pd_gains(trained))


def export_command(checkpoint: str, onnx_path: str, check: bool = False,
                   observation: Sequence[str] = (), pd: Sequence[str] = ()) -> int:
    """`mjx-stairs export`: write the graph and sidecar (with the `observation` and `pd`
    overrides, see with_observation and with_pd), optionally check them against JAX on 64 random
    observations; exit status 0, 1 (the graph disagrees) or 2 (bad input)."""
    import sys

    try:
        policy = with_pd(with_observation(load_policy(checkpoint), observation), pd)
        export_policy(policy, onnx_path)
        print(f"wrote {onnx_path} and {sidecar_path(onnx_path)}", flush=True)
        if check:
            err = verify(policy, onnx_path)
            print(f"onnxruntime vs JAX on 64 random observations: max |diff| of the applied "
                  f"action = {err:.2e} of the largest raw action", flush=True)
            if err > 1e-5:
                print("mjx-stairs export: error: the ONNX graph does not match the policy",
                      file=sys.stderr)
                return 1
    except ExportError as e:
        print(f"mjx-stairs export: error: {e}", file=sys.stderr)
        return 2
    return 0
