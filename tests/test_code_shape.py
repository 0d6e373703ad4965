"""Functions stay short enough to read: issue 66's floor of no function in ``pneubayes/``
over 250 lines (the compiled kernel's window included: its parts are functions of
their own, inlined by numba)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "pneubayes"
MAX_LINES = 250


def _function_lengths(path: Path):
    """(line, name, lines) of every function in one file, decorators excluded."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node.lineno, node.name, node.end_lineno - node.lineno + 1


def test_the_length_count_sees_a_long_function(tmp_path):
    src = tmp_path / "long.py"
    src.write_text("def f():\n" + "    x = 1\n" * (MAX_LINES + 5) + "\n\ndef g():\n    pass\n")
    lengths = {name: n for _, name, n in _function_lengths(src)}
    assert lengths == {"f": MAX_LINES + 6, "g": 2}


def test_no_function_over_250_lines():
    long = [f"{path.relative_to(PACKAGE.parent)}:{line} {name} ({n} lines)"
            for path in sorted(PACKAGE.rglob("*.py"))
            for line, name, n in _function_lengths(path) if n > MAX_LINES]
    assert not long, "functions over 250 lines:\n" + "\n".join(long)
