"""experiments/sim2sim_generalist_table.py: every committed generalist sim2sim folder's table.md
has the rows its cell files give (docs/deploy.md quotes those tables)."""

import hashlib
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = sorted((ROOT / "experiments/results/sim2sim").glob("generalist*"))
spec = importlib.util.spec_from_file_location(
    "sim2sim_generalist_table", ROOT / "experiments/sim2sim_generalist_table.py")
tables = importlib.util.module_from_spec(spec)
spec.loader.exec_module(tables)


def test_the_folders_are_there():
    names = {p.name for p in FOLDERS}
    assert {"generalist", "generalist_latency20", "generalist_first_run",
            "generalist_first_run_latency20", "generalist_first_run_latency10",
            "generalist_first_run_damping01"} <= names


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_table_md_matches_the_cell_files(folder):
    committed = (folder / "table.md").read_text().split("\n\n")[0]
    assert tables.table(folder).split("\n\n")[0] == committed


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _policy_folder(name: str) -> str:
    """generalist_first_run*/ hold the first run's cells, generalist_line*/ the second run's
    (generalist_line/), the other generalist*/ the first run's successor (generalist/)."""
    for prefix, policy in (("generalist_first_run", "generalist/first_run"),
                           ("generalist_line", "generalist_line")):
        if name.startswith(prefix):
            return policy
    return "generalist"


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_each_folder_is_its_policys(folder):
    policy = ROOT / f"experiments/results/{_policy_folder(folder.name)}/policy.onnx"
    assert {d["onnx_sha256"] for _, d in tables._cells(folder)} == {_sha(policy)}


def test_the_current_policy_has_all_twelve_cells_with_and_without_latency():
    for name in ("generalist", "generalist_latency20"):
        cells = tables._cells(ROOT / "experiments/results/sim2sim" / name)
        assert [c for c, _ in cells] == [f"u_shaped_test_{d}_L{lv}" for d in ("down", "up")
                                         for lv in range(1, 7)]
