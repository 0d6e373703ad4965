"""The compiled integrator against invariants, closed forms and independent solvers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pneubayes.effects.path import N_SLOTS, SLOT_INDEX
from pneubayes.errors import SimulationError
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    kernel,
    rig_constants,
    simulate,
    simulate_windows,
    simulate_windows_sensitivity,
)
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM
VOLUMES = (1e-7, 2.4e-6, 2e-5)
ALL_EFFECTS = ["cylinder_leak", "tube_delay", "valve_deadzone", "supply_fluctuation",
               "heat_transfer", "spool_lag"]


def _config(rtol):
    """A SolverConfig whose absolute tolerance scales with rtol (1e5 Pa reference)."""
    return SolverConfig(rtol=rtol, atol_Pa=rtol * 1e5, atol_K=0.01, max_step_s=0.02,
                        min_step_s=1e-12, max_steps_per_s=2.5e6)


def _closed_slots(volume):
    """A slot matrix with both ports shut: offset 0 and a 0, so every area is exactly 0."""
    sl = np.zeros((1, N_SLOTS))
    for port, c in (("inlet", 1.5), ("exhaust", -1.5)):
        sl[0, SLOT_INDEX[f"{port}_b"]] = 3.0
        sl[0, SLOT_INDEX[f"{port}_c_per_V"]] = c
    sl[0, SLOT_INDEX["volume_m3"]] = volume
    return sl


def _run_kernel(slots, rig, solver, t, u, x, ps, p0):
    out, status = kernel.simulate_windows(
        np.ascontiguousarray(slots), rig_constants(rig), solver.as_array(), t, u,
        np.zeros_like(t), x, ps, np.array([0], dtype=np.int64), t.size,
        np.array([float(p0)]))
    assert not status.any(), status
    return out[:, 0, :]


# ---------------------------------------------------------------- conservation
@pytest.mark.parametrize("volume", VOLUMES)
@pytest.mark.parametrize("p0", [1.2e5, 3.3e5, 5.4e5])
def test_closed_valve_fixed_volume_keeps_pressure(rig, volume, p0, step_command):
    t = np.arange(2001) * 1e-3
    u = step_command(11, t.size, 1e-3)
    p = _run_kernel(_closed_slots(volume), rig, SolverConfig.standard(), t, u,
                    np.full(t.size, 0.01), np.full(t.size, P_SUP), p0)[0]
    assert np.max(np.abs(p / p0 - 1.0)) < 1e-9


def test_closed_valve_keeps_pressure_exactly_with_dense_output(rig, step_command):
    """Both ports shut, no leak, position and supply held: every sample, whether a step
    ends on it or crosses it, keeps p0 exactly."""
    t = np.arange(2001) * 1e-3
    u = step_command(11, t.size, 1e-3)
    p = _run_kernel(_closed_slots(2.4e-6), rig, SolverConfig.sampling(), t, u,
                    np.full(t.size, 0.01), np.full(t.size, P_SUP), 2.5e5)[0]
    assert np.all(p == 2.5e5)


@pytest.mark.parametrize("solver", [SolverConfig.standard(), SolverConfig.reference(),
                                    SolverConfig.sampling()],
                         ids=["standard", "reference", "dense"])
@pytest.mark.parametrize("volume", [2.4e-6, 2e-5])
def test_closed_valve_moving_piston_is_adiabatic(rig, solver, volume, hand):
    """Closed chamber, moving piston: eq. 5 reduces to dp/p = -k dV/V, so p V^1.4 is constant.

    The position is linear between samples, so V(t) is known exactly at the samples.
    Allowed drift: 10 rtol, at most 1e-6 — an order-3 integrator with local error
    control stays far below either. With dense output (no flows: steps of 20 ms cross
    the samples on the position's chord) each crossed sample is moved to its own volume
    adiabatically.
    """
    t = np.arange(2001) * 1e-3
    x = hand.moving_position(t, mean=0.01, amp=0.01, freq=3.0)
    u = np.zeros(t.size)
    p0 = 3e5
    p = _run_kernel(_closed_slots(volume), rig, solver, t, u, x, np.full(t.size, P_SUP), p0)[0]
    vol = volume + rig.bore_area_m2 * x
    invariant = p * vol ** 1.4
    drift = np.max(np.abs(invariant / invariant[0] - 1.0))
    assert drift < max(10 * solver.rtol, 1e-6), (
        f"p V^1.4 drifts by {drift:.3g} (rtol {solver.rtol:g})")


CLOSABLE = {  # inside the model's bounds; both Gompertz terms underflow to 0 at u = 0
    "inlet_offset_m2": 0.0, "inlet_a_m2": 5.5e-7, "inlet_b": 3.5, "inlet_c_per_V": 20.0,
    "inlet_d_V": -3.0, "exhaust_offset_m2": 0.0, "exhaust_a_m2": 6e-7, "exhaust_b": 3.5,
    "exhaust_c_per_V": -20.0, "exhaust_d_V": 3.0}


@pytest.mark.parametrize("volume,freq", [(1e-6, 2.0), (2.4e-6, 3.0), (2e-5, 3.0)])
def test_standard_preset_meets_accuracy_floor_on_a_moving_closed_chamber(rig, volume, freq,
                                                                        hand, make_inputs):
    """SolverConfig.standard promises 0.1 % of the range for volumes 1e-7..2e-5 m^3.

    A model inside its bounds whose valve is shut at u = 0 (a dead band does the same),
    the piston swinging +-10 mm (AIR37 stroke 37.5 mm): the exact answer is
    p0 (V0 / V)^1.4, and the pressure stays within 1.3-3.5 bar.
    """
    params = dict(CLOSABLE, dead_volume_m3=volume)
    t = np.arange(2001) * 1e-3
    x = hand.moving_position(t, freq=freq)
    inputs = make_inputs(t, np.zeros(t.size), position=x)
    p = simulate(Model([]), params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    vol = volume + rig.bore_area_m2 * x
    exact = 2e5 * (vol[0] / vol) ** 1.4
    err = np.max(np.abs(p - exact))
    assert err <= 1e-3 * RANGE, f"max error {err:.0f} Pa > {1e-3 * RANGE:.0f} Pa"


# ---------------------------------------------------------------- limits
@pytest.mark.parametrize("volume", VOLUMES)
def test_full_command_settles_at_supply_and_atmosphere(leak_model, base_params, rig, volume,
                                                       standard, make_inputs, hand):
    base_params["dead_volume_m3"] = volume
    t = np.arange(2001) * 1e-3
    up = simulate(leak_model, base_params, make_inputs(t, np.full(t.size, 5.0)), rig, P_ATM,
                  standard).pressure_Pa[0]
    down = simulate(leak_model, base_params, make_inputs(t, np.full(t.size, -5.0)), rig, P_SUP,
                    standard).pressure_Pa[0]
    assert np.all(np.isfinite(up)) and np.all(np.isfinite(down))
    # within 1 % of the range of the rails, on the right side of them
    assert P_SUP - 0.01 * RANGE < up[-1] < P_SUP
    assert P_ATM < down[-1] < P_ATM + 0.01 * RANGE
    # and exactly at the flow balance of eqs. 4/9 (independent root finding)
    assert up[-1] == pytest.approx(hand.equilibrium(base_params, u=5.0), abs=1.0)
    assert down[-1] == pytest.approx(hand.equilibrium(base_params, u=-5.0), abs=1.0)
    # monotone approach: the fill never overshoots the balance
    assert np.all(np.diff(up) >= -1e-6 * P_SUP) and np.all(np.diff(down) <= 1e-6 * P_SUP)


# ---------------------------------------------------------------- agreement with Radau
_REF_CACHE: dict = {}


def _random_inputs(hand, seed, n, dt, moving=False):
    t = np.arange(n) * dt
    u = hand.random_steps(np.random.default_rng(seed), n, dt)
    x = hand.moving_position(t) if moving else np.full(n, 0.0)
    return Inputs(t, u, x, np.full(n, P_SUP))


def _reference(model, params, inputs, rig, key):
    if key not in _REF_CACHE:
        _REF_CACHE[key] = reference_simulate(model, params, inputs, rig, P_ATM, method="Radau",
                                             rtol=1e-10)
    return _REF_CACHE[key]


@pytest.mark.slow
@pytest.mark.parametrize("volume", VOLUMES)
def test_agrees_with_radau_fixed_volume(leak_model, base_params, rig, volume, standard, hand):
    base_params["dead_volume_m3"] = volume
    inputs = _random_inputs(hand, 100, 1001, 1e-3)
    ref = _reference(leak_model, base_params, inputs, rig, ("fixed", volume))
    got = simulate(leak_model, base_params, inputs, rig, P_ATM, standard).pressure_Pa[0]
    err = np.max(np.abs(got - ref))
    assert err <= 1e-3 * RANGE, f"max error {err:.1f} Pa"
    assert np.ptp(ref) > 0.5 * RANGE  # the command really swept the range


@pytest.mark.slow
@pytest.mark.parametrize("volume", [2.4e-6, 2e-5])
def test_agrees_with_radau_moving_volume(leak_model, base_params, rig, volume, standard, hand):
    base_params["dead_volume_m3"] = volume
    inputs = _random_inputs(hand, 101, 1001, 1e-3, moving=True)
    ref = _reference(leak_model, base_params, inputs, rig, ("moving", volume))
    got = simulate(leak_model, base_params, inputs, rig, P_ATM, standard).pressure_Pa[0]
    err = np.max(np.abs(got - ref))
    assert err <= 1e-3 * RANGE, f"max error {err:.1f} Pa"


@pytest.mark.slow
@pytest.mark.parametrize("dt,n", [(1e-2, 201), (1e-4, 1501)], ids=["100Hz", "10kHz"])
def test_agrees_with_radau_other_output_rates(leak_model, base_params, rig, dt, n, standard,
                                              hand):
    base_params["dead_volume_m3"] = 1e-6
    inputs = _random_inputs(hand, 102, n, dt)
    ref = reference_simulate(leak_model, base_params, inputs, rig, P_ATM, rtol=1e-10)
    got = simulate(leak_model, base_params, inputs, rig, P_ATM, standard).pressure_Pa[0]
    err = np.max(np.abs(got - ref))
    assert err <= 1e-3 * RANGE, f"max error {err:.1f} Pa"


@pytest.mark.slow
def test_reference_solver_matches_independent_plain_math_solver(leak_model, base_params, rig,
                                                               hand):
    """The project's reference shares the physics functions; check it against ours.

    Inputs exercise everything the plain-math solver models: random steps, a moving
    piston and a fluctuating supply column (seen with supply_gain 1).
    """
    base_params["dead_volume_m3"] = 2.4e-6
    n, dt = 301, 1e-3
    t = np.arange(n) * dt
    u = hand.random_steps(np.random.default_rng(5), n, dt, hold_s=(0.02, 0.06))
    x = hand.moving_position(t, freq=4.0)
    s = hand.fluctuating_supply(t)
    inputs = Inputs(t, u, x, s)
    model = leak_model.with_effect("supply_fluctuation")
    params = dict(base_params, supply_gain=1.0)
    mine = hand.reference(base_params, t, u, x, s, P_ATM)
    theirs = reference_simulate(model, params, inputs, rig, P_ATM, rtol=1e-10)
    assert np.max(np.abs(mine - theirs)) < 0.05  # Pa: both are Radau at rtol 1e-10
    # the compiled integrator against the independent solution, at the accuracy floor
    got = simulate(model, params, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - mine)) <= 1e-3 * RANGE
    # with the nominal supply (gain 0) the column is ignored
    nominal = hand.reference(base_params, t, u, x, np.full(n, P_SUP), P_ATM)
    got0 = simulate(leak_model, base_params, inputs, rig, P_ATM,
                    SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got0 - nominal)) <= 1e-3 * RANGE


# ---------------------------------------------------------------- convergence
@pytest.mark.slow
def test_error_decreases_with_tolerance(leak_model, base_params, rig, hand):
    base_params["dead_volume_m3"] = 2.4e-6
    inputs = _random_inputs(hand, 100, 1001, 1e-3)
    ref = _reference(leak_model, base_params, inputs, rig, ("fixed", 2.4e-6))
    errs = []
    for rtol in (1e-4, 1e-5, 1e-6, 1e-7):
        got = simulate(leak_model, base_params, inputs, rig, P_ATM, _config(rtol)).pressure_Pa[0]
        errs.append(float(np.max(np.abs(got - ref))))
    assert all(b < a for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] < 10.0, errs
    assert errs[0] > 2 * errs[-1], errs  # the tolerance really controls the error


def test_halving_the_sample_interval_gives_the_same_trajectory(leak_model, base_params, rig,
                                                              hand):
    base_params["dead_volume_m3"] = 2.4e-6
    n, dt = 1001, 1e-3
    t = np.arange(n) * dt
    u = hand.random_steps(np.random.default_rng(7), n, dt)
    x = hand.moving_position(t)
    t2 = np.arange(2 * n - 1) * (dt / 2)
    u2 = np.repeat(u, 2)[:-1]  # each sample's hold duplicated
    x2 = np.interp(t2, t, x)  # position is linear between samples: the same signal
    coarse = Inputs(t, u, x, np.full(n, P_SUP))
    fine = Inputs(t2, u2, x2, np.full(t2.size, P_SUP))
    tight = _config(1e-8)
    a = simulate(leak_model, base_params, coarse, rig, P_ATM, tight).pressure_Pa[0]
    b = simulate(leak_model, base_params, fine, rig, P_ATM, tight).pressure_Pa[0][::2]
    assert np.max(np.abs(a - b)) < 1.0  # Pa
    # and with the standard preset within its accuracy floor
    std = SolverConfig.standard()
    a = simulate(leak_model, base_params, coarse, rig, P_ATM, std).pressure_Pa[0]
    b = simulate(leak_model, base_params, fine, rig, P_ATM, std).pressure_Pa[0][::2]
    assert np.max(np.abs(a - b)) < 1e-3 * RANGE


# ---------------------------------------------------------------- batching and windows
def test_batch_equals_separate_runs(rig, hand, standard):
    model = Model(ALL_EFFECTS)
    rng = np.random.default_rng(21)
    batch = np.array([[p.sample_prior(rng) for p in model.parameters] for _ in range(6)])
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(rng, n, 1e-3), hand.moving_position(t, amp=0.0005,
                                                                               mean=0.0105),
                    hand.fluctuating_supply(t))
    together = simulate(model, batch, inputs, rig, 2e5, standard).pressure_Pa
    assert together.shape == (6, n)
    for b in range(6):
        alone = simulate(model, batch[b], inputs, rig, 2e5, standard).pressure_Pa
        assert np.array_equal(together[b], alone[0])
    # and a dict gives the same as its vector
    as_dict = simulate(model, model.as_dict(batch[2]), inputs, rig, 2e5, standard).pressure_Pa
    assert np.array_equal(as_dict[0], together[2])


def test_windows_equal_simulations_started_at_those_samples(rig, hand, standard):
    # (no delay or spool lag: their state at a window start comes from the history)
    model = Model(["cylinder_leak", "valve_deadzone", "supply_fluctuation", "heat_transfer"])
    params = valve_preset("valve2").parameters()
    params.update(dead_volume_m3=1.5e-6, leak_area_m2=3e-8, deadzone_halfwidth_V=0.3,
                  supply_gain=1.0, heat_transfer_rate_per_s=5.0, heat_transfer_coupling=1.0)
    n = 1201
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(8), n, 1e-3),
                    hand.moving_position(t), hand.fluctuating_supply(t))
    starts = np.array([0, 137, 500, 880])
    length = 300
    p0 = np.array([1.1e5, 2.5e5, 4.0e5, 5.2e5])
    win = simulate_windows(model, params, inputs, rig, starts, length, p0, standard)
    assert win.shape == (1, 4, length)
    for w, s in enumerate(starts):
        sl = slice(s, s + length)
        sub = Inputs(t[sl], inputs.command_V[sl], inputs.position_m[sl],
                     inputs.supply_pressure_Pa[sl])
        alone = simulate(model, params, sub, rig, p0[w], standard).pressure_Pa[0]
        assert np.array_equal(win[0, w], alone)


def test_start_sensitivity_matches_finite_differences(rig, hand, standard):
    model = Model(["cylinder_leak"])
    params = valve_preset("valve1").parameters()
    params.update(dead_volume_m3=1.5e-6, leak_area_m2=3e-9)
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(4), n, 1e-3, levels=(-1.0, 1.0)),
                    np.full(n, 0.01), np.full(n, 6.0e5))
    starts = np.array([0, 200, 400])
    p0 = np.array([2.0e5, 3.0e5, 4.0e5])
    tight = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=1e-6, max_step_s=1e-3,
                         min_step_s=1e-14, max_steps_per_s=5e6)
    out, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 400, p0, tight)
    assert np.array_equal(out, simulate_windows(model, params, inputs, rig, starts, 400, p0,
                                                tight))
    d = 20.0
    up = simulate_windows(model, params, inputs, rig, starts, 400, p0 + d, tight)
    dn = simulate_windows(model, params, inputs, rig, starts, 400, p0 - d, tight)
    fd = (up - dn) / (2 * d)
    assert np.all(sens[..., 0] == 1.0)
    assert np.all((sens >= 0) & (sens <= 1 + 1e-12))
    # first order in the step: a few per cent of the start error at worst
    assert np.max(np.abs(sens - fd)) < 0.03


def test_start_sensitivity_across_a_kink_of_the_volume_table_matches_fd(rig, hand):
    """Where the pressure crosses a point of a compliant chamber's volume table, dV/dp
    and so dp/dt jump: the start's sensitivity jumps by the ratio of the rates (the
    saltation), which the step's e^{hJ} alone misses (by 0.74 here)."""
    from pneubayes.effects.volume_closure import VolumeClosure

    model = Model([VolumeClosure()])
    params = dict(valve_preset("valve1").parameters(), dead_volume_m3=5e-7,
                  volume_closure_compliance_0=1e-11, volume_closure_threshold_0=2.5e5)
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(4), n, 1e-3, levels=(-1.0, 1.0)),
                    np.full(n, 0.01), np.full(n, 6.0e5))
    starts, p0 = np.array([0, 400]), np.array([2.0e5, 4.0e5])
    tight = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=1e-6, max_step_s=1e-3,
                         min_step_s=1e-14, max_steps_per_s=5e6)
    out, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 400, p0, tight)
    d = 20.0
    fd = (simulate_windows(model, params, inputs, rig, starts, 400, p0 + d, tight)
          - simulate_windows(model, params, inputs, rig, starts, 400, p0 - d, tight)) / (2 * d)
    crossed = np.diff(np.sign(out - 2.5e5), axis=-1) != 0
    assert crossed.sum() >= 2  # the windows cross the hinge, both ways
    assert np.max(np.abs(sens - fd)) < 0.01


def test_start_sensitivity_is_one_in_a_closed_fixed_chamber(rig, standard):
    # both ports shut, no leak, fixed volume: dp/dt = 0, so a start error never decays
    n = 501
    t = np.arange(n) * 1e-3
    u = np.where(t < 0.2, 3.0, -3.0)
    out, sens, status = kernel.simulate_windows_sensitivity(
        _closed_slots(1e-6), rig_constants(rig), standard.as_array(), t, u, np.zeros(n),
        np.full(n, 0.01), np.full(n, 6.0e5), np.array([0, 100], dtype=np.int64), 400,
        np.array([3e5, 2e5]))
    assert not status.any()
    assert np.all(out[0, 0] == 3e5) and np.all(sens == 1.0)


@pytest.mark.parametrize("effects,extra,without_history_Pa", [
    (["tube_delay"], {"tube_delay_s": 0.02}, 1e3),
    (["spool_lag"], {"spool_time_constant_s": 0.008}, 100.0),
    (["tube_delay", "spool_lag"], {"tube_delay_s": 0.012, "spool_time_constant_s": 0.005},
     1e3),
])
def test_windows_with_delay_use_the_command_history(rig, hand, standard, effects, extra,
                                                    without_history_Pa):
    """A delayed or lagged window must see the commands issued before its start.

    Started from the full run's pressure at sample s, it reproduces the full run
    (to solver accuracy); slicing the inputs instead (no history) would not.
    """
    model = Model(["cylinder_leak", *effects])
    params = valve_preset("valve1").parameters()
    params.update(dead_volume_m3=1e-6, leak_area_m2=3e-8, **extra)
    n = 1201
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(9), n, 1e-3, hold_s=(0.01, 0.04))
    inputs = Inputs(t, u, np.zeros(n), np.full(n, P_SUP))
    full = simulate(model, params, inputs, rig, P_ATM, _config(1e-8)).pressure_Pa[0]
    # windows that start 5 samples after a command change (inside the delay)
    changes = np.nonzero(np.abs(np.diff(u)) > 3.0)[0] + 1  # large command steps
    changes = changes[(changes > 30) & (changes < n - 300)]
    starts = changes[[0, len(changes) // 2, -1]] + 5
    assert starts.max() + 250 <= n
    length = 250
    win = simulate_windows(model, params, inputs, rig, starts, length, full[starts],
                           _config(1e-8))[0]
    for w, s in enumerate(starts):
        assert np.max(np.abs(win[w] - full[s:s + length])) < 5.0
    # control: without the history (inputs sliced at the start) the windows differ
    for s in starts:
        sub = Inputs(t[s:s + length], u[s:s + length], np.zeros(length), np.full(length, P_SUP))
        cut = simulate(model, params, sub, rig, full[s], _config(1e-8)).pressure_Pa[0]
        assert np.max(np.abs(cut - full[s:s + length])) > without_history_Pa


_LINE = ("tube_delay", "line", {"tube_delay_s": 0.002, "tube_diameter_m": 0.002})


@pytest.mark.parametrize("forms", [
    [("heat_transfer", "rate", {"heat_transfer_rate_per_s": 20.0, "heat_transfer_coupling": 1.0})],
    [("heat_transfer", "convective", {"heat_transfer_coefficient_W_per_m2_K": 60.0,
                                      "heat_transfer_coupling": 1.0})],
    [_LINE],
    [_LINE, ("heat_transfer", "convective", {"heat_transfer_coefficient_W_per_m2_K": 60.0,
                                             "heat_transfer_coupling": 1.0})],
], ids=["heat rate", "heat convective", "line", "line and heat"])
def test_contiguous_windows_carry_the_unmeasured_states(rig, hand, forms):
    """The temperature and an acoustic line's cells are states no recording measures.
    Contiguous windows restarted from the full run's own pressures reproduce the full
    run (to solver accuracy) only because each window starts where the previous one
    ended; the same windows simulated apart (each from the supply temperature, or the
    line at rest) do not."""
    from pneubayes.effects import make_effect

    model = Model([make_effect(effect, form=form) for effect, form, _ in forms])
    extra = {k: v for _, _, e in forms for k, v in e.items()}
    params = dict(valve_preset("valve1").parameters(), dead_volume_m3=5e-7, **extra)
    if "tube_delay" in model.effect_names:  # the dead volume includes the tube's
        params["dead_volume_m3"] += float(model.effect("tube_delay").tube_volume_m3(extra, rig))
    n = 1201
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(10), n, 1e-3, hold_s=(0.02, 0.08))
    inputs = Inputs(t, u, hand.moving_position(t), np.full(n, P_SUP))
    tight = _config(1e-8)
    full = simulate(model, params, inputs, rig, 2e5, tight).pressure_Pa[0]
    length = 301
    starts = np.arange(0, n - length + 1, length - 1)
    assert starts.size == 4
    win = simulate_windows(model, params, inputs, rig, starts, length, full[starts], tight)[0]
    for w, s in enumerate(starts):
        assert np.max(np.abs(win[w] - full[s:s + length])) < 5.0
    # control: one window at a time starts each at the supply temperature
    apart = [simulate_windows(model, params, inputs, rig, starts[w:w + 1], length,
                              full[starts[w:w + 1]], tight)[0, 0] for w in range(4)]
    assert np.max(np.abs(apart[0] - full[:length])) < 5.0  # the first is the same
    assert max(np.max(np.abs(apart[w] - full[s:s + length]))
               for w, s in enumerate(starts) if w > 0) > 1e3


def _line_model_params(rig, delay_s=0.002, dia_m=0.002, segments=3):
    from pneubayes.effects import make_effect

    model = Model(["cylinder_leak", make_effect("tube_delay", form="line", segments=segments)])
    params = dict(valve_preset("valve1").parameters(), leak_area_m2=3e-9,
                  tube_delay_s=delay_s, tube_diameter_m=dia_m)
    params["dead_volume_m3"] = 5e-7 + float(
        model.effect("tube_delay").tube_volume_m3(params, rig))
    return model, params


def test_an_acoustic_line_fills_to_supply_and_vents_to_atmosphere(rig, standard, make_inputs,
                                                                  hand):
    """Through a 2-m line (5.8 ms) the chamber still settles at the flow balance of the
    bare chamber (eqs. 4/9): without a leak the settled line passes no flow and drops no
    pressure."""
    model, params = _line_model_params(rig, delay_s=0.0058)
    params["leak_area_m2"] = 0.0
    bare = {k: v for k, v in params.items() if not k.startswith("tube_")}
    t = np.arange(3001) * 1e-3
    up = simulate(model, params, make_inputs(t, np.full(t.size, 5.0)), rig, P_ATM,
                  standard).pressure_Pa[0]
    down = simulate(model, params, make_inputs(t, np.full(t.size, -5.0)), rig, P_SUP,
                    standard).pressure_Pa[0]
    assert up[-1] == pytest.approx(hand.equilibrium(bare, u=5.0), abs=5.0)
    assert down[-1] == pytest.approx(hand.equilibrium(bare, u=-5.0), abs=5.0)
    # the line delays the start: nothing reaches the chamber early (three lumped cells
    # smear the front: 0.5 Pa at L / 6c, 50 Pa at L / 3c), then it fills
    assert abs(up[1] - P_ATM) < 5.0 and up[8] - P_ATM > 1e3


def _line_first_resonance_rad_per_s(rig, segments, volume_ratio):
    """The lowest natural frequency of the model's line (1 m, 2 mm bore, frictionless,
    both ports shut, at rest at 3 bar) into a chamber of ``volume_ratio`` x the line's
    volume: the imaginary parts of its Jacobian's eigenvalues."""
    from pneubayes.effects import make_effect
    from pneubayes.simulation.line import line_rhs

    length_m, dia_m = 1.0, 0.002
    area = math.pi * dia_m**2 / 4
    c = rig.gas.speed_of_sound_m_per_s
    model = Model([make_effect("tube_delay", form="line", segments=segments,
                               air_viscosity_Pa_s=1e-12)])
    params = dict(valve_preset("valve1").parameters(), tube_delay_s=length_m / c,
                  tube_diameter_m=dia_m, dead_volume_m3=area * length_m * (1 + volume_ratio))
    sl = np.ascontiguousarray(model.lower(model.as_matrix(params), rig))[0]
    ny = 1 + 2 * segments
    y = np.zeros(ny)
    y[:1 + segments] = 3e5
    f, jac, vt = np.empty(ny), np.empty((ny, ny)), np.empty(ny)
    line_rhs(y, segments, 0.0, 0.0, area * length_m * volume_ratio, 0.0, 7e5, sl,
             rig_constants(rig), 1e-4, True, 0.0, 0.0, 0.0, f, jac, vt)
    ev = np.linalg.eigvals(jac)
    return float(np.min(np.abs(ev.imag[ev.imag > 1e-6]))), c / length_m


@pytest.mark.parametrize("volume_ratio", [0.5, 2.0, 5.0])
def test_the_lumped_lines_resonance_converges_to_the_continuous_tubes(rig, volume_ratio):
    """A tube shut at the valve and ending in a chamber of volume V rings where
    tan(kL) = -k V / A (the continuous line's closed form, k = w / c). The model's
    staggered lumping (cell pressures at the centres, a half link into the chamber) is
    within 1.5 % with 3 cells and converges at second order; lumping each cell at its
    upstream end (every link dx long) was 8-14 % low with 3 cells and 3-6 % with 8, and
    the fitted tube length reads short by as much."""
    from scipy.optimize import brentq

    x1 = brentq(lambda x: math.tan(x) + volume_ratio * x, math.pi / 2 + 1e-9, math.pi - 1e-9)
    errs = []
    for n in (3, 6):
        w1, c_over_l = _line_first_resonance_rad_per_s(rig, n, volume_ratio)
        errs.append(abs(w1 / (c_over_l * x1) - 1.0))
    assert errs[0] < 0.015, errs
    assert errs[1] < 0.3 * errs[0], errs  # second order: 4x from 3 to 6 cells


def test_an_acoustic_line_rings_and_a_bare_chamber_does_not(rig, standard, make_inputs):
    """A valve slammed shut on a flowing line: the chamber overshoots its final pressure
    and rings at about the line's quarter-wave frequency; a bare chamber stops at once."""
    model, params = _line_model_params(rig, delay_s=0.0058, dia_m=0.004)
    t = np.arange(801) * 1e-4  # 10 kHz to see the wave
    u = np.where(t < 0.02, 5.0, 0.0)
    p = simulate(model, params, make_inputs(t, u), rig, P_ATM, standard).pressure_Pa[0]
    after = p[t >= 0.02]
    final = after[-1]
    assert after.max() - final > 2e3  # overshoot after the valve shut
    crossings = np.nonzero(np.diff(np.sign(after - final)) != 0)[0]
    assert crossings.size >= 3  # it oscillates about the final pressure


@pytest.mark.parametrize("heat", [None, "convective"])
def test_start_sensitivity_through_an_acoustic_line_matches_finite_differences(rig, hand, heat):
    from pneubayes.effects import make_effect

    model, params = _line_model_params(rig)
    if heat:  # the temperature joins the line's state and its propagator
        model = model.with_effect(make_effect("heat_transfer", form=heat))
        params["heat_transfer_coefficient_W_per_m2_K"] = 60.0
        params["heat_transfer_coupling"] = 1.0
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(4), n, 1e-3, levels=(-1.0, 1.0)),
                    np.full(n, 0.01), np.full(n, 6.0e5))
    starts = np.array([0, 400])
    p0 = np.array([2.0e5, 4.0e5])
    tight = _config(1e-9)
    out, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 400, p0, tight)
    d = 20.0
    up = simulate_windows(model, params, inputs, rig, starts, 400, p0 + d, tight)
    dn = simulate_windows(model, params, inputs, rig, starts, 400, p0 - d, tight)
    fd = (up - dn) / (2 * d)
    assert np.all(sens[..., 0] == 1.0)
    assert np.max(np.abs(sens - fd)) < 0.03


def _hot_line_slots(form):
    sl = np.zeros(N_SLOTS)
    sl[SLOT_INDEX["volume_m3"]] = 2e-6
    sl[SLOT_INDEX["line_length_m"]] = 1.0
    sl[SLOT_INDEX["line_diameter_m"]] = 0.002
    sl[SLOT_INDEX["line_viscosity_Pa_s"]] = 1.81e-5
    sl[SLOT_INDEX["leak_orifice_area_m2"]] = 3e-9
    sl[SLOT_INDEX["leak_laminar_kg_per_s_Pa2"]] = 1e-15
    sl[SLOT_INDEX["leak_laminar_gradient_kg_per_s_Pa2_m"]] = 1e-14
    if form == "rate":
        sl[SLOT_INDEX["heat_rate_per_s"]] = 8.0
    else:
        sl[SLOT_INDEX["heat_coefficient_W_per_m2_K"]] = 40.0
    sl[SLOT_INDEX["heat_coupling"]] = 0.6  # (a partial coupling: every term of it)
    return sl


@pytest.mark.parametrize("form", ["rate", "convective"])
@pytest.mark.parametrize("last_flow", [5e-5, -5e-5], ids=["into", "out of"])
def test_the_hot_line_jacobian_and_time_derivative_match_finite_differences(rig, form,
                                                                            last_flow):
    """With heat transfer the line's state ends with the chamber temperature; the
    exponential method keeps its order only with the exact Jacobian of the whole state
    (the p-T and flow-T couplings included: air leaves the chamber at T, with the flow
    out of it into the line or through a leak) and the exact explicit time derivative
    of a moving volume. Both against central differences, flow into and out of the
    chamber."""
    from pneubayes.simulation.line import line_rhs
    from pneubayes.simulation.simulator import rig_constants

    sl, cs = _hot_line_slots(form), rig_constants(rig)
    y = np.array([3.0e5, 4.0e5, 3.6e5, 3.2e5, 1e-4, 8e-5, last_flow, 320.0])
    ny = y.size
    vol_m3, vdot_m3_per_s = 1.5e-6, 3e-6

    def rhs(state, vol, need_j=False):
        f, jac, vt = np.empty(ny), np.empty((ny, ny)), np.empty(ny)
        line_rhs(state, 3, 2e-7, 1e-7, vol, vdot_m3_per_s, 6e5, sl, cs, 1e-12, need_j,
                 0.0, 0.0, 0.0, f, jac, vt)
        return f, jac, vt

    f, jac, vt = rhs(y, vol_m3, True)
    assert f[0] < 0.0 and f[-1] < 0.0  # the chamber is at 320 K and cools: p and T fall
    fd = np.empty((ny, ny))
    for k in range(ny):
        d = 1e-6 * abs(y[k])
        up, dn = y.copy(), y.copy()
        up[k] += d
        dn[k] -= d
        fd[:, k] = (rhs(up, vol_m3)[0] - rhs(dn, vol_m3)[0]) / (2 * d)
    scale = np.abs(fd).max(axis=1, keepdims=True)
    assert np.max(np.abs(jac - fd) / scale) < 1e-6
    assert np.all(jac[[0, -1]][:, [0, 6, 7]] != 0.0)  # the couplings are there
    dt = 1e-7
    fd_t = (rhs(y, vol_m3 + vdot_m3_per_s * dt)[0]
            - rhs(y, vol_m3 - vdot_m3_per_s * dt)[0]) / (2 * dt)
    np.testing.assert_allclose(vt[[0, -1]], fd_t[[0, -1]], rtol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("form, key, value", [
    ("rate", "heat_transfer_rate_per_s", 20.0),
    ("convective", "heat_transfer_coefficient_W_per_m2_K", 60.0)])
def test_an_acoustic_line_beside_heat_transfer_agrees_with_radau(rig, form, key, value):
    """A 1-m line into a chamber exchanging heat with its wall, a moving piston and an
    orifice leak: the compiled step against scipy's Radau on the reference right-hand
    side (an isothermal line: gas enters the chamber at the supply's temperature and
    leaves at the chamber's). Measured: 12-13 Pa at the standard preset, 0.2 Pa at
    100x tighter, on a 0.4-MPa span; heat transfer moves the pressure by 23-26 kPa."""
    from pneubayes.effects import make_effect

    n, dt = 301, 1e-3
    t = np.arange(n) * dt
    u = np.repeat(np.random.default_rng(7).uniform(-1.5, 1.5, n // 20 + 1), 20)[:n]
    inputs = Inputs(t, u, 0.015 + 0.008 * np.sin(2 * np.pi * 5 * t), np.full(n, P_SUP))
    model = Model(["cylinder_leak", make_effect("tube_delay", form="line", segments=3),
                   make_effect("heat_transfer", form=form)])
    params = dict(valve_preset("valve1").parameters(), leak_area_m2=3e-9, tube_delay_s=0.003,
                  tube_diameter_m=0.002, **{key: value, "heat_transfer_coupling": 1.0})
    params["dead_volume_m3"] = 1e-6 + float(model.effect("tube_delay").tube_volume_m3(params,
                                                                                     rig))
    ref = reference_simulate(model, params, inputs, rig, P_ATM, rtol=1e-10)
    assert np.ptp(ref) > 0.5 * RANGE
    standard = SolverConfig.standard()
    got = simulate(model, params, inputs, rig, P_ATM, standard).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 1e-4 * RANGE
    tight = simulate(model, params, inputs, rig, P_ATM, standard.tightened(100)).pressure_Pa[0]
    assert np.max(np.abs(tight - ref)) <= 2e-6 * RANGE
    iso = Model(["cylinder_leak", make_effect("tube_delay", form="line", segments=3)])
    plain = simulate(iso, {k: v for k, v in params.items() if not k.startswith("heat_")},
                     inputs, rig, P_ATM,
                     standard).pressure_Pa[0]
    assert np.max(np.abs(plain - ref)) > 0.03 * RANGE  # the heat transfer matters here


@pytest.mark.slow
# (scipy's finite-difference Jacobian overflows on the flows' tiny scale, harmlessly)
@pytest.mark.filterwarnings("ignore:overflow encountered in multiply:RuntimeWarning")
def test_the_benchmarks_acoustic_line_agrees_with_radau_and_converges(rig):
    """The 3-cell line of ``benchmarks/simulate.py``'s effect rows (1-ms transit, 2.5-mm
    bore, into 2.4e-6 m^3 with the orifice leak) under five valve switches, against
    scipy's Radau on the reference right-hand side (issue 68's floor: 0.1 % of the
    range). Measured: 22 Pa at the standard preset, 1.1 Pa at 10x tighter, 0.34 Pa at
    100x (Radau's own error near there), on a 0.45-MPa span; a faster line step must
    keep the standard preset within 1e-4 of the range and converge as it tightens."""
    from pneubayes.effects import make_effect

    n = 151
    t = np.arange(n) * 1e-3
    u = np.repeat(np.random.default_rng(3).uniform(-5.0, 5.0, 6), 30)[:n]
    inputs = Inputs(t, u, np.zeros(n), np.full(n, P_SUP))
    model = Model(["cylinder_leak", make_effect("tube_delay", form="line", segments=3)])
    params = dict(valve_preset("valve1").parameters(), dead_volume_m3=2.4e-6,
                  leak_area_m2=3.04e-8, tube_delay_s=0.001, tube_diameter_m=0.0025)
    ref = reference_simulate(model, params, inputs, rig, P_ATM, rtol=1e-10)
    assert np.ptp(ref) > 0.9 * RANGE
    standard = SolverConfig.standard()
    errors = [np.max(np.abs(simulate(model, params, inputs, rig, P_ATM, solver)
                            .pressure_Pa[0] - ref))
              for solver in (standard, standard.tightened(10), standard.tightened(100))]
    assert errors[0] <= 1e-4 * RANGE
    assert errors[1] <= 0.2 * errors[0]
    assert errors[2] <= 2e-6 * RANGE


def test_a_shut_line_and_chamber_compressed_with_fast_wall_exchange_keep_pv(rig,
                                                                          closable_params):
    """Limits: valve shut, no leak, the piston compresses the chamber 2x in 0.5 s behind a
    line of about its volume. A wall exchange much faster than the compression keeps the
    chamber at the wall's temperature (Boyle: p V = const for its gas), while the line's
    cells change pressure with kappa Rs T per kg, as eq. 5 and the line's wave speed
    sqrt(kappa Rs T) have it; the quasi-static line is at the chamber's pressure, so
    mass conservation is p (V + V_line / kappa) = const. Without exchange the chamber
    heats and the pressure ends 4 % above that."""
    from pneubayes.effects import make_effect

    line = make_effect("tube_delay", form="line", segments=3)
    model = Model([line, make_effect("heat_transfer", form="rate")],
                  bounds={"heat_transfer_rate_per_s": (0.0, 1e6)})  # (1e5/s: out of the prior)
    params = dict(closable_params, tube_delay_s=0.002, tube_diameter_m=0.002)
    v_line = float(line.tube_volume_m3(params, rig))
    params["dead_volume_m3"] = 3e-7 + v_line
    n = 501
    t = np.arange(n) * 1e-3
    x = 0.025 - 0.015 * t / t[-1]
    inputs = Inputs(t, np.zeros(n), x, np.full(n, P_SUP))
    kappa = rig.gas.heat_capacity_ratio
    total = params["dead_volume_m3"] - v_line + rig.bore_area_m2 * x + v_line / kappa
    p0 = 1.5e5
    tight = _config(1e-8)
    fast = simulate(model, dict(params, heat_transfer_rate_per_s=1e5,
                                heat_transfer_coupling=1.0), inputs, rig, p0,
                    tight).pressure_Pa[0]
    # (3e-4 at the start: the piston starts at once and the line rings)
    np.testing.assert_allclose(fast * total, p0 * total[0], rtol=5e-4)
    slow = simulate(model, dict(params, heat_transfer_rate_per_s=1e-3,
                                heat_transfer_coupling=1.0), inputs, rig, p0,
                    tight).pressure_Pa[0]
    assert slow[-1] * total[-1] > 1.03 * p0 * total[0]  # (4 %: 80 times the tolerance)


def test_the_line_exponential_of_a_non_finite_matrix_is_nan_not_an_exception():
    """A trial parameter set can make the line's Jacobian non-finite; the compiled solve
    would raise inside the kernel's parallel loop (numba then reports a SystemError and
    the whole fit dies). The exponential returns NaN instead, and the step is rejected."""
    from scipy.linalg import expm

    from pneubayes.simulation.line import expm_small, phi_combination

    a = np.array([[-3.0, 1.0], [0.5, -2.0]])
    assert np.allclose(expm_small(a), expm(a), rtol=1e-13)
    for bad in (np.nan, np.inf):
        a2 = a.copy()
        a2[0, 1] = bad
        assert np.all(np.isnan(expm_small(a2)))
        out, prop = phi_combination(a2, np.ones((2, 2)), np.ones(2))
        assert np.all(np.isnan(out)) and np.all(np.isnan(prop))


def test_the_line_small_matrix_algebra_matches_numpy_and_scipy():
    """The line's exponential uses plain-loop products and a pivoted elimination (no
    BLAS/LAPACK to compile, which halved the kernel's cold compile): they match numpy on
    random matrices, on one that needs pivoting (zero diagonal) and on sparse ones; a
    singular system is NaN, and expm matches scipy at a norm needing squarings."""
    from scipy.linalg import expm

    from pneubayes.simulation.line import _matmul_into, _solve_in_place, expm_small

    def _matmul(a, b):
        c = np.empty((a.shape[0], b.shape[1]))
        _matmul_into(a, b, c)
        return c

    def _solve(a, b):
        x = b.copy()
        _solve_in_place(a.copy(), x)
        return x

    rng = np.random.default_rng(8)
    for n in (1, 3, 9, 17):
        a, b = rng.standard_normal((n, n)), rng.standard_normal((n, 4))
        sparse = a * (rng.random((n, n)) < 0.3)
        assert np.allclose(_matmul(a, b), a @ b, rtol=1e-13, atol=1e-13)
        assert np.allclose(_matmul(sparse, a), sparse @ a, rtol=1e-13, atol=1e-13)
        well = a + n * np.eye(n)
        assert np.allclose(_solve(well, b), np.linalg.solve(well, b), rtol=1e-11)
        big = 3.0 * a  # 1-norm > 0.5: scaled and squared several times
        assert np.allclose(expm_small(big), expm(big), rtol=1e-10, atol=1e-12)
    pivot = np.array([[0.0, 2.0, 1.0], [1.0, 0.0, 3.0], [4.0, 1.0, 0.0]])
    b = rng.standard_normal((3, 2))
    assert np.allclose(_solve(pivot, b), np.linalg.solve(pivot, b), rtol=1e-13)
    assert np.all(np.isnan(_solve(np.array([[1.0, 2.0], [2.0, 4.0]]) * 0.0, b[:2])))


def test_the_line_right_hand_side_divides_by_zero_without_raising(rig):
    """The kernel computes with IEEE semantics (numba's error_model="numpy"): a division
    by zero gives inf or NaN, which fails the step, instead of a ZeroDivisionError. Inside
    the kernel's parallel loop an exception surfaces as numba's opaque "SystemError:
    CPUDispatcher(_simulate) returned a result with an exception set" and kills the
    caller: a least-squares Jacobian of a discovery line fit died so (AIR37 dead-zone case,
    a 9-mm line of 1.4 mm). Here two empty cells (zero density) divide by zero."""
    from pneubayes.effects.path import N_SLOTS, SLOT_INDEX
    from pneubayes.simulation.line import line_rhs
    from pneubayes.simulation.simulator import rig_constants

    sl = np.zeros(N_SLOTS)
    sl[SLOT_INDEX["volume_m3"]] = 2e-7
    sl[SLOT_INDEX["line_length_m"]] = 0.01
    sl[SLOT_INDEX["line_diameter_m"]] = 0.002
    sl[SLOT_INDEX["line_viscosity_Pa_s"]] = 1.81e-5
    y = np.array([2.0e5, 0.0, 0.0, 2.0e5, 1e-4, 1e-4, 1e-4])
    f, jac, vt = np.empty(7), np.empty((7, 7)), np.empty(7)
    line_rhs(y, 3, 1e-7, 0.0, 2e-7, 0.0, 6e5, sl, rig_constants(rig), 1e-5, True, 0.0, 0.0,
             0.0, f, jac, vt)
    assert not np.all(np.isfinite(f))


def test_an_acoustic_line_refuses_an_oversized_tube(rig, make_inputs):
    model, params = _line_model_params(rig)
    t = np.arange(11) * 1e-3
    with pytest.raises(SimulationError, match="line's volume"):
        simulate(model, dict(params, dead_volume_m3=1e-7), make_inputs(t, 0 * t), rig, P_ATM,
                 _config(1e-6))


# ---------------------------------------------------------------- robustness
@pytest.mark.slow
@pytest.mark.parametrize("form", ["orifice", "laminar"])
def test_random_parameters_inside_bounds_simulate(rig, hand, form, standard):
    from pneubayes.effects import make_effect

    effects = [make_effect("cylinder_leak", form=form)] + ALL_EFFECTS[1:]
    model = Model(effects)
    assert set(model.effect_names) == set(ALL_EFFECTS)
    rng = np.random.default_rng(2024 if form == "orifice" else 2025)
    n = 1001
    t = np.arange(n) * 1e-3
    draws = 50 if form == "orifice" else 20
    failures, out_of_range = [], []
    lo_bound, hi_bound = 0.5 * P_ATM, 1.5 * P_SUP
    for i in range(draws):
        theta = np.array([p.sample_prior(rng) for p in model.parameters])
        lo, hi = model.bounds
        assert np.all((theta >= lo) & (theta <= hi))
        inputs = Inputs(t, hand.random_steps(rng, n, 1e-3),
                        hand.moving_position(t, mean=0.0105, amp=0.0005),
                        hand.fluctuating_supply(t, amp=10_000.0))
        p0 = rng.uniform(P_ATM, P_SUP)
        try:
            p = simulate(model, theta, inputs, rig, p0, standard).pressure_Pa[0]
        except SimulationError as exc:
            failures.append((i, str(exc).splitlines()[1][:300]))
            continue
        assert np.all(np.isfinite(p)), model.as_dict(theta)
        if p.min() < lo_bound or p.max() > hi_bound:
            out_of_range.append((i, float(p.min()), float(p.max()), model.as_dict(theta)))
    assert not failures, f"{len(failures)} of {draws} draws failed: {failures[:3]}"
    assert not out_of_range, f"{len(out_of_range)} of {draws} left [0.5 P_atm, 1.5 P_sup]: " \
                             f"{out_of_range[:2]}"


def test_simulation_error_names_the_parameters(leak_model, base_params, rig, make_inputs):
    t = np.arange(201) * 1e-3
    tiny = SolverConfig(rtol=1e-5, atol_Pa=5.0, atol_K=0.01, max_step_s=0.02, min_step_s=1e-12,
                        max_steps_per_s=3.0)
    batch = np.stack([leak_model.vector(base_params)] * 2)
    with pytest.raises(SimulationError) as info:
        simulate(leak_model, batch, make_inputs(t, np.full(t.size, 5.0)), rig, P_ATM, tiny)
    msg = str(info.value)
    assert "parameter set" in msg
    for name in leak_model.parameter_names:
        assert name in msg
    assert "parameter set 0" in msg and "parameter set 1" in msg
    assert "max_steps_per_s" in msg
    assert f"{base_params['inlet_b']:.6g}" in msg


def test_step_budget_is_per_simulated_second_beyond_one_step_per_sample(
        leak_model, base_params, rig, make_inputs):
    """SolverConfig.max_steps_per_s: a window of N samples over D s may take
    N - 1 + max_steps_per_s * D steps. A fill from atmospheric pressure needs extra steps
    in its first 0.2 s and about one per sample once the chamber is full, so a 2-s window
    of the same fill passes with about a tenth of the rate the 0.2-s window needs; were
    the one step per sample not free, it would need 1,800 more steps than that."""
    t = np.arange(2001) * 1e-3
    fill = make_inputs(t, np.full(t.size, 5.0))

    def passes(rate, length):
        solver = SolverConfig(rtol=1e-6, atol_Pa=1.0, atol_K=0.01, max_step_s=0.02,
                              min_step_s=1e-12, max_steps_per_s=rate)
        out = simulate_windows(leak_model, base_params, fill, rig, [0], length, P_ATM,
                               solver, on_failure="nan")
        return bool(np.all(np.isfinite(out)))

    assert not passes(1e-9, 201)
    assert passes(2.5e6, 201)
    lo, hi = 1e-9, 2.5e6  # bisection for the smallest rate the 0.2-s window passes with
    while hi / lo > 1.01:
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if passes(mid, 201) else (mid, hi)
    assert not passes(lo, 201)
    assert hi * 0.2 < 1800  # the extra steps of the fill: fewer than the free ones
    assert passes(hi / 9.0, 2001)


# ---------------------------------------------------------------- argument checks
def test_simulate_rejects_bad_arguments(leak_model, base_params, rig, make_inputs):
    t = np.arange(11) * 1e-3
    inputs = make_inputs(t, np.zeros(t.size))
    with pytest.raises(TypeError):
        simulate(leak_model, base_params, inputs, rig, P_ATM, None)
    with pytest.raises(ValueError):
        simulate(leak_model, dict(base_params, inlet_b=100.0), inputs, rig, P_ATM,
                 SolverConfig.standard())
    with pytest.raises(ValueError):
        simulate(leak_model, base_params, inputs, rig, -1.0, SolverConfig.standard())
    with pytest.raises(ValueError):
        simulate_windows(leak_model, base_params, inputs, rig, [5], 10, [P_ATM],
                         SolverConfig.standard())
    with pytest.raises(ValueError):
        Inputs(t, np.zeros(t.size), np.zeros(t.size), np.full(t.size, np.nan))
    with pytest.raises(ValueError):
        Inputs(t[::-1], np.zeros(t.size), np.zeros(t.size), np.full(t.size, P_SUP))
    with pytest.raises(ValueError):
        SolverConfig(rtol=0.0, atol_Pa=1.0, atol_K=1.0, max_step_s=1.0, min_step_s=0.1,
                     max_steps_per_s=10.0)


def test_trajectory_records_solver_and_parameters(leak_model, base_params, rig, make_inputs,
                                                  standard):
    t = np.arange(21) * 1e-3
    traj = simulate(leak_model, base_params, make_inputs(t, np.zeros(t.size)), rig, 2e5,
                    standard)
    assert traj.solver == standard
    assert traj.parameter_names == leak_model.parameter_names
    assert np.array_equal(traj.parameters[0], leak_model.vector(base_params))
    assert traj.pressure_Pa[0, 0] == 2e5
    assert math.isclose(traj.time_s[-1], 0.02)


@pytest.mark.parametrize("threads", [2, 3, 7])
def test_threads_give_the_serial_answer_for_every_task(rig, base_params, leak_model,
                                                       make_inputs, monkeypatch, threads):
    """The tasks (parameter set x window) are cut into chunks that Python threads take as
    they come free; on any thread count every task runs once and gives the one-thread
    answer bit for bit (a skipped task would leave its row as np.empty's garbage)."""
    t = np.arange(301) * 1e-3
    inputs = make_inputs(t, 3.0 * np.sin(2 * np.pi * 7 * t))
    theta = np.repeat(leak_model.vector(base_params)[None, :], 11, axis=0)
    theta[:, leak_model.parameter_names.index("dead_volume_m3")] *= np.linspace(0.5, 2, 11)
    starts = np.array([0, 60, 120, 180, 240])

    def run(n):
        monkeypatch.setattr(kernel.numba, "get_num_threads", lambda: n)
        return simulate_windows(leak_model, theta, inputs, rig, starts, 61,
                                np.full(5, 2e5), SolverConfig.standard())

    np.testing.assert_array_equal(run(threads), run(1))


def test_read_only_inputs_reuse_the_one_compiled_kernel(rig, base_params, leak_model,
                                                         make_inputs):
    """A recording's arrays are read-only; numba would compile a new copy of the kernel
    (tens of seconds) for every combination of read-only flags. The simulator hands the
    kernel writeable copies, so read-only and writeable inputs share one signature."""
    t = np.arange(201) * 1e-3
    inputs = make_inputs(t, np.where(t < 0.1, 3.0, -3.0))
    for a in (inputs.time_s, inputs.command_V, inputs.position_m, inputs.supply_pressure_Pa):
        a.flags.writeable = False
    def signatures():
        return set(kernel._simulate_tasks.signatures)

    before = signatures()
    ro = simulate(leak_model, base_params, inputs, rig, P_ATM, SolverConfig.standard())
    p0 = np.array([P_ATM, 2e5])
    p0.flags.writeable = False
    simulate_windows(leak_model, base_params, inputs, rig, np.array([0, 100]), 100, p0,
                     SolverConfig.standard())
    writeable = make_inputs(np.arange(201) * 1e-3, np.where(t < 0.1, 3.0, -3.0))
    rw = simulate(leak_model, base_params, writeable, rig, P_ATM, SolverConfig.standard())
    np.testing.assert_array_equal(ro.pressure_Pa, rw.pressure_Pa)
    new = signatures() - before
    assert len(new) <= 1, new
    assert all(not arg.readonly for sig in new for arg in sig if hasattr(arg, "readonly"))


def test_the_carried_chain_has_one_signature_for_scalar_array_and_read_only_starts(
        rig, base_params, leak_model, make_inputs):
    """A scalar start for one set broadcasts to a read-only view, an array start may be a
    recording's read-only column; each would be another compiled copy of the carried
    chain (seconds each) unless the simulator hands the kernel writeable copies."""
    from pneubayes.simulation import fresh_carry, simulate_carried

    t = np.arange(101) * 1e-3
    inputs = make_inputs(t, np.where(t < 0.05, 3.0, -3.0))
    measured = np.full(t.shape, 2e5)
    measured.flags.writeable = False
    before = set(kernel._chain_carried.signatures)
    runs = []
    for nb, p_start in ((1, 2e5), (2, 2e5), (2, np.array([2e5, 2e5])), (1, np.array([2e5]))):
        if isinstance(p_start, np.ndarray):
            p_start.flags.writeable = False
        theta = np.repeat(leak_model.vector(base_params)[None, :], nb, axis=0)
        out, _ = simulate_carried(leak_model, theta, inputs, rig, [0, 50, 100], p_start,
                                  fresh_carry(nb, rig), measured, 0.0,
                                  SolverConfig.standard())
        runs.append(out[0])
    new = set(kernel._chain_carried.signatures) - before
    assert len(new) <= 1, new
    for other in runs[1:]:
        np.testing.assert_array_equal(other, runs[0])


def test_numba_cache_is_cleared_when_any_compiled_source_changes(tmp_path):
    """numba checks only a cached function's own file; an edit to a file it calls must
    clear the cache too (pneubayes.compile_cache)."""
    from pneubayes.compile_cache import clear_if_stale

    kern, phys = tmp_path / "simulation", tmp_path / "physics"
    for d in (kern, phys):
        (d / "__pycache__").mkdir(parents=True)
    (kern / "kernel.py").write_text("def f(): return g()\n")
    (phys / "orifice.py").write_text("def g(): return 1\n")
    stamp = kern / "__pycache__" / "stamp"

    def cached():
        for d in (kern, phys):
            (d / "__pycache__" / "m.f-1.py311.nbi").write_text("index")
            (d / "__pycache__" / "m.f-1.py311.1.nbc").write_text("code")
        (kern / "__pycache__" / "kernel.cpython-311.pyc").write_text("bytecode")

    cached()
    assert clear_if_stale([kern, phys], stamp) == 4  # no stamp yet: cleared once
    cached()
    assert clear_if_stale([kern, phys], stamp) == 0  # same sources: the cache stays
    assert (kern / "__pycache__" / "m.f-1.py311.1.nbc").exists()
    (phys / "orifice.py").write_text("def g(): return 2\n")  # only the callee changes
    assert clear_if_stale([kern, phys], stamp) == 4
    assert not list((phys / "__pycache__").glob("*.nb*"))
    assert (kern / "__pycache__" / "kernel.cpython-311.pyc").exists()  # not numba's
    assert clear_if_stale([kern, phys], stamp) == 0


@pytest.mark.parametrize("m", [
    [[-3.0, 1.0], [0.5, -2.0]],                # real, distinct
    [[-2.0, 1.0], [0.0, -2.0]],                # repeated eigenvalue, a Jordan block
    [[-0.5, 4.0], [-4.0, -0.5]],               # complex pair (oscillatory)
    [[-4.0e4, 3.0e2], [-2.0e-1, -1.0e-2]],     # stiff pressure beside slow temperature
    [[1e-9, 0.0], [0.0, -1e-9]],               # at the origin: the Taylor branch only
    [[0.3, -0.2], [0.1, 0.05]],                # positive eigenvalues (a growing state)
], ids=["real", "jordan", "complex", "stiff", "tiny", "growing"])
def test_the_thermal_phi_functions_match_scipys_augmented_exponential(m):
    """phi_0..phi_3 of a 2 x 2 matrix (the (p, T) step) against the top row of
    expm([[M, I, 0, 0], [0, 0, I, 0], [0, 0, 0, I], [0, 0, 0, 0]]) = [e^M, phi_1, phi_2,
    phi_3] (Sidje 1998)."""
    from scipy.linalg import expm

    from pneubayes.simulation.phi import phi0123_2x2

    m = np.array(m)
    big = np.zeros((8, 8))
    big[:2, :2] = m
    for k in range(3):
        big[2 * k:2 * k + 2, 2 * k + 2:2 * k + 4] = np.eye(2)
    top = expm(big)[:2]
    got = phi0123_2x2(tuple(m.ravel()))
    for k in range(4):
        want = top[:, 2 * k:2 * k + 2]
        np.testing.assert_allclose(np.reshape(got[k], (2, 2)), want, rtol=1e-10,
                                   atol=1e-13 * np.abs(want).max(), err_msg=f"phi_{k}")
    nan = phi0123_2x2((np.nan, 0.0, 0.0, 1.0))
    assert all(np.all(np.isnan(f)) for f in nan)


def test_the_line_steps_third_order_correction_is_phi3_within_a_fifth():
    """The second stage's ``phi_3(hJ) b`` is ``(6 I - 2 hJ)^-1 b``: exact at hJ = 0,
    within 20 % of phi_3 (from scipy's expm of the augmented matrix) on damped waves and
    stiff decay, slow to fast (rates x step 0.1 to 300, in a rotated basis); the exact
    combination where the chamber grows on its own (hJ[0, 0] > 0.5, near the pole)."""
    from scipy.linalg import expm

    from pneubayes.simulation.line import phi3_correction

    def exact(hj, b):
        n = hj.shape[0]
        big = np.zeros((n + 3, n + 3))
        big[:n, :n] = hj
        big[:n, n] = b
        big[n, n + 1] = big[n + 1, n + 2] = 1.0
        return expm(big)[:n, n + 2]

    rng = np.random.default_rng(5)
    n = 9
    assert np.allclose(phi3_correction(np.zeros((n, n)), np.arange(1.0, n + 1), np.ones(n)),
                       np.arange(1.0, n + 1) / 6.0, rtol=1e-14)
    for scale_of_rates in (0.1, 3.0, 300.0):
        q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        skew = rng.normal(size=(n, n))
        skew = scale_of_rates * (skew - skew.T) / 2  # waves: imaginary eigenvalues
        hj = skew - np.diag(rng.uniform(0.0, scale_of_rates, n))
        hj = q @ hj @ q.T
        b = rng.normal(size=n)
        want = exact(hj, b)
        scale = np.exp(rng.normal(size=n))  # balancing changes nothing but rounding
        got = phi3_correction(hj, b, scale)
        assert np.linalg.norm(got - want) <= 0.2 * np.linalg.norm(want)
        assert np.linalg.norm(got - want) > 1e-6 * np.linalg.norm(want)  # (an approximant)
    growing = -np.eye(n)
    growing[0, 0] = 2.0
    b = rng.normal(size=n)
    assert np.allclose(phi3_correction(growing, b, np.ones(n)), exact(growing, b),
                       rtol=1e-12)


@pytest.mark.parametrize("first, second, message", [
    ("wave_length_m", "heat_coupling", "transmission-line tube"),
    ("wave_length_m", "line_length_m", "transmission-line tube"),
    ("compliance_m3_per_Pa", "line_length_m", "compliant chamber"),
    ("volume_table_points", "heat_coupling", "compliant chamber"),
    ("tank_volume_m3", "heat_coupling", "supply tank"),
    ("tank_volume_m3", "wave_length_m", "supply tank"),
    ("lung_volume_m3", "tank_volume_m3", "two-compartment"),
    ("lung_volume_m3", "line_length_m", "two-compartment"),
])
def test_forms_with_a_second_state_are_refused_together_in_one_parameter_set(first, second,
                                                                             message):
    """The kernel steps one second state at a time: a parameter set with two is refused,
    while the two in different parameter sets of one batch, or one beside a separately
    commanded exhaust, are not."""
    from pneubayes.effects.path import SLOT_INDEX
    from pneubayes.simulation.simulator import _FORM_COLUMNS, _check_exclusive_forms

    col = _FORM_COLUMNS
    slots = np.zeros((2, len(SLOT_INDEX)))  # (read only beside a closure)
    both = np.zeros((2, len(col)), dtype=bool)
    both[1, [col[first], col[second]]] = True
    with pytest.raises(ValueError, match=message):
        _check_exclusive_forms(both, slots)
    apart = np.zeros((2, len(col)), dtype=bool)
    apart[0, col[first]] = apart[1, col[second]] = True
    apart[:, col["exhaust_own_command"]] = True
    _check_exclusive_forms(apart, slots)


def test_the_wrapper_sees_every_second_state_the_kernel_steps():
    """``_window_call`` tells the kernel whether a parameter set has a second state from
    the form columns it checks; each of the kernel's second-state slots must be one."""
    from pneubayes.simulation import kernel
    from pneubayes.simulation import simulator as sim

    assert sorted(sim._FORM_SLOTS[sim._GENERAL_COLUMNS]) == sorted(kernel.GENERAL_SLOTS)
    for k in kernel.GENERAL_SLOTS:
        slots = np.zeros((2, N_SLOTS))
        slots[1, k] = 1.0
        forms = slots[:, sim._FORM_SLOTS] > 0
        assert forms[:, sim._GENERAL_COLUMNS].any() == kernel.needs_general(slots)


def _form_windows(rig, form, general):
    """A valve with open ports stepped through one window without and with ``form``
    (slot values) in the kernel ``general`` chooses: ``(plain, (out, status), needs)``."""
    t = np.arange(301) * 1e-3
    u = np.where(t < 0.1, 5.0, -5.0)
    sl = _closed_slots(2.4e-6)
    for port in ("inlet", "exhaust"):  # ports that open
        sl[0, SLOT_INDEX[f"{port}_a_m2"]] = 1e-6
    args = (rig_constants(rig), SolverConfig.standard().as_array(), t, u, np.zeros_like(t),
            np.zeros_like(t), np.full(t.size, P_SUP), np.array([0], dtype=np.int64),
            t.size, np.array([2e5]))
    plain, status = kernel.simulate_windows(np.ascontiguousarray(sl), *args)
    assert not status.any() and not kernel.needs_general(sl)
    for name, value in form.items():
        sl[0, SLOT_INDEX[name]] = value
    return (plain, kernel.simulate_windows(np.ascontiguousarray(sl), *args, general=general),
            kernel.needs_general(sl))


@pytest.mark.parametrize("form", [
    {"spool_natural_frequency_rad_per_s": 900.0, "spool_damping": 0.7},
    {"command_clock_period_s": 7e-3}], ids=["spool2", "clock"])
def test_the_pressure_only_kernel_refuses_the_rarer_forms(rig, form):
    """A second-order spool and a valve driver's clock run in the general kernel
    (``needs_general``); handed to the pressure-only kernel they are refused with
    ``NEEDS_GENERAL``, not silently left out, and the general kernel steps them (its
    result differs from the form's absence)."""
    _, (_, status), needs = _form_windows(rig, form, False)
    assert needs and status[0, 0] == kernel.NEEDS_GENERAL
    plain, (out, status), _ = _form_windows(rig, form, True)
    assert status[0, 0] == kernel.OK
    assert np.max(np.abs(out[0, 0] - plain[0, 0])) > 100.0


@pytest.mark.parametrize("form", [
    {"sensor_time_constant_s": 2e-3},
    {"sensor_natural_frequency_rad_per_s": 900.0, "sensor_damping": 0.7},
    {"inlet_critical_ratio": 0.3, "exhaust_critical_ratio": 0.25},
    {"inlet_critical_ratio": 0.3, "exhaust_critical_ratio": 0.3,
     "port_subsonic_index": 0.4}],
    ids=["sensor", "sensor2", "critical_ratio", "iso6358"])
def test_a_form_runs_in_the_pressure_only_kernel_as_in_the_general_one(rig, form):
    """A lagged reading (first or second order) and the ports' own critical ratios (and
    subsonic index) are stepped by the pressure-only kernel (``needs_general`` false),
    as the general kernel steps them, and they change the pressure."""
    plain, (out, status), needs = _form_windows(rig, form, False)
    assert not needs and status[0, 0] == kernel.OK
    assert np.max(np.abs(out[0, 0] - plain[0, 0])) > 100.0
    _, (general, status), _ = _form_windows(rig, form, True)
    assert status[0, 0] == kernel.OK
    np.testing.assert_allclose(out[0, 0], general[0, 0], rtol=1e-9)
