"""The second-order spool (effect ``spool_lag``, form ``second_order``): against the
reference solver's ODE states, the bench plant's independent SecondOrderSpool, the
first-order lag it tends to at large damping, a window started mid-recording, and its
lowering and candidate forms."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import moving_step_inputs, valve1_params

from pneubayes.bench.forms import SecondOrderSpool
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.effects import make_effect
from pneubayes.effects.discovery import CandidateContext
from pneubayes.effects.spool_lag import RATE_BOUNDS, START_RATE, spool_settle_s
from pneubayes.model import Model
from pneubayes.simulation import Inputs, SolverConfig, simulate, simulate_windows
from pneubayes.simulation.reference import reference_simulate
from pneubayes.simulation.spool import first_order_lag, spool_step

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM
TIGHT = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=1e-6, max_step_s=1e-3,
                     min_step_s=1e-14, max_steps_per_s=5e6)
SECOND = make_effect("spool_lag", form="second_order")


def test_lowering_and_neutral_delay():
    """w = 2 z / D; a zero group delay is no spool lag at all (bit-identical)."""
    model = Model([SECOND])
    assert model.parameter_names[-2:] == ("spool_delay_s", "spool_damping")
    slots = model.lower(model.as_matrix(dict(valve1_params(), spool_delay_s=2e-3,
                                             spool_damping=0.5)), None)
    from pneubayes.effects.path import SLOT_INDEX as S

    assert slots[0, S["spool_natural_frequency_rad_per_s"]] == pytest.approx(500.0)
    assert slots[0, S["spool_damping"]] == 0.5 and slots[0, S["spool_time_constant_s"]] == 0
    assert spool_settle_s(slots)[0] == pytest.approx(1 / (0.5 * 500.0))
    off = model.lower(model.as_matrix(dict(valve1_params(), spool_delay_s=0.0,
                                           spool_damping=0.5)), None)
    assert np.array_equal(off, Model().lower(Model().as_matrix(valve1_params()), None))
    with pytest.raises(ValueError, match="form must be one of"):
        make_effect("spool_lag", form="third_order").parameters()


def test_a_zero_delay_simulates_as_the_plain_model(rig):
    inputs = moving_step_inputs(3, 201, 1e-3, hold_s=(0.01, 0.05))
    plain = simulate(Model(), valve1_params(), inputs, rig, 2e5, SolverConfig.standard())
    off = simulate(Model([SECOND]), valve1_params(spool_delay_s=0.0, spool_damping=0.4), inputs,
                   rig, 2e5, SolverConfig.standard())
    assert np.array_equal(plain.pressure_Pa, off.pressure_Pa)


@pytest.mark.parametrize("delay,damping,volume", [
    (2.5e-3, 0.3, 2e-5),  # underdamped: the spool overshoots the commanded opening
    pytest.param(3e-3, 2.5, 1e-7, marks=pytest.mark.slow)])  # overdamped, a tiny chamber
def test_the_spool_agrees_with_the_reference_solvers_ode_states(rig, delay, damping,
                                                                volume):
    """The compiled integrator steps the spool exactly under the held command; the
    reference integrates its position and velocity as two more states (rtol 1e-8)."""
    inputs = moving_step_inputs(5, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("tube_delay"), SECOND])
    params = valve1_params(volume, tube_delay_s=0.0013, spool_delay_s=delay, spool_damping=damping)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    got = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    # and the spool matters here: without it the chamber differs by far more
    plain = simulate(Model(["tube_delay"]), valve1_params(volume, tube_delay_s=0.0013), inputs,
                     rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(plain - ref)) > 10 * np.max(np.abs(got - ref))


def test_a_heavily_damped_spool_is_the_first_order_lag(rig):
    inputs = moving_step_inputs(7, 401, 1e-3, hold_s=(0.01, 0.05))
    first = simulate(Model(["spool_lag"]), valve1_params(spool_time_constant_s=2e-3), inputs, rig,
                     2e5, TIGHT).pressure_Pa[0]
    second = simulate(Model([SECOND]), valve1_params(spool_delay_s=2e-3, spool_damping=5.0),
                      inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    plain = simulate(Model(), valve1_params(), inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    # the fast pole (1 / (2 z w) = 0.02 ms) is all that differs
    assert np.max(np.abs(second - first)) < 0.03 * np.max(np.abs(first - plain))


def test_the_model_agrees_with_the_plants_second_order_spool(rig):
    """The bench plant's SecondOrderSpool (LSODA, written apart) and the model's form at
    the same natural frequency and damping solve the same spool."""
    dt = 1e-4
    t = np.arange(5001) * dt
    rng = np.random.default_rng(11)
    u = np.repeat(rng.uniform(-5.0, 5.0, 51), 100)[:t.size]
    inputs = Inputs.constant(t, u, 0.01, P_SUP)
    base = valve1_params(1.5e-7)
    form = SecondOrderSpool(125.0, 0.45)
    plant = simulate_plant(base, (form,), inputs, rig, P_ATM,
                           PlantConfig.reference()).pressure_Pa
    w = 2 * np.pi * form.natural_frequency_Hz
    params = dict(base, spool_delay_s=2 * form.damping / w, spool_damping=form.damping)
    got = simulate(Model([SECOND]), params, inputs, rig, P_ATM,
                   SolverConfig.reference()).pressure_Pa[0]
    err = np.max(np.abs(plant - got))
    first = simulate(Model(["spool_lag"]), dict(base, spool_time_constant_s=2 * form.damping
                                                / w), inputs, rig, P_ATM,
                     SolverConfig.reference()).pressure_Pa[0]
    assert err < 50.0, f"plant vs compiled second-order spool: {err:.1f} Pa"
    assert np.max(np.abs(plant - first)) > 20 * err  # the first-order lag is not it
    # the plant also reads the catalogue's form from its lowered slots: the same spool
    planted = simulate_plant(params, (), inputs, rig, P_ATM, PlantConfig.reference(),
                             effects=(SECOND,)).pressure_Pa
    assert np.max(np.abs(planted - plant)) < 1e-6 * RANGE


def test_a_window_mid_recording_starts_from_the_spools_history(rig):
    """A window that starts at sample i from the full run's pressure continues the full
    run: the spool's position and velocity follow from the commands before it."""
    inputs = moving_step_inputs(9, 801, 1e-3, hold_s=(0.003, 0.02))
    model = Model([SECOND])
    params = valve1_params(spool_delay_s=4e-3, spool_damping=0.35)
    full = simulate(model, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    starts = np.array([0, 137, 402, 651])
    length = 120
    got = simulate_windows(model, params, inputs, rig, starts, length, full[starts], TIGHT)[0]
    for w, i in enumerate(starts):
        assert np.max(np.abs(got[w] - full[i:i + length])) < 1e-5 * RANGE, i
    # a spool started at rest at the held command instead differs
    first = simulate_windows(Model(["spool_lag"]), dict(valve1_params(), spool_time_constant_s=0.0),
                             inputs, rig, starts, length, full[starts], TIGHT)[0]
    assert np.max(np.abs(first[1:] - np.stack([full[i:i + length] for i in starts[1:]]))) \
        > 1e-3 * RANGE


def test_the_first_order_candidate_also_offers_the_second_order(rig):
    ctx = CandidateContext(model=Model(), params=valve1_params(), rig=rig,
                           term_start={"spool_time_constant_s": 0.004},
                           second_state_free=True, line_segments=0, line_cutoff_Hz=0.0,
                           dead_volume_m3=2.4e-6)
    forms = make_effect("spool_lag").candidate_forms(ctx)
    assert [(f.form, s) for f, s in forms] == [
        ("first_order", {"spool_time_constant_s": 0.004}),
        ("second_order", {"spool_delay_s": 0.004, "spool_damping": 0.7}),
        ("rate_limited", {"spool_time_constant_s": 0.004,
                          "spool_rate_limit_V_per_s": START_RATE}),
        ("asymmetric", {"spool_time_constant_s": 0.004, "spool_fall_time_constant_s": 0.004})]
    assert SECOND.candidate_forms(ctx)[0][0] is SECOND


# ---------------------------------------------------------------- the speed-limited spool
LIMITED = make_effect("spool_lag", form="rate_limited")


@pytest.mark.parametrize("s0, cmd, h", [(0.0, 5.0, 0.002), (0.0, 5.0, 0.02), (3.0, -4.0, 0.004),
                                        (1.0, 1.5, 0.003), (2.0, 2.0, 0.01)])
def test_the_speed_limited_lag_is_its_ode_integrated(s0, cmd, h):
    """first_order_lag's closed form (a ramp at r, then the lag) against the ODE ds/dt =
    clip((u - s) / tau, -r, r) stepped finely (RK4 at 1 us), position and rate."""
    tau, r = 0.002, 800.0

    def f(s):
        return min(max((cmd - s) / tau, -r), r)

    s, dt = s0, 1e-6
    for _ in range(round(h / dt)):
        k1 = f(s)
        k2 = f(s + 0.5 * dt * k1)
        k3 = f(s + 0.5 * dt * k2)
        k4 = f(s + dt * k3)
        s += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    got, rate = first_order_lag(s0, cmd, h, tau, r, 0.0)
    assert got == pytest.approx(s, abs=1e-9)
    assert rate == pytest.approx(f(got), abs=1e-6)
    # a step under r tau (1.6 V) is the plain lag's
    if abs(cmd - s0) <= r * tau:
        assert got == pytest.approx(spool_step(s0, 0.0, cmd, h, tau, 0.0, 0.0, 0.0, 0.0)[0],
                                    abs=1e-12)


def test_the_speed_limit_lowers_and_at_its_bound_is_the_first_order(rig):
    """The limit lowers to its slot; at the upper bound (the neutral value) the
    model simulates as the first-order lag bit for bit (steps of a few volts)."""
    from pneubayes.effects.path import SLOT_INDEX as S

    model = Model([LIMITED])
    assert model.parameter_names[-2:] == ("spool_time_constant_s", "spool_rate_limit_V_per_s")
    bounds = {p.name: (p.lower, p.upper) for p in LIMITED.parameters()}
    assert bounds["spool_rate_limit_V_per_s"] == RATE_BOUNDS
    slots = model.lower(model.as_matrix(valve1_params(spool_time_constant_s=0.003,
                                                      spool_rate_limit_V_per_s=250.0)), None)
    assert slots[0, S["spool_rate_limit_V_per_s"]] == 250.0
    inputs = moving_step_inputs(3, 201, 1e-3, hold_s=(0.01, 0.05))
    first = simulate(Model(["spool_lag"]), valve1_params(spool_time_constant_s=0.003), inputs,
                     rig, 2e5, SolverConfig.standard())
    unlimited = simulate(model, valve1_params(spool_time_constant_s=0.003,
                                              spool_rate_limit_V_per_s=RATE_BOUNDS[1]),
                         inputs, rig, 2e5, SolverConfig.standard())
    assert np.array_equal(first.pressure_Pa, unlimited.pressure_Pa)
    # the bench plant refuses it rather than drop it
    with pytest.raises(ValueError, match="SpoolSlewLimit"):
        simulate_plant(valve1_params(spool_time_constant_s=0.003, spool_rate_limit_V_per_s=250.0),
                       [], inputs, rig, 2e5, PlantConfig("LSODA", 1e-6, 1.0, 1e-4, 1e-5, 0.005),
                       effects=[LIMITED])


def test_the_speed_limited_spool_agrees_with_the_reference_and_is_slower(rig):
    """The compiled integrator (closed-form ramp and lag) against the reference solver's
    spool ODE; the limit (250 V/s: a 3-V step takes 12 ms) moves the pressure by far
    more than their difference; windows mid-recording start from the spool's history."""
    inputs = moving_step_inputs(5, 301, 1e-3, hold_s=(0.02, 0.06))
    params = valve1_params(2e-5, spool_time_constant_s=0.002, spool_rate_limit_V_per_s=250.0)
    model = Model([LIMITED])
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)  # (45 Pa asserted)
    got = simulate(model, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    first = simulate(Model(["spool_lag"]), valve1_params(2e-5, spool_time_constant_s=0.002),
                     inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    err = np.max(np.abs(got - ref))
    assert err <= 1e-4 * RANGE
    assert np.max(np.abs(first - ref)) > 100 * err
    # windows that start 3 ms after a command step: mid-ramp
    changes = np.nonzero(np.diff(inputs.command_V))[0] + 1
    starts = np.concatenate(([0], changes[changes < 240][:4] + 3))
    length = 50
    win = simulate_windows(model, params, inputs, rig, starts, length, got[starts], TIGHT)[0]
    assert np.max(np.abs(win - np.stack([got[i:i + length] for i in starts]))) <= 1e-4 * RANGE


# ---------------------------------------------------------------- the asymmetric spool
ASYM = make_effect("spool_lag", form="asymmetric")


def test_the_asymmetric_lag_rises_and_falls_with_its_own_time_constants():
    """Closed form: a rise from s0 below the command is the first-order lag of tau, a
    fall of tau_down; equal time constants are the first-order lag bit for bit; a time
    constant of 0 in the spool's direction jumps onto the command."""
    tau, tau_dn, h = 0.001, 0.004, 0.003
    assert first_order_lag(-2.0, 3.0, h, tau, 0.0, tau_dn)[0] == pytest.approx(
        3.0 - 5.0 * np.exp(-h / tau), abs=1e-14)
    assert first_order_lag(3.0, -2.0, h, tau, 0.0, tau_dn)[0] == pytest.approx(
        -2.0 + 5.0 * np.exp(-h / tau_dn), abs=1e-14)
    for s0, cmd in ((-2.0, 3.0), (3.0, -2.0)):
        assert first_order_lag(s0, cmd, h, tau, 0.0, tau)[0] == \
            first_order_lag(s0, cmd, h, tau, 0.0, 0.0)[0]
    assert first_order_lag(-2.0, 3.0, h, 0.0, 0.0, tau_dn) == (3.0, 0.0)
    assert spool_step(3.0, 0.0, -2.0, h, 0.0, 0.0, 0.0, 0.0, tau_dn)[0] == pytest.approx(
        -2.0 + 5.0 * np.exp(-h / tau_dn), abs=1e-14)


def test_the_asymmetric_spool_lowers_and_equal_time_constants_are_the_first_order(rig):
    from pneubayes.effects.path import SLOT_INDEX as S

    model = Model([ASYM])
    assert model.parameter_names[-2:] == ("spool_time_constant_s", "spool_fall_time_constant_s")
    slots = model.lower(model.as_matrix(valve1_params(spool_time_constant_s=0.001,
                                                      spool_fall_time_constant_s=0.004)), None)
    assert slots[0, S["spool_fall_time_constant_s"]] == 0.004
    inputs = moving_step_inputs(3, 201, 1e-3, hold_s=(0.01, 0.05))
    first = simulate(Model(["spool_lag"]), valve1_params(spool_time_constant_s=0.003), inputs,
                     rig, 2e5, SolverConfig.standard())
    same = simulate(model, valve1_params(spool_time_constant_s=0.003,
                                         spool_fall_time_constant_s=0.003),
                    inputs, rig, 2e5, SolverConfig.standard())
    assert np.array_equal(first.pressure_Pa, same.pressure_Pa)


def test_the_asymmetric_spool_agrees_with_the_reference_and_the_plant(rig):
    """The compiled integrator against the reference solver's spool ODE and against the
    bench plant's own spring-returned spool (the catalogue effect planted); windows
    mid-recording start from the spool's history; the asymmetry moves the pressure by
    far more than the disagreements."""
    inputs = moving_step_inputs(5, 301, 1e-3, hold_s=(0.02, 0.06))
    params = valve1_params(2e-5, spool_time_constant_s=0.001, spool_fall_time_constant_s=0.005)
    model = Model([ASYM])
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)  # (45 Pa asserted)
    got = simulate(model, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    plant = simulate_plant(params, [], inputs, rig, 2e5,
                           PlantConfig("LSODA", 1e-9, 0.01, 1e-6, 1e-9, 0.005),
                           effects=[ASYM]).pressure_Pa
    first = simulate(Model(["spool_lag"]), valve1_params(2e-5, spool_time_constant_s=0.001),
                     inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    err, err_plant = np.max(np.abs(got - ref)), np.max(np.abs(got - plant))
    assert err <= 1e-4 * RANGE
    assert err_plant <= 1e-4 * RANGE
    assert np.max(np.abs(first - ref)) > 100 * err
    changes = np.nonzero(np.diff(inputs.command_V))[0] + 1
    starts = np.concatenate(([0], changes[changes < 240][:4] + 2))
    length = 50
    win = simulate_windows(model, params, inputs, rig, starts, length, got[starts], TIGHT)[0]
    assert np.max(np.abs(win - np.stack([got[i:i + length] for i in starts]))) <= 1e-4 * RANGE
