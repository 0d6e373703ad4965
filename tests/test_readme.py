"""The README's Python section runs as written (from the repository root)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python_blocks():
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Python\n"):]
    section = section[:section.index("\n## ", 1)]
    return re.findall(r"```python\n(.*?)```", section, flags=re.S)


def test_the_readme_has_its_python_example():
    blocks = _python_blocks()
    assert len(blocks) == 1
    for call in ("pb.simulate(", "pb.identify(", "fit.predictor(", "pb.discover("):
        assert call in blocks[0]


@pytest.mark.slow
def test_the_readme_python_example_runs(tmp_path):
    (block,) = _python_blocks()
    block = block.replace('"results/my_fit"', repr(str(tmp_path / "my_fit")))
    here = os.getcwd()
    os.chdir(ROOT)
    try:
        ns: dict = {}
        exec(compile(block, "README.md (Python)", "exec"), ns)  # noqa: S102
    finally:
        os.chdir(here)
    assert ns["traj"].pressure_Pa.shape[1] == ns["rec"].n_samples
    assert ns["fit"].posterior is not None and (tmp_path / "my_fit" / "posterior.nc").exists()
    assert ns["q"].shape == (2, 3, 401)
    assert "tube_delay" in ns["found"].effect_names
    assert ns["found"].final.heldout_rmse_Pa < ns["found"].base.heldout_rmse_Pa
