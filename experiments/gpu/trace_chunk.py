"""Profile one training chunk on the GPU and sum its kernel time by piece.

    python3 experiments/gpu/trace_chunk.py --config experiments/stage2_u_lean.toml \
        --out /tmp/out/trace_chunk.json [overrides...]

Compiles the trainer's chunk, runs it once to warm up, then runs one chunk under
``jax.profiler.trace`` with a Perfetto trace. The trace's device events are summed (a) by the
trainer's named scopes in each event's op name (``rollout``, ``ppo_update``, the rest, and whether
inside the CNN ``encoder``), (b) by the first components of that op name and (c) by HLO op (the 40
largest of each, with their op names), against the chunk's wall time; the rollout's time also by the
env step's named pieces (physics, nan_guard, contacts, rewards, auto_reset, observe; a reset's
observation counts as auto_reset) and by deeper op-name paths. Kernels can overlap on several
streams, so the sums are busy time, not wall time. cuBLAS kernels inside a CUDA graph carry no
instruction name; run with XLA_FLAGS=--xla_gpu_enable_command_buffer= to attribute them too.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import tempfile
import time

import jax

from mjx_stairs import atomic
from mjx_stairs.rl import trainer as train
from mjx_stairs.study import experiment


def _events(trace_dir: str) -> tuple[list[dict], dict[int, str]]:
    files = glob.glob(os.path.join(trace_dir, "**", "*.trace.json.gz"), recursive=True)
    if not files:
        raise SystemExit(f"no Perfetto trace under {trace_dir}")
    with gzip.open(max(files, key=os.path.getmtime)) as f:
        data = json.load(f)
    events = data["traceEvents"] if isinstance(data, dict) else data
    names = {e["pid"]: e.get("args", {}).get("name", "") for e in events
             if e.get("ph") == "M" and e.get("name") == "process_name"}
    return events, names


# named scopes of StairEnv.step, in the order a kernel's op name is matched against them
ENV_PIECES = ("physics", "nan_guard", "contacts", "rewards", "auto_reset", "observe", "encoder")
_INSTR = re.compile(r'^\s*(?:ROOT\s+)?%?([\w.\-]+) = .*?op_name="([^"]*)"')
_NOISE = re.compile(r"^(jit\(\w+\)|while|body|cond|closed_call|checkpoint|pjit\(\w*\))$")


def _op_names(hlo_text: str) -> dict[str, str]:
    """HLO instruction name -> the JAX op_name in its metadata (scopes, transformations)."""
    out = {}
    for line in hlo_text.splitlines():
        m = _INSTR.match(line)
        if m:
            out[m.group(1)] = m.group(2)
    return out


def _scope_path(op_name: str, depth: int) -> str:
    parts = [p for p in op_name.split("/") if p and not _NOISE.match(p)]
    return "/".join(parts[:depth]) or "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="experiments/stage2_u_lean.toml")
    ap.add_argument("overrides", nargs="*")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    config, _ = experiment.load(args.config, args.overrides, cpu=False)
    env = experiment.make_env(config)
    trainer = train.build_trainer(config, env)
    state = trainer.init(jax.random.PRNGKey(0))
    chunk = trainer.chunk.lower(state).compile()
    state, m = chunk(state)
    jax.block_until_ready(m)
    trace_dir = tempfile.mkdtemp(prefix="trace_")
    with jax.profiler.trace(trace_dir, create_perfetto_trace=True):
        t = time.perf_counter()
        state, m = chunk(state)
        jax.block_until_ready(m)
        wall_ms = (time.perf_counter() - t) * 1e3

    events, pnames = _events(trace_dir)
    device_pids = {p for p, n in pnames.items() if re.search(r"GPU|gpu|device", n)
                   and "host" not in n.lower()}
    if not device_pids:  # CPU backend: the XLA ops run on the host threads
        device_pids = set(pnames)
    op_names = _op_names(chunk.as_text())
    by_scope: dict[str, float] = collections.Counter()
    by_path: dict[str, float] = collections.Counter()
    by_kernel: dict[str, float] = collections.Counter()
    by_piece: dict[str, float] = collections.Counter()
    by_deep_path: dict[str, float] = collections.Counter()
    op_of_kernel: dict[str, str] = {}
    sample_args = []
    for e in events:
        hlo_op = e.get("args", {}).get("hlo_op")
        if e.get("ph") != "X" or e.get("pid") not in device_pids or not hlo_op:
            continue
        dur = float(e.get("dur", 0.0)) / 1e3  # us -> ms
        # inside a CUDA graph (command buffer) the event's name is the fused instruction's
        op_name = op_names.get(hlo_op) or op_names.get(e.get("name", ""), "")
        scope = next((s for s in ("ppo_update", "rollout") if s in op_name), "other")
        by_scope[scope] += dur
        if "encoder" in op_name:
            by_scope[scope + "/encoder"] += dur
        by_path[_scope_path(op_name, 4)] += dur
        deep = _scope_path(op_name, 8)
        if scope == "rollout":  # the env step's named pieces (mjx_stairs/env/stair_env.py)
            piece = next((p for p in ENV_PIECES  # under vmap a scope reads "vmap(name)"
                          if f"/{p}/" in f"/{op_name}/" or f"({p})" in op_name), "rest")
            by_piece[piece] += dur
            by_deep_path[deep] += dur
        kernel = f"{hlo_op} [{e.get('name', '?')[:60]}]"
        op_of_kernel[kernel] = deep
        by_kernel[kernel] += dur
        if len(sample_args) < 5:
            sample_args.append({"name": e.get("name"), "args": e["args"], "op_name": op_name})
    tc = config.train
    out = {
        "device": jax.devices()[0].device_kind, "jax": jax.__version__, "config": args.config,
        "overrides": args.overrides, "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "robots": tc.num_envs,
        "iterations": tc.iterations_per_chunk,
        "env_steps_per_s": tc.num_envs * tc.unroll_length * tc.iterations_per_chunk
        / (wall_ms / 1e3),
        "chunk_wall_ms": wall_ms,
        "device_processes": sorted(pnames[p] for p in device_pids),
        "busy_ms_by_scope": dict(by_scope),
        "busy_ms_top_scope_paths": dict(by_path.most_common(40)),
        "busy_ms_top_kernels": dict(by_kernel.most_common(40)),
        "busy_ms_rollout_by_env_piece": dict(by_piece),
        "busy_ms_rollout_top_paths": dict(by_deep_path.most_common(40)),
        "top_kernel_ops": {k: op_of_kernel[k] for k, _ in by_kernel.most_common(40)},
        "busy_ms_top_unattributed_kernels": dict(collections.Counter(
            {k: v for k, v in by_kernel.items() if op_of_kernel[k] == "?"}).most_common(20)),
        "kernels": len(by_kernel),
        "sample_event_args": sample_args,
    }
    print(json.dumps({k: v for k, v in out.items() if k != "sample_event_args"}, indent=1))
    atomic.write_text(args.out, json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
