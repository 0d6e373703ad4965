"""A sensor zero that drifts (effect ``sensor_drift``): the reading P_atm + g (p - P_atm)
+ o(t) with o(t) = o + a t + b (1 - exp(-t / tau)) on the recording's clock, against
its hand formula, conservation (a closed chamber's reading moves by the zero alone), the
reference solver, the bench that plants it and the recovery of planted values."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import moving_step_inputs, valve1_params
from scipy.optimize import least_squares

from pneubayes.bench import BenchConfig, run_bench
from pneubayes.effects import make_effect
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.physics.calibration import (
    reading_zero_Pa,
    reading_zero_rate_scalar,
    reading_zero_scalar,
)
from pneubayes.simulation import Inputs, SolverConfig, simulate, simulate_windows
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM
DRIFT = {"reading_drift_Pa_per_s": -900.0, "reading_warm_up_Pa": 6000.0,
         "reading_warm_up_time_constant_s": 0.15}
FULL = Model([make_effect("sensor_drift", form="linear_warm_up")])


def _zero(t, o=0.0, d=DRIFT):
    """The zero by hand: o + a t + b (1 - exp(-t / tau)), the warm-up 0 before t = 0."""
    t = np.asarray(t, dtype=np.float64)
    warm = np.where(t > 0, 1.0 - np.exp(-np.maximum(t, 0) / d["reading_warm_up_time_constant_s"]),
                    0.0)
    return o + d["reading_drift_Pa_per_s"] * t + d["reading_warm_up_Pa"] * warm


def test_the_zero_and_its_rate_follow_the_hand_formula():
    t = np.array([-0.5, 0.0, 0.01, 0.2, 3.0])
    args = (250.0, *DRIFT.values())
    np.testing.assert_allclose(reading_zero_Pa(t, *args), _zero(t, 250.0), rtol=1e-14,
                               atol=1e-9)
    for ti in t:
        assert reading_zero_scalar(args, ti) == pytest.approx(float(_zero(ti, 250.0)),
                                                              rel=1e-14, abs=1e-9)
    for ti in (0.01, 0.2, 3.0):  # the rate against central differences
        h = 1e-6
        fd = (_zero(ti + h) - _zero(ti - h)) / (2 * h)
        assert reading_zero_rate_scalar(args, ti) == pytest.approx(float(fd), rel=1e-6)
    # no warm-up: its time constant is not read (0 here would divide by zero)
    assert reading_zero_Pa(1.0, 0.0, 5.0, 0.0, 0.0) == 5.0
    assert reading_zero_scalar((0.0, 5.0, 0.0, 0.0), 1.0) == 5.0


def test_a_neutral_drift_is_exactly_no_drift(rig):
    inputs = moving_step_inputs(3, 301, 1e-3, hold_s=(0.01, 0.05))
    solver = SolverConfig.standard()
    plain = simulate(Model(), valve1_params(), inputs, rig, 2e5, solver).pressure_Pa
    neutral = simulate(FULL, valve1_params(**FULL.effect("sensor_drift").neutral_values()),
                       inputs, rig, 2e5, solver).pressure_Pa
    assert np.array_equal(plain, neutral)


def test_a_closed_chamber_reads_its_pressure_plus_the_zero_of_each_time(
        rig, closable_params, make_inputs):
    """Both ports shut, no leak: the chamber holds the pressure its window's first
    reading stands for at that time, and the reading moves by the zero's change alone;
    windows starting at other times invert their own start's zero."""
    n = 401
    t = 0.05 + np.arange(n) * 1e-3
    inputs = make_inputs(t, np.zeros(n))
    params = dict(closable_params, **DRIFT)
    starts = np.array([0, 120, 300])
    p0 = np.array([2.5e5, 2.5e5, 3.1e5])
    got = simulate_windows(FULL, params, inputs, rig, starts, 100, p0,
                           SolverConfig.standard())[0]
    for w, s in enumerate(starts):
        want = p0[w] + _zero(t[s:s + 100]) - _zero(t[s])
        np.testing.assert_allclose(got[w], want, rtol=0, atol=1e-9 * p0[w])


@pytest.mark.parametrize("volume", [2.4e-6, 1e-7])
def test_the_drifting_reading_agrees_with_the_reference_solver(rig, volume):
    """With a lagged sensor, the gain error and a warm-up that moves within the window,
    started at a reading and its rate (the zero's rate is the reading's, not the
    chamber's)."""
    inputs = moving_step_inputs(5, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("sensor_lag"),
                   make_effect("sensor_calibration", form="offset_gain"),
                   make_effect("sensor_drift", form="linear_warm_up")])
    params = valve1_params(volume, sensor_time_constant_s=1e-3, reading_offset_Pa=3000.0,
                           reading_gain_error=0.03, **DRIFT)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8,
                             initial_rate_Pa_per_s=-3e5)
    got = simulate_windows(model, params, inputs, rig, np.array([0]), inputs.n_samples,
                           np.array([2e5]), SolverConfig.standard(),
                           initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    # the drift matters here: without it the reading differs by far more
    still = dict(params, reading_drift_Pa_per_s=0.0, reading_warm_up_Pa=0.0)
    plain = simulate_windows(model, still, inputs, rig, np.array([0]), inputs.n_samples,
                             np.array([2e5]), SolverConfig.standard(),
                             initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(plain - ref)) > 10 * np.max(np.abs(got - ref))


def _bench(tmp_path, name, effects, overrides=None):
    kw = dict(protocol="fixed", duration_s=0.6, seed=4, ranges_V=(3.0,), positions=(0.5,))
    return run_bench(BenchConfig("AIR37", "valve1", effects, overrides=overrides or {}, **kw),
                     tmp_path / name)


def test_the_bench_plants_the_drift_in_the_reading(tmp_path):
    """The same seed draws the same noise and commands: the recordings differ by the
    zero's drift on the recording's clock, to the 0.1-Pa logging."""
    truth = {"reading_warm_up_Pa": -4000.0, "reading_warm_up_time_constant_s": 0.2}
    res = _bench(tmp_path, "drift", (make_effect("sensor_drift"),), truth)
    plain = _bench(tmp_path, "plain", ())
    got, want = (read_recording(r.recordings[0]) for r in (res, plain))
    d = dict(truth, reading_drift_Pa_per_s=0.0)
    np.testing.assert_allclose(got.pressure_Pa - want.pressure_Pa, _zero(got.time_s, d=d),
                               atol=0.11)
    assert res.truth["parameters"]["reading_warm_up_Pa"] == -4000.0
    assert reading_zero_Pa(0.0, 0.0, 0.0, truth["reading_warm_up_Pa"],
                           truth["reading_warm_up_time_constant_s"]) == 0.0


def test_a_planted_warm_up_is_recovered_from_windows(tmp_path):
    """Windows of a bench recording with a warming sensor, the valve known: least squares
    through the simulator finds the warm-up's amplitude and time constant."""
    truth = {"reading_warm_up_Pa": 5000.0, "reading_warm_up_time_constant_s": 0.25}
    res = _bench(tmp_path, "drift", (make_effect("sensor_drift"),), truth)
    rec = read_recording(res.recordings[0])
    known = {k: v for k, v in res.truth["parameters"].items() if k not in truth}
    model = Model([make_effect("sensor_drift")])
    rig = rec.rig()
    inputs = Inputs.from_recording(rec)
    length = 60
    starts = np.arange(0, rec.n_samples - length, length - 1)

    def residual(v):
        params = {**known, "reading_warm_up_Pa": v[0],
                  "reading_warm_up_time_constant_s": np.exp(v[1])}
        sim = simulate_windows(model, params, inputs, rig, starts, length,
                               rec.pressure_Pa[starts], SolverConfig.standard())[0]
        return (sim - rec.pressure_Pa[starts[:, None] + np.arange(length)]).ravel()

    fit = least_squares(residual, [1000.0, np.log(1.0)], x_scale=[1000.0, 1.0])
    assert fit.x[0] == pytest.approx(5000.0, rel=0.1)
    assert np.exp(fit.x[1]) == pytest.approx(0.25, rel=0.15)
    # and the fit is the drift's doing: without it the windows miss by far more
    base = residual([0.0, np.log(0.25)])
    assert np.sqrt(np.mean(base**2)) > 3 * np.sqrt(np.mean(fit.fun**2))


def test_the_controller_predicts_every_candidate_from_now_on_the_recordings_clock(rig):
    """A drifting zero is read on the recording's clock: the predictor simulates each
    candidate from ``time_s`` (two equal candidates predict the same), as a window of
    a recording starting then does; without a drift it batches the candidates."""
    from pneubayes.inference.predictive import PressurePredictor

    model = Model([make_effect("sensor_drift")])
    params = valve1_params(reading_warm_up_Pa=5000.0, reading_warm_up_time_constant_s=0.5)
    solver = SolverConfig.standard()
    pred = PressurePredictor(model, model.as_matrix(params), rig, solver)
    assert pred.clocked
    dt, n = 5e-3, 80
    u = np.where(np.arange(n) < 30, 2.0, -1.0)
    got = pred.predict_draws(2.5e5, np.stack([u, u]), 0.01, dt, time_s=0.2)
    assert np.array_equal(got[:, 0], got[:, 1])
    # the same window on a recording's clock, from 0.2 s (its history held before)
    n_h = int(np.ceil(pred.lookback_s / dt)) + 1
    t = 0.2 + (np.arange(n_h + n + 1) - n_h) * dt
    cmd = np.concatenate([np.full(n_h, u[0]), u, u[-1:]])
    inputs = Inputs(t, cmd, np.full(t.size, 0.01), np.full(t.size, P_SUP))
    want = simulate_windows(model, params, inputs, rig, np.array([n_h]), n + 1,
                            np.array([2.5e5]), solver)[0, 0]
    np.testing.assert_allclose(got[0, 0], want, rtol=0, atol=1e-6 * RANGE)
    # which is the plain chamber started at the pressure the reading stands for now,
    # read through the zero of each time
    warm = dict(DRIFT, reading_drift_Pa_per_s=0.0, reading_warm_up_Pa=5000.0,
                reading_warm_up_time_constant_s=0.5)
    plain = simulate_windows(Model(), valve1_params(), inputs, rig, np.array([n_h]), n + 1,
                             np.array([2.5e5 - _zero(0.2, d=warm)]), solver)[0, 0]
    assert float(_zero(t[-1], d=warm) - _zero(0.2, d=warm)) > 1000.0
    np.testing.assert_allclose(got[0, 0, 1:], plain[1:] + _zero(t[n_h + 1:], d=warm),
                               rtol=0, atol=1e-6 * RANGE)
    assert not PressurePredictor(Model(), Model().as_matrix(valve1_params()), rig,
                                 solver).clocked
