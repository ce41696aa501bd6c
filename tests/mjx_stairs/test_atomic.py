"""Atomic writes: the target is either the old file or the complete new one, never a part."""

import pytest

from mjx_stairs import atomic


def test_write_replaces_and_failure_leaves_target(tmp_path):
    target = tmp_path / "sub" / "results.json"
    atomic.write_text(target, "old")
    assert target.read_text() == "old"
    with pytest.raises(RuntimeError):
        with atomic.atomic_path(target) as tmp:
            assert tmp.suffix == ".json" and tmp.parent == target.parent
            tmp.write_text("half")
            raise RuntimeError("writer crashed")
    assert target.read_text() == "old"
    assert [p.name for p in target.parent.iterdir()] == ["results.json"]  # no temp file left
    atomic.write_bytes(target, b"new")
    assert target.read_bytes() == b"new"
    atomic.copy_file(target, tmp_path / "copy.json")
    assert (tmp_path / "copy.json").read_bytes() == b"new"
