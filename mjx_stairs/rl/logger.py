"""Run directories, JSONL + TensorBoard metrics, and the console block printed per chunk."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

from mjx_stairs import atomic

RUN_TIME_FORMAT = "%Y%m%d-%H%M%S"


def run_name(experiment: str, seed: int, when: float | None = None) -> str:
    """``<experiment>__<seed>__<YYYYmmdd-HHMMSS>`` (CleanRL style)."""
    stamp = time.strftime(RUN_TIME_FORMAT, time.localtime(time.time() if when is None else when))
    return f"{experiment}__{seed}__{stamp}"


def new_run_dir(log_dir: str | Path, experiment: str, seed: int) -> Path:
    """Create a fresh run directory under ``log_dir`` (adds a suffix if the name is taken)."""
    base = Path(log_dir) / run_name(experiment, seed)
    path, i = base, 1
    while path.exists():
        path = base.with_name(f"{base.name}-{i}")
        i += 1
    path.mkdir(parents=True)
    return path


def latest_run_dir(log_dir: str | Path, experiment: str, seed: int) -> Path | None:
    """The newest ``<experiment>__<seed>__*`` directory under ``log_dir``, if any."""
    found = sorted(Path(log_dir).glob(f"{experiment}__{seed}__*"))
    found = [p for p in found if p.is_dir()]
    return found[-1] if found else None


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


class MetricsLogger:
    """Appends one JSON line per chunk to ``metrics.jsonl`` and scalars to TensorBoard."""

    def __init__(self, run_dir: str | Path, tensorboard: bool = True):
        self.run_dir = Path(run_dir)
        self.jsonl_path = self.run_dir / "metrics.jsonl"
        self._jsonl = self.jsonl_path.open("a", encoding="utf-8")
        self._tb = None
        if tensorboard:
            from tensorboardX import SummaryWriter

            self._tb = SummaryWriter(str(self.run_dir / "tb"))

    def log(self, record: dict[str, Any], step: int) -> None:
        """Write a flat dict of scalars; ``step`` (env steps) is TensorBoard's x axis."""
        self._jsonl.write(json.dumps({k: _jsonable(v) for k, v in record.items()}) + "\n")
        self._jsonl.flush()
        if self._tb is not None:
            for k, v in record.items():
                if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                    self._tb.add_scalar(k, v, global_step=step)
            self._tb.flush()

    def close(self) -> None:
        self._jsonl.close()
        if self._tb is not None:
            self._tb.close()


def read_jsonl(path: str | Path) -> list[dict[str, Any]]:
    """The records of a JSON-lines file; a clear error naming a missing file or a broken line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: metrics file not found")
    rows = []
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            raise ValueError(f"{path}:{n}: not a JSON line") from None
    return rows


def truncate_jsonl(path: str | Path, max_iteration: int) -> None:
    """Drop lines logged after ``max_iteration`` (used on resume from an older checkpoint)."""
    path = Path(path)
    if not path.exists():
        return
    keep = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            if json.loads(line).get("iteration", 0) <= max_iteration:
                keep.append(line)
        except json.JSONDecodeError:
            continue
    atomic.write_text(path, "".join(x + "\n" for x in keep))


HEADLINE = ("episode/return", "episode/length", "level", "success")


def console_block(record: dict[str, Any], total_iterations: int) -> str:
    """rsl_rl-style block: a title line, the headline numbers, then every other metric."""
    it = record.get("iteration", 0)
    title = (
        f" iteration {it}/{total_iterations} | {record.get('env_steps', 0):,} env steps | "
        f"{record.get('perf/steps_per_s', 0.0):,.0f} steps/s | "
        f"chunk {record.get('perf/chunk_s', 0.0):.2f} s "
    )
    width = max(len(title) + 4, 72)
    lines = [title.center(width, "-")]
    skip = {"iteration", "env_steps", "perf/steps_per_s", "perf/chunk_s"}
    keys = [k for k in HEADLINE if k in record] + sorted(
        k for k in record if k not in HEADLINE and k not in skip
    )
    for k in keys:
        v = record[k]
        if isinstance(v, float):
            lines.append(f"{k:>36s}: {v:.5g}")
        else:
            lines.append(f"{k:>36s}: {v}")
    return "\n".join(lines)


class RunLogger:
    """What a run shows and keeps per chunk: metrics.jsonl + TensorBoard (MetricsLogger), a tqdm
    bar of env steps and an rsl_rl-style console block."""

    def __init__(self, run_dir: str | Path, *, steps_per_iteration: int, iteration: int,
                 target_iteration: int, tensorboard: bool, progress: bool, console: bool):
        self.metrics = MetricsLogger(run_dir, tensorboard=tensorboard)
        self.steps_per_iteration = steps_per_iteration
        self.iteration = iteration
        self.target_iteration = target_iteration
        self.console = console
        self.bar = None
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=target_iteration * steps_per_iteration,
                            initial=iteration * steps_per_iteration, unit="step",
                            unit_scale=True, dynamic_ncols=True)

    def log(self, record: dict[str, Any]) -> None:
        """One chunk's record (with "iteration" and "env_steps")."""
        self.metrics.log(record, step=record["env_steps"])
        done = record["iteration"] - self.iteration
        self.iteration = record["iteration"]
        if self.bar is not None:
            self.bar.update(done * self.steps_per_iteration)
            post = {"ret": f"{record['episode/return']:.3g}"}
            for k in ("level", "success"):
                if k in record:
                    post[k] = f"{record[k]:.3g}"
            self.bar.set_postfix(post, refresh=False)
        if self.console:
            text = console_block(record, self.target_iteration)
            if self.bar is not None:
                self.bar.write(text)
            else:
                print(text, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        self.metrics.close()


class SilentLogger:
    """RunLogger's stand-in on processes other than 0 (rl.distributed): shows and keeps nothing."""

    def log(self, record: dict[str, Any]) -> None:
        pass

    def close(self) -> None:
        pass
