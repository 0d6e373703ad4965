"""The sensor lag (effect ``sensor_lag``): the reading as a first-order lag of the
chamber pressure, against closed forms, the reference solver's ODE state, step halving,
finite differences and the one-step predictions of the discovery library."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fluctuating_supply, moving_position, moving_step_inputs, random_steps

from pneubayes.discovery.one_step import one_step_data
from pneubayes.effects import make_effect
from pneubayes.io import Recording, RecordingMetadata
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    simulate,
    simulate_windows,
    simulate_windows_sensitivity,
)
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM
TIGHT = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=1e-6, max_step_s=1e-3,
                     min_step_s=1e-14, max_steps_per_s=5e6)


def _params(tau=None, volume=2.4e-6, valve="valve1"):
    """Valve-1 base parameters, and a first-order lag of ``tau`` s unless None."""
    params = valve_preset(valve).parameters()
    params["dead_volume_m3"] = volume
    if tau is not None:
        params["sensor_time_constant_s"] = tau
    return params


def test_a_closed_chamber_is_read_as_an_exact_exponential(rig, closable_params, make_inputs):
    """Both ports shut, fixed volume: the chamber holds p0 + tau * rate, and the reading
    relaxes to it as r(t) = p_c + (p0 - p_c) exp(-t / tau)."""
    tau, p0, rate = 2e-3, 2.0e5, 4.0e6
    n = 41
    t = np.arange(n) * 5e-4
    inputs = make_inputs(t, np.zeros(n))
    model = Model(["sensor_lag"])
    params = dict(closable_params, sensor_time_constant_s=tau)
    got = simulate_windows(model, params, inputs, rig, np.array([0]), n, np.array([p0]),
                           SolverConfig.standard(), initial_rate_Pa_per_s=rate)[0, 0]
    p_c = p0 + tau * rate
    want = p_c + (p0 - p_c) * np.exp(-t / tau)
    assert np.max(np.abs(got - want)) < 1e-6 * p_c
    # without a lag the chamber starts at the reading and keeps it (rate or none)
    still = simulate_windows(model, dict(params, sensor_time_constant_s=0.0), inputs, rig,
                             np.array([0]), n, np.array([p0]), SolverConfig.standard(),
                             initial_rate_Pa_per_s=rate)[0, 0]
    assert np.all(still == p0)


def test_a_closed_chamber_is_read_through_a_second_order_lag_in_closed_form(
        rig, closable_params, make_inputs):
    """Both ports shut: the chamber holds p0 + D rate, the reading starts at p0 with
    rate ``rate`` and rings towards it as the damped oscillator's free response."""
    delay, z, p0, rate = 2e-3, 0.4, 2.0e5, 4.0e6
    w = 2 * z / delay
    n = 81
    t = np.arange(n) * 2.5e-4
    model = Model([make_effect("sensor_lag", form="second_order")])
    params = dict(closable_params, sensor_delay_s=delay, sensor_damping=z)
    got = simulate_windows(model, params, make_inputs(t, np.zeros(n)), rig, np.array([0]),
                           n, np.array([p0]), SolverConfig.standard(),
                           initial_rate_Pa_per_s=rate)[0, 0]
    p_c = p0 + delay * rate
    e0, de0 = p0 - p_c, rate
    wd = w * np.sqrt(1 - z * z)
    want = p_c + np.exp(-z * w * t) * (e0 * np.cos(wd * t)
                                       + (de0 + z * w * e0) / wd * np.sin(wd * t))
    assert np.max(np.abs(got - want)) < 1e-6 * p_c
    assert got.max() > p_c  # underdamped: it overshoots


def test_a_heavily_damped_second_order_lag_is_the_first_order_lag(rig):
    inputs = moving_step_inputs(7, 401, 1e-3, hold_s=(0.01, 0.05))
    first = simulate(Model(["sensor_lag"]), _params(1e-3), inputs, rig, 2e5,
                     TIGHT).pressure_Pa[0]
    model = Model([make_effect("sensor_lag", form="second_order")])
    params = dict(_params(), sensor_delay_s=1e-3, sensor_damping=5.0)
    second = simulate(model, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    plain = simulate(Model(), _params(), inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    # the fast pole (1 / (2 z w) = 0.01 ms) is all that differs
    assert np.max(np.abs(second - first)) < 0.03 * np.max(np.abs(first - plain))


def _exponential_step_cases():
    """Steps of every regime: h and tau over 1e-5..1e-2 s, hJ from -1e3 to ~0 and at
    -h / tau (the divided differences' close arguments), rates and curvatures large."""
    rng = np.random.default_rng(1)
    for trial in range(24):
        h, tau = 10 ** rng.uniform(-5, -2), 10 ** rng.uniform(-5, -2)
        z = -10 ** rng.uniform(-4, 3)
        if trial % 7 == 0:
            z = rng.uniform(-3e-4, 3e-4)
        if trial % 11 == 0:
            z = -h / tau * (1 + rng.uniform(-1e-3, 1e-3))
        yield (h, tau, z, rng.normal() * 1e7, rng.normal() * 1e9, rng.normal() * 10,
               3e5 + rng.normal() * 1e3, 2 * np.pi * 10 ** rng.uniform(1, 3.5),
               rng.choice([0.5, 0.7071, 1.0, 1.5]), rng.normal() * 1e5)


def _radau_end(rhs, y0, h, rtol=1e-12):
    """The state after ``h`` s of dy/ds = rhs(s, y), scipy's Radau at ``rtol``."""
    from scipy.integrate import solve_ivp

    return solve_ivp(rhs, (0, h), y0, method="Radau", rtol=rtol, atol=1e-9).y[:, -1]


def test_the_reading_over_an_exponential_step_is_its_ode_solution():
    """Over the pressure step's own solution p(s) = p_a + s phi_1(sJ) f + s^2 phi_2(sJ) v
    (+ the correction as a ramp), the closed forms of both lags and of the first-order
    lag's sensitivity against scipy's Radau on the reading's ODE (rtol 1e-12; for the
    second-order lag, asserted to 1e-5 of the step, rtol 1e-9: its solution moves by
    3e-7 of that from rtol 1e-12's, measured)."""
    from pneubayes.simulation.phi import phi123
    from pneubayes.simulation.reading import (
        first_order_exponential_sensitivity,
        first_order_exponential_step,
        first_order_step,
        second_order_curvature,
        second_order_step,
    )

    def pressure(s, pa, jac, f, v, e, h):
        q1, q2, _ = phi123(s * jac)
        return pa + s * q1 * f + s * s * q2 * v + e * s / h

    chord_worst = 0.0
    for h, tau, z, f, v, e, pa, w, zeta, rate in _exponential_step_cases():
        step = (pa, z / h, f, v, e, h)
        r0 = pa + 700.0
        scale = abs(pressure(h, *step) - pa) + 700.0
        want = _radau_end(lambda s, y, st=step, tau=tau: [(pressure(s, *st) - y[0]) / tau],
                          [r0], h)[0]
        got = first_order_exponential_step(r0, pa, h, tau, z, f, v, e)
        assert abs(got - want) <= 1e-8 * scale
        chord = first_order_step(r0, pa, pressure(h, *step), h, tau)
        chord_worst = max(chord_worst, abs(chord - want) / scale)
        want = _radau_end(lambda s, y, j=z / h, tau=tau: [(0.7 * np.exp(j * s) - y[0]) / tau],
                          [0.9], h)[0]
        assert abs(first_order_exponential_sensitivity(0.9, 0.7, h, tau, z) - want) <= 1e-8
        want = _radau_end(lambda s, y, st=step, w=w, zeta=zeta: [
            y[1], w * w * (pressure(s, *st) - y[0]) - 2 * zeta * w * y[1]], [r0, rate], h,
            rtol=1e-9)[0]
        r, _ = second_order_step(r0, rate, pa, pressure(h, *step), h, w, zeta)
        d_r, _ = second_order_curvature(z, f, v, h, w, zeta)
        assert abs(r + d_r - want) <= 1e-5 * scale
    assert chord_worst > 0.1  # the chord's reading errs by far more on these steps


def test_the_reading_over_a_cubic_step_is_its_ode_solution():
    """A first-order reading over the cubic Hermite path through a step's ends and
    their rates (the acoustic line's steps): the chord's closed form plus
    first_order_hermite_deviation against DOP853 on the reading's ODE, for lags from
    1e-3 to 1e3 step lengths (both branches: closed form and quadrature); a straight
    path deviates by nothing."""
    from scipy.integrate import solve_ivp

    from pneubayes.simulation.reading import first_order_hermite_deviation, first_order_step

    rng = np.random.default_rng(0)
    for _ in range(40):
        pa, pb, r0 = rng.uniform(1e5, 5e5, 3)
        da, db = rng.normal(0.0, 1e5, 2)
        h, tau = 10 ** rng.uniform(-5, -2), 10 ** rng.uniform(-5, -2)

        def path(t, pa=pa, pb=pb, da=da, db=db, h=h):
            s = t / h
            return (pa * (2 * s**3 - 3 * s**2 + 1) + da * (s**3 - 2 * s**2 + s)
                    + pb * (3 * s**2 - 2 * s**3) + db * (s**3 - s**2))

        want = solve_ivp(lambda t, r, tau=tau, path=path: (path(t) - r) / tau, (0.0, h),
                         [r0], method="DOP853", rtol=1e-12, atol=1e-6).y[0, -1]
        got = first_order_step(r0, pa, pb, h, tau) + first_order_hermite_deviation(
            pa, pb, da, db, h, tau)
        assert abs(got - want) <= 1e-7 * (abs(da) + abs(db) + abs(pb - pa))
        assert first_order_hermite_deviation(pa, pb, pb - pa, pb - pa, h, tau) == \
            pytest.approx(0.0, abs=1e-9 * abs(pb - pa))


@pytest.mark.parametrize("form,heat", [
    pytest.param("first_order", False, marks=pytest.mark.slow),  # (the heated forms step
    pytest.param("second_order", False, marks=pytest.mark.slow),  # the same lag and more)
    ("first_order", True), ("second_order", True)])
def test_a_fast_lag_on_a_tiny_chamber_agrees_with_the_reference_solver(rig, form, heat):
    """The bench's lags (a 0.53-ms RC stage; a 250-Hz Butterworth) on a 1e-7 m^3
    chamber, whose pressure settles within a fraction of a 1-ms step: read along the
    chord between the step's ends the reading erred 0.5-0.6 kPa at any tolerance
    (with heat transfer, the (p, T) step: 145 Pa on a like case). Four steps in 0.12 s;
    the reference at rtol 1e-8 (0.35 mPa from rtol 1e-10's here)."""
    inputs = moving_step_inputs(5, 121, 1e-3, hold_s=(0.01, 0.05))
    effect = make_effect("sensor_lag", form=form)
    model = Model([effect, make_effect("heat_transfer")] if heat else [effect])
    params = _params(None, 1e-7, "valve2")
    for e in model.effects:
        params.update(e.bench_defaults())
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    got = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 1e-4 * RANGE


@pytest.mark.slow
@pytest.mark.parametrize("form,heat", [("first_order", False), ("first_order", True),
                                       ("second_order", False)])
def test_a_lag_read_over_the_acoustic_lines_steps_agrees_with_the_reference(rig, form, heat):
    """The tube's acoustic line (form 'line') with the bench's lags (0.53-ms RC; 250-Hz
    Butterworth) on 2.4e-6 m^3 against DOP853 at rtol 1e-10 (Radau's finite-difference
    Jacobian of the line is slow). The chamber rings with the line within a step: read
    along the chord of a step's ends the reading erred 354 / 430 / 326 Pa (first order,
    with heat transfer, second order; 15 / 18.5 without a lag); over the cubic through
    the ends and their rates, its departure from the chord's in the error estimate,
    17.6 / 37.1 / 64.5 Pa."""
    n = 301
    t = np.arange(n) * 1e-3
    u = random_steps(np.random.default_rng(32), n, 1e-3, hold_s=(0.02, 0.08))
    inputs = Inputs(t, u, moving_position(t, freq=3.0), fluctuating_supply(t))
    effects = [make_effect("tube_delay", form="line"), make_effect("sensor_lag", form=form)]
    model = Model(effects + [make_effect("heat_transfer")] if heat else effects)
    params = _params(None, 2.4e-6)
    for e in model.effects:
        params.update(e.bench_defaults())
    ref = reference_simulate(model, params, inputs, rig, 2e5, method="DOP853", rtol=1e-10)
    got = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 2e-4 * RANGE


SLOW = pytest.mark.slow  # the reference solver: 1-5 s a case; one per form in the fast tier


@pytest.mark.parametrize("form,lag,volume", [
    pytest.param("first_order", {"sensor_time_constant_s": 2.3e-4}, 2.4e-6, marks=SLOW),
    pytest.param("first_order", {"sensor_time_constant_s": 3e-3}, 1e-7, marks=SLOW),
    ("first_order", {"sensor_time_constant_s": 1e-3}, 2e-5),
    pytest.param("second_order", {"sensor_delay_s": 9e-4, "sensor_damping": 0.7071}, 2.4e-6,
                 marks=SLOW),
    pytest.param("second_order", {"sensor_delay_s": 3e-3, "sensor_damping": 2.5}, 1e-7,
                 marks=SLOW),
    ("second_order", {"sensor_delay_s": 5e-4, "sensor_damping": 0.3}, 2e-5)])
def test_the_reading_agrees_with_the_reference_solvers_ode_state(rig, form, lag,
                                                                 volume):
    """The compiled integrator steps the reading exactly for a pressure linear on each
    step; the reference integrates dr/dt = (p - r) / tau (or the second-order lag's
    reading and rate) as more states (at rtol 1e-8: 0.2 mPa from rtol 1e-10's)."""
    inputs = moving_step_inputs(5, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("tube_delay"), make_effect("sensor_lag", form=form)])
    params = dict(_params(None, volume), tube_delay_s=0.0013, **lag)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8,
                             initial_rate_Pa_per_s=-3e5)
    got = simulate_windows(model, params, inputs, rig, np.array([0]), inputs.n_samples,
                           np.array([2e5]), SolverConfig.standard(),
                           initial_rate_Pa_per_s=-3e5)[0, 0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    # and the lag matters here: the unlagged chamber differs by far more
    plain = simulate(Model(["tube_delay"]), dict(_params(None, volume), tube_delay_s=0.0013),
                     inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(plain - ref)) > 10 * np.max(np.abs(got - ref))


@pytest.mark.parametrize("form,lag,samples", [
    ("first_order", {"sensor_time_constant_s": 2e-3}, 2),
    ("second_order", {"sensor_delay_s": 3e-3, "sensor_damping": 0.7071}, 3)])
def test_a_lag_on_every_channel_reads_position_and_supply_ahead_by_its_group_delay(
        rig, form, lag, samples):
    """``channels="all"``: the chamber sees the measured position and supply at t + D
    (D the group delay). With D a whole number of sample intervals that is the
    pressure-only lag on inputs shifted by as many samples (the last one held), which
    the integrator steps with the same break points: the two agree to its tolerance."""
    n = 601
    inputs = moving_step_inputs(12, n, 1e-3, hold_s=(0.01, 0.05))
    ahead = np.minimum(np.arange(n) + samples, n - 1)
    shifted = Inputs(inputs.time_s, inputs.command_V, inputs.position_m[ahead],
                     inputs.supply_pressure_Pa[ahead])
    params = dict(_params(None, 2e-7), **lag)
    every = Model([make_effect("sensor_lag", form=form, channels="all")])
    pressure = Model([make_effect("sensor_lag", form=form)])
    got = simulate(every, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    want = simulate(pressure, params, shifted, rig, 2e5, TIGHT).pressure_Pa[0]
    assert np.max(np.abs(got - want)) <= 1e-6 * RANGE
    # and the advance matters: the reading with unshifted inputs differs by far more
    late = simulate(pressure, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    assert np.max(np.abs(late - want)) > 1e-3 * RANGE


def test_a_lag_on_every_channel_agrees_with_the_reference_solver(rig):
    """A group delay that is not a whole sample (0.37 ms): the reference solver cuts its
    intervals at the shifted sample times and reads position and supply there."""
    inputs = moving_step_inputs(13, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("sensor_lag", channels="all")])
    params = _params(3.7e-4, 2e-7)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    got = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    pressure = simulate(Model(["sensor_lag"]), params, inputs, rig, 2e5,
                        SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(pressure - ref)) > 10 * np.max(np.abs(got - ref))


def test_a_late_reading_is_the_chamber_pressure_shifted_by_its_delay(rig):
    """``form="delay"`` with a whole number of samples (4 ms) on a moving piston with a
    fluctuating supply: windows that start at the plain model's pressure 4 samples
    before their first sample read exactly the plain model's pressure 4 samples late,
    the position and supply read early (their shift matters: with them on time the
    windows miss by far more); ``channels="all"`` (a late command alone) differs."""
    n, k = 601, 4
    inputs = moving_step_inputs(21, n, 1e-3, hold_s=(0.01, 0.05))
    params = _params(None, 2e-7)
    plain = simulate(Model(), params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    late = Model([make_effect("sensor_lag", form="delay")])
    lp = dict(params, sensor_transport_delay_s=k * 1e-3)
    starts, length = np.array([50, 200, 400]), 150
    got = simulate_windows(late, lp, inputs, rig, starts, length, plain[starts - k],
                           TIGHT)[0]
    want = plain[starts[:, None] - k + np.arange(length)]
    assert np.max(np.abs(got - want)) <= 1e-6 * RANGE
    on_time = Inputs(inputs.time_s, inputs.command_V,
                     inputs.position_m[np.maximum(np.arange(n) - k, 0)],
                     inputs.supply_pressure_Pa[np.maximum(np.arange(n) - k, 0)])
    assert np.max(np.abs(simulate_windows(late, lp, on_time, rig, starts, length,
                                          plain[starts - k], TIGHT)[0] - want)) \
        > 1e-3 * RANGE
    command = Model([make_effect("sensor_lag", form="delay", channels="all")])
    other = simulate_windows(command, lp, inputs, rig, starts, length, plain[starts - k],
                             TIGHT)[0]
    assert np.max(np.abs(other - want)) > 1e-3 * RANGE


def test_a_late_reading_agrees_with_the_reference_solver_and_is_a_candidate(rig):
    """A delay that is not a whole sample (2.7 ms): the compiled simulator against the
    reference solver; the form is among a named lag's candidates, started at the best
    term's lag; beside an exhaust valve with its own command it is refused."""
    from pneubayes.effects.discovery import CandidateContext

    inputs = moving_step_inputs(23, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("sensor_lag", form="delay")])
    params = dict(_params(None, 2e-7), sensor_transport_delay_s=2.7e-3)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    got = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    ctx = CandidateContext(model=Model(), params={}, rig=rig,
                           term_start={"sensor_time_constant_s": 8e-4},
                           second_state_free=True, line_segments=8, dead_volume_m3=1e-4)
    forms = make_effect("sensor_lag").candidate_forms(ctx)
    (delay,) = [(f, st) for f, st in forms if f.form == "delay"]
    assert delay[1] == {"sensor_transport_delay_s": 8e-4}
    own = Model([make_effect("sensor_lag", form="delay"), make_effect("valve_deadzone")])
    assert own.parameter_names  # (a model that lowers; the refusal needs an own exhaust)
    from pneubayes.effects.path import SLOT_INDEX, SLOTS
    from pneubayes.simulation.simulator import _FORM_COLUMNS, _check_exclusive_forms
    slots = np.zeros((1, len(SLOTS)))
    slots[0, SLOT_INDEX["inputs_advance_s"]] = -2e-3
    slots[0, SLOT_INDEX["exhaust_own_command"]] = 1.0
    forms_on = np.zeros((1, len(_FORM_COLUMNS)), dtype=bool)
    forms_on[0, _FORM_COLUMNS["exhaust_own_command"]] = True
    with pytest.raises(ValueError, match="late reading"):
        _check_exclusive_forms(forms_on, slots)


def test_a_sensor_lag_names_its_channels_or_refuses():
    assert make_effect("sensor_lag").options() == {"form": "first_order"}
    every = make_effect("sensor_lag", form="second_order", channels="all")
    assert every.options() == {"form": "second_order", "channels": "all"}
    assert every != make_effect("sensor_lag", form="second_order")
    with pytest.raises(ValueError, match="channels must be one of"):
        make_effect("sensor_lag", channels="both").parameters()


def test_halving_the_sample_interval_gives_the_same_reading(rig):
    n = 401
    coarse = moving_step_inputs(9, n, 1e-3, hold_s=(0.01, 0.05))
    t2 = np.arange(2 * n - 1) * 5e-4
    fine = Inputs(t2, np.repeat(coarse.command_V, 2)[:-1],
                  np.interp(t2, coarse.time_s, coarse.position_m),
                  np.interp(t2, coarse.time_s, coarse.supply_pressure_Pa))
    model = Model(["sensor_lag"])
    params = _params(4e-4)
    a = simulate(model, params, coarse, rig, 2e5, TIGHT).pressure_Pa[0]
    b = simulate(model, params, fine, rig, 2e5, TIGHT).pressure_Pa[0, ::2]
    assert np.max(np.abs(a - b)) < 1e-5 * RANGE


@pytest.mark.parametrize("form,lag,tol", [
    ("first_order", {"sensor_time_constant_s": 1e-3}, 0.03),
    # the frozen step's sensitivity plus the time constant's own dependence on p and r
    # (measured: 0.004 off the central difference)
    ("pressure_dependent", {"sensor_time_constant_s": 3e-3, "sensor_pressure_exponent": 1.0},
     0.01)])
def test_start_sensitivity_of_the_reading_matches_finite_differences(rig, form, lag, tol):
    model = Model([make_effect("sensor_lag", form=form)])
    params = dict(_params(None), **lag)
    inputs = moving_step_inputs(4, 601, 1e-3, levels=(-1.0, 1.0))
    starts, p0 = np.array([0, 200, 300]), np.array([2.0e5, 3.0e5, 4.0e5])
    rate = np.array([0.0, 1e6, -5e5])
    out, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 300, p0,
                                             TIGHT, initial_rate_Pa_per_s=rate)
    d = 20.0
    up, dn = (simulate_windows(model, params, inputs, rig, starts, 300, p0 + s * d, TIGHT,
                               initial_rate_Pa_per_s=rate) for s in (1, -1))
    assert np.all(sens[..., 0] == 1.0)
    assert np.max(np.abs(sens - (up - dn) / (2 * d))) < tol


def test_one_step_predictions_of_a_lagged_reading_carry_the_lag(rig, tmp_path):
    """On noise-free readings lagged by tau, the one-step predictions of the model with
    the lag (the chamber started ahead of the reading by tau times the lagged chamber
    rate) miss by far less than those of the model without it: 0.10 of it, measured
    (the reading's backward difference instead of the model's rate left 0.30)."""
    tau = 5e-4
    inputs = moving_step_inputs(12, 1501, 1e-3, hold_s=(0.02, 0.08))
    model = Model(["sensor_lag"])
    params = _params(tau)
    md = RecordingMetadata("test", "valve1", rig.bore_m, rig.stroke_m, P_ATM, P_SUP, 293.15)
    probe = Recording(md, inputs.time_s, inputs.command_V, np.full(inputs.n_samples, 2e5),
                      supply_pressure_Pa=inputs.supply_pressure_Pa,
                      position_m=inputs.position_m)
    reading = simulate(model, params, inputs, probe.rig(), 2e5,
                       SolverConfig.reference()).pressure_Pa[0]
    rec = Recording(md, inputs.time_s, inputs.command_V, reading,
                    supply_pressure_Pa=inputs.supply_pressure_Pa, position_m=inputs.position_m)
    d = one_step_data(rec, block=10)
    with_lag = d.errors(model, params, SolverConfig.standard())[0]
    without = d.errors(model, dict(params, sensor_time_constant_s=0.0),
                       SolverConfig.standard())[0]
    rms = lambda e: float(np.sqrt(np.mean(e[5:] ** 2)))  # noqa: E731
    assert rms(with_lag) < 0.15 * rms(without)


def test_windows_warm_up_the_chambers_lead_from_the_command_history(rig):
    """Windows started mid-recording from the reading of one long simulation: warmed up
    over the command history (no rate given), they follow it far more closely than
    windows whose chamber starts at the reading; from the recorded reading before the
    start (the inputs' ``reading_Pa``), closer still (RMS 0.20 and 0.041 of it,
    measured: from the window's own start pressure the warm-up misses where the
    pressure moved over those 5 time constants; from the recorded reading, only the
    chamber's own lead there)."""
    model = Model(["sensor_lag"])
    params = _params(1e-3, volume=1e-6)
    inputs = moving_step_inputs(21, 1201, 1e-3, hold_s=(0.005, 0.03))
    whole = simulate(model, params, inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    recorded = Inputs(inputs.time_s, inputs.command_V, inputs.position_m,
                      inputs.supply_pressure_Pa, reading_Pa=whole)
    starts, length = np.arange(50, 1100, 7), 60
    kw = dict(starts=starts, length=length, initial_pressure_Pa=whole[starts], solver=TIGHT)
    warm = simulate_windows(model, params, inputs, rig, **kw)[0]
    best = simulate_windows(model, params, recorded, rig, **kw)[0]
    cold = simulate_windows(model, params, inputs, rig, initial_rate_Pa_per_s=0.0, **kw)[0]
    truth = whole[starts[:, None] + np.arange(length)]
    rms = {k: float(np.sqrt(np.mean((v - truth) ** 2)))
           for k, v in (("warm", warm), ("best", best), ("cold", cold))}
    assert rms["cold"] > 1e-3 * RANGE
    assert rms["warm"] < 0.3 * rms["cold"]
    assert rms["best"] < 0.06 * rms["cold"]


@pytest.mark.parametrize("form,lag", [("first_order", {"sensor_time_constant_s": 5e-4}),
                                      ("second_order", {"sensor_delay_s": 5e-4,
                                                        "sensor_damping": 0.7})])
def test_a_lagged_reading_gets_no_declared_filter_corner_term(rig, form, lag):
    """The declared zero-phase filter's corner term is for a chamber read directly; a
    lagged reading rounds its corners itself, so the declared filter leaves it as is."""
    from dataclasses import replace

    from pneubayes.physics.sensor_filter import PressureFilter

    inputs = moving_step_inputs(3, 301, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("sensor_lag", form=form)])
    params = dict(_params(), **lag)
    bare = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa
    declared = replace(rig, pressure_filter=PressureFilter(2, 1000.0))
    read = simulate(model, params, inputs, declared, 2e5, SolverConfig.standard()).pressure_Pa
    assert np.array_equal(bare, read)
    unlagged = simulate(Model(), _params(), inputs, declared, 2e5,
                        SolverConfig.standard()).pressure_Pa
    assert not np.array_equal(unlagged, simulate(Model(), _params(), inputs, rig, 2e5,
                                                 SolverConfig.standard()).pressure_Pa)



@pytest.mark.parametrize("volume,lag,exponent,tol", [
    (2.4e-6, 2e-3, 1.0, 1e-4), (2e-5, 1e-3, 2.0, 1e-4), (2.4e-6, 2e-3, -0.5, 1e-4),
    pytest.param(1e-7, 3e-3, 1.0, 3e-4, marks=SLOW)])
def test_a_pressure_dependent_lag_agrees_with_the_reference_solvers_ode_state(
        rig, volume, lag, exponent, tol):
    """dr/dt = (p - r) / tau, tau = tau_a (2 P_atm / (p + r))^n: the compiled integrator
    steps it over substeps of the chamber's exponential path at the harmonic mean of
    their ends' time constants; the reference integrates it as a state (rtol 1e-8).
    Measured (the standard preset, 0.15 s): 1.0e-5 / 7e-6 of the range on 2.4e-6 m^3
    (n = 1 / -0.5), 2e-8 on 2e-5, 7e-5 on 1e-7 (a chamber that settles within a
    fraction of a sample); the first-order lag at tau_a misses by 2600-370000 x more."""
    inputs = moving_step_inputs(5, 151, 1e-3, hold_s=(0.01, 0.05))
    model = Model([make_effect("tube_delay"),
                   make_effect("sensor_lag", form="pressure_dependent")])
    params = dict(_params(None, volume), tube_delay_s=0.0013, sensor_time_constant_s=lag,
                  sensor_pressure_exponent=exponent)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8,
                             initial_rate_Pa_per_s=-3e5)

    def window(values):
        return simulate_windows(model, values, inputs, rig, np.array([0]), inputs.n_samples,
                                np.array([2e5]), SolverConfig.standard(),
                                initial_rate_Pa_per_s=-3e5)[0, 0]
    got = window(params)
    assert np.max(np.abs(got - ref)) <= tol * RANGE
    flat = window(dict(params, sensor_pressure_exponent=0.0))
    assert np.max(np.abs(flat - ref)) > 20 * np.max(np.abs(got - ref))


def test_a_pressure_dependent_lag_without_its_exponent_is_the_first_order_lag(rig):
    inputs = moving_step_inputs(5, 301, 1e-3, hold_s=(0.01, 0.05))
    params = dict(_params(2e-3), sensor_pressure_exponent=0.0)
    dependent = Model([make_effect("sensor_lag", form="pressure_dependent")])
    a = simulate(dependent, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa
    b = simulate(Model(["sensor_lag"]), _params(2e-3), inputs, rig, 2e5,
                 SolverConfig.standard()).pressure_Pa
    assert np.array_equal(a, b)


def test_a_pressure_dependent_lag_reads_as_the_benchs_capillary(rig):
    """The bench's capillary sensor port (an independent implementation: the Riccati
    equation dr/dt = c (p^2 - r^2) in closed form per interval of a fine grid, applied
    to the plain chamber's pressure) is the form at n = 1 with tau_a = tau_ref p_ref /
    P_atm. On a 0.02-ms grid they agree to 1.2e-6 of the range; the first-order lag at
    tau_ref is 7.6 % of the range off."""
    from pneubayes.bench.forms import CapillarySensorPort

    dt = 2e-5
    coarse = moving_step_inputs(5, 301, 1e-3, hold_s=(0.02, 0.06))
    t = np.arange(15001) * dt
    inputs = Inputs(t, np.interp(np.floor(t / 1e-3) * 1e-3, coarse.time_s, coarse.command_V),
                    np.interp(t, coarse.time_s, coarse.position_m),
                    np.interp(t, coarse.time_s, coarse.supply_pressure_Pa))
    cap = CapillarySensorPort(time_constant_s=1e-3, reference_pressure_Pa=P_SUP)
    plain = simulate(Model(), _params(None), inputs, rig, 2e5, TIGHT).pressure_Pa[0]
    bench = cap.read(t, plain)
    params = dict(_params(None), sensor_time_constant_s=1e-3 * P_SUP / P_ATM,
                  sensor_pressure_exponent=1.0)
    ours = simulate(Model([make_effect("sensor_lag", form="pressure_dependent")]), params,
                    inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(ours - bench)) <= 1e-5 * RANGE
    first = simulate(Model(["sensor_lag"]), _params(1e-3), inputs, rig, 2e5,
                     SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(first - bench)) > 0.03 * RANGE


@pytest.mark.slow
def test_discovery_names_a_late_reading_on_a_moving_piston():
    """Four 8-s valve1 recordings on a moving piston whose pressure is logged 8 ms late
    against the command and the position: the loop names the sensor lag in its delay
    form (a command delay, the catalogue tube, closes far less: its position stays on
    time), with the delay, and the held-out error falls to about the noise floor."""
    from conftest import BORE, P_ATM, P_SUP, STROKE, discovery_settings

    from pneubayes.discovery.loop import Discovery

    truth_model = Model([make_effect("sensor_lag", form="delay")])
    truth = dict(_params(None, 2.4e-6), sensor_transport_delay_s=0.008)
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15)
    recs, n = [], 8001
    for seed in range(4):
        rng = np.random.default_rng(10 + seed)
        t = np.arange(n) * 1e-3
        u = random_steps(rng, n, 1e-3, hold_s=(0.1, 0.6))
        x = moving_position(t, freq=1.5 + 0.5 * seed)
        blank = Recording(md, t, u, np.full(n, P_ATM), position_m=x)
        p = simulate(truth_model, truth, Inputs.from_recording(blank), blank.rig(), P_ATM,
                     SolverConfig.standard()).pressure_Pa[0]
        recs.append(Recording(md, t, u, p + rng.normal(0.0, 200.0, n), position_m=x,
                              source=f"late_{seed}.csv"))
    settings = discovery_settings(posterior={"method": "none"},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 3})
    doc = Discovery(settings, None, log=None).fit(recs).result_.to_dict()
    (effect,) = doc["effects"]
    assert effect["name"] == "sensor_lag" and effect["options"] == {"form": "delay"}
    fitted = effect["parameters"]["sensor_transport_delay_s"]
    assert fitted.get("estimate", fitted.get("median")) == pytest.approx(0.008, rel=0.02)
    assert doc["rmse_final_Pa"] < 1.2 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"] / 20
