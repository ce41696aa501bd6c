"""Imports run one way only: terrains <- sim <- env; rl knows no env; study and tools on top.

Read from the source (ast), not by importing: an import inside a function counts as well.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOP = {"mjx_stairs.config", "mjx_stairs.atomic"}  # leaf utilities every layer may use

# study/tools modules that may use more of rl than its policy files (rl.policy): the experiment
# config gathers the learner's config dataclasses; the pipelines train; the bench times the trainer
# over the devices it names
RL_BEYOND_POLICY = {
    "mjx_stairs.study.experiment": {"networks", "ppo", "trainer", "logger"},
    "mjx_stairs.study.exp1": {"runner"},
    "mjx_stairs.study.plots": {"logger"},  # reads metrics.jsonl
    "mjx_stairs.study.transfer": {"runner"},
    "mjx_stairs.study.bench": {"trainer", "rollout", "sharding"},
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Every module a file imports (absolute names; `from a import b` gives a and a.b)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return out


def _ours(names: set[str]) -> set[str]:
    """The names of mjx_stairs's layers among ``names`` (the package and TOP left out)."""
    return {n for n in names if n.startswith("mjx_stairs.")
            and not any(n == t or n.startswith(t + ".") for t in TOP)}


FILES = sorted(p for d in ("mjx_stairs", "terrains") for p in (ROOT / d).rglob("*.py"))


def _layer(name: str) -> str:
    parts = name.split(".")
    return parts[1] if parts[0] == "mjx_stairs" and len(parts) > 1 else parts[0]


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_run_the_right_way(path):
    name = _module_name(path)
    ours = _ours(_imports(path))
    layers = {_layer(n) for n in ours}
    if name.startswith("terrains"):
        assert not ours, f"{name} imports {sorted(ours)}: terrains imports nothing of mjx_stairs"
        return
    layer = _layer(name)
    allowed = {
        "sim": {"sim"},
        "env": {"sim", "env"},
        "rl": {"rl"},
    }.get(layer)
    if allowed is not None:
        assert layers <= allowed, f"{name} ({layer}) imports {sorted(ours)}"
    if layer in ("study", "tools"):
        rl = {n.split(".")[2] for n in ours if _layer(n) == "rl" and n.count(".") >= 2}
        extra = rl - {"policy"} - RL_BEYOND_POLICY.get(name, set())
        assert not extra, f"{name} uses rl.{sorted(extra)}: read policies through rl.policy"


def test_every_layer_is_checked():
    names = {_layer(_module_name(p)) for p in FILES}
    assert {"sim", "env", "rl", "study", "tools"} <= names
