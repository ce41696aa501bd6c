"""Atomic pytree checkpoints: one .npz per checkpoint, tree paths as keys, JSON metadata inside.

File layout: every leaf is stored under its ``jax.tree_util.keystr`` path (e.g.
``.params['actor'][0]['w']``); the metadata dict is stored as UTF-8 JSON bytes under
``__metadata__``, and the list of leaf keys in order under ``__keys__`` (inside the metadata).
Typed PRNG key leaves are stored as their raw key data and re-wrapped on load.

Writes go to a temporary file in the same directory, are fsynced and then ``os.replace``d over
the target, so a crash leaves either the old or the new file, never a torn one. Every load
error is a ``CheckpointError`` with one line naming the file and what is wrong.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

META_KEY = "__metadata__"


class CheckpointError(Exception):
    """A checkpoint is missing, unreadable or does not fit the expected structure."""


def _flatten(tree: Any) -> tuple[list[str], list[Any]]:
    paths_leaves, _ = jax.tree_util.tree_flatten_with_path(tree)
    keys = [jax.tree_util.keystr(p) for p, _ in paths_leaves]
    return keys, [leaf for _, leaf in paths_leaves]


def _is_key(x: Any) -> bool:
    dtype = getattr(x, "dtype", None)
    return dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)


def save(path: str | Path, tree: Any, metadata: dict[str, Any] | None = None) -> None:
    """Atomically write ``tree`` (arrays only) and JSON-serialisable ``metadata`` to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    keys, leaves = _flatten(tree)
    if len(set(keys)) != len(keys):
        raise CheckpointError(f"{path}: duplicate tree paths in the pytree")
    arrays: dict[str, np.ndarray] = {}
    key_impls: dict[str, str] = {}
    for k, leaf in zip(keys, leaves, strict=True):
        if _is_key(leaf):
            key_impls[k] = str(jax.random.key_impl(leaf))
            leaf = jax.random.key_data(leaf)
        arrays[k] = np.asarray(jax.device_get(leaf))
    meta = dict(metadata or {})
    meta["__keys__"] = keys
    meta["__prng_keys__"] = key_impls
    arrays[META_KEY] = _meta_entry(meta)
    _write(path, arrays)


def _meta_entry(meta: dict[str, Any]) -> np.ndarray:
    """The metadata dict as the UTF-8 JSON bytes stored under META_KEY."""
    return np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)


def _write(path: Path, arrays: dict[str, np.ndarray], compressed: bool = False) -> None:
    """Write ``arrays`` to ``path`` atomically: a temporary file beside it, fsynced, replaced."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            (np.savez_compressed if compressed else np.savez)(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    try:
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:  # pragma: no cover - some filesystems refuse directory fsync
        pass


def _open(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    if not path.exists():
        raise CheckpointError(f"{path}: checkpoint file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise CheckpointError(f"{path}: corrupt or unreadable checkpoint ({e})") from None
    if META_KEY not in arrays:
        raise CheckpointError(f"{path}: not a checkpoint (no {META_KEY} entry)")
    try:
        meta = json.loads(arrays.pop(META_KEY).tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"{path}: corrupt metadata ({e})") from None
    return arrays, meta


def load_metadata(path: str | Path) -> dict[str, Any]:
    """Only the metadata dict of a checkpoint."""
    return _open(Path(path))[1]


def compact(src: str | Path, dst: str | Path, zero: tuple[str, ...] = (),
            set_to: dict[str, Any] | None = None) -> None:
    """Rewrite checkpoint ``src`` to ``dst`` (may be ``src``) compressed, with the entries named
    in ``zero`` (tree paths, e.g. ``".env_state['obs']"``) set to zeros of their shape and dtype
    and those in ``set_to`` to the values given (each broadcast to the entry's shape and dtype);
    metadata and every other entry unchanged, written atomically. For a training state that must
    travel: its observation buffer is the largest entry and compresses worst (a resumed run's first
    step then acts on a zero observation); ``set_to``: a state changed before it is resumed (e.g.
    experiments/reset_state_std.py). A name that is not an entry is an error."""
    src, dst = Path(src), Path(dst)
    arrays, meta = _open(src)
    values = {k: 0 for k in zero} | dict(set_to or {})
    missing = [k for k in values if k not in arrays]
    if missing:
        verb = "zero" if missing[0] in zero else "set"
        raise CheckpointError(f"{src}: no entry {missing[0]} to {verb}")
    for k, v in values.items():
        arrays[k] = np.broadcast_to(np.asarray(v), arrays[k].shape).astype(arrays[k].dtype)
    arrays[META_KEY] = _meta_entry(meta)
    dst.parent.mkdir(parents=True, exist_ok=True)
    _write(dst, arrays, compressed=True)


def load(path: str | Path, template: Any = None,
         zero_if_missing: Callable[[str], bool] | None = None) -> tuple[Any, dict[str, Any]]:
    """Read a checkpoint; returns (tree, metadata).

    With ``template`` (a pytree of arrays or ``jax.ShapeDtypeStruct``s, e.g. from
    ``jax.eval_shape``) the stored leaves must have exactly the template's tree paths, shapes and
    dtypes, and the result has the template's structure (numpy leaves; typed PRNG keys
    re-wrapped). Without a template the result is a flat ``{tree path: np.ndarray}`` dict.
    ``zero_if_missing(tree path)``: a template entry the file lacks that may start as zeros
    (e.g. a per-step metric that a later version added, which the env rewrites every step).
    """
    path = Path(path)
    arrays, meta = _open(path)
    keys = meta.get("__keys__", [])
    key_impls = meta.get("__prng_keys__", {})
    if sorted(keys) != sorted(arrays):
        raise CheckpointError(f"{path}: stored arrays do not match its key list (corrupt file)")
    if template is None:
        return {k: arrays[k] for k in keys}, meta
    t_keys, t_leaves = _flatten(template)
    for k, t in zip(t_keys, t_leaves, strict=True):
        if k not in arrays and zero_if_missing is not None and zero_if_missing(k) \
                and not _is_key(t):
            arrays[k] = np.zeros(t.shape, t.dtype)
    missing = [k for k in t_keys if k not in arrays]
    extra = [k for k in keys if k not in set(t_keys)]
    if missing or extra:
        parts = []
        if missing:
            parts.append(f"missing {len(missing)} entries (first: {missing[0]})")
        if extra:
            parts.append(f"{len(extra)} unexpected entries (first: {extra[0]})")
        raise CheckpointError(f"{path}: structure mismatch: {'; '.join(parts)}")
    leaves = []
    for k, t in zip(t_keys, t_leaves, strict=True):
        a = arrays[k]
        want_dtype = t.dtype
        if _is_key(t):
            want_shape = tuple(jax.eval_shape(jax.random.key_data, t).shape)
            if tuple(a.shape) != want_shape or k not in key_impls:
                raise CheckpointError(
                    f"{path}: {k}: PRNG key data of shape {a.shape}, expected {want_shape}"
                )
            leaves.append(jax.random.wrap_key_data(a, impl=key_impls[k]))
            continue
        if tuple(a.shape) != tuple(t.shape):
            raise CheckpointError(
                f"{path}: {k}: shape {tuple(a.shape)} does not match expected {tuple(t.shape)}"
            )
        if np.dtype(a.dtype) != np.dtype(want_dtype):
            raise CheckpointError(f"{path}: {k}: dtype {a.dtype} does not match {want_dtype}")
        leaves.append(a)
    treedef = jax.tree_util.tree_structure(template)
    return jax.tree_util.tree_unflatten(treedef, leaves), meta


def checkpoint_path(directory: str | Path, iteration: int) -> Path:
    return Path(directory) / f"state_{iteration:08d}.npz"


def list_checkpoints(directory: str | Path) -> list[Path]:
    """Full-state checkpoints in ``directory``, oldest first."""
    d = Path(directory)
    if not d.is_dir():
        return []
    return sorted(d.glob("state_*.npz"))


def latest_checkpoint(directory: str | Path) -> Path | None:
    found = list_checkpoints(directory)
    return found[-1] if found else None


def prune(directory: str | Path, keep: int) -> None:
    """Delete all but the newest ``keep`` full-state checkpoints (keep <= 0 keeps all)."""
    if keep <= 0:
        return
    for p in list_checkpoints(directory)[:-keep]:
        p.unlink(missing_ok=True)
