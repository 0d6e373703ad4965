"""The open form on the command: a valve driver on its own clock (effect
``command_clock``), its simulation against the bench plant's drivers, its search in the
prediction windows' residual and the stage that adds it (issue 69)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import P_ATM, P_SUP, random_steps

from pneubayes.effects.command_clock import CommandClock
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, SolverConfig, simulate, simulate_windows
from pneubayes.simulation.reference import reference_simulate

RANGE = P_SUP - P_ATM
BASE = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}


def _inputs(seed, n, hold_s=(0.1, 0.6)):
    t = np.arange(n) * 1e-3
    u = random_steps(np.random.default_rng(seed), n, 1e-3, hold_s=hold_s)
    return Inputs(t, u, np.full(n, 0.015), np.full(n, P_SUP))


def _hold(period, phase, latency):
    return {**BASE, "command_clock_period": period, "command_clock_phase": phase,
            "command_clock_latency": latency}


def _rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.mark.parametrize("period, latency, phase", [(0.0123, 0.003, 0.37),
                                                    (0.004, 0.0, 0.0),
                                                    (0.025, 0.0071, 0.9)])
def test_a_holding_driver_agrees_with_the_plant_s_sampling_driver(rig, period, latency,
                                                                 phase):
    """Against the bench plant's ZohDriver (its switch times built apart, LSODA): within
    1e-5 of the range where the valve without it misses by over 0.3 %."""
    from pneubayes.bench.forms.valve import ZohDriver
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    inputs = _inputs(3, 2501)
    ref = simulate_plant(BASE, (ZohDriver(period, latency, phase),), inputs, rig, P_ATM,
                         PlantConfig.reference()).pressure_Pa
    got = simulate(Model([CommandClock()]), _hold(period, phase, latency), inputs, rig,
                   P_ATM, SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert _rms(got, ref) < 1e-5 * RANGE
    assert _rms(plain, ref) > 3e-3 * RANGE


@pytest.mark.parametrize("frequency_Hz, opening_s, closing_s", [(50.0, 3e-3, 2e-3),
                                                                (20.0, 1e-3, 1e-3)])
def test_a_modulating_driver_agrees_with_the_plant_s_pwm_valve(rig, frequency_Hz, opening_s,
                                                              closing_s):
    """Against the bench plant's PwmValve (solenoid delays on its pulses, LSODA): the
    pulses' latency is the opening delay and their trim the opening less the closing
    delay; within 1e-5 of the range where the proportional valve misses by over 5 %."""
    from pneubayes.bench.forms.valve import PwmValve
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    inputs = _inputs(3, 2501)
    ref = simulate_plant(BASE, (PwmValve(frequency_Hz, opening_s, closing_s, 5.0),), inputs,
                         rig, P_ATM, PlantConfig.reference()).pressure_Pa
    params = {**_hold(1.0 / frequency_Hz, 0.0, opening_s), "command_clock_full_command": 5.0,
              "command_clock_pulse_trim": opening_s - closing_s}
    got = simulate(Model([CommandClock("pwm")]), params, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert _rms(got, ref) < 1e-5 * RANGE
    assert _rms(plain, ref) > 0.05 * RANGE


def test_windows_continue_the_run_and_the_step_halves(rig):
    """Windows started mid-recording from the run's own pressure take the driver's ticks
    on the recording's clock (they continue the one-window run); a 100 x tighter solver
    moves the run by under 0.05 % of the range; no period is the valve without it,
    exactly."""
    inputs = _inputs(7, 4001, hold_s=(0.02, 0.2))
    model, params = Model([CommandClock()]), _hold(0.0173, 0.61, 0.004)
    whole = simulate(model, params, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    starts, length = np.arange(500, 3501, 497), 401
    got = simulate_windows(model, params, inputs, rig, starts, length, whole[starts],
                           SolverConfig.standard())[0]
    assert np.max(np.abs(got - whole[starts[:, None] + np.arange(length)])) < 2e-3 * RANGE
    tight = simulate(model, params, inputs, rig, P_ATM,
                     SolverConfig.standard().tightened(100.0)).pressure_Pa[0]
    assert np.max(np.abs(whole - tight)) < 5e-4 * RANGE
    off = simulate(model, {**params, "command_clock_period": 0.0,
                           "command_clock_latency": 0.0}, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_array_equal(off, plain)
    # with no clock the latency (4 ms) is a pure delay: the command recorded 4 samples late
    late = simulate(model, {**params, "command_clock_period": 0.0}, inputs, rig, P_ATM,
                    SolverConfig.standard()).pressure_Pa[0]
    u = np.concatenate([np.full(4, inputs.command_V[0]), inputs.command_V[:-4]])
    shifted = Inputs(inputs.time_s, u, inputs.position_m, inputs.supply_pressure_Pa)
    delayed = simulate(Model(), BASE, shifted, rig, P_ATM,
                       SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(late, delayed, rtol=0, atol=1e-6 * RANGE)
    windows = simulate_windows(model, {**params, "command_clock_period": 0.0}, inputs, rig,
                               starts, length, late[starts], SolverConfig.standard())[0]
    assert np.max(np.abs(windows - late[starts[:, None] + np.arange(length)])) < 2e-3 * RANGE


def test_the_driver_is_refused_by_the_ode_reference_and_checks_its_form(rig):
    with pytest.raises(ValueError, match="plant's driver"):
        reference_simulate(Model([CommandClock()]), _hold(0.01, 0.0, 0.0), _inputs(1, 201),
                           rig, 2e5)
    with pytest.raises(ValueError, match="form"):
        CommandClock("square")
    assert "command_clock_full_command" not in CommandClock().parameter_names()
    assert "command_clock_pulse_trim" in CommandClock("pwm").parameter_names()


def test_a_full_duty_pulse_holds_the_valve_open_and_none_shuts_it(rig):
    """At the full command the PWM valve is the proportional valve at full command from
    the first tick (no gap between periods); at 0 it is shut."""
    n = 801
    t = np.arange(n) * 1e-3
    full = Inputs(t, np.full(n, 5.0), np.full(n, 0.015), np.full(n, P_SUP))
    params = {**_hold(0.02, 0.0, 0.0), "command_clock_full_command": 5.0,
              "command_clock_pulse_trim": 0.002}
    pwm = simulate(Model([CommandClock("pwm")]), params, full, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, full, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(pwm, plain, rtol=0, atol=1e-6 * RANGE)
    shut = Inputs(t, np.zeros(n), np.full(n, 0.015), np.full(n, P_SUP))
    closed = simulate(Model([CommandClock("pwm")]), params, shut, rig, 3e5,
                      SolverConfig.standard()).pressure_Pa[0]
    at_zero = simulate(Model(), BASE, shut, rig, 3e5, SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(closed, at_zero, rtol=0, atol=1e-6 * RANGE)
