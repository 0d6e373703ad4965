"""Dense output (``SolverConfig.dense_output``): steps cross the samples over which the inputs
hold, and the samples they cross are read from the step's interpolant; over a moving
piston a step reads the position's chord. Checked against the reference preset, against
the default stepping, by the flow balance and by tightening; models it does not apply
to, and a supply the model reads that moves every sample, must give the default's
numbers bit for bit (a measured supply the model does not read does not stop the
steps). (A shut valve keeps its pressure exactly with dense output:
tests/test_simulator.py, beside the other conservation tests.)"""

from __future__ import annotations

import numpy as np
import pytest

from pneubayes.effects import make_effect
from pneubayes.inference.predictive import PressurePredictor
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    simulate,
    simulate_windows,
    simulate_windows_sensitivity,
)

P_ATM, P_SUP = 101325.0, 551325.0
RANGE_PA = P_SUP - P_ATM
RIG = Rig(0.009, P_ATM, P_SUP)


def _held_steps(rng, n, dt, hold_s=(0.03, 0.3)):
    """Random step commands held for 30-300 ms, on a grid of period dt."""
    out = np.empty(n)
    i = 0
    while i < n:
        k = max(1, round(rng.uniform(*hold_s) / dt))
        out[i:i + k] = rng.uniform(-5.0, 5.0)
        i += k
    return out


def _inputs(u, dt, x=None, sup=None):
    n = u.size
    return Inputs(np.arange(n) * dt, u, np.zeros(n) if x is None else x,
                  np.full(n, P_SUP) if sup is None else sup)


def _model(effects=("cylinder_leak",), volume=2.4e-6, **extra):
    model = Model(list(effects))
    p = {**model.neutral_values(), **valve_preset("valve1").parameters()}
    p.update(dead_volume_m3=volume, leak_area_m2=3.04e-8, **extra)
    return model, model.vector({k: v for k, v in p.items() if k in model.parameter_names})


def _run(model, theta, inputs, solver, dense, p0=3e5, sens=False):
    """``solver`` with dense output set to ``dense``."""
    fn = simulate_windows_sensitivity if sens else simulate_windows
    return fn(model, theta, inputs, RIG, np.array([0]), inputs.n_samples, np.array([p0]),
              solver.with_dense_output(dense))


@pytest.mark.parametrize("volume", [1e-7, 2.4e-7, 2.4e-6])
@pytest.mark.parametrize("dt", [0.005, 0.001])
def test_dense_output_agrees_with_the_reference_within_the_accuracy_floor(volume, dt):
    rng = np.random.default_rng(11)
    model, theta = _model(volume=volume)
    inputs = _inputs(_held_steps(rng, round(2.0 / dt), dt), dt)
    ref = _run(model, theta, inputs, SolverConfig.reference(), False)
    stops = _run(model, theta, inputs, SolverConfig.standard(), False)
    dense = _run(model, theta, inputs, SolverConfig.standard(), True)
    err = np.abs(dense - ref).max()
    assert err < 1e-3 * RANGE_PA  # the standard preset's floor, 0.1 % of the range
    # it does change the stepping (else this test checks nothing)
    assert np.abs(dense - stops).max() > 0.0


def test_dense_output_converges_to_the_reference_when_tightened():
    rng = np.random.default_rng(5)
    model, theta = _model(volume=2.4e-6)
    dt = 0.001
    inputs = _inputs(_held_steps(rng, 2000, dt), dt)
    ref = _run(model, theta, inputs, SolverConfig.reference(), False)
    errs = [np.abs(_run(model, theta, inputs, SolverConfig.standard().tightened(f), True)
                   - ref).max() for f in (1.0001, 10.0, 100.0)]
    assert errs[1] < 0.5 * errs[0] and errs[2] < 0.5 * errs[1], errs
    assert errs[2] < 5.0, errs


def test_dense_output_sensitivity_agrees_with_the_stepped_one():
    rng = np.random.default_rng(2)
    model, theta = _model(volume=2.4e-7)
    dt = 0.005
    inputs = _inputs(_held_steps(rng, 400, dt), dt)
    _, s_stops = _run(model, theta, inputs, SolverConfig.standard().tightened(10), False,
                      sens=True)
    _, s_dense = _run(model, theta, inputs, SolverConfig.standard().tightened(10), True,
                      sens=True)
    assert s_dense[0, 0, 0] == 1.0
    assert np.abs(s_dense - s_stops).max() < 0.02


@pytest.mark.parametrize("volume", [1e-7, 2.4e-6])
def test_full_commands_settle_at_the_flow_balance_with_dense_output(leak_model, base_params,
                                                                   rig, volume, standard,
                                                                   make_inputs, hand):
    base_params["dead_volume_m3"] = volume
    theta = leak_model.vector(base_params)
    t = np.arange(2001) * 1e-3
    up, down = (simulate_windows(leak_model, theta, make_inputs(t, np.full(t.size, u)), rig,
                                 np.array([0]), t.size, np.array([p0]),
                                 standard.with_dense_output())[0, 0]
                for u, p0 in ((5.0, P_ATM), (-5.0, P_SUP)))
    # at the flow balance of eqs. 4/9 (independent root finding), approached monotonely
    assert up[-1] == pytest.approx(hand.equilibrium(base_params, u=5.0), abs=1.0)
    assert down[-1] == pytest.approx(hand.equilibrium(base_params, u=-5.0), abs=1.0)
    assert np.all(np.diff(up) >= -1e-6 * P_SUP) and np.all(np.diff(down) <= 1e-6 * P_SUP)


def test_dense_output_behind_a_transport_delay_agrees_with_the_reference():
    rng = np.random.default_rng(8)
    model, theta = _model(("cylinder_leak", "tube_delay"), volume=2.4e-7,
                          tube_delay_s=0.0123)
    dt = 0.005
    inputs = _inputs(_held_steps(rng, 400, dt), dt)
    ref = _run(model, theta, inputs, SolverConfig.reference(), False)
    dense = _run(model, theta, inputs, SolverConfig.standard(), True)
    assert np.abs(dense - ref).max() < 1e-3 * RANGE_PA


@pytest.mark.parametrize("form", ["first_order", "second_order"])
@pytest.mark.parametrize("volume", [1e-7, 2.4e-6])
def test_dense_output_behind_a_lagging_spool_and_a_delay_agrees_with_the_reference(form,
                                                                                   volume):
    """The spool moves in closed form across the crossed samples as within one."""
    model = Model([make_effect("cylinder_leak"), make_effect("tube_delay", form="transport"),
                   make_effect("spool_lag", form=form)])
    p = {**model.neutral_values(), **valve_preset("valve1").parameters()}
    p.update(dead_volume_m3=volume, leak_area_m2=3.04e-8, tube_delay_s=0.012)
    if form == "first_order":
        p["spool_time_constant_s"] = 0.009
    else:
        p.update(spool_delay_s=0.01, spool_damping=0.6)
    theta = model.vector({k: v for k, v in p.items() if k in model.parameter_names})
    rng = np.random.default_rng(12)
    for dt in (0.005, 0.001):
        inputs = _inputs(_held_steps(rng, round(2.0 / dt), dt), dt)
        ref = _run(model, theta, inputs, SolverConfig.reference(), False)
        stops = _run(model, theta, inputs, SolverConfig.standard(), False)
        dense = _run(model, theta, inputs, SolverConfig.standard(), True)
        assert np.abs(dense - ref).max() < 1e-3 * RANGE_PA
        assert np.abs(dense - stops).max() > 0.0


@pytest.mark.parametrize("effects,extra", [
    (("cylinder_leak", "sensor_lag"), {"sensor_time_constant_s": 0.004}),
    (("cylinder_leak", "heat_transfer"), {"heat_transfer_rate_per_s": 20.0,
                                          "heat_transfer_coupling": 1.0}),
])
def test_models_dense_output_does_not_cover_step_as_without_it(effects, extra):
    rng = np.random.default_rng(4)
    model, theta = _model(effects, volume=2.4e-6, **extra)
    dt = 0.005
    inputs = _inputs(_held_steps(rng, 200, dt), dt)
    a = _run(model, theta, inputs, SolverConfig.standard(), False)
    b = _run(model, theta, inputs, SolverConfig.standard(), True)
    assert np.array_equal(a, b)


def _aggressive_motion(t, seed):
    """Piston motion as benchmarks/simulate.py's: 1-8 Hz sines, 0.5 m/s at most, within
    the AIR37 stroke (37.5 mm) less 1.25 mm at each end."""
    rng = np.random.default_rng(seed)
    f = np.array([1.0, 2.0, 3.5, 5.5, 8.0])
    x = (f[:, None] ** -0.2 * np.sin(2 * np.pi * f[:, None] * t[None, :]
                                     + rng.uniform(0, 2 * np.pi, f.size)[:, None])).sum(0)
    scale = min(0.5 / np.abs(np.diff(x) / np.diff(t)).max(), 0.035 / np.ptp(x))
    return (x - 0.5 * (x.max() + x.min())) * scale + 0.01875


@pytest.mark.parametrize("volume", [2e-7, 2.4e-6])
def test_a_moving_piston_is_crossed_on_its_chord_within_the_floor(volume):
    """Over a moving piston a step reads the position's chord; the samples it crosses are
    moved to their own position adiabatically less the flows' response, and the step's
    end by that response (first order; its size is checked against the tolerance).
    (On benchmarks/simulate.py's seed-0 motion with the command at 0 V, 2.4e-6 m^3, p0
    3 bar, the error was 266 Pa RMS without the corrections and 43 Pa with the adiabatic
    one alone, measured while building them.) Within the floor of the reference, and
    converging on it."""
    rng = np.random.default_rng(21)
    dt = 0.001
    t = np.arange(2001) * dt
    model, theta = _model(volume=volume)
    inputs = _inputs(_held_steps(rng, t.size, dt), dt, x=_aggressive_motion(t, 3))
    ref = _run(model, theta, inputs, SolverConfig.reference().tightened(10.0), False)
    stops = _run(model, theta, inputs, SolverConfig.standard(), False)
    errs = [np.abs(_run(model, theta, inputs, SolverConfig.standard().tightened(f), True)
                   - ref).max() for f in (1.0001, 10.0, 100.0)]
    assert errs[0] < 1e-3 * RANGE_PA, errs  # the standard preset's floor
    assert errs[0] < 2.0 * np.abs(stops - ref).max() + 20.0, errs
    assert errs[1] < 0.5 * errs[0] and errs[2] < 0.5 * errs[1], errs
    # it does cross the samples (else this test checks nothing)
    assert not np.array_equal(_run(model, theta, inputs, SolverConfig.standard(), True), stops)


@pytest.mark.parametrize("volume", [2e-7, 2.4e-6])
def test_a_closed_rigid_chamber_over_an_aggressive_piston_is_exact(volume, closable_params):
    """Both ports shut, no leak: p V^1.4 is constant. A crossing step in a rigid chamber
    whose compression outpaces the flows is taken in q = p V^n, so every sample is exact
    to rounding, and dp/dp0 = (V0 / V)^n (moving p alone to each sample's volume, second
    order, left 436 Pa at 2e-7 m^3 on this motion, 0.87-18.7 bar, when measured)."""
    model = Model([])
    theta = model.vector(dict(closable_params, dead_volume_m3=volume))
    dt = 0.001
    t = np.arange(2001) * dt
    x = _aggressive_motion(t, 1)
    inputs = _inputs(np.zeros(t.size), dt, x=x)
    out, sens = _run(model, theta, inputs, SolverConfig.standard(), True, p0=2e5, sens=True)
    ratio = ((volume + RIG.bore_area_m2 * x[0]) / (volume + RIG.bore_area_m2 * x)) ** 1.4
    assert np.abs(out[0, 0] / (2e5 * ratio) - 1.0).max() < 1e-9
    assert np.abs(sens[0, 0] / ratio - 1.0).max() < 1e-9
    # the stepped solution is not exact here (else this checks nothing new)
    stops = _run(model, theta, inputs, SolverConfig.standard(), False, p0=2e5)
    assert np.abs(stops[0, 0] / (2e5 * ratio) - 1.0).max() > 1e-7


@pytest.mark.parametrize("leak_m2", [1e-9, 3e-8])
def test_dense_sensitivity_over_a_moving_piston_agrees_with_the_stepped_one(leak_m2,
                                                                           closable_params):
    """dp/dp0 across chords against the stepped sensitivity: a shut valve and a leak whose
    relaxation (about 20 / s and 700 / s at 2e-7 m^3) is slower than the compression on
    part of the motion and faster on the rest, and a valve cycling open and shut, so steps
    in q = p V^n and in p alternate (12 % and 25 % of the crossing steps in q, counted
    when written)."""
    dt = 0.001
    t = np.arange(1001) * dt
    model = Model(["cylinder_leak"])
    theta = model.vector(dict(closable_params, dead_volume_m3=2e-7, leak_area_m2=leak_m2))
    u = np.where((t % 0.4) < 0.1, 4.0, 0.0)  # open 100 ms of every 400
    inputs = _inputs(u, dt, x=_aggressive_motion(t, 2))
    solver = SolverConfig.standard().tightened(10)
    _, s_stops = _run(model, theta, inputs, solver, False, sens=True)
    _, s_dense = _run(model, theta, inputs, solver, True, sens=True)
    assert s_dense[0, 0, 0] == 1.0
    assert np.abs(s_dense - s_stops).max() < 0.02


def test_the_predictor_takes_dense_output_from_its_solver():
    model, theta = _model(volume=2.4e-6)
    draws = np.tile(theta, (3, 1))
    rng = np.random.default_rng(9)
    cands = np.stack([_held_steps(rng, 400, 0.005) for _ in range(2)])
    plain = PressurePredictor(model, draws, RIG, SolverConfig.standard())
    dense = PressurePredictor(model, draws, RIG, SolverConfig.sampling())
    a = plain.predict_draws(3e5, cands, 0.0, 0.005)
    b = dense.predict_draws(3e5, cands, 0.0, 0.005)
    assert a.shape == b.shape
    assert 0.0 < np.abs(a - b).max() < 1e-3 * RANGE_PA
    # one switch, on the solver: the call takes no second one
    with pytest.raises(TypeError, match="dense_output"):
        simulate_windows(model, theta, _inputs(cands[0], 0.005), RIG, np.array([0]), 401,
                         np.array([3e5]), SolverConfig.standard(), dense_output=True)


def test_simulate_takes_dense_output_from_its_solver():
    rng = np.random.default_rng(10)
    model, theta = _model(volume=2.4e-6)
    inputs = _inputs(_held_steps(rng, 1000, 0.001), 0.001)
    whole = simulate(model, theta, inputs, RIG, 3e5, SolverConfig.sampling()).pressure_Pa
    assert np.array_equal(whole, _run(model, theta, inputs, SolverConfig.standard(), True)[:, 0])
    assert not np.array_equal(whole, simulate(model, theta, inputs, RIG, 3e5,
                                              SolverConfig.standard()).pressure_Pa)


def test_a_measured_supply_the_model_does_not_read_does_not_stop_the_steps():
    """Without ``supply_fluctuation`` the model reads the nominal supply: a measured one
    that moves every sample leaves dense output crossing samples (numbers within the
    floor of the reference's, and those of a held supply bit for bit); with it, the
    supply drives the model and every sample ends a step, as without dense output."""
    rng = np.random.default_rng(12)
    dt, n = 0.001, 2000
    u = _held_steps(rng, n, dt)
    sup = P_SUP - 3e3 + 1e3 * np.sin(2 * np.pi * 3.0 * np.arange(n) * dt) + rng.normal(
        0.0, 300.0, n)
    model, theta = _model(volume=2.4e-6)
    moving, held = _inputs(u, dt, sup=sup), _inputs(u, dt)
    dense = _run(model, theta, moving, SolverConfig.standard(), True)
    assert np.array_equal(dense, _run(model, theta, held, SolverConfig.standard(), True))
    assert not np.array_equal(dense, _run(model, theta, moving, SolverConfig.standard(),
                                          False))
    ref = _run(model, theta, moving, SolverConfig.reference(), False)
    assert np.abs(dense - ref).max() < 1e-3 * RANGE_PA
    model_s, theta_s = _model(("cylinder_leak", "supply_fluctuation"), volume=2.4e-6,
                              supply_gain=1.0)
    assert np.array_equal(_run(model_s, theta_s, moving, SolverConfig.standard(), True),
                          _run(model_s, theta_s, moving, SolverConfig.standard(), False))


def test_solver_config_carries_dense_output_and_keeps_old_identities():
    std = SolverConfig.standard()
    dense = std.with_dense_output()
    assert not std.dense_output and dense.dense_output
    assert "dense_output" not in std.to_dict()  # settings saved before it: same identity
    assert dense.to_dict()["dense_output"] is True
    assert SolverConfig(**dense.to_dict()) == dense and SolverConfig(**std.to_dict()) == std
    assert std.as_array().size == 6 and dense.as_array().size == 7
    assert dense.tightened(10.0).dense_output
    # the posterior's preset: the standard tolerances with dense output, the fits' default
    from pneubayes.inference.fit import FitSettings
    assert SolverConfig.sampling() == dense and FitSettings().sample_solver == dense
    with pytest.raises(TypeError, match="dense_output"):
        std.with_dense_output("yes")
    rng = np.random.default_rng(13)
    model, theta = _model(volume=2.4e-6)
    inputs = _inputs(_held_steps(rng, 400, 0.005), 0.005)
    assert not np.array_equal(_run(model, theta, inputs, std, False),
                              _run(model, theta, inputs, std, True))


def test_dense_output_worst_error_is_no_larger_than_stopping_at_every_sample():
    """Over a sweep (16 perturbed parameter sets, three volumes, 200 Hz and 1 kHz, three
    seeds) the largest error against the reference with dense output is no larger than
    stopping at every sample. Where steps cross samples a step grows on the larger of its
    own and its predecessor's error estimate; growing on its own alone (a curvature
    changing sign gives one small estimate by cancellation) measured 121.6 Pa here
    against 110.6 Pa stopping at samples (with the guard 91.1 Pa)."""
    worst_dense = worst_stops = 0.0
    for seed in (1, 3, 5):
        for volume in (1e-7, 2.4e-7, 2.4e-6):
            for dt in (0.005, 0.001):
                rng = np.random.default_rng(100 + seed)
                model, theta = _model(volume=volume)
                theta = theta * np.random.default_rng(seed).uniform(0.95, 1.05,
                                                                    (16, theta.size))
                inputs = _inputs(_held_steps(rng, round(2.0 / dt), dt), dt)
                ref = _run(model, theta, inputs, SolverConfig.reference(), False)
                for dense in (False, True):
                    err = np.abs(_run(model, theta, inputs, SolverConfig.standard(), dense)
                                 - ref).max()
                    if dense:
                        worst_dense = max(worst_dense, err)
                    else:
                        worst_stops = max(worst_stops, err)
    assert worst_dense <= worst_stops
