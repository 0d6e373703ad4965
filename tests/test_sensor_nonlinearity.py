"""A curved sensor (effect ``sensor_nonlinearity``): the reading P_atm + g y + k (y /
1 bar)^2 + o, against its hand formula and inverse, its limits (full exhaust reads
P_atm + o, full inlet the supply through the curve), conservation, the reference solver,
the start sensitivity by central differences and the bench that plants it."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import moving_step_inputs, valve1_params

from pneubayes.bench import BenchConfig, run_bench
from pneubayes.effects import make_effect
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.physics.calibration import (
    pressure_behind_reading_Pa,
    pressure_behind_reading_scalar,
    reading_slope_scalar,
    sensor_reading_Pa,
    sensor_reading_scalar,
)
from pneubayes.simulation import (
    SolverConfig,
    simulate,
    simulate_windows,
    simulate_windows_sensitivity,
)
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM
CAL = {"reading_offset_Pa": 2000.0, "reading_gain_error": 0.02, "reading_curvature_Pa": -3000.0}
CURVED = Model([make_effect("sensor_calibration", form="offset_gain"),
                make_effect("sensor_nonlinearity")])


def _read(pressure_Pa, cal=CAL):
    """The reading by hand."""
    y = np.asarray(pressure_Pa, dtype=np.float64) - P_ATM
    return (P_ATM + (1.0 + cal["reading_gain_error"]) * y
            + cal["reading_curvature_Pa"] * (y / 1e5) ** 2 + cal["reading_offset_Pa"])


def test_the_curved_maps_read_invert_and_slope():
    p = np.array([2e4, P_ATM, 2e5, P_SUP, 9e5])
    o, g, k = CAL["reading_offset_Pa"], 1.0 + CAL["reading_gain_error"], \
        CAL["reading_curvature_Pa"]
    r = sensor_reading_Pa(p, P_ATM, o, g, k)
    np.testing.assert_allclose(r, _read(p), rtol=1e-15)
    np.testing.assert_allclose(sensor_reading_Pa(p, P_ATM, o, 1.0, k),
                               _read(p, dict(CAL, reading_gain_error=0.0)), rtol=1e-15)
    np.testing.assert_allclose(pressure_behind_reading_Pa(r, P_ATM, o, g, k), p, rtol=1e-12)
    for pi, ri in zip(p, r):
        assert sensor_reading_scalar(pi, P_ATM, o, (g, k)) == pytest.approx(ri, rel=1e-15)
        assert pressure_behind_reading_scalar(ri, P_ATM, o, (g, k)) == pytest.approx(
            pi, rel=1e-12)
        h = 1.0
        fd = (_read(pi + h) - _read(pi - h)) / (2 * h)
        assert reading_slope_scalar(pi, P_ATM, (g, k)) == pytest.approx(float(fd), rel=1e-8)
    # beyond the curve's turning point (y = g / (2 |k|) bar... read above its top) no
    # pressure stands for the reading
    top = float(_read(P_ATM + 1e5 * g / (2 * abs(k) / 1e5)))
    assert np.isnan(pressure_behind_reading_Pa(top + 1e3, P_ATM, o, g, k))
    assert np.isnan(pressure_behind_reading_scalar(top + 1e3, P_ATM, o, (g, k)))


def test_a_neutral_curvature_is_exactly_no_curvature(rig):
    inputs = moving_step_inputs(3, 301, 1e-3, hold_s=(0.01, 0.05))
    solver = SolverConfig.standard()
    plain = simulate(Model(), valve1_params(), inputs, rig, 2e5, solver).pressure_Pa
    neutral = simulate(Model(["sensor_nonlinearity"]), valve1_params(reading_curvature_Pa=0.0),
                       inputs, rig, 2e5, solver).pressure_Pa
    assert np.array_equal(plain, neutral)


def test_full_exhaust_and_full_inlet_read_through_the_curve(rig, make_inputs):
    n = 2001
    t = np.arange(n) * 1e-3
    solver = SolverConfig.standard()
    params = valve1_params(inlet_offset_m2=0.0, exhaust_offset_m2=0.0)
    for command, end in ((-5.0, P_ATM), (5.0, P_SUP)):
        inputs = make_inputs(t, np.full(n, command))
        true = simulate(Model(), params, inputs, rig, 3e5, solver).pressure_Pa[0]
        start = float(_read(3e5))
        got = simulate(CURVED, {**params, **CAL}, inputs, rig, start, solver).pressure_Pa[0]
        assert got[0] == start
        np.testing.assert_allclose(got, _read(true), rtol=0, atol=1e-6 * RANGE)
        assert abs(got[-1] - _read(end)) < 1e-4 * RANGE


def test_a_closed_chamber_keeps_its_curved_reading(rig, closable_params, make_inputs):
    n = 201
    inputs = make_inputs(np.arange(n) * 1e-3, np.zeros(n))
    got = simulate(CURVED, dict(closable_params, **CAL), inputs, rig, 2.5e5,
                   SolverConfig.standard()).pressure_Pa[0]
    assert np.all(np.abs(got - 2.5e5) < 1e-9 * 2.5e5)


@pytest.mark.parametrize("volume", [2.4e-6, 1e-7])
def test_the_curved_reading_agrees_with_the_reference_solver(rig, volume):
    inputs = moving_step_inputs(5, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("sensor_lag"), make_effect("sensor_calibration",
                                                          form="offset_gain"),
                   make_effect("sensor_nonlinearity")])
    params = valve1_params(volume, sensor_time_constant_s=1e-3, **CAL)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8,
                             initial_rate_Pa_per_s=-3e5)
    got = simulate_windows(model, params, inputs, rig, np.array([0]), inputs.n_samples,
                           np.array([2e5]), SolverConfig.standard(),
                           initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    straight = simulate_windows(model, dict(params, reading_curvature_Pa=0.0), inputs, rig,
                                np.array([0]), inputs.n_samples, np.array([2e5]),
                                SolverConfig.standard(), initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(straight - ref)) > 10 * np.max(np.abs(got - ref))


@pytest.mark.parametrize("dense", [False, True])
def test_the_start_sensitivity_is_the_curved_readings(rig, dense):
    """d(reading)/d(measured start) against central differences: the chamber's dp/dp0
    times the curve's slope at the sample over its slope at the start (on the dense
    output's path and the stepped one)."""
    inputs = moving_step_inputs(9, 201, 1e-3, hold_s=(0.01, 0.05))
    params = valve1_params(**dict(CAL, reading_curvature_Pa=-8000.0))
    starts, p0 = np.array([0, 50]), np.array([2e5, 4e5])
    tight = SolverConfig(rtol=1e-10, atol_Pa=1e-5, atol_K=1e-7, max_step_s=1e-3,
                         min_step_s=1e-14, max_steps_per_s=5e6, dense_output=dense)
    _, sens = simulate_windows_sensitivity(CURVED, params, inputs, rig, starts, 100, p0, tight)
    h = 10.0
    up = simulate_windows(CURVED, params, inputs, rig, starts, 100, p0 + h, tight)
    down = simulate_windows(CURVED, params, inputs, rig, starts, 100, p0 - h, tight)
    np.testing.assert_allclose(sens[0], (up - down)[0] / (2 * h), atol=2e-3)


def test_the_bench_plants_the_curvature_in_the_reading(tmp_path):
    kw = dict(protocol="fixed", duration_s=0.3, seed=4, ranges_V=(3.0,), positions=(0.5,))
    truth = {"reading_curvature_Pa": 2500.0}
    res = run_bench(BenchConfig("AIR37", "valve1", (make_effect("sensor_nonlinearity"),),
                                overrides=truth, **kw), tmp_path / "curve")
    plain = run_bench(BenchConfig("AIR37", "valve1", (), **kw), tmp_path / "plain")
    got, want = (read_recording(r.recordings[0]).pressure_Pa for r in (res, plain))
    # noise and the DAQ's filter act after the sensor: the difference is the curve at
    # the true pressure, the plain recording's less its noise (~500 Pa, times a slope
    # of < 0.25) and its filtered corners (within 1 % of the curve's reach here)
    y = want - P_ATM
    assert np.max(np.abs(got - want - 2500.0 * (y / 1e5) ** 2)) < 250.0
    assert np.max(got - want) > 20_000.0


def test_the_bench_reads_the_calibration_and_the_curve_as_the_simulator_does(tmp_path):
    """With a calibration's offset and gain beside the curve the bench records P_atm +
    g y + k (y / 1 bar)^2 + o (the simulator's map, not the curve read again through the
    gain)."""
    kw = dict(protocol="fixed", duration_s=0.3, seed=4, ranges_V=(3.0,), positions=(0.5,))
    effects = (make_effect("sensor_calibration", form="offset_gain"),
               make_effect("sensor_nonlinearity"))
    res = run_bench(BenchConfig("AIR37", "valve1", effects, overrides=CAL, **kw),
                    tmp_path / "both")
    plain = run_bench(BenchConfig("AIR37", "valve1", (), **kw), tmp_path / "plain")
    got, want = (read_recording(r.recordings[0]).pressure_Pa for r in (res, plain))
    # noise (~500 Pa, times a slope within 2 % of 1.02 of it) and filtered corners
    assert np.max(np.abs(got - _read(want))) < 250.0
    # the curve read again through the gain (g (y + k (y / 1 bar)^2) + o) misses it
    y = want - P_ATM
    again = (P_ATM + (1.0 + CAL["reading_gain_error"])
             * (y + CAL["reading_curvature_Pa"] * (y / 1e5) ** 2) + CAL["reading_offset_Pa"])
    assert np.max(np.abs(got - again)) > 300.0
