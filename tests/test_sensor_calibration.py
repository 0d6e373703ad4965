"""A miscalibrated sensor (effect ``sensor_calibration``): the reading P_atm + g (p -
P_atm) + o, against its limits (full exhaust reads P_atm + o, full inlet the supply
through the sensor), conservation, the reference solver, finite differences and the
bench that plants it."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import moving_step_inputs, valve1_params

from pneubayes.bench import BenchConfig, run_bench
from pneubayes.effects import make_effect
from pneubayes.errors import SimulationError
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.physics.calibration import (
    pressure_behind_reading_Pa,
    pressure_behind_reading_scalar,
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
CAL = {"reading_offset_Pa": 7000.0, "reading_gain_error": -0.04}
BOTH = Model([make_effect("sensor_calibration", form="offset_gain")])


def _read(pressure_Pa, cal):
    """The reading by hand: P_atm + g (p - P_atm) + o."""
    g = 1.0 + cal.get("reading_gain_error", 0.0)
    return P_ATM + g * (np.asarray(pressure_Pa, dtype=np.float64) - P_ATM) \
        + cal["reading_offset_Pa"]


def test_the_calibration_maps_read_and_invert():
    """The effect's reading and the physics maps the simulator uses, against the hand
    formula; the pressure behind a reading is its inverse, scalar and array alike."""
    p = np.array([P_ATM, 2e5, P_SUP])
    g = 1.0 + CAL["reading_gain_error"]
    r = sensor_reading_Pa(p, P_ATM, CAL["reading_offset_Pa"], g)
    np.testing.assert_allclose(r, _read(p, CAL), rtol=1e-15)
    assert r[0] == P_ATM + CAL["reading_offset_Pa"]  # atmosphere reads P_atm + o
    np.testing.assert_allclose(pressure_behind_reading_Pa(r, P_ATM, CAL["reading_offset_Pa"],
                                                          g), p, rtol=1e-14)
    assert pressure_behind_reading_scalar(float(r[1]), P_ATM, CAL["reading_offset_Pa"],
                                          (g, 0.0)) == pytest.approx(2e5, rel=1e-14)
    assert sensor_reading_scalar(2e5, P_ATM, 0.0, (1.0, 0.0)) == 2e5


def test_a_neutral_calibration_is_exactly_no_calibration(rig):
    inputs = moving_step_inputs(3, 301, 1e-3, hold_s=(0.01, 0.05))
    solver = SolverConfig.standard()
    plain = simulate(Model(), valve1_params(), inputs, rig, 2e5, solver).pressure_Pa
    neutral = simulate(BOTH, valve1_params(reading_offset_Pa=0.0, reading_gain_error=0.0), inputs,
                       rig, 2e5, solver).pressure_Pa
    assert np.array_equal(plain, neutral)


def test_full_exhaust_reads_atmosphere_plus_the_offset_and_full_inlet_the_supply(
        rig, make_inputs):
    """The limits read through the sensor (valve maps without leakage offsets): a full
    vent settles at P_atm + o, a full fill at P_atm + g (P_s - P_atm) + o; all the way
    the reading is the uncalibrated chamber's, read."""
    n = 2001
    t = np.arange(n) * 1e-3
    solver = SolverConfig.standard()
    params = valve1_params(inlet_offset_m2=0.0, exhaust_offset_m2=0.0)
    g, o = 1 + CAL["reading_gain_error"], CAL["reading_offset_Pa"]
    for command, end in ((-5.0, P_ATM + o), (5.0, P_ATM + g * RANGE + o)):
        inputs = make_inputs(t, np.full(n, command))
        true = simulate(Model(), params, inputs, rig, 3e5, solver).pressure_Pa[0]
        start = float(_read(3e5, CAL))  # the same chamber, read
        got = simulate(BOTH, {**params, **CAL}, inputs, rig, start, solver).pressure_Pa[0]
        assert got[0] == start
        np.testing.assert_allclose(got, _read(true, CAL), rtol=0,
                                   atol=1e-6 * RANGE)
        assert abs(got[-1] - end) < 1e-4 * RANGE


def test_a_closed_chamber_keeps_its_reading(rig, closable_params, make_inputs):
    """Both ports shut, no leak: whatever the calibration, the reading stays at the
    measured start (the chamber holds the pressure it stands for)."""
    n = 201
    inputs = make_inputs(np.arange(n) * 1e-3, np.zeros(n))
    got = simulate(BOTH, dict(closable_params, **CAL), inputs, rig, 2.5e5,
                   SolverConfig.standard()).pressure_Pa[0]
    assert np.all(got == got[0])
    assert abs(got[0] - 2.5e5) < 1e-9 * 2.5e5


@pytest.mark.parametrize("volume", [2.4e-6, 1e-7])
def test_the_calibrated_reading_agrees_with_the_reference_solver(rig, volume):
    inputs = moving_step_inputs(5, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("sensor_lag"),
                   make_effect("sensor_calibration", form="offset_gain")])
    params = valve1_params(volume, sensor_time_constant_s=1e-3, **CAL)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8,
                             initial_rate_Pa_per_s=-3e5)
    got = simulate_windows(model, params, inputs, rig, np.array([0]), inputs.n_samples,
                           np.array([2e5]), SolverConfig.standard(),
                           initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    # the calibration matters here: without it the reading differs by far more
    plain = simulate_windows(Model(["sensor_lag"]),
                             valve1_params(volume, sensor_time_constant_s=1e-3), inputs, rig,
                             np.array([0]), inputs.n_samples, np.array([2e5]),
                             SolverConfig.standard(), initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(plain - ref)) > 10 * np.max(np.abs(got - ref))


def test_the_start_sensitivity_is_the_readings(rig):
    """d(reading)/d(measured start), from the kernel, against central differences."""
    inputs = moving_step_inputs(9, 201, 1e-3, hold_s=(0.01, 0.05))
    params = valve1_params(**CAL)
    starts, p0 = np.array([0, 50]), np.array([2e5, 3e5])
    tight = SolverConfig(rtol=1e-10, atol_Pa=1e-5, atol_K=1e-7, max_step_s=1e-3,
                         min_step_s=1e-14, max_steps_per_s=5e6)
    _, sens = simulate_windows_sensitivity(BOTH, params, inputs, rig, starts, 100, p0, tight)
    h = 10.0
    up = simulate_windows(BOTH, params, inputs, rig, starts, 100, p0 + h, tight)
    down = simulate_windows(BOTH, params, inputs, rig, starts, 100, p0 - h, tight)
    np.testing.assert_allclose(sens[0], (up - down)[0] / (2 * h), atol=2e-3)


def test_a_start_the_calibration_reads_below_vacuum_fails_clearly(rig, make_inputs):
    n = 11
    inputs = make_inputs(np.arange(n) * 1e-3, np.zeros(n))
    with pytest.raises(SimulationError, match="calibration"):
        simulate(BOTH, valve1_params(reading_offset_Pa=40_000.0, reading_gain_error=0.0), inputs,
                 rig, 30_000.0, SolverConfig.standard())


def test_the_bench_plants_the_calibration_in_the_reading(tmp_path):
    """A chamber at rest reads P_atm + o; the recording is the uncalibrated one read
    through the sensor (the same seed draws the same noise and commands)."""
    kw = dict(protocol="fixed", duration_s=0.3, seed=4, ranges_V=(3.0,), positions=(0.5,))
    truth = {"reading_offset_Pa": 6000.0, "reading_gain_error": 0.05}
    cal = BenchConfig("AIR37", "valve1", (make_effect("sensor_calibration",
                                                      form="offset_gain"),),
                      overrides=truth, **kw)
    res = run_bench(cal, tmp_path / "cal")
    plain = run_bench(BenchConfig("AIR37", "valve1", (), **kw), tmp_path / "plain")
    got = read_recording(res.recordings[0])
    want = read_recording(plain.recordings[0])
    # noise is added after the sensor, so the difference is the calibration alone
    read = _read(want.pressure_Pa, truth)
    assert np.max(np.abs(got.pressure_Pa - read)) < 0.1 + 0.05 * 500.0 * 6
    assert abs(got.pressure_Pa[0] - (P_ATM + 6000.0)) < 4 * 500.0
    assert res.truth["parameters"]["reading_offset_Pa"] == 6000.0


def test_the_bench_reads_a_realistic_plant_through_the_calibration(tmp_path):
    """With a realistic form the truth comes from the independent plant, which knows no
    calibration: the bench reads its pressure through the sensor all the same."""
    from pneubayes.bench.forms import forms_from_names

    kw = dict(protocol="fixed", duration_s=0.3, seed=4, ranges_V=(3.0,), positions=(0.5,),
              forms=forms_from_names(["valve_deadzone"], "AIR37"))
    cal = run_bench(BenchConfig("AIR37", "valve1", (make_effect("sensor_calibration"),), **kw),
                    tmp_path / "cal")
    plain = run_bench(BenchConfig("AIR37", "valve1", (), **kw), tmp_path / "plain")
    diff = (read_recording(cal.recordings[0]).pressure_Pa
            - read_recording(plain.recordings[0]).pressure_Pa)
    assert np.allclose(diff, 5000.0, atol=0.11)  # the bench default offset, 0.1-Pa logging
