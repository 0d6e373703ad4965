"""The controller API (PressurePredictor): every (draw, candidate) pair in one batched
call must equal simulating that pair on its own, history included."""

from __future__ import annotations

import numpy as np
import pytest

from pneubayes.inference.predictive import PressurePredictor, draw_quantiles
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

P_ATM, P_SUP = 101325.0, 551325.0
DT = 0.005  # a 200-Hz controller


@pytest.fixture(scope="module")
def lagging():
    """A valve behind a 12-ms transport delay with a 9-ms spool: the first 20 ms of a
    prediction depend on the commands already applied."""
    model = Model(["cylinder_leak", "tube_delay", "spool_lag"])
    p = valve_preset("valve1").parameters()
    p.update(dead_volume_m3=2.4e-6, leak_area_m2=3.04e-8, tube_delay_s=0.012,
             spool_time_constant_s=0.009)
    rng = np.random.default_rng(3)
    draws = model.vector(p) * rng.uniform(0.95, 1.05, (5, model.n_parameters))
    return model, draws, Rig(0.009, P_ATM, P_SUP)


def _one_at_a_time(model, draws, rig, history, cand, p0, solver):
    """The same prediction as a plain recording: history then candidate, one window."""
    u = np.concatenate([history, cand, cand[-1:]])
    n = u.size
    t = (np.arange(n) - history.size) * DT
    inputs = Inputs(t, u, np.zeros(n), np.full(n, P_SUP))
    return simulate_windows(model, draws, inputs, rig, np.array([history.size]),
                            cand.size + 1, np.array([p0]), solver)[:, 0, :]


def test_batched_candidates_equal_each_simulated_alone(lagging):
    model, draws, rig = lagging
    rng = np.random.default_rng(0)
    cands = rng.uniform(-5, 5, (3, 40))
    history = np.concatenate([np.full(10, -4.0), np.full(6, 4.5)])  # a step 30 ms ago
    solver = SolverConfig.standard()
    api = PressurePredictor(model, draws, rig, solver)
    got = api.predict_draws(2.5e5, cands, 0.0, DT, command_history_V=history)
    assert got.shape == (5, 3, 41)
    for c in range(3):
        want = _one_at_a_time(model, draws, rig, history, cands[c], 2.5e5, solver)
        np.testing.assert_allclose(got[:, c], want, rtol=0, atol=1e-6)
    # the history matters: without it the first 20 ms differ
    fresh = api.predict_draws(2.5e5, cands, 0.0, DT)
    assert np.abs(fresh[:, :, 1:5] - got[:, :, 1:5]).max() > 1e3


def test_short_history_is_extended_by_its_oldest_command(lagging):
    model, draws, rig = lagging
    api = PressurePredictor(model, draws, rig, SolverConfig.standard())
    assert api.lookback_s == pytest.approx(
        np.max(draws[:, -2] + 20 * draws[:, -1]))
    cand = np.full(30, 2.0)
    short = api.predict_draws(2e5, cand, 0.0, DT, command_history_V=[-3.0])
    long = np.full(int(np.ceil(api.lookback_s / DT)) + 5, -3.0)
    want = _one_at_a_time(model, draws, rig, long, cand, 2e5, SolverConfig.standard())
    np.testing.assert_allclose(short[:, 0], want, rtol=0, atol=1e-6)


def test_quantiles_are_those_of_the_draws(lagging):
    model, draws, rig = lagging
    api = PressurePredictor(model, draws, rig, SolverConfig.standard(), quantiles=(0.1, 0.9))
    cands = np.array([np.full(20, 3.0), np.full(20, -3.0)])
    q = api.predict(3e5, cands, 0.0, DT)
    sims = api.predict_draws(3e5, cands, 0.0, DT)
    assert q.shape == (2, 2, 21)
    np.testing.assert_allclose(q, np.moveaxis(np.quantile(sims, (0.1, 0.9), axis=0), 0, 1))
    assert q[0, 1, -1] > 3.5e5 and q[1, 0, -1] < 2.5e5  # fill vs vent


def test_control_preset_stays_within_its_stated_error(lagging):
    """SolverConfig.standard() against the reference preset on a 2-s 200-Hz horizon."""
    model, draws, rig = lagging
    rng = np.random.default_rng(1)
    cands = np.repeat(rng.uniform(-5, 5, (2, 20)), 20, axis=1)
    ref = PressurePredictor(model, draws, rig, SolverConfig.reference())
    ctl = PressurePredictor(model, draws, rig, SolverConfig.standard())
    err = np.abs(ctl.predict_draws(3e5, cands, 0.0, DT)
                 - ref.predict_draws(3e5, cands, 0.0, DT)).max()
    assert err < 0.001 * (P_SUP - P_ATM)


@pytest.mark.parametrize("bad, what", [({"dt_s": 0.0}, "dt_s"),
                                       ({"commands_V": np.zeros((2, 0))}, "commands_V"),
                                       ({"command_history_V": []}, "command_history_V")])
def test_bad_arguments_are_named(lagging, bad, what):
    model, draws, rig = lagging
    api = PressurePredictor(model, draws, rig, SolverConfig.standard())
    kw = {"pressure_Pa": 2e5, "commands_V": np.zeros(5), "position_m": 0.0, "dt_s": DT}
    kw.update(bad)
    with pytest.raises(ValueError, match=what):
        api.predict(**kw)


def test_predictive_reading_carries_the_start_noise_as_the_likelihood_does(lagging):
    """r_k = n_k - S_k n_0: nothing is added at the start; a constant noise path cancels
    while the start is remembered (one tick on, S ~ 1) and is added in full once the
    chamber has forgotten it (full exhaust pulls it to the atmosphere, S -> 0); in
    between it grows as the start is forgotten, faster when venting."""
    model, draws, rig = lagging
    api = PressurePredictor(model, draws, rig, SolverConfig.standard())
    n_l = 60  # 300 ms
    cands = np.array([np.full(n_l, 0.0), np.full(n_l, -5.0)])
    const = np.full((draws.shape[0], n_l + 1), 5e3)
    p, reading = api.predictive_draws(3e5, cands, 0.0, DT, const,
                                      command_history_V=np.zeros(5))
    np.testing.assert_array_equal(p, api.predict_draws(3e5, cands, 0.0, DT,
                                                       command_history_V=np.zeros(5)))
    np.testing.assert_array_equal(reading[:, :, 0], p[:, :, 0])
    added = reading - p
    assert np.all(added[:, 0, 1] < 0.1 * 5e3)                  # one tick: remembered
    np.testing.assert_allclose(added[:, 1, -1], 5e3, rtol=0.01)  # vented: forgotten
    assert np.all(np.diff(added, axis=2) >= -1e-6) and np.all(added <= 5e3 * (1 + 1e-9))
    # the delay: both candidates see the same history for 12 ms, then venting forgets
    assert np.all(added[:, 1] >= added[:, 0] - 1e-6)
    assert np.all(added[:, 1, -1] > added[:, 0, -1] + 500.0)
    # a zero path adds nothing
    _, quiet = api.predictive_draws(3e5, cands, 0.0, DT, np.zeros_like(const))
    np.testing.assert_array_equal(quiet, api.predict_draws(3e5, cands, 0.0, DT))
    with pytest.raises(ValueError, match="noise_Pa"):
        api.predictive_draws(3e5, cands, 0.0, DT, const[:, :-1])


def test_draw_quantiles_are_numpys_bit_for_bit():
    """The controller's one-sort quantiles equal np.quantile's default (linear) method
    exactly: ties, one draw, the extreme quantiles, and NaN slices as NaN."""
    rng = np.random.default_rng(7)
    for trial in range(300):
        n = 1 if trial == 0 else int(rng.integers(2, 130))  # one draw, then many
        x = rng.normal(size=(n, int(rng.integers(1, 4)), int(rng.integers(1, 9))))
        x *= 10.0 ** rng.uniform(-3, 6)
        if trial % 3 == 0:
            x = np.round(x)  # ties
        q = np.concatenate([[0.0, 1.0, 0.5, 0.05, 0.95], rng.uniform(0, 1, 3)])
        np.testing.assert_array_equal(draw_quantiles(x, q), np.quantile(x, q, axis=0))
    x = rng.normal(size=(64, 2, 5))
    x[3, 1, 2] = np.nan
    got = draw_quantiles(x, (0.05, 0.5, 0.95))
    np.testing.assert_array_equal(got, np.quantile(x, (0.05, 0.5, 0.95), axis=0))
    assert np.isnan(got[:, 1, 2]).all() and np.isfinite(got[:, 0]).all()
