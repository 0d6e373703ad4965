"""The README stays a short introduction, and the documentation it points to exists."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"

# [text](target): a Markdown link; targets with a scheme are external, not checked.
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _local_links(path: Path) -> list[tuple[str, Path]]:
    found = []
    for target in LINK.findall(path.read_text()):
        if re.match(r"^[a-z]+:", target) or target.startswith("#"):
            continue
        found.append((target, (path.parent / target.split("#", 1)[0]).resolve()))
    return found


def test_the_readme_is_short_and_keeps_its_quick_start():
    text = README.read_text()
    assert len(text.splitlines()) <= 250
    quick = text[text.index("## Quick start\n"):]
    quick = quick[:quick.index("\n## ", 1)]
    assert "make demo" in quick and "make test" in quick


def test_every_docs_page_the_readme_links_exists():
    links = _local_links(README)
    assert any(t.startswith("docs/") for t, _ in links)
    missing = [t for t, p in links if not p.exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_the_docs_pages_link_to_pages_that_exist():
    missing = [(page.name, t) for page in sorted(DOCS.glob("*.md"))
               for t, p in _local_links(page) if not p.exists()]
    assert not missing, f"docs pages link to missing files: {missing}"


def test_every_docs_page_is_in_the_site():
    index = (DOCS / "index.md").read_text()
    toctree = index[index.index("```{toctree}"):]
    for page in sorted(DOCS.glob("*.md")) + sorted(DOCS.glob("*.rst")):
        if page.stem != "index":
            assert re.search(rf"^{re.escape(page.stem)}$", toctree, flags=re.M), page.name


@pytest.mark.slow
def test_the_site_builds_without_warnings(tmp_path):
    for module in ("sphinx", "myst_parser"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed (the docs extra: pip install -e '.[docs]')")
    done = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q",
         str(DOCS), str(tmp_path / "html")],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-4000:]
    assert (tmp_path / "html" / "api.html").exists()
