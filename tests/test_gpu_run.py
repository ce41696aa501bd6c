"""experiments/gpu/run.sh, the GPU host's step runner: valid bash, and its header names every step
its case statement runs (issue 20: the one-off session scripts became named steps)."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

RUN = Path(__file__).resolve().parents[1] / "experiments" / "gpu" / "run.sh"


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_run_sh_parses():
    subprocess.run(["bash", "-n", str(RUN)], check=True)


def test_header_names_every_step():
    text = RUN.read_text()
    header = " ".join(line[1:] for line in text.split("set -uo pipefail")[0].splitlines()
                      if line.startswith("#"))
    body = text.split('for step in "$@"; do')[1]
    steps = set()
    for pattern in re.findall(r"^    ([a-z0-9|-]+)\)", body, flags=re.M):
        steps.update(pattern.split("|"))
    assert {"fidelity", "ground-truth", "sim2sim", "transfer-eval", "rq1-eval"} <= steps
    missing = sorted(s for s in steps if not re.search(rf"(?<![\w-]){re.escape(s)}(?![\w-])",
                                                       header))
    assert not missing, f"steps missing from run.sh's header: {missing}"
