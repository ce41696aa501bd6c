"""Several processes, one training run: ``jax.distributed`` set up from environment variables.

Every process runs the same program on its local devices; the mesh (rl.sharding) spans the
devices of all processes, so each compiled chunk sees one global batch of robots and XLA reduces
gradients, the observation normaliser and the metrics over every device of every process (the
NCCL backend on GPUs, gloo on CPUs). Process 0 alone writes logs, checkpoints and published
files; the others compute and take part in the collectives (gathers, agreed stops).

The variables, read before any JAX computation (``initialize_from_env``)::

    MJX_STAIRS_COORDINATOR   host:port of process 0's coordinator  (or JAX_COORDINATOR_ADDRESS)
    MJX_STAIRS_NUM_PROCESSES number of processes                    (or JAX_NUM_PROCESSES)
    MJX_STAIRS_PROCESS_ID    this process's index, 0 .. n - 1       (or JAX_PROCESS_ID)

None set: one process, nothing to initialise. A coordinator without the other two: JAX's own
cluster detection (SLURM, Open MPI, ...) supplies them. One GPU per process on one host:
``CUDA_VISIBLE_DEVICES=<id>`` per process (or JAX_LOCAL_DEVICE_IDS, which JAX reads itself).
"""

from __future__ import annotations

import os
from typing import Mapping

import jax
import numpy as np

VARIABLES = {  # ours first, then JAX's names
    "coordinator": ("MJX_STAIRS_COORDINATOR", "JAX_COORDINATOR_ADDRESS"),
    "num_processes": ("MJX_STAIRS_NUM_PROCESSES", "JAX_NUM_PROCESSES"),
    "process_id": ("MJX_STAIRS_PROCESS_ID", "JAX_PROCESS_ID"),
}
TEXT_BYTES = 4096  # room for one path or stop reason in the host collectives below


def settings_from_env(environ: Mapping[str, str] | None = None) -> dict[str, str | int] | None:
    """{coordinator, num_processes, process_id} from the variables (missing ones left out), or
    None when no coordinator is named (a single process)."""
    environ = os.environ if environ is None else environ
    found: dict[str, str | int] = {}
    for key, names in VARIABLES.items():
        value = next((environ[n] for n in names if environ.get(n)), None)
        if value is None:
            continue
        try:
            found[key] = value if key == "coordinator" else int(value)
        except ValueError:
            raise ValueError(f"{names[0]}={value!r} is not an integer") from None
    if "coordinator" not in found:
        if found:
            names = ", ".join(VARIABLES[k][0] for k in sorted(found))
            raise ValueError(f"{names} set without {VARIABLES['coordinator'][0]}")
        return None
    return found


def initialize_from_env(environ: Mapping[str, str] | None = None) -> bool:
    """``jax.distributed.initialize`` from the variables (module docstring); True when it ran.
    Call it first, before any JAX computation; a second call is a no-op."""
    found = settings_from_env(environ)
    if found is None or jax.distributed.is_initialized():
        return False
    jax.distributed.initialize(
        coordinator_address=str(found["coordinator"]),
        num_processes=found.get("num_processes"),
        process_id=found.get("process_id"),
    )
    return True


def is_main() -> bool:
    """Whether this process writes logs, checkpoints and published files (process 0)."""
    return jax.process_index() == 0


def gather_text(text: str) -> list[str]:
    """Every process's ``text``, in process order (a host collective: all processes call it)."""
    if jax.process_count() == 1:
        return [text]
    from jax.experimental import multihost_utils

    raw = text.encode("utf-8")
    if len(raw) > TEXT_BYTES:
        raise ValueError(f"gather_text: {len(raw)} bytes, at most {TEXT_BYTES}")
    buf = np.zeros(TEXT_BYTES, np.uint8)
    buf[: len(raw)] = np.frombuffer(raw, np.uint8)
    rows = np.asarray(multihost_utils.process_allgather(buf)).reshape(-1, TEXT_BYTES)
    return [bytes(r).rstrip(b"\0").decode("utf-8") for r in rows]


def main_text(text: str) -> str:
    """Process 0's ``text`` on every process (e.g. the run directory it chose)."""
    return gather_text(text)[0]


def agree(reason: str) -> str:
    """The stop reason every process acts on: the first non-empty one in process order, so a
    signal or a time budget seen by any process stops all of them after the same chunk."""
    return next((r for r in gather_text(reason) if r), "")
