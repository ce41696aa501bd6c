"""Levels, the sampler, tile persistence and error messages."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import terrains
from terrains import Tile, sample_heights


def test_schedules_have_the_protocol_figures():
    for fam in terrains.PAPER_FAMILIES:
        assert len(terrains.levels(fam, "train")) == 10
        assert len(terrains.levels(fam, "extended")) >= 5
    assert terrains.levels("pyramid", "test") == terrains.levels("pyramid", "train")
    for fam in ("straight", "l_shaped", "u_shaped", "spiral"):
        test = terrains.levels(fam, "test")
        assert [round(lv.riser, 3) for lv in test] == [0.04, 0.06, 0.08, 0.10, 0.12, 0.14]
        assert all(lv.width == 2.0 and lv.landing == 1.4 for lv in test)
    u = terrains.levels("u_shaped", "train")
    assert (u[0].riser, u[-1].riser, u[0].width, u[-1].width) == (0.02, 0.12, 2.0, 1.4)
    assert all(lv.steps == 10 and lv.landing == 1.2 and lv.tread == 0.26 for lv in u)
    p = terrains.levels("pyramid", "train")
    assert (p[0].riser, p[-1].riser, p[0].tread) == (0.0, 0.15, 0.30)
    s = terrains.levels("straight", "train")
    assert (s[0].riser, s[-1].riser, s[0].width, s[-1].width) == (0.04, 0.14, 3.0, 1.5)
    ext = [lv for f in terrains.PAPER_FAMILIES for lv in terrains.levels(f, "extended")]
    assert max(lv.riser for lv in ext) == 0.20 and min(lv.tread for lv in ext) == 0.25
    assert min(lv.width for lv in ext if lv.width > 0) == 0.9
    for fam in terrains.PAPER_FAMILIES:  # risers grow with the level
        assert np.all(np.diff([lv.riser for lv in terrains.levels(fam, "train")]) > 0)


def test_the_tall_pyramid_rises_to_the_residential_riser_with_the_pyramid_s_rings():
    tall, low = terrains.levels("pyramid_tall", "train"), terrains.levels("pyramid", "train")
    assert len(tall) == 10 and tall[0].riser == 0.0 and tall[-1].riser == 0.21
    assert (tall[0].tread, tall[-1].tread) == (0.30, 0.25)
    assert np.all(np.diff([lv.riser for lv in tall]) > 0)
    assert np.all(np.diff([lv.tread for lv in tall]) < 0)
    assert tall[-1].riser > 0.197 > low[-1].riser   # the residential code riser, 19.7 cm
    top = terrains.make_tile("pyramid_tall", 9, "+y", resolution=0.05)
    base = terrains.make_tile("pyramid", 9, "+y", resolution=0.05)
    assert top.family == "pyramid_tall" and base.family == "pyramid"
    # the same generator: rings of 21 cm over 25 cm treads, goal on the high border
    assert top.spec["riser"] == 0.21 and top.spec["steps"] == 9
    assert top.goal_height == pytest.approx(9 * 0.21, abs=1e-3)
    assert np.unique(np.round(top.heights, 3)).size == 10   # the platform and nine rings
    down = terrains.make_tile("pyramid_tall", 9, "+y", resolution=0.05, direction="down")
    assert down.family == "pyramid_tall" and down.direction == "down"
    np.testing.assert_array_equal(down.heights, top.heights)
    assert "pyramid_tall" in terrains.FAMILIES


@pytest.mark.parametrize("fam", list(terrains.PAPER_FAMILIES))
def test_extended_levels_build(fam):
    for i in range(len(terrains.levels(fam, "extended"))):
        for v in terrains.variants(fam):
            t = terrains.make_tile(fam, i, v, schedule="extended", resolution=0.05)
            assert t.goal_height > 1.0


def test_errors_name_the_problem():
    with pytest.raises(ValueError, match=r"'stairs'.*pyramid.*spiral.*building"):
        terrains.make_tile("stairs", 0)
    with pytest.raises(ValueError, match=r"'sideways'.*left, right"):
        terrains.make_tile("u_shaped", 0, "sideways")
    with pytest.raises(ValueError, match=r"'hard'.*train, test, extended"):
        terrains.levels("u_shaped", "hard")
    with pytest.raises(ValueError, match="level 10 out of range"):
        terrains.make_tile("u_shaped", 10)
    with pytest.raises(ValueError, match="level -1 out of range"):
        terrains.make_tile("u_shaped", -1)
    with pytest.raises(ValueError, match="does not fit a 5.0 m tile"):
        terrains.make_tile("u_shaped", 0, tile_size=5.0, resolution=0.05)
    with pytest.raises(ValueError, match="resolution"):
        terrains.make_tile("u_shaped", 0, resolution=0.5)
    with pytest.raises(ValueError, match="whole multiple"):
        terrains.make_tile("u_shaped", 0, resolution=0.03)


def test_all_train_levels_fit_an_8m_tile():
    for fam in terrains.PAPER_FAMILIES:
        for i in range(10):
            t = terrains.make_tile(fam, i, resolution=0.05, tile_size=8.0)
            assert t.heights.shape == (160, 160)


def test_sampler_bilinear_exact_on_planes_and_clamped():
    res = 0.1
    iy, ix = np.mgrid[0:5, 0:7]
    h = 0.3 * ix * res - 0.2 * iy * res + 1.0          # a plane
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 0.6, 50), rng.uniform(0, 0.4, 50)
    np.testing.assert_allclose(sample_heights(h, res, x, y), 0.3 * x - 0.2 * y + 1.0, atol=1e-12)
    # at grid points it returns the grid values; outside it clamps to the edge
    assert sample_heights(h, res, 0.2, 0.3) == pytest.approx(h[3, 2])
    assert sample_heights(h, res, -5.0, 0.1) == pytest.approx(h[1, 0])
    assert sample_heights(h, res, 9.0, 9.0) == pytest.approx(h[-1, -1])
    # a bilinear (non-planar) cell: centre is the mean of the 4 corners
    g = np.array([[0.0, 1.0], [2.0, 7.0]])
    assert sample_heights(g, 1.0, 0.5, 0.5) == pytest.approx(2.5)
    assert sample_heights(g, 1.0, np.zeros((2, 3)), np.ones((2, 3))).shape == (2, 3)


def test_tile_save_load(tmp_path):
    t = terrains.make_tile("spiral", 2, "cw", resolution=0.05)
    t.save(tmp_path / "t.npz")
    b = Tile.load(tmp_path / "t.npz")
    for k in ("heights", "spawn", "goal", "centreline", "walls"):
        assert np.array_equal(getattr(t, k), getattr(b, k)), k
    assert (b.family, b.level, b.variant, b.resolution) == ("spiral", 2, "cw", 0.05)
    assert b.spec["riser"] == t.spec["riser"]
    with pytest.raises(FileNotFoundError, match="missing.npz"):
        Tile.load(tmp_path / "missing.npz")


def test_no_jax_in_terrains():
    root = Path(terrains.__file__).parent
    for py in root.rglob("*.py"):
        text = py.read_text()
        assert "import jax" not in text and "from jax" not in text, py
    code = ("import sys, terrains, terrains.atlas, terrains.preview; "
            "assert 'jax' not in sys.modules, 'jax imported'")
    subprocess.run([sys.executable, "-c", code], check=True)
