"""Sizes that keep the package readable: no module over 400 lines, no function over 60 lines
unless its docstring gives the reason on a line starting with "Long:"."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted(p for d in ("mjx_stairs", "terrains") for p in (ROOT / d).rglob("*.py"))
MAX_MODULE, MAX_FUNCTION = 400, 60


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_module_and_function_sizes(path):
    text = path.read_text()
    assert len(text.splitlines()) <= MAX_MODULE, f"{path.name}: over {MAX_MODULE} lines"
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1
            doc = ast.get_docstring(node) or ""
            reason = any(line.strip().startswith("Long:") for line in doc.splitlines())
            assert n <= MAX_FUNCTION or reason, (
                f"{path.name}:{node.lineno} {node.name} has {n} lines and no 'Long:' reason")
