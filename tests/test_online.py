"""The online tracker (pneubayes.inference.online) and ``pneubayes track``."""

import json
import shutil

import numpy as np
import pytest

from pneubayes.cli import main
from pneubayes.inference.online import OnlineTracker, forecast, systematic_resample
from pneubayes.inference.population import LogNormalPrior, LogUniformPrior
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate

P_ATM, P_SUP = 101325.0, 551325.0
RIG = Rig(0.009, P_ATM, P_SUP, stroke_m=0.03)
MODEL = Model()
TRUE_VOLUME = 2.4e-6
NOISE_PA = 300.0
DT = 0.005


def plant(volumes, seconds_each=2.0, seed=1):
    """A plain chamber (valve 1, fixed position) driven by random steps at 200 Hz, its
    dead volume ``volumes[i]`` for the i-th stretch of ``seconds_each``; returns
    ``(t, u, noisy pressure)``."""
    rng = np.random.default_rng(seed)
    n_each = int(round(seconds_each / DT))
    n = n_each * len(volumes)
    t = np.arange(n) * DT
    u = np.repeat(rng.uniform(-5.0, 5.0, size=n // 30 + 1), 30)[:n]
    p = np.empty(n)
    p0 = 2e5
    for i, v in enumerate(volumes):
        sl = slice(i * n_each, (i + 1) * n_each)
        params = {**valve_preset("valve1").parameters(), "dead_volume_m3": v}
        seg = simulate(MODEL, params, Inputs.constant(t[sl], u[sl], 0.0, P_SUP), RIG, p0,
                       SolverConfig.standard()).pressure_Pa[0]
        p[sl] = seg
        p0 = seg[-1]
    return t, u, p + rng.normal(0.0, NOISE_PA, n)


def tracker(seed=0, **kw):
    start = {**valve_preset("valve1").parameters(), "dead_volume_m3": 1e-5}
    options = {"n_particles": 64, "lookback_s": 0.2, "memory_s": 0.2, "n_moves": 2,
               "warm_up_windows": 0, **kw}
    return OnlineTracker(MODEL, start, LogUniformPrior(MODEL, ["dead_volume_m3"]), RIG,
                         SolverConfig.standard(), NOISE_PA, **options).reset(
                             np.random.default_rng(seed))


def stream(tr, t, u, p, block=20):
    out = []
    for k in range(0, t.size, block):
        tr.update(t[k:k + block], u[k:k + block], p[k:k + block])
        out.append((tr.time_s_, tr.quantiles()["dead_volume_m3"], tr.ess_,
                    np.unique(tr.particles_).size))
    return out


def test_planted_dead_volume_is_recovered_from_a_flat_prior():
    t, u, p = plant([TRUE_VOLUME], seconds_each=3.0)
    tr = tracker()
    q05, q50, q95 = stream(tr, t, u, p)[-1][1]
    # from four decades (1e-8 .. 1e-4 m^3) to within a few per cent of the truth
    assert q50 == pytest.approx(TRUE_VOLUME, rel=0.05)
    assert q95 / q05 < 1.3
    assert q05 * 0.95 <= TRUE_VOLUME <= q95 * 1.05


def test_the_tracker_follows_a_plant_that_steps_mid_run():
    new = 2.5 * TRUE_VOLUME
    t, u, p = plant([TRUE_VOLUME, new], seconds_each=2.0)
    trace = stream(tracker(drift_log_per_sqrt_s=0.3), t, u, p)
    before = next(q for time, q, _, _ in trace if time >= 1.9)
    after = trace[-1][1]
    assert before[1] == pytest.approx(TRUE_VOLUME, rel=0.1)
    assert after[1] == pytest.approx(new, rel=0.1)
    # constant quantities (no drift): the weights and moves alone follow too slowly
    still = stream(tracker(), t, u, p)[-1][1]
    assert still[1] < 0.9 * new


def test_rejuvenation_keeps_the_particles_apart():
    t, u, p = plant([TRUE_VOLUME], seconds_each=3.0)
    tr = tracker(n_moves=2)
    trace = stream(tr, t, u, p)
    assert tr.n_resamples_ > 0
    # resampling whenever the ESS falls below half the particles: never below after an
    # update; the moves keep distinct particles (without them, duplicates pile up)
    assert min(ess for _, _, ess, _ in trace) >= 0.5 * 64
    assert trace[-1][3] >= 16
    bare = tracker(n_moves=0)
    assert stream(bare, t, u, p)[-1][3] < trace[-1][3]


def test_an_adapted_noise_scale_follows_the_errors_the_run_shows():
    t, u, p = plant([TRUE_VOLUME], seconds_each=2.0, seed=2)
    p = p + np.random.default_rng(9).normal(0.0, 900.0, p.size)  # ~950 Pa in all
    fixed, adapted = tracker(), tracker(adapt_noise_s=0.5)
    stream(fixed, t, u, p)
    stream(adapted, t, u, p)
    assert fixed.noise_scale_Pa_ == NOISE_PA
    assert adapted.noise_scale_Pa_ == pytest.approx(np.hypot(NOISE_PA, 900.0), rel=0.3)
    # never below the stated scale, on data that fit it
    t, u, p = plant([TRUE_VOLUME], seconds_each=1.0)
    low = tracker(adapt_noise_s=0.5)
    stream(low, t, u, p)
    assert low.noise_scale_Pa_ >= NOISE_PA


def test_a_seed_gives_the_same_particles_and_another_seed_others():
    t, u, p = plant([TRUE_VOLUME], seconds_each=1.0)
    a, b, c = tracker(seed=3), tracker(seed=3), tracker(seed=4)
    for tr in (a, b, c):
        stream(tr, t, u, p)
    assert np.array_equal(a.particles_, b.particles_)
    assert np.array_equal(a.log_weights_, b.log_weights_)
    assert not np.array_equal(a.particles_, c.particles_)


def test_the_predictor_and_forecast_use_the_particles():
    t, u, p = plant([TRUE_VOLUME], seconds_each=2.0)
    tr = tracker()
    stream(tr, t, u, p)
    q = tr.predictor(16, np.random.default_rng(0)).predict(
        3e5, [np.full(40, 5.0), np.full(40, -5.0)], 0.0, DT)
    assert q.shape == (2, 3, 41)
    assert np.all(q[0, 2, 1:] > 3e5) and np.all(q[1, 0, 1:] < 3e5)  # filling, venting
    assert np.all(q[:, 0] <= q[:, 2])
    # forecast from the measured pressure: the tracked model predicts the samples
    k, h = 200, 100
    sims = forecast(MODEL, tr.draws(8, np.random.default_rng(1)),
                    Inputs.constant(t, u, 0.0, P_SUP), RIG, k, h + 1, p,
                    SolverConfig.standard())
    assert sims.shape == (8, h + 1) and np.all(sims[:, 0] == p[k])
    assert np.sqrt(np.mean((sims.mean(0)[1:] - p[k + 1:k + h + 1]) ** 2)) < 2 * NOISE_PA


def test_population_prior_from_point_fits():
    names = ["dead_volume_m3"]
    fits = [{"dead_volume_m3": v} for v in (2e-6, 2.4e-6, 3e-6)]
    pr = LogNormalPrior.from_point_fits(MODEL, names, fits, floor_log_sd=0.1)
    assert np.exp(pr.log_median[0]) == pytest.approx(2.4e-6)
    sd = np.std(np.log([2e-6, 2.4e-6, 3e-6]), ddof=1)
    assert pr.log_sd[0] == pytest.approx(np.hypot(sd, 0.1))
    z = pr.sample(2000, np.random.default_rng(0))
    assert np.median(z) == pytest.approx(np.log(2.4e-6), abs=0.02)
    assert np.all(np.isfinite(pr.logpdf(z)))
    assert pr.logpdf(np.array([[np.log(1e-3)]]))[0] == -np.inf  # beyond the bound


def test_systematic_resample_keeps_proportions():
    idx = systematic_resample(np.array([0.5, 0.25, 0.25, 0.0]), np.random.default_rng(0))
    assert np.bincount(idx, minlength=4).tolist() == [2, 1, 1, 0]


@pytest.mark.parametrize("kw, says", [
    ({"noise_std_Pa": 0.0}, "noise_std_Pa"),
    ({"temper": 1.5}, "temper"),
    ({"memory_s": 0.5, "lookback_s": 0.2}, "memory_s"),
    ({"n_particles": 0}, "n_particles"),
    ({"n_moves": -1}, "n_moves"),
    ({"warm_up_windows": 1.5}, "warm_up_windows"),
    ({"drift_log_per_sqrt_s": -0.1}, "drift_log_per_sqrt_s"),
    ({"adapt_noise_s": float("nan")}, "adapt_noise_s"),
])
def test_bad_arguments_are_errors_naming_them(kw, says):
    start = {**valve_preset("valve1").parameters(), "dead_volume_m3": 1e-5}
    options = {"noise_std_Pa": NOISE_PA, "lookback_s": 0.2, "memory_s": 0.2, **kw}
    noise = options.pop("noise_std_Pa")
    tr = OnlineTracker(MODEL, start, LogUniformPrior(MODEL, ["dead_volume_m3"]), RIG,
                       SolverConfig.standard(), noise, **options)
    with pytest.raises(ValueError, match=says):
        tr.reset(np.random.default_rng(0))


def test_misuse_is_an_error():
    with pytest.raises(ValueError, match="lower bound"):  # not in log space
        LogUniformPrior(MODEL, ["inlet_offset_m2"])
    tr = OnlineTracker(MODEL, {**valve_preset("valve1").parameters(), "dead_volume_m3": 1e-5},
                       LogUniformPrior(MODEL, ["dead_volume_m3"]), RIG,
                       SolverConfig.standard(), NOISE_PA)
    with pytest.raises(RuntimeError, match="reset"):
        tr.update([0.0], [0.0], [2e5])
    with pytest.raises(TypeError, match="Generator"):
        tr.reset(0)
    tr.reset(np.random.default_rng(0))
    tr.update([0.0, 0.005], [0.0, 0.0], [2e5, 2e5])
    with pytest.raises(ValueError, match="increase"):
        tr.update([0.005], [0.0], [2e5])
    with pytest.raises(ValueError, match="pressure_Pa"):
        tr.update([0.01, 0.015], [0.0, 0.0], [2e5])


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    """A 3-s bench recording of the plain model and a run folder with its card."""
    out = tmp_path_factory.mktemp("track_bench")
    assert main(["bench", "--cylinder", "AIR37", "--valve", "valve1", "--effects", "",
                 "--protocol", "moving", "--duration", "3", "--count", "1", "--seed", "5",
                 "--out", str(out / "rec"), "-q"]) == 0
    run = out / "run"
    run.mkdir()
    shutil.copy(out / "rec" / "truth.json", run / "model.json")
    return next((out / "rec").glob("*.csv")), run


def test_track_command_writes_ticks_and_refuses_to_overwrite(bench_run, tmp_path, capsys):
    rec, run = bench_run
    out = tmp_path / "track.json"
    argv = ["track", str(run), str(rec), "--vary", "dead_volume_m3", "--out", str(out),
            "--noise-std", "2000", "--tick", "0.1", "--horizon", "0.5", "--particles", "32",
            "--draws", "16", "--predict-every", "5", "--lookback", "0.2", "--temper", "1"]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    assert doc["settings"]["vary"] == ["dead_volume_m3"] and doc["settings"]["seed"] == 0
    assert len(doc["ticks"]) >= 25
    q = doc["final_quantiles"]["dead_volume_m3"]
    truth = json.loads((run / "model.json").read_text())["parameters"]["dead_volume_m3"]
    assert q[0] <= truth * 1.2 and q[2] >= truth / 1.2  # the truth's neighbourhood
    s = doc["summary"]
    assert s["predicted_ticks"] > 0 and np.isfinite(s["online_rmse_Pa"])
    assert 0.0 <= s["conformal_coverage_90"] <= 1.0
    # the rescaled band: the model's own until predictions complete, then the run's
    first = next(r for r in doc["ticks"] if "conformal_band_90_width_Pa" in r)
    assert first["conformal_band_90_width_Pa"] > 0.0
    assert "track.json" in capsys.readouterr().out
    before = out.read_text()
    assert main(argv) == 2  # exists: refused, untouched
    assert "--overwrite" in capsys.readouterr().err and out.read_text() == before
    # the carried-state update: the same neighbourhood, its knobs recorded
    carried = tmp_path / "carried.json"
    argv[argv.index(str(out))] = str(carried)
    assert main([*argv, "--update-mode", "carried", "--pressure-gain", "0.5"]) == 0
    doc = json.loads(carried.read_text())
    assert doc["settings"]["tracker"]["update_mode"] == "carried"
    assert doc["settings"]["tracker"]["pressure_gain"] == 0.5
    q = doc["final_quantiles"]["dead_volume_m3"]
    assert q[0] <= truth * 1.2 and q[2] >= truth / 1.2


def test_track_refit_method_finds_a_moved_quantity_and_records_its_knobs(
        bench_run, tmp_path):
    # the run's card with the dead volume 1.6 x the recording's truth: the anchored
    # refit (wide anchor) finds the truth within the run, the frozen fit predicts worse
    rec, run = bench_run
    moved = tmp_path / "run"
    moved.mkdir()
    card = json.loads((run / "model.json").read_text())
    truth = card["parameters"]["dead_volume_m3"]
    card["parameters"]["dead_volume_m3"] = 1.6 * truth
    (moved / "model.json").write_text(json.dumps(card))
    out = tmp_path / "refit.json"
    assert main(["track", str(moved), str(rec), "--vary", "dead_volume_m3", "--out",
                 str(out), "--noise-std", "2000", "--tick", "0.1", "--horizon", "0.5",
                 "--draws", "16", "--predict-every", "5", "--method", "refit",
                 "--relative-sd", "1", "--refit-every", "0.5"]) == 0
    doc = json.loads(out.read_text())
    assert doc["settings"]["method"] == "refit"
    assert doc["settings"]["refit"]["relative_sd"] == 1.0
    assert doc["settings"]["refit"]["refit_every_s"] == 0.5
    q = doc["final_quantiles"]["dead_volume_m3"]
    assert q[0] <= truth * 1.1 and q[2] >= truth / 1.1 and q[0] < q[1] < q[2]
    s = doc["summary"]
    assert s["online_rmse_Pa"] < 0.5 * s["frozen_rmse_Pa"], s
    assert all(r["ess"] is None for r in doc["ticks"])


def test_track_refit_of_every_quantity_and_all_refused_for_particles(bench_run, tmp_path,
                                                                     capsys):
    # the recording's own truth as the run: every quantity refitted on the run so far
    # (a refit on its first window alone is poorly informed; by the end it is not)
    rec, run = bench_run

    def argv(out):
        return ["track", str(run), str(rec), "--vary", "all", "--out", str(out),
                "--noise-std", "600", "--horizon", "0.5", "--draws", "8",
                "--predict-every", "5"]

    out = tmp_path / "all.json"
    assert main([*argv(out), "--method", "refit", "--refit-every", "1",
                 "--relative-sd", "0.1"]) == 0
    doc = json.loads(out.read_text())
    names = list(json.loads((run / "model.json").read_text())["parameters"])
    assert sorted(doc["settings"]["vary"]) == sorted(names)
    assert sorted(doc["final_quantiles"]) == sorted(names)
    truth = json.loads((run / "model.json").read_text())["parameters"]
    for n in ("dead_volume_m3", "inlet_a_m2", "exhaust_a_m2"):
        assert doc["final_quantiles"][n][1] == pytest.approx(truth[n], rel=0.05), n
    assert main(argv(tmp_path / "p.json")) == 2
    assert "--vary all" in capsys.readouterr().err and not (tmp_path / "p.json").exists()


@pytest.mark.parametrize("extra, says", [
    (["--vary", "no_such_quantity"], "--vary"),
    (["--vary", "inlet_offset_m2"], "lower bound"),
    (["--vary", "dead_volume_m3,dead_volume_m3"], "more than once"),
    (["--vary", "dead_volume_m3", "--tick", "0.00001"], "--tick"),
    (["--vary", "dead_volume_m3", "--temper", "0"], "--temper"),
])
def test_track_bad_arguments_name_the_argument(bench_run, tmp_path, capsys, extra, says):
    rec, run = bench_run
    out = tmp_path / "t.json"
    assert main(["track", str(run), str(rec), "--out", str(out), "--noise-std", "2000",
                 *extra]) == 2
    assert says in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("extra, says", [
    (["--pressure-gain", "2"], "--pressure-gain"),
    (["--update-mode", "replay"], "--update-mode"),
])
def test_track_carried_mode_options_are_checked(bench_run, tmp_path, capsys, extra, says):
    rec, run = bench_run
    out = tmp_path / "t.json"
    with pytest.raises(SystemExit) as exc:
        main(["track", str(run), str(rec), "--out", str(out), "--noise-std", "2000",
              "--vary", "dead_volume_m3", *extra])
    assert exc.value.code == 2
    assert says in capsys.readouterr().err and not out.exists()


def test_track_never_writes_over_an_input(bench_run, capsys):
    rec, run = bench_run
    before = (run / "model.json").read_text()
    assert main(["track", str(run), str(rec), "--vary", "dead_volume_m3", "--out",
                 str(run / "model.json"), "--overwrite", "--noise-std", "2000"]) == 2
    assert "input" in capsys.readouterr().err
    assert (run / "model.json").read_text() == before


@pytest.mark.slow
def test_respiraworks_online_experiment_smoke(tmp_path):
    import sys
    from pathlib import Path

    from conftest import load_experiment

    experiments = str(Path(__file__).resolve().parents[1] / "experiments")
    if experiments not in sys.path:  # its siblings (real_respiraworks, ..._forms)
        sys.path.insert(0, experiments)
    mod = load_experiment("real_respiraworks_online")
    assert mod.main(["--out", str(tmp_path), "--sets", "OXY", "--smoke", "--quick",
                     "--modes", "lookback,carried", "--set", "pressure_gain=0.5"]) == 0
    doc = json.loads((tmp_path / "real_respiraworks_online.json").read_text())
    res = doc["sets"]["OXY"]
    assert set(res["protocol_windows"]) == {"setpoint", "frozen", "calibrated"}  # --quick
    assert all(np.isfinite(v) for v in res["protocol_windows"].values())
    online = res["online"]["0"]
    assert np.isfinite(online["protocol_rmse_Pa"]) and np.isfinite(online["every_tick_rmse_Pa"])
    assert 0.0 <= online["coverage_90_protocol"] <= 1.0
    assert set(res["online_modes"]) == {"lookback", "carried"}
    assert res["online_modes"]["lookback"] == res["online"]
    assert np.isfinite(res["online_modes"]["carried"]["0"]["protocol_rmse_Pa"])
    assert doc["tracker"]["pressure_gain"] == 0.5
