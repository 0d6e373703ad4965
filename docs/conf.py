"""Sphinx configuration of the pneubayes documentation (``make docs``)."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

project = "pneubayes"
author = "the pneubayes authors"
copyright = "2026, the pneubayes authors"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "myst_parser",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build"]

# Markdown pages (MyST): heading anchors so pages can link to sections.
myst_heading_anchors = 3

# The API reference: the public modules' members as their ``__all__`` lists them,
# documented where they are defined; signatures without the type hints (the
# docstrings name the types and units).
autodoc_default_options = {
    "members": True,
    "undoc-members": False,
    "show-inheritance": True,
}
autodoc_typehints = "none"
autodoc_member_order = "bysource"
napoleon_numpy_docstring = True
napoleon_google_docstring = False
# A class's "Attributes" section as a field list: its dataclass fields are documented
# as members already.
napoleon_use_ivar = True

# Docstrings name modules and functions in :mod:/:func: roles with short names that
# Sphinx cannot always resolve; those are links that fall back to plain text.
nitpicky = False
# Napoleon turns a parameter's type text ("mapping of str to (lower, upper)") into
# cross-references word by word; a word that names attributes of several classes
# (``lower``, ``upper``) warns as ambiguous. Those words are prose, not links.
suppress_warnings = ["ref.python"]

html_theme = "alabaster"
html_title = "pneubayes"


def _hanging_items(lines: list[str]) -> list[str]:
    """Give docutils the settings lists some docstrings write as ``name: text`` with a
    hanging indent and no blank line between items: such an item's continuation lines
    are joined to its own indent and the items are separated by blank lines (docutils
    otherwise reads the first line as a definition-list term and warns at the next item).
    Only an item whose hanging block is followed directly by a line at its own indent is
    touched; everything else is left as written."""

    def indent(line: str) -> int:
        return len(line) - len(line.lstrip())

    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        j = i + 1
        while j < len(lines) and lines[j].strip() and indent(lines[j]) > indent(line):
            j += 1
        hanging = (
            line.strip()
            and not line.lstrip().startswith((":", "..", "-", "*"))
            and not line.rstrip().endswith("::")
            and j > i + 1
            and j < len(lines)
            and lines[j].strip()
            and indent(lines[j]) == indent(line)
        )
        if not hanging:
            out.append(line)
            i += 1
            continue
        if out and out[-1].strip():
            out.append("")
        pad = " " * indent(line)
        out.append(line.rstrip())
        out.extend(pad + cont.strip() for cont in lines[i + 1:j])
        out.append("")
        i = j
    return out


def _process_docstring(app, what, name, obj, options, lines):
    lines[:] = _hanging_items(lines)


def setup(app):
    # after napoleon (priority 500), so its own field lists are already in place
    app.connect("autodoc-process-docstring", _process_docstring, priority=600)
