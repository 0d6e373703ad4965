"""The online refit (:class:`~pneubayes.inference.online_refit.OnlineRefit`) and the
refiner's Gaussian anchor, on the shipped RespiraWorks card driven by run 5's commands,
with a planted plant that differs from the card's start in its lung and inhale valve."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pneubayes.inference.online import forecast
from pneubayes.inference.online_refit import OnlineRefit
from pneubayes.inference.refine import (
    GaussianAnchor,
    TrajectoryRefiner,
    parameter_scales,
    relative_spread,
)
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.rigcard import load_rig_card
from pneubayes.simulation import Inputs, SolverConfig, simulate

DATA = Path(__file__).resolve().parents[1] / "data" / "real" / "respiraworks"
NAMES = ("lung_compliance_m3_per_Pa", "resistance_Pa_s_per_m3", "inlet_a_m2")
NOISE_PA = 20.0
N = 1400  # 14 s at 100 Hz


@pytest.fixture(scope="module")
def plant():
    """The OXY card's start values (the 'shared fit') and a run simulated from a plant
    whose lung compliance is 2 x, resistance 0.5 x and inhale area 0.6 x those."""
    card = load_rig_card(DATA / "respiraworks-oxy.rig.json")
    rec = read_recording(DATA / "OXY" / "covent_pc_5.csv", rig_card=card).slice(0, N)
    model = Model(rig_card=card)
    params = model.base_start_values()
    truth = {**params, NAMES[0]: 2.0 * params[NAMES[0]], NAMES[1]: 0.5 * params[NAMES[1]],
             NAMES[2]: 0.6 * params[NAMES[2]]}
    rig = rec.rig()
    inputs = Inputs.from_recording(rec)
    clean = simulate(model, truth, inputs, rig, float(rec.pressure_Pa[0]),
                     SolverConfig.standard()).pressure_Pa[0]
    p = clean + np.random.default_rng(11).normal(0.0, NOISE_PA, clean.size)
    return {"model": model, "params": params, "truth": truth, "rig": rig,
            "rec": replace(rec, pressure_Pa=p)}


def _refit(plant, relative_sd, **kw):
    return OnlineRefit(plant["model"], plant["params"], NAMES, relative_sd, 50.0,
                       SolverConfig.standard(), max_nfev=30, **kw).reset()


def _forecast_rmse(plant, params, start):
    model, rec = plant["model"], plant["rec"]
    h = 200
    pred = forecast(model, model.vector(params)[None], Inputs.from_recording(rec),
                    plant["rig"], start, h + 1, rec.pressure_Pa, SolverConfig.standard())
    return float(np.sqrt(np.mean((rec.pressure_Pa[start + 1:start + h + 1] - pred[0, 1:]) ** 2)))


def test_the_refit_follows_a_plant_unlike_the_shared_fit(plant):
    on = _refit(plant, 1.0, refit_every_s=2.0)
    for k in (400, 600, 800):  # the run so far at 4, 6 and 8 s
        on.update(plant["rec"].slice(0, k + 1))
    assert on.n_refits_ == 3 and len(on.refit_seconds_) == 3
    # the next 2 s predicted: the frozen fit well above the noise, the refit at it
    frozen = _forecast_rmse(plant, plant["params"], 800)
    online = _forecast_rmse(plant, on.params_, 800)
    assert frozen > 2.5 * NOISE_PA and online < 1.2 * NOISE_PA, (online, frozen)
    # the planted quantities: the valve's area found, the lung's (which its unfitted
    # volume partly stands in for, over 8 s) nearer the truth than the shared fit
    assert abs(np.log(on.params_[NAMES[2]] / plant["truth"][NAMES[2]])) < 0.05
    for n in NAMES[:2]:
        moved = abs(np.log(on.params_[n] / plant["truth"][n]))
        assert moved < 0.8 * abs(np.log(plant["params"][n] / plant["truth"][n])), n
    # the quantities not refitted stay where the shared fit put them
    others = [n for n in plant["model"].parameter_names if n not in NAMES]
    assert all(on.params_[n] == plant["params"][n] for n in others)


def test_an_update_inside_the_refit_interval_refits_nothing(plant):
    on = _refit(plant, 1.0, refit_every_s=2.0)
    on.update(plant["rec"].slice(0, 401))
    before = dict(on.params_)
    on.update(plant["rec"].slice(0, 501))  # 1 s later
    assert on.n_refits_ == 1 and on.params_ == before


def test_no_refit_before_the_run_holds_min_windows(plant):
    on = _refit(plant, 1.0, min_windows=3)
    on.update(plant["rec"].slice(0, 501))  # 5 s: two 2-s windows
    assert on.n_refits_ == 0 and on.params_ == plant["params"]
    on.update(plant["rec"].slice(0, 601))  # 6 s: three
    assert on.n_refits_ == 1
    with pytest.raises(ValueError, match="min_windows"):
        _refit(plant, 1.0, min_windows=0)


def test_a_narrow_anchor_holds_the_quantities_at_its_centre(plant):
    on = _refit(plant, 1e-4)
    on.update(plant["rec"].slice(0, 601))
    for n in NAMES:
        sd = on.anchor_.sd[n]
        assert abs(on.params_[n] - plant["params"][n]) < 5 * sd, n
        # the posterior no wider than the prior
        assert np.sqrt(on.covariance_[NAMES.index(n), NAMES.index(n)]) <= sd * (1 + 1e-9)


def test_each_quantity_its_own_anchor_width(plant):
    """A centre right in the lung, wrong in the inhale area (the plant's is 0.6 x): with
    the area's anchor wide and the lung's narrow, the lung stays at the centre and the
    area is found."""
    truth = plant["truth"]
    centre = {**truth, NAMES[2]: plant["params"][NAMES[2]]}
    widths = {NAMES[0]: 1e-4, NAMES[1]: 1e-4, NAMES[2]: 3.0}
    on = OnlineRefit(plant["model"], centre, NAMES, widths, 50.0, SolverConfig.standard(),
                     max_nfev=30).reset()
    sd = on.anchor_.sd
    on.update(plant["rec"].slice(0, 801))
    for n in NAMES[:2]:
        assert abs(on.params_[n] - centre[n]) < 5 * sd[n], n
    assert abs(np.log(on.params_[NAMES[2]] / truth[NAMES[2]])) < 0.05
    narrow = _refit(plant, 1e-4)  # one narrow width for all: the area held too
    assert narrow.anchor_.sd[NAMES[2]] < 1e-4 * sd[NAMES[2]]
    with pytest.raises(ValueError, match="no value for"):
        _refit(plant, {NAMES[0]: 1.0})
    with pytest.raises(ValueError, match="must be > 0"):
        _refit(plant, {**widths, NAMES[1]: 0.0})


def test_relative_spread_is_the_runs_rms_over_the_scale(plant):
    model, centre = plant["model"], plant["params"]
    scale = dict(zip(model.parameter_names, parameter_scales(model, model.vector(centre))))
    a, b = NAMES[0], NAMES[2]
    fits = [{**centre, a: centre[a] + 0.3 * scale[a]},
            {**centre, a: centre[a] - 0.4 * scale[a]}]
    out = relative_spread(model, centre, fits, (a, b), floor=0.01)
    assert out[a] == pytest.approx(np.sqrt((0.09 + 0.16) / 2), rel=1e-12)
    assert out[b] == 0.01  # the runs agree on it: the floor
    with pytest.raises(ValueError, match="no per-run fits"):
        relative_spread(model, centre, [], (a,), floor=0.01)
    with pytest.raises(ValueError, match="floor"):
        relative_spread(model, centre, fits, (a,), floor=0.0)
    with pytest.raises(ValueError, match="not a parameter"):
        relative_spread(model, centre, fits, ("nope",), floor=0.01)


def test_the_laplace_covariance_adds_the_anchors_precision(plant):
    model, rec = plant["model"], plant["rec"].slice(0, 601)
    anchor = GaussianAnchor.relative(model, plant["params"], NAMES, 0.3, 50.0)
    fit = TrajectoryRefiner(model, SolverConfig.standard(), free=NAMES, max_nfev=30,
                            anchor=anchor).fit(WindowSet([rec], 2.0, 2.0), plant["params"])
    precision = fit.information_ + np.diag([1.0 / anchor.sd[n] ** 2 for n in NAMES])
    s = np.sqrt(np.diag(fit.covariance_))  # compared in units of each posterior SD
    product = (fit.covariance_ / np.outer(s, s)) @ (precision * np.outer(s, s))
    assert np.allclose(product, np.eye(len(NAMES)), atol=1e-6)
    # the draws: the posterior's mean and covariance, within the bounds
    on = _refit(plant, 0.3)
    on.params_, on.covariance_ = dict(fit.params_), fit.covariance_
    d = on.draws(4000, np.random.default_rng(0))
    cols = [model.parameter_names.index(n) for n in NAMES]
    lo, hi = model.bounds
    assert np.all(d >= lo) and np.all(d <= hi)
    sd = np.sqrt(np.diag(fit.covariance_))
    assert np.all(np.abs(d[:, cols].mean(axis=0) - model.vector(fit.params_)[cols]) < 0.1 * sd)
    inside = np.all((d[:, cols] > lo[cols]) & (d[:, cols] < hi[cols]), axis=1)
    assert np.allclose(d[inside][:, cols].std(axis=0), sd, rtol=0.1)
    assert np.allclose(np.corrcoef(d[inside][:, cols].T),
                       fit.covariance_ / np.outer(sd, sd), atol=0.06)
    q = on.quantiles((0.05, 0.5, 0.95))
    assert q[NAMES[0]][1] == fit.params_[NAMES[0]]


def test_bad_arguments_are_named(plant):
    with pytest.raises(ValueError, match="error_Pa"):
        GaussianAnchor({"a": 1.0}, {"a": 1.0}, 0.0)
    with pytest.raises(ValueError, match="sd must be > 0"):
        GaussianAnchor({"a": 1.0}, {"a": -1.0}, 1.0)
    with pytest.raises(ValueError, match="no mean"):
        GaussianAnchor({}, {"a": 1.0}, 1.0)
    with pytest.raises(ValueError, match="not parameters"):
        GaussianAnchor.relative(plant["model"], plant["params"], ["nope"], 0.1, 1.0)
    with pytest.raises(ValueError, match="memory_s"):
        _refit(plant, 1.0, memory_s=1.0)
    with pytest.raises(RuntimeError, match="reset"):
        OnlineRefit(plant["model"], plant["params"], NAMES, 1.0, 50.0,
                    SolverConfig.standard()).update(plant["rec"])
    with pytest.raises(TypeError, match="GaussianAnchor"):
        TrajectoryRefiner(plant["model"], SolverConfig.standard(), anchor={"a": 1})
