"""Checkpoints: round trip, atomic writes, clear errors for missing/corrupt/mismatched files."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_stairs.rl import checkpoint
from mjx_stairs.rl.checkpoint import CheckpointError
from mjx_stairs.rl.normalizer import init_stats


def _tree():
    return {
        "params": {"w": jnp.arange(6.0).reshape(2, 3), "layers": [{"b": jnp.ones(3)}]},
        "stats": init_stats(4),
        "counter": jnp.asarray(7, jnp.int32),
        "metrics": {"reward/feet air": jnp.zeros(5)},
        "key": jax.random.PRNGKey(3),
        "typed_key": jax.random.split(jax.random.key(1), 2),
    }


def test_round_trip_with_template(tmp_path):
    tree = _tree()
    path = tmp_path / "sub" / "ck.npz"
    checkpoint.save(path, tree, {"iteration": 3, "note": "x"})
    assert [p.name for p in path.parent.iterdir()] == ["ck.npz"]  # no temp file left behind
    template = jax.eval_shape(lambda: _tree())
    out, meta = checkpoint.load(path, template)
    assert meta["iteration"] == 3 and meta["note"] == "x"
    assert jax.tree_util.tree_structure(out) == jax.tree_util.tree_structure(tree)
    for a, b in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(tree), strict=True):
        if jax.dtypes.issubdtype(b.dtype, jax.dtypes.prng_key):
            a, b = jax.random.key_data(a), jax.random.key_data(b)
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    flat, _ = checkpoint.load(path)
    assert "['params']['w']" in flat
    assert checkpoint.load_metadata(path)["note"] == "x"


def test_overwrite_is_atomic_replace(tmp_path):
    path = tmp_path / "ck.npz"
    checkpoint.save(path, {"a": jnp.zeros(2)}, {"v": 1})
    checkpoint.save(path, {"a": jnp.ones(2)}, {"v": 2})
    out, meta = checkpoint.load(path, {"a": jnp.zeros(2)})
    assert meta["v"] == 2 and float(out["a"][0]) == 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ck.npz"]


def test_missing_file(tmp_path):
    with pytest.raises(CheckpointError, match=r"nothere\.npz: checkpoint file not found"):
        checkpoint.load(tmp_path / "nothere.npz")


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_corrupt_file(tmp_path, damage):
    path = tmp_path / "ck.npz"
    checkpoint.save(path, _tree(), {})
    data = path.read_bytes()
    if damage == "truncate":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        path.write_bytes(b"not a zip file at all" * 10)
    else:
        path.write_bytes(b"")
    with pytest.raises(CheckpointError) as e:
        checkpoint.load(path, jax.eval_shape(_tree))
    msg = str(e.value)
    assert "ck.npz" in msg and ("corrupt" in msg or "not a checkpoint" in msg)
    assert "\n" not in msg


def test_plain_npz_without_metadata(tmp_path):
    path = tmp_path / "plain.npz"
    np.savez(path, a=np.zeros(2))
    with pytest.raises(CheckpointError, match="plain.npz: not a checkpoint"):
        checkpoint.load(path)


def test_shape_mismatch_names_the_entry(tmp_path):
    path = tmp_path / "ck.npz"
    checkpoint.save(path, _tree(), {})
    template = jax.eval_shape(_tree)
    template["params"]["w"] = jax.ShapeDtypeStruct((3, 3), jnp.float32)
    with pytest.raises(CheckpointError,
                       match=r"ck\.npz: \['params'\]\['w'\]: shape \(2, 3\) does not match "
                             r"expected \(3, 3\)"):
        checkpoint.load(path, template)


def test_dtype_mismatch(tmp_path):
    path = tmp_path / "ck.npz"
    checkpoint.save(path, {"a": jnp.zeros(2, jnp.int32)}, {})
    with pytest.raises(CheckpointError, match="dtype int32 does not match float32"):
        checkpoint.load(path, {"a": jax.ShapeDtypeStruct((2,), jnp.float32)})


def test_structure_mismatch(tmp_path):
    path = tmp_path / "ck.npz"
    checkpoint.save(path, _tree(), {})
    template = jax.eval_shape(_tree)
    template["params"]["extra"] = jax.ShapeDtypeStruct((1,), jnp.float32)
    with pytest.raises(CheckpointError, match=r"structure mismatch: missing 1 entries "
                                              r"\(first: \['params'\]\['extra'\]\)"):
        checkpoint.load(path, template)
    template = jax.eval_shape(_tree)
    del template["counter"]
    with pytest.raises(CheckpointError, match=r"1 unexpected entries \(first: \['counter'\]\)"):
        checkpoint.load(path, template)


def test_listing_and_pruning(tmp_path):
    for it in (10, 2, 30):
        checkpoint.save(checkpoint.checkpoint_path(tmp_path, it), {"a": jnp.zeros(1)}, {})
    assert checkpoint.latest_checkpoint(tmp_path).name == "state_00000030.npz"
    checkpoint.prune(tmp_path, 2)
    assert [p.name for p in checkpoint.list_checkpoints(tmp_path)] == [
        "state_00000010.npz", "state_00000030.npz"]
    assert checkpoint.latest_checkpoint(tmp_path / "none") is None


def test_compact_zeroes_named_entries_and_keeps_the_rest(tmp_path):
    """compact: compressed, the named entry zeroed, every other leaf and the metadata kept, and a
    template load of the result still works; a name that is not an entry is a one-line error."""
    big = np.tile(np.linspace(0.0, 1.0, 64, dtype=np.float32), (256, 1))
    tree = {"obs": jnp.asarray(np.random.default_rng(0).normal(size=(256, 64)).astype(np.float32)),
            "w": jnp.asarray(big), "key": jax.random.key(3)}
    src, dst = tmp_path / "state.npz", tmp_path / "small" / "state.npz"
    checkpoint.save(src, tree, {"iteration": 7})
    checkpoint.compact(src, dst, zero=("['obs']",))
    out, meta = checkpoint.load(dst, template=jax.eval_shape(lambda: tree))
    assert meta["iteration"] == 7
    assert np.all(out["obs"] == 0) and out["obs"].shape == (256, 64)
    np.testing.assert_array_equal(out["w"], big)
    assert jnp.array_equal(jax.random.key_data(out["key"]), jax.random.key_data(tree["key"]))
    assert dst.stat().st_size < src.stat().st_size / 4
    with pytest.raises(CheckpointError, match="no entry"):
        checkpoint.compact(src, dst, zero=("['nope']",))
    # set_to: a value broadcast to the entry's shape and dtype, the rest as before
    checkpoint.compact(src, dst, zero=("['obs']",), set_to={"['w']": 0.5})
    out, _ = checkpoint.load(dst, template=jax.eval_shape(lambda: tree))
    assert np.all(out["w"] == 0.5) and out["w"].dtype == jnp.float32 and np.all(out["obs"] == 0)
    with pytest.raises(CheckpointError, match="no entry .* to set"):
        checkpoint.compact(src, dst, set_to={"['nope']": 1.0})
