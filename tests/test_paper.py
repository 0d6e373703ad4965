"""The paper's study scripts and the report assembler (issue 5)."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))

import make_paper  # noqa: E402
import table3  # noqa: E402


def test_report_says_what_is_missing(tmp_path):
    path = make_paper.assemble(tmp_path / "none", tmp_path / "paper", smoke=False)
    text = path.read_text()
    assert "*Missing: run `python experiments/table3.py`.*" in text
    assert "## Where we differ from the paper, and why" in text


@pytest.mark.slow
def test_table3_smoke_then_report_carries_numbers_and_provenance(tmp_path):
    out = tmp_path / "results"
    assert table3.main(["--smoke", "--out", str(out), "--workers", "1", "-q"]) == 0
    doc = json.loads((out / "table3-smoke.json").read_text())
    (row,) = doc["numbers"]["rows"]
    assert row["cylinder"] == "SMC" and row["paper_percent"] == 3.2
    assert 0 < row["ours_paper_model_rmse_Pa"] < 0.2 * row["working_range_Pa"]
    assert doc["provenance"]["git_revision"] and doc["studies"]["table3"]["seeds"] == [0]
    report = make_paper.assemble(out, tmp_path / "paper", smoke=True).read_text()
    assert "Smoke build" in report
    assert f"| {row['ours_paper_model_rmse_Pa']:.0f} |" in report
    assert "seeds [0]" in report and "git revision" in report
    # a second run resumes from the cached cell
    assert table3.main(["--smoke", "--out", str(out), "--workers", "1", "-q"]) == 0
    again = json.loads((out / "studies" / "table3-smoke" / "results.json").read_text())
    assert again["counts"]["cached"] == 1 and again["counts"]["run_now"] == 0
