"""python -m terrains: preview, export, import, atlas."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import terrains
from terrains import Atlas, Tile
from terrains.__main__ import run


def test_preview_png(tmp_path):
    out = tmp_path / "p.png"
    assert run(["preview", "u_shaped", "--level", "3", "--variant", "right",
                "--resolution", "0.05", "--out", str(out)]) == 0
    img = Image.open(out)
    assert img.size == (600, 600)
    px = np.asarray(img.convert("RGB"), float)
    assert px.std() > 10  # not blank


def test_export_import_round_trip(tmp_path):
    mesh, tile = tmp_path / "s.obj", tmp_path / "s.npz"
    assert run(["export", "straight", "--level", "4", "--resolution", "0.05",
                "--out", str(mesh)]) == 0
    t = terrains.make_tile("straight", 3, resolution=0.05)
    start = f"{t.spawn[0]},{t.spawn[1]}"
    goal = f"{t.goal[0]},{t.goal[1]}"
    assert run(["import", str(mesh), "--start", start, "--goal", goal, "--resolution", "0.05",
                "--out", str(tile), "--preview", str(tmp_path / "s.png")]) == 0
    back = Tile.load(tile)
    assert np.abs(back.heights - t.heights).max() <= terrains.HEIGHT_QUANTUM
    assert (tmp_path / "s.png").stat().st_size > 1000


def test_atlas_command(tmp_path):
    out = tmp_path / "a.npz"
    assert run(["atlas", "u_shaped", "spiral", "--levels", "1,10", "--variants", "1",
                "--resolution", "0.1", "--out", str(out)]) == 0
    a = Atlas.load(out)
    assert (a.rows, a.cols) == (2, 2) and list(a.level[::2]) == [0, 9]
    assert run(["export", str(out), "--out", str(tmp_path / "a.stl")]) == 0


@pytest.mark.parametrize("args,msg", [
    (["preview", "stairs", "--level", "1", "--out", "x.png"], "unknown terrain family 'stairs'"),
    (["preview", "u_shaped", "--level", "11", "--out", "x.png"], "--level 11 out of range"),
    (["import", "missing.obj", "--start", "0,0", "--goal", "1,1", "--out", "t.npz"],
     "missing.obj: no such mesh file"),
])
def test_errors_are_one_line_exit_2(args, msg, tmp_path):
    r = subprocess.run([sys.executable, "-m", "terrains", *args], cwd=tmp_path,
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert msg in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_main_returns_status(tmp_path, capsys):
    from terrains.__main__ import main
    assert main(["preview", "spiral", "--level", "2", "--resolution", "0.1",
                 "--out", str(tmp_path / "s.png")]) == 0
    assert main(["export", "u_shaped", "--level", "0", "--out", str(tmp_path / "u.glb")]) == 2
    assert "--level 0 out of range" in capsys.readouterr().err
