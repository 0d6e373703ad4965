"""The shipped data match their registry, and the demo runs on them."""

import json
from pathlib import Path

import pytest

from pneubayes.demo import main as demo_main
from pneubayes.demo import verify_registry
from pneubayes.io import check_recording

DATA = Path(__file__).resolve().parents[1] / "data"


def reg_filter():
    return json.loads((DATA / "registry.json").read_text())["pressure_filter"]


def test_shipped_data_match_registry_and_format():
    assert verify_registry(DATA) == []
    reg = json.loads((DATA / "registry.json").read_text())
    csvs = [DATA / e["file"] for e in reg["files"] if e["file"].endswith(".csv")]
    assert csvs
    for f in csvs:
        assert check_recording(f) == []
    total = sum((DATA / e["file"]).stat().st_size for e in reg["files"])
    assert total < 5e6  # a few MB at most


@pytest.mark.slow
def test_demo_runs_on_shipped_data(tmp_path):
    assert demo_main(["--data", str(DATA), "--out", str(tmp_path), "--fit-steps", "60"]) == 0
    summary = json.loads((tmp_path / "demo_summary.json").read_text())
    for rows in summary["sets"].values():
        for r in rows:
            # the true model beats the plain thin-port model on every recording
            assert r["true model"] < r["plain thin-port"]
    assert (tmp_path / "demo_prediction.png").stat().st_size > 10_000
    # what the demo found, from its files (never from its log's wording): the transport
    # delay fits at the noise floor, so the costly line form is not fitted, nor the later
    # forms of the other trials of the round
    doc = json.loads((tmp_path / "discover" / "discovery.json").read_text())
    assert [e["name"] for e in doc["effects"]] == ["tube_delay"]
    tube = [e for e in doc["ledger"] if e.get("effect") == "tube_delay" and "forms" in e][0]
    assert list(tube["forms"]["train_rmse_Pa"]) == ["transport"]
    # (the outside tube's form, the loop's default: the transmission-line tube, wave/8)
    assert [f.split("/")[0] for f in tube["forms"]["not_fitted"]] == ["wave"]
    # the other trials with several forms (the sensor lag's two orders; heat's two laws)
    # were fitted in their first form only
    multi = [e for e in doc["ledger"] if "forms" in e
             and e.get("effect") in ("sensor_lag", "heat_transfer")]
    assert multi and all(len(e["forms"]["train_rmse_Pa"]) == 1 and e["forms"]["not_fitted"]
                         for e in multi)
    assert doc["rmse_final_Pa"] < 0.2 * doc["rmse_base_Pa"]
    # the registry's DAQ filter is declared to the fits and recorded in the card
    card = json.loads((tmp_path / "discover" / "model.json").read_text())
    assert card["fit"]["pressure_filter"] == reg_filter() == {"order": 2, "cutoff_Hz": 1000.0,
                                                              "phase": "zero"}
    pred = summary["discovery"]["prediction"]
    assert (tmp_path / "discover" / "posterior.nc").exists()
    assert 0.0 <= pred["coverage_90"] <= 1.0
