"""End to end: pneubayes fit / predict on small bench data; the controller API."""

import json

import numpy as np
import pytest

from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.cli import main
from pneubayes.effects import effects_from_names
from pneubayes.inference.predictive import (
    PressurePredictor,
    ar1_noise,
    estimate_noise_std,
)
from pneubayes.io import prepare_recording, read_recording
from pneubayes.model import Model
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.simulation import SolverConfig


def test_noise_estimate_is_unbiased_for_white_noise_on_steps():
    rng = np.random.default_rng(1)
    t = np.arange(20000) * 1e-3
    p = 3e5 + 1e5 * np.sin(2 * np.pi * 0.5 * t) + np.where(t % 1 < 0.5, 0.0, 5e4)
    assert estimate_noise_std(p + rng.normal(0, 500, t.size)) == pytest.approx(500, rel=0.05)


def test_ar1_noise_has_the_requested_statistics():
    e = ar1_noise(np.random.default_rng(2), np.array([2.0]), np.array([0.8]), (1, 200, 500))
    x = e[0, :, 100:]  # past the start-up from zero
    assert np.std(x) == pytest.approx(2.0 / np.sqrt(1 - 0.8**2), rel=0.05)
    lag1 = np.sum(x[:, 1:] * x[:, :-1]) / np.sum(x[:, :-1] ** 2)
    assert lag1 == pytest.approx(0.8, abs=0.02)


def test_stationary_ar1_noise_is_stationary_from_the_first_sample():
    e = ar1_noise(np.random.default_rng(3), np.array([2.0]), np.array([0.8]), (1, 4000, 50),
                  stationary=True)
    sd = 2.0 / np.sqrt(1 - 0.8**2)
    assert np.std(e[0, :, 0]) == pytest.approx(sd, rel=0.04)
    assert np.std(e[0, :, -1]) == pytest.approx(sd, rel=0.04)
    assert np.corrcoef(e[0, :, 0], e[0, :, 1])[0, 1] == pytest.approx(0.8, abs=0.02)


#: The chain's length of the fast tier's run folder, which has no figures: what its tests
#: read is the folder's files and stamps, not the posterior (the slow tier's ``fitted``
#: runs 150 steps and draws the figures).
QUICK_STEPS = "40"


def _fit(root, steps, *options):
    cfg = BenchConfig("PRN", "valve1", effects_from_names(["cylinder_leak"]), protocol="fixed",
                      duration_s=6.0, seed=8, positions=(0.5, 0.9), ranges_V=(5.0,))
    train = run_bench(cfg, root / "train")
    held = run_bench(BenchConfig("PRN", "valve1", effects_from_names(["cylinder_leak"]),
                                 protocol="moving", duration_s=4.0, seed=9, count=1),
                     root / "held")
    run = root / "run"
    rc = main(["fit", *map(str, train.recordings), "--out", str(run), "--walkers", "32",
               "--max-steps", steps, "--seed", "3", "-q", *options])
    assert rc == 0
    return run, train, held


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    return _fit(tmp_path_factory.mktemp("pipeline"), "150")


@pytest.fixture(scope="module")
def fitted_quick(tmp_path_factory):
    return _fit(tmp_path_factory.mktemp("pipeline_quick"), QUICK_STEPS, "--no-figures")


@pytest.mark.slow
def test_fit_writes_the_run_folder(fitted):
    run, train, _ = fitted
    for name in ("model.json", "posterior.nc", "summary.json", "chain.h5",
                 "figures/areas.png", "figures/volume.png", "figures/corner.png"):
        assert (run / name).exists(), name
    model, median = Model.load_card(run / "model.json")
    assert model.effect_names == ("cylinder_leak",)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["seed"] == 3 and summary["steps"] == 150
    # the catalogue's leak model fits the bench's leak data at the noise floor: no misfit
    assert summary["misfit"]["note"] is None
    assert summary["misfit"]["rmse_over_noise_floor"] < 1.5
    for name, s in summary["parameters"].items():
        assert s["q05"] <= s["median"] <= s["q95"], name
        assert np.isfinite(s["rhat"]) and s["ess"] > 0
    assert summary["parameters"]["inlet_a_m2"]["median"] == pytest.approx(median["inlet_a_m2"])
    kinds = {tuple(g["parameters"]) for g in summary["identifiability"]["groups"]}
    assert ("exhaust_offset_m2", "leak_area_m2") in kinds
    assert ("inlet_b", "inlet_d_V") in kinds
    _, truth = Model.load_card(train.truth_path)
    for k in ("inlet_a_m2", "exhaust_a_m2", "dead_volume_m3"):
        assert median[k] == pytest.approx(truth[k], rel=0.05), k


@pytest.mark.slow
def test_predict_writes_bands_and_metrics(fitted, tmp_path):
    run, _, held = fitted
    out = tmp_path / "pred.csv"
    assert main(["predict", str(run), str(held.recordings[0]), "--horizon", "2",
                 "--draws", "60", "--out", str(out), "--no-figure"]) == 0
    header = out.read_text().splitlines()[0]
    assert header == "window,time_s,horizon_s,measured_Pa,mean_Pa,q05_Pa,q50_Pa,q95_Pa"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert np.all(data[:, 5] <= data[:, 6]) and np.all(data[:, 6] <= data[:, 7])
    m = json.loads(out.with_suffix(".metrics.json").read_text())
    for k in ("rmse_Pa", "rmse_percent_of_range", "coverage_50", "coverage_90",
              "noise_floor_Pa"):
        assert k in m
    assert m["rmse_Pa"] < 2.0 * m["noise_floor_Pa"]
    assert 0.7 < m["coverage_90"] <= 1.0
    # a model at the noise floor: its band is what white sensor noise gives, not wider
    assert 0.7 < m["band_90_width_over_sensor_noise"] < 1.5
    assert m["rmse_percent_of_span"] == pytest.approx(100 * m["rmse_Pa"]
                                                      / m["measured_span_Pa"])


@pytest.mark.slow
def test_fit_resumes_a_stopped_chain(fitted, tmp_path):
    run, train, _ = fitted
    summary = json.loads((run / "summary.json").read_text())
    assert summary["resumed"] is False
    rc = main(["fit", *map(str, train.recordings), "--out", str(run), "--walkers", "32",
               "--max-steps", "180", "--seed", "3", "-q", "--no-figures"])
    assert rc == 0
    again = json.loads((run / "summary.json").read_text())
    assert again["resumed"] is True and again["steps"] == 180


def test_controller_api_quantiles_are_ordered_and_respond_to_the_command(tmp_path):
    cfg = BenchConfig("AIR37", "valve1", effects_from_names(["cylinder_leak"]),
                      protocol="moving", duration_s=0.5, seed=1, count=1)
    res = run_bench(cfg, tmp_path)
    model, truth = Model.load_card(res.truth_path)
    rng = np.random.default_rng(0)
    draws = model.vector(truth)[None] * rng.uniform(0.97, 1.03, (64, model.n_parameters))
    rec = read_recording(res.recordings[0])
    pred = PressurePredictor(model, draws, rec.rig(), SolverConfig.standard())
    cands = np.array([np.full(2000, 3.0), np.full(2000, -3.0)])
    q = pred.predict(2e5, cands, 0.01, 1e-3)
    assert q.shape == (2, 3, 2001)
    assert np.all(q[:, 0] <= q[:, 1]) and np.all(q[:, 1] <= q[:, 2])
    assert q[0, 1, -1] > 5e5 and q[1, 1, -1] < 1.2e5  # fill vs vent
    assert np.all(q[:, :, 0] == 2e5)


def test_fit_method_lsq_writes_a_point_estimate(fitted_quick, tmp_path, capsys):
    _, train, _ = fitted_quick
    out = tmp_path / "lsq"
    assert main(["fit", *map(str, train.recordings), "--out", str(out), "--method", "lsq",
                 "--supply-cutoff", "80", "--pressure-filter", "2:1000", "-q"]) == 0
    model, params = Model.load_card(out / "model.json")
    # the bench's recordings are plausible: the run records no input finding
    assert json.loads((out / "summary.json").read_text())["input_findings"] == []
    # the preparation is in the card, and predict reads it back from there
    from pneubayes.inference.pipeline import run_preparation

    card = json.loads((out / "model.json").read_text())
    assert card["fit"]["position_cutoff_Hz"] == 50.0 and card["fit"]["supply_cutoff_Hz"] == 80.0
    declared = {"order": 2, "cutoff_Hz": 1000.0, "phase": "zero"}
    assert run_preparation(out) == {"position_cutoff_Hz": 50.0, "supply_cutoff_Hz": 80.0,
                                    "pressure_filter": declared, "despike_pressure": False}
    rec = prepare_recording(read_recording(train.recordings[0]), run_preparation(out))
    assert rec.rig().pressure_filter == PressureFilter(2, 1000.0)
    del card["fit"]["supply_cutoff_Hz"]  # a card from before the supply's low-pass: raw
    del card["fit"]["pressure_filter"]  # and from before the pressure filter: none
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "model.json").write_text(json.dumps(card))
    old = run_preparation(tmp_path / "old")
    assert old["supply_cutoff_Hz"] is None and old["pressure_filter"] is None
    assert prepare_recording(read_recording(train.recordings[0]), old).rig().pressure_filter \
        is None
    _, truth = Model.load_card(train.truth_path)
    # equation-error least squares is biased by sensor noise (500 Pa here); the
    # refinement stage removes that bias (test_fit_writes_the_run_folder: 5 %)
    assert params["inlet_a_m2"] == pytest.approx(truth["inlet_a_m2"], rel=0.3)
    assert json.loads((out / "summary.json").read_text())["method"] == "lsq"
    assert "only exhaust_offset_m2 + leak_area_m2" in capsys.readouterr().out


@pytest.mark.slow
def test_identification_experiment_smoke(tmp_path):
    from conftest import load_experiment

    mod = load_experiment("identification")
    assert mod.main(["--smoke", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["config"]["smoke"] and report["provenance"]["numpy"]
    for fig in report["figures"]:
        assert (tmp_path / fig).stat().st_size > 5000, fig


@pytest.mark.slow
def test_refine_from_the_generic_start_recovers_another_valve(tmp_path):
    """Moving data only (no eq.-10 start): valve1's maps as the start, valve2 planted."""
    cfg = BenchConfig("SMC", "valve2", effects_from_names(["cylinder_leak"]),
                      protocol="moving", duration_s=8.0, seed=5, count=1)
    res = run_bench(cfg, tmp_path / "bench")
    assert main(["fit", str(res.recordings[0]), "--out", str(tmp_path / "run"),
                 "--method", "refine", "-q"]) == 0
    _, truth = Model.load_card(res.truth_path)
    _, est = Model.load_card(tmp_path / "run" / "model.json")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["start"]["method"] == "generic"
    assert summary["refined"]["start_rmse_Pa"] > 20 * summary["refined"]["rmse_Pa"]
    for k in ("inlet_a_m2", "exhaust_a_m2", "dead_volume_m3", "inlet_c_per_V",
              "exhaust_c_per_V"):
        assert est[k] == pytest.approx(truth[k], rel=0.02), k


def _snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_predict_never_combines_files_of_different_runs(fitted_quick, tmp_path, capsys):
    import shutil

    run, _, held = fitted_quick
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    rec = str(held.recordings[0])
    out = tmp_path / "p.csv"
    card = json.loads((copy / "model.json").read_text())
    card["parameters"]["dead_volume_m3"] *= 1.01  # a card edited, or taken from another run
    (copy / "model.json").write_text(json.dumps(card))
    capsys.readouterr()
    assert main(["predict", str(copy), rec, "--out", str(out), "--no-figure"]) == 2
    assert "not the file its run produced" in capsys.readouterr().err
    # a folder without a stamp (written before stamps): the posterior's own card tells
    (copy / "run.json").unlink()
    assert main(["predict", str(copy), rec, "--out", str(out), "--no-figure"]) == 2
    assert "sampled for another model card" in capsys.readouterr().err
    # a truncated posterior is a message, not a traceback
    shutil.copy(run / "model.json", copy / "model.json")
    data = (run / "posterior.nc").read_bytes()
    (copy / "posterior.nc").write_bytes(data[: len(data) // 2])
    assert main(["predict", str(copy), rec, "--out", str(out), "--no-figure"]) == 2
    err = capsys.readouterr().err
    assert "posterior.nc" in err and "Traceback" not in err
    assert not out.exists()


def test_predict_checks_its_output_names_and_options_before_any_work(fitted_quick, tmp_path,
                                                                     capsys):
    run, _, held = fitted_quick
    rec = str(held.recordings[0])
    capsys.readouterr()
    assert main(["predict", str(run), rec, "--out", str(tmp_path / "p.png")]) == 2
    assert "must end in .csv" in capsys.readouterr().err
    (tmp_path / "p.png").write_text("a figure of mine")
    assert main(["predict", str(run), rec, "--out", str(tmp_path / "p.csv")]) == 2
    assert "p.png exists" in capsys.readouterr().err
    assert (tmp_path / "p.png").read_text() == "a figure of mine"
    for bad in (["--horizon", "-1"], ["--horizon", "0"], ["--draws", "0"], ["--stride", "0"]):
        with pytest.raises(SystemExit) as exc:
            main(["predict", str(run), rec, "--out", str(tmp_path / "q.csv"), *bad])
        assert exc.value.code == 2
        assert "must be >" in capsys.readouterr().err
    assert not (tmp_path / "q.csv").exists()


def test_fit_refuses_to_mix_runs_and_overwrites_only_its_own_files(fitted_quick, tmp_path, capsys):
    import shutil

    run, train, held = fitted_quick
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    recs = [str(p) for p in train.recordings]
    before = _snapshot(copy)
    capsys.readouterr()
    # the stale-posterior case: another method into a copy of a finished run
    assert main(["fit", *recs, "--out", str(copy), "--method", "refine", "-q"]) == 2
    err = capsys.readouterr().err
    assert "refusing to mix runs" in err and "--overwrite" in err
    assert _snapshot(copy) == before
    (copy / "notes.txt").write_text("mine")
    assert main(["fit", *recs, "--out", str(copy), "--method", "lsq", "--overwrite", "-q"]) == 0
    assert not (copy / "posterior.nc").exists() and not (copy / "chain.h5").exists()
    assert (copy / "notes.txt").read_text() == "mine"
    stamp = json.loads((copy / "run.json").read_text())
    assert stamp["command"] == "fit" and set(stamp["files"]) == {"model.json", "summary.json"}
    assert stamp["argv"][:1] == ["fit"]
    assert main(["predict", str(copy), str(held.recordings[0]), "--out",
                 str(tmp_path / "p.csv")]) == 2
    assert "no posterior.nc" in capsys.readouterr().err
    # the same command again is its own run: allowed; resuming an empty folder is not
    assert main(["fit", *recs, "--out", str(copy), "--method", "lsq", "-q"]) == 0
    assert main(["resume", str(tmp_path / "new")]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    # emcee needs twice as many walkers as dimensions: said before any work
    assert main(["fit", *recs, "--out", str(tmp_path / "w"), "--walkers", "1", "-q"]) == 2
    assert "--walkers 1" in capsys.readouterr().err and not (tmp_path / "w").exists()


def test_a_truncated_chain_is_a_message_naming_it(fitted_quick, tmp_path, capsys):
    import shutil

    run, train, _ = fitted_quick
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    data = (copy / "chain.h5").read_bytes()
    (copy / "chain.h5").write_bytes(data[: len(data) // 3])
    capsys.readouterr()
    # the same fit resumes (its least squares and refinement are saved) and meets the file
    rc = main(["fit", *map(str, train.recordings), "--out", str(copy), "--walkers", "32",
               "--max-steps", QUICK_STEPS, "--seed", "3", "-q", "--no-figures"])
    err = capsys.readouterr().err
    assert rc == 2 and "chain.h5" in err and "Traceback" not in err


def test_misfit_is_stated_apart_from_noise():
    from pneubayes.inference.pipeline import misfit_report

    assert misfit_report(520.0, 500.0, 0.05)["note"] is None
    note = misfit_report(4000.0, 500.0, 0.98)["note"]
    assert "8.0 x the noise floor" in note and "absorbs" in note
    assert "absorbs" not in misfit_report(4000.0, 500.0, 0.2)["note"]


def test_parameters_pushed_to_a_bound_are_named():
    from pneubayes.effects import make_effect
    from pneubayes.inference.pipeline import at_bounds

    model = Model([make_effect("cylinder_leak")])
    lo, hi = model.bounds
    j = model.parameter_names.index("leak_area_m2")
    summary = {"leak_area_m2": {"q05": lo[j], "q95": lo[j] + 1e-3 * (hi[j] - lo[j])},
               "dead_volume_m3": {"q05": 1e-6, "q95": 1.1e-6}}
    found = at_bounds(model, summary)
    assert found == [{"parameter": "leak_area_m2", "bound": "lower", "value": lo[j],
                      "q05": summary["leak_area_m2"]["q05"],
                      "q95": summary["leak_area_m2"]["q95"]}]
    # a parameter the data leave at its prior (a Gompertz nuisance) is not "pushed"
    i = model.parameter_names.index("inlet_d_V")
    assert at_bounds(model, {"inlet_d_V": {"q05": lo[i], "q95": hi[i]}}) == []
    k = model.parameter_names.index("dead_volume_m3")
    summary["dead_volume_m3"] = {"q05": 0.5 * hi[k], "q95": hi[k]}
    assert {(f["parameter"], f["bound"]) for f in at_bounds(model, summary)} == {
        ("dead_volume_m3", "upper"), ("leak_area_m2", "lower")}


def test_an_edited_saved_stage_is_not_resumed(fitted_quick, tmp_path, capsys):
    """Issue 70: a finished fit's refined.json edited, then the same fit run again: the
    edited values are refused, not used."""
    import shutil

    run, train, _ = fitted_quick
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    doc = json.loads((copy / "refined.json").read_text())
    (copy / "refined.json").write_text(json.dumps(doc) + "\n ")
    capsys.readouterr()
    assert main(["fit", *map(str, train.recordings), "--out", str(copy), "--walkers", "32",
                 "--max-steps", QUICK_STEPS, "--seed", "3", "-q"]) == 2
    assert "refined.json: not the file its run produced" in capsys.readouterr().err
