"""Docstrings stay short enough to read and the public names document their inputs.

Issue 66's floors: no docstring in ``pneubayes/`` over 40 lines (measurement history
goes to ``docs/history.md``, not docstrings), and every name in ``pneubayes.__all__``
has a numpydoc Parameters or Attributes section.
"""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import pneubayes

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "pneubayes"
MAX_LINES = 40

# A numpydoc section header: the word on its own line, underlined with dashes.
SECTION = re.compile(r"^[ \t]*(Parameters|Attributes)[ \t]*\n[ \t]*-{3,}[ \t]*$", re.M)

# Public names excused from the section check while their file is being rewritten
# elsewhere (each entry with a comment naming that file); empty otherwise.
MISSING_SECTION_ALLOWED: set[str] = set()


def _docstring_lengths(path: Path):
    """(line, name, lines) of every module, class and function docstring in one file;
    lines counts the string literal's lines in the source, its quotes included."""
    tree = ast.parse(path.read_text(), filename=str(path))
    nodes = [tree] + [node for node in ast.walk(tree) if isinstance(
        node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]
    for node in nodes:
        body = node.body
        if (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            first = body[0]
            yield first.lineno, getattr(node, "name", "<module>"), \
                first.end_lineno - first.lineno + 1


def test_no_docstring_is_over_40_lines():
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for line, name, lines in _docstring_lengths(path):
            if lines > MAX_LINES:
                long.append(f"{path.relative_to(ROOT)}:{line} {name} ({lines} lines)")
    assert not long, (f"docstrings over {MAX_LINES} lines (move measurements and case "
                      "histories to docs/history.md):\n  " + "\n  ".join(long))


def _docstrings(obj) -> list[str]:
    docs = [inspect.getdoc(obj) or ""]
    if inspect.isclass(obj) and "__init__" in vars(obj):
        docs.append(inspect.getdoc(vars(obj)["__init__"]) or "")
    return docs


def _where(obj) -> str:
    try:
        path = Path(inspect.getsourcefile(obj)).resolve()
        line = inspect.getsourcelines(obj)[1]
    except (OSError, TypeError):
        return "?"
    return f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:{line}"


def test_every_public_name_has_a_parameters_or_attributes_section():
    missing, listed = [], []
    for name in pneubayes.__all__:
        obj = getattr(pneubayes, name)
        if not (inspect.isclass(obj) or inspect.isfunction(obj)):
            continue
        if any(SECTION.search(doc) for doc in _docstrings(obj)):
            continue
        entry = f"{_where(obj)} {name}"
        (listed if name in MISSING_SECTION_ALLOWED else missing).append(entry)
    assert not missing, ("public names without a numpydoc Parameters or Attributes "
                         "section:\n  " + "\n  ".join(missing + [
                             f"{e} (allowed: being edited in parallel)" for e in listed]))


def test_the_allow_list_names_only_public_names():
    assert MISSING_SECTION_ALLOWED <= set(pneubayes.__all__)
