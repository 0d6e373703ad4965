"""The effect catalogue: the common contract, and each effect's physics against closed forms."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pneubayes.discovery.settings import FormSettings
from pneubayes.effects import CATALOGUE, Effect, make_effect
from pneubayes.effects.path import SLOT_INDEX
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
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM

VARIANTS = [("cylinder_leak", {"form": "orifice"}), ("cylinder_leak", {"form": "laminar"}),
            ("cylinder_leak", {"form": "graded"}),
            ("tube_delay", {}), ("tube_delay", {"form": "line", "segments": 3}),
            ("tube_delay", {"form": "wave"}),
            ("valve_deadzone", {}), ("valve_deadzone", {"form": "rounded"}),
            ("supply_fluctuation", {}),
            ("heat_transfer", {"form": "rate"}), ("heat_transfer", {"form": "convective"}),
            ("spool_lag", {}), ("spool_lag", {"form": "second_order"}), ("sensor_lag", {}),
            ("sensor_lag", {"form": "second_order"}),
            ("sensor_lag", {"form": "second_order", "channels": "all"}),
            ("sensor_lag", {"form": "pressure_dependent"}),
            ("closure", {}), ("closure", {"terms": "inlet_flow*pressure_hinge; "
                                                   "spool_hinge_down; one"}),
            ("reading_closure", {}), ("reading_closure", {"terms": 2}),
            ("volume_closure", {}), ("volume_closure", {"terms": 2}),
            ("volume_play", {}), ("volume_play", {"terms": 2}), ("loaded_wall", {}),
            ("command_clock", {}), ("command_clock", {"form": "pwm"})]
IDS = ["leak_orifice", "leak_laminar", "leak_graded", "tube_delay", "tube_line", "tube_wave",
       "valve_deadzone",
       "valve_deadzone_rounded", "supply_fluctuation", "heat_rate", "heat_convective",
       "spool_lag", "spool_lag_2", "sensor_lag", "sensor_lag_2", "sensor_lag_2_all",
       "sensor_lag_pressure", "closure", "closure_hinges", "reading_closure",
       "reading_closure_2", "volume_closure", "volume_closure_2", "volume_play",
       "volume_play_2", "loaded_wall", "command_clock", "command_clock_pwm"]


def _tight():
    return SolverConfig(rtol=1e-8, atol_Pa=1e-3, atol_K=1e-6, max_step_s=0.02,
                        min_step_s=1e-14, max_steps_per_s=2.5e7)


@pytest.fixture(params=VARIANTS, ids=IDS)
def effect(request) -> Effect:
    name, opts = request.param
    return make_effect(name, **opts)


@pytest.fixture
def valve_params():
    """The thin-port base parameters: Table II valve 1 and a 2.4e-6 m^3 dead volume."""
    v = valve_preset("valve1").parameters()
    v["dead_volume_m3"] = 2.4e-6
    return v


@pytest.fixture
def rich_inputs(hand):
    """Random steps, a moving piston and a fluctuating supply column: 0.8 s at 1 kHz."""
    n = 801
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(31), n, 1e-3, hold_s=(0.02, 0.1))
    return Inputs(t, u, hand.moving_position(t, freq=3.0), hand.fluctuating_supply(t))


def _sim(model, params, inputs, rig, p0=2e5, solver=None):
    return simulate(model, params, inputs, rig, p0,
                    solver or SolverConfig.standard()).pressure_Pa[0]


# ---------------------------------------------------------------- the contract
def test_catalogue_names():
    assert list(CATALOGUE) == ["cylinder_leak", "tube_delay", "valve_deadzone",
                               "supply_fluctuation", "heat_transfer", "spool_lag", "sensor_lag",
                               "sensor_calibration", "sensor_drift", "sensor_nonlinearity",
                               "valve_stiction", "closure", "reading_closure",
                               "reading_play", "reading_command", "reading_flow",
                               "reading_hinge", "volume_closure",
                               "volume_play", "loaded_wall", "port_restriction", "command_clock",
                               "valve_dead_time", "supply_restriction", "critical_ratio"]
    for name, cls in CATALOGUE.items():
        assert cls.name == name
    with pytest.raises(ValueError):
        make_effect("friction")
    with pytest.raises(ValueError):
        make_effect("cylinder_leak", colour="red")


def test_parameters_have_units_bounds_and_neutral_values(effect):
    params = effect.parameters()
    assert params
    for p in params:
        assert isinstance(p.unit, str) and p.unit.strip()
        assert p.description.strip()
        assert math.isfinite(p.lower) and math.isfinite(p.upper) and p.lower < p.upper
        assert p.neutral is not None and p.lower <= p.neutral <= p.upper
    neutral = effect.neutral_values()
    assert set(neutral) == set(effect.parameter_names())
    bench = effect.bench_defaults()
    assert set(bench) == set(effect.parameter_names())
    for p in params:
        assert p.lower <= bench[p.name] <= p.upper
        assert bench[p.name] != neutral[p.name]
        rng = np.random.default_rng(0)
        draws = p.sample_prior(rng, 200)
        assert np.all((draws >= p.lower) & (draws <= p.upper))
        assert np.all(np.isfinite(p.log_prior(draws)))
        assert p.log_prior(p.upper + abs(p.upper) + 1.0) == -np.inf


def test_lower_writes_only_declared_slots(effect, rig, valve_params):
    rng = np.random.default_rng(1)
    values = {p.name: p.sample_prior(rng, 4) for p in effect.parameters()}
    contrib = effect.lower(values, rig)
    assert set(contrib) <= set(effect.acts_on)
    assert set(effect.acts_on) <= set(SLOT_INDEX)
    for v in contrib.values():
        assert np.shape(np.broadcast_to(v, (4,))) == (4,)
        assert np.all(np.isfinite(v))
    # and through the model: only the declared slot columns move relative to the base
    model = Model([effect])
    base = Model([])
    theta = np.array([dict(valve_params, **{k: v[i] for k, v in values.items()})[n]
                      for i in range(4) for n in model.parameter_names]).reshape(4, -1)
    with_effect = model.lower(theta, rig)
    without = base.lower(theta[:, :base.n_parameters], rig)
    changed = {name for name, j in SLOT_INDEX.items()
               if not np.array_equal(with_effect[:, j], without[:, j])}
    assert changed <= set(effect.acts_on)
    # random draws in the bounds do something (a reading closure acts after the kernel,
    # on no slot: what it does, test_bench_defaults_have_an_effect)
    assert changed or not effect.acts_on


def test_neutral_values_reproduce_the_base_model_exactly(effect, rig, valve_params,
                                                         rich_inputs):
    base = Model([])
    model = Model([effect])
    params = dict(valve_params, **effect.neutral_values())
    a = _sim(base, valve_params, rich_inputs, rig)
    b = _sim(model, params, rich_inputs, rig)
    assert np.array_equal(a, b)
    # also next to another effect (the leak), which is how ablations are compared
    if effect.name != "cylinder_leak":
        leak = Model(["cylinder_leak"])
        lp = dict(valve_params, leak_area_m2=3.04e-8)
        a = _sim(leak, lp, rich_inputs, rig)
        b = _sim(leak.with_effect(effect), dict(lp, **effect.neutral_values()), rich_inputs, rig)
        assert np.array_equal(a, b)


def test_bench_defaults_have_an_effect(effect, rig, valve_params, rich_inputs):
    base = _sim(Model([]), valve_params, rich_inputs, rig)
    got = _sim(Model([effect]), dict(valve_params, **effect.bench_defaults()), rich_inputs, rig)
    assert np.all(np.isfinite(got))
    assert np.max(np.abs(got - base)) > 1e-3 * RANGE


@pytest.mark.slow
def test_bench_defaults_agree_with_the_reference_solver(effect, rig, valve_params, hand):
    """Each effect as the compiled integrator runs it vs scipy Radau at rtol 1e-10 (an
    acoustic line vs DOP853 at 1e-10: Radau's finite-difference Jacobian of the line
    took 65-80 s on a like case, DOP853 7 s, and the two agreed within 1e-3 Pa)."""
    n = 301
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(32), n, 1e-3, hold_s=(0.02, 0.08))
    inputs = Inputs(t, u, hand.moving_position(t, freq=3.0), hand.fluctuating_supply(t))
    model = Model([effect])
    params = dict(valve_params, **effect.bench_defaults())
    if getattr(effect, "form", None) == "wave":  # a delay system: no ODE reference
        with pytest.raises(ValueError, match="plant's finely lumped acoustic tube"):
            reference_simulate(model, params, inputs, rig, 2e5)
        return  # its independent reference: tests/test_wave.py
    if effect.name == "volume_play":  # a play: no ODE reference
        with pytest.raises(ValueError, match="plant's friction-held wall"):
            reference_simulate(model, params, inputs, rig, 2e5)
        return  # its independent reference: tests/test_volume_play.py
    if effect.name == "loaded_wall":  # two more states: no ODE reference
        with pytest.raises(ValueError, match="plant's loaded wall"):
            reference_simulate(model, params, inputs, rig, 2e5)
        return  # its independent reference: tests/test_loaded_wall.py
    if effect.name == "command_clock":  # switches between samples: no ODE reference
        with pytest.raises(ValueError, match="plant's driver"):
            reference_simulate(model, params, inputs, rig, 2e5)
        return  # its independent reference: tests/test_command_clock.py
    method = "DOP853" if getattr(effect, "form", None) == "line" else "Radau"
    ref = reference_simulate(model, params, inputs, rig, 2e5, method=method, rtol=1e-10)
    got = _sim(model, params, inputs, rig)
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE


@pytest.mark.slow
def test_all_effects_together_agree_with_the_reference_solver(rig, valve_params, hand):
    """Delay break points, spool lag, dead band, heat state, leak and supply all at once
    (all but the volume's closure and play, whose compliant chamber the simulator steps
    with the pressure as its only state: not beside the heat state; the loaded wall, which
    the reference does not step, nor the simulator beside a compliant chamber; the driver's clock,
    which the reference does not step; the port flows' terms in the reading, which it
    solves only on the chamber's own reading: tests/test_reading_flow.py; and the supply's
    restriction and the ports' critical ratio, not beside the port's restriction:
    tests/test_supply_restriction.py, tests/test_critical_ratio.py)."""
    model = Model([n for n in CATALOGUE
                   if n not in ("volume_closure", "volume_play", "loaded_wall",
                                "command_clock", "reading_flow", "supply_restriction",
                                "critical_ratio")])
    params = dict(valve_params, dead_volume_m3=1e-6)
    for e in model.effects:
        params.update(e.bench_defaults())
    params["tube_delay_s"] = 0.0123  # not a multiple of the sample interval
    n = 301
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(2), n, 1e-3, hold_s=(0.01, 0.05))
    inputs = Inputs(t, u, hand.moving_position(t, freq=3.0), hand.fluctuating_supply(t))
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-10)
    got = _sim(model, params, inputs, rig)
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE


def test_model_card_round_trip(effect, valve_params, tmp_path):
    model = Model([effect])
    values = dict(valve_params, **effect.bench_defaults())
    card = model.to_card(values)
    again, vals = Model.from_card(json.loads(json.dumps(card)))
    assert again == model
    assert again.effect(effect.name).options() == effect.options()
    assert vals == model.as_dict(model.vector(values))
    path = tmp_path / "cards" / "MODEL.json"
    model.save_card(values, path, extra={"note": "test"})
    loaded, lvals = Model.load_card(path)
    assert loaded == model and lvals == vals
    assert json.loads(path.read_text())["note"] == "test"
    assert not [p for p in path.parent.iterdir() if p.name != "MODEL.json"]  # no temp files


# ---------------------------------------------------------------- tube delay
def _first_rise(t, p, t_step, rise=1000.0):
    """First time after t_step at which p exceeds p(t_step) + rise (linear interpolation)."""
    i0 = np.searchsorted(t, t_step)
    level = p[i0] + rise
    idx = np.nonzero(p[i0:] > level)[0]
    assert idx.size, "pressure never rose"
    i = i0 + idx[0]
    return t[i - 1] + (level - p[i - 1]) / (p[i] - p[i - 1]) * (t[i] - t[i - 1])


def test_tube_delay_shifts_the_step_response(rig, valve_params, make_inputs):
    valve_params["dead_volume_m3"] = 1e-6
    dt = 5e-5
    t = np.arange(int(0.08 / dt) + 1) * dt
    t_step = 0.03
    u = np.where(t < t_step - dt / 2, -5.0, 5.0)
    inputs = make_inputs(t, u)
    base = _sim(Model([]), valve_params, inputs, rig, P_ATM)
    delayed = _sim(Model(["tube_delay"]), dict(valve_params, tube_delay_s=0.01), inputs, rig,
                   P_ATM)
    shift = _first_rise(t, delayed, t_step) - _first_rise(t, base, t_step)
    assert abs(shift - 0.01) < 1.5e-3, f"shift {shift * 1e3:.3f} ms"
    # nothing happens inside the delay
    inside = (t >= t_step) & (t < t_step + 0.0095)
    assert np.ptp(delayed[inside]) < 1000.0


def test_tube_delay_lowering_by_hand(rig):
    eff = make_effect("tube_delay")
    delays = np.array([0.0, 0.003, 0.01])
    out = eff.lower({"tube_delay_s": delays}, rig)
    k, rs, temp = 1.4, 8.31 / 0.029, 293.15
    c = math.sqrt(k * rs * temp)
    length = c * delays
    d, mu = 0.002, 1.81e-5
    np.testing.assert_allclose(out["command_delay_s"], delays, rtol=1e-15)
    # phi = exp(-R_t Rs T L / (2 p c)), R_t = 32 mu / D^2
    np.testing.assert_allclose(out["flow_attenuation_Pa"],
                               32 * mu / d ** 2 * rs * temp * length / (2 * c), rtol=1e-13)
    # the tube's volume is part of the dead volume (recording format), not added here
    assert "volume_m3" not in out
    vol = eff.tube_volume_m3({"tube_delay_s": delays}, rig)
    np.testing.assert_allclose(vol, math.pi / 4 * d * d * length, rtol=1e-13)
    assert vol[2] == pytest.approx(1.08e-5, rel=0.01)  # a 3.4 m tube of 2 mm


# ---------------------------------------------------------------- spool lag
def test_spool_lag_delays_and_slows_the_response(rig, valve_params, make_inputs):
    dt = 1e-4
    t = np.arange(int(0.1 / dt) + 1) * dt
    t_step = 0.02
    u = np.where(t < t_step - dt / 2, -5.0, 5.0)
    inputs = make_inputs(t, u)
    base = _sim(Model([]), valve_params, inputs, rig, P_ATM)
    tau = 0.01
    lag = _sim(Model(["spool_lag"]), dict(valve_params, spool_time_constant_s=tau), inputs,
               rig, P_ATM)
    shift = _first_rise(t, lag, t_step) - _first_rise(t, base, t_step)
    # the spool reaches the inlet's opening (~ -0.3 V .. +1 V) after tau ln(10/5..10/4)
    assert 0.4 * tau < shift < 1.5 * tau, shift
    # slower everywhere after the step (the lagged spool is never further open)
    after = t > t_step
    assert np.all(lag[after] <= base[after] + 1.0)


@pytest.mark.slow
def test_spool_lag_closed_form_spool_matches_reference_ode(rig, valve_params, hand):
    """The kernel integrates the spool in closed form, the reference as an ODE state."""
    model = Model(["spool_lag"])
    params = dict(valve_params, spool_time_constant_s=0.008)
    n = 301
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(33), n, 1e-3, hold_s=(0.01, 0.05))
    inputs = Inputs(t, u, np.zeros(n), np.full(n, P_SUP))
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-10)
    got = _sim(model, params, inputs, rig, 2e5, _tight())
    assert np.max(np.abs(got - ref)) < 20.0


# ---------------------------------------------------------------- dead zone
def test_valve_deadzone_maps_commands_inside_the_band_to_zero(rig, valve_params, make_inputs):
    t = np.arange(501) * 1e-3
    model = Model(["valve_deadzone"])
    params = dict(valve_params, deadzone_halfwidth_V=0.5)
    run = {c: _sim(model, params, make_inputs(t, np.full(t.size, c)), rig, 3e5)
           for c in (0.0, 0.3, -0.45, 0.8, -0.8)}
    assert np.array_equal(run[0.3], run[0.0])
    assert np.array_equal(run[-0.45], run[0.0])
    # outside the band the command is shifted by the half-width: 0.8 V acts as 0.3 V
    # (up to the rounding of 0.8 - 0.5)
    base = Model([])
    for c in (0.8, -0.8):
        shifted = _sim(base, valve_params, make_inputs(t, np.full(t.size, math.copysign(0.3, c))),
                       rig, 3e5)
        np.testing.assert_allclose(run[c], shifted, rtol=1e-9)
    assert not np.array_equal(run[0.8], run[0.0])


def test_rounded_dead_band_is_c2_zero_inside_and_hard_outside_its_corners():
    """phi(|s| - w): 0 for |s| <= w - r, |s| - w beyond w + r, odd in s; value, slope and
    curvature continuous at both corners (finite differences), slope in [0, 1]; r = 0
    is the hard band, bit for bit."""
    from pneubayes.simulation.rates import dead_band

    w, r = 0.4, 0.15
    s = np.linspace(-1.2, 1.2, 24001)
    hard = dead_band(s, w, 0.0)
    assert np.array_equal(hard, np.sign(s) * np.maximum(np.abs(s) - w, 0.0))
    got = dead_band(s, w, r)
    far = np.abs(np.abs(s) - w) >= r
    assert np.array_equal(got[far], hard[far])
    assert np.all(got[np.abs(s) <= w - r] == 0.0)
    assert np.array_equal(dead_band(-s, w, r), -got)
    h = 1e-6
    for corner in (w - r, w + r):
        x = np.array([corner - 2 * h, corner - h, corner, corner + h, corner + 2 * h])
        y = dead_band(x, w, r)
        slope_l, slope_r = (y[2] - y[1]) / h, (y[3] - y[2]) / h
        assert abs(slope_l - slope_r) < 1e-4
        curv_l, curv_r = (y[2] - 2 * y[1] + y[0]) / h**2, (y[4] - 2 * y[3] + y[2]) / h**2
        assert abs(curv_l - curv_r) < 1e-2 * (1 / r)
    slope = np.diff(got) / np.diff(s)
    assert slope.min() >= -1e-9 and slope.max() <= 1 + 1e-9
    # convex: across the corner it opens before the hard band and stays ahead of it
    corner = np.abs(np.abs(s) - w) < r
    assert np.all(np.abs(got[corner]) >= np.abs(hard[corner]))
    assert dead_band(w, w, r) > 0.0 and dead_band(w + 0.5 * r, w, r) > 0.5 * r


def test_rounded_deadzone_at_zero_rounding_is_the_hard_band(rig, valve_params):
    t = np.arange(401) * 1e-3
    u = np.repeat(np.random.default_rng(4).uniform(-0.7, 0.7, 9), 45)[:t.size]
    inputs = Inputs.constant(t, u, 0.01, P_SUP)
    hard = _sim(Model(["valve_deadzone"]), dict(valve_params, deadzone_halfwidth_V=0.4),
                inputs, rig, 3e5)
    rounded = Model([make_effect("valve_deadzone", form="rounded")])
    zero = _sim(rounded, dict(valve_params, deadzone_halfwidth_V=0.4,
                              deadzone_rounding_fraction=0.0), inputs, rig, 3e5)
    assert np.array_equal(hard, zero)
    half = _sim(rounded, dict(valve_params, deadzone_halfwidth_V=0.4,
                              deadzone_rounding_fraction=0.5), inputs, rig, 3e5)
    assert np.max(np.abs(half - hard)) > 1e3  # commands near the band feel the corners
    assert make_effect("valve_deadzone").options() == {}  # cards before the form alike
    assert make_effect("valve_deadzone", form="rounded").options() == {"form": "rounded"}
    with pytest.raises(ValueError, match="form must be one of"):
        make_effect("valve_deadzone", form="soft").parameters()


def test_the_plant_refuses_the_catalogues_rounded_dead_zone(rig, valve_params):
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    effect = make_effect("valve_deadzone", form="rounded")
    t = np.arange(11) * 1e-3
    with pytest.raises(ValueError, match="RoundedDeadzone"):
        simulate_plant(dict(valve_params, **effect.bench_defaults()), (),
                       Inputs.constant(t, np.ones(t.size), 0.01, P_SUP), rig, P_ATM,
                       PlantConfig.reference(), effects=(effect,))


# ---------------------------------------------------------------- cylinder leak
def test_laminar_leak_depletes_a_closed_chamber(rig, closable_params, make_inputs, hand):
    k_l, vol, p0 = 1.9e-16, closable_params["dead_volume_m3"], 5.0e5
    model = Model([make_effect("cylinder_leak", form="laminar")])
    params = dict(closable_params, leak_conductance_kg_per_s_Pa2=k_l)
    t = np.arange(2001) * 1e-3
    got = _sim(model, params, make_inputs(t, np.zeros(t.size)), rig, p0)
    g = hand.gas()
    c = g.kappa * g.rs * g.T * k_l / vol
    # dp/dt = -c (p^2 - Pa^2): scipy ...
    sol = solve_ivp(lambda _, p: -c * (p * p - P_ATM ** 2), (0, 2), [p0], t_eval=t,
                    method="Radau", rtol=1e-11, atol=1e-6)
    np.testing.assert_allclose(got, sol.y[0], rtol=0, atol=1.0)
    # ... and its closed form (p - a)/(p + a) = K exp(-2 a c t)
    a = P_ATM
    e = (p0 - a) / (p0 + a) * np.exp(-2 * a * c * t)
    np.testing.assert_allclose(got, a * (1 + e) / (1 - e), rtol=0, atol=1.0)
    assert got[-1] < 0.5 * p0  # a real depletion over the 2 s


@pytest.mark.parametrize("position_fraction", [0.1, 0.9])
def test_graded_leak_depletes_a_closed_chamber_at_its_position(
        rig, closable_params, make_inputs, hand, position_fraction):
    """A fixed piston at x: the laminar closed form with k(x) = k (1 + g (x/S - 1/2))."""
    k_mid, grad, p0 = 1.9e-16, 0.8, 5.0e5
    x = position_fraction * rig.stroke_m
    model = Model([make_effect("cylinder_leak", form="graded")])
    params = dict(closable_params, leak_conductance_kg_per_s_Pa2=k_mid,
                  leak_conductance_gradient=grad)
    t = np.arange(2001) * 1e-3
    got = _sim(model, params, make_inputs(t, np.zeros(t.size), position=x), rig, p0)
    g = hand.gas()
    vol = closable_params["dead_volume_m3"] + rig.bore_area_m2 * x
    c = g.kappa * g.rs * g.T * k_mid * (1.0 + grad * (position_fraction - 0.5)) / vol
    a = P_ATM
    e = (p0 - a) / (p0 + a) * np.exp(-2 * a * c * t)
    np.testing.assert_allclose(got, a * (1 + e) / (1 - e), rtol=0, atol=1.0)


def test_graded_leak_without_gradient_is_the_laminar_leak(rig, valve_params, rich_inputs):
    k = {"leak_conductance_kg_per_s_Pa2": 3e-16}
    lam = _sim(Model([make_effect("cylinder_leak", form="laminar")]), dict(valve_params, **k),
               rich_inputs, rig)
    graded = _sim(Model([make_effect("cylinder_leak", form="graded")]),
                  dict(valve_params, leak_conductance_gradient=0.0, **k), rich_inputs, rig)
    np.testing.assert_array_equal(graded, lam)


def test_graded_leak_needs_the_stroke(valve_params):
    model = Model([make_effect("cylinder_leak", form="graded")])
    params = dict(valve_params, leak_conductance_kg_per_s_Pa2=1e-16,
                  leak_conductance_gradient=0.5)
    with pytest.raises(ValueError, match="stroke_m"):
        model.lower(model.vector(params)[None], Rig(0.009, P_ATM, P_SUP))


def test_orifice_leak_depletes_a_closed_chamber(rig, closable_params, make_inputs, hand):
    a_l, vol, p0 = 3.04e-8, closable_params["dead_volume_m3"], 5.0e5
    model = Model(["cylinder_leak"])
    params = dict(closable_params, leak_area_m2=a_l)
    t = np.arange(1501) * 1e-3
    got = _sim(model, params, make_inputs(t, np.zeros(t.size)), rig, p0)
    g = hand.gas()
    # The chamber reaches P_atm in finite time (~0.74 s here), where the flow has a
    # square-root singularity that stalls scipy: compare up to 0.6 s, then check it stays.
    early = t <= 0.6
    sol = solve_ivp(lambda _, p: [-g.kappa * g.rs * g.T * a_l * hand.flow(p[0], P_ATM) / vol],
                    (0, 0.6), [p0], t_eval=t[early], method="Radau", rtol=1e-11, atol=1e-6)
    assert sol.success
    np.testing.assert_allclose(got[early], sol.y[0], rtol=0, atol=1e-3 * RANGE)
    # choked while p > theta P_atm: p decays exactly exponentially at k Rs T a_l beta / V
    rate = g.kappa * g.rs * g.T * a_l * g.beta / vol
    choked = got > g.theta * P_ATM * 1.001
    np.testing.assert_allclose(got[choked], p0 * np.exp(-rate * t[choked]), rtol=1e-4)
    assert np.all(np.abs(got[t >= 1.0] - P_ATM) < 1.0)


def test_heat_transfer_survives_venting_after_a_compression(rig, closable_params, hand):
    """A shut chamber compressed tenfold heats above kappa T_w; then it vents.

    With the vented air leaving at the supply's enthalpy (an earlier version) the
    temperature ran away to 1e14 K and the solver stopped. Now: the compression follows
    the adiabat p V^kappa = const (wall exchange nearly off), the vent reaches the
    atmosphere, and the compiled integrator agrees with the reference solver.
    """
    rate = 1e-3  # 1/s: a wall time constant of 1000 s
    model = Model([make_effect("heat_transfer")])
    params = dict(closable_params, heat_transfer_rate_per_s=rate,
                  heat_transfer_coupling=1.0, dead_volume_m3=1.5e-7)
    dt, p0 = 1e-3, 1.2e5
    t = np.arange(601) * dt
    x_hi, x_lo = 0.025, 0.001
    x = np.where(t < 0.1, x_hi - (x_hi - x_lo) * t / 0.1, x_lo)
    u = np.where(t < 0.15, 0.0, -5.0)  # shut, then full exhaust
    inputs = Inputs(t, u, x, np.full(t.size, P_SUP))
    got = _sim(model, params, inputs, rig, p0)
    assert np.all(np.isfinite(got))
    v_hi, v_lo = (params["dead_volume_m3"] + rig.bore_area_m2 * xx for xx in (x_hi, x_lo))
    gas = hand.gas()
    assert (v_hi / v_lo) ** (gas.kappa - 1.0) > 1.5 * gas.kappa  # T well above kappa T_w
    i = int(round(0.12 / dt))
    assert got[i] == pytest.approx(p0 * (v_hi / v_lo) ** gas.kappa, rel=2e-3)
    assert abs(got[-1] - P_ATM) < 2e3
    # the reference up to the first 2 ms of the vent (the chamber reaches P_atm within
    # a few ms, where the orifice's square-root singularity stalls scipy)
    m = int(round(0.152 / dt)) + 1
    early = Inputs(t[:m], u[:m], x[:m], np.full(m, P_SUP))
    ref = reference_simulate(model, params, early, rig, p0, rtol=1e-10)
    assert ref[-1] < 0.9 * ref[m - 3]  # the vent is under way
    assert np.max(np.abs(got[:m] - ref)) <= 1e-3 * RANGE


def test_closable_valve_really_closes(rig, closable_params, make_inputs):
    t = np.arange(1001) * 1e-3
    for p0 in (1.5e5, 4.5e5):
        p = _sim(Model([]), closable_params, make_inputs(t, np.zeros(t.size)), rig, p0)
        assert np.all(p == p0)


# ---------------------------------------------------------------- heat transfer
def test_heat_transfer_relaxes_after_a_fast_fill(rig, closable_params, make_inputs):
    rate = 5.0
    t = np.arange(1501) * 1e-3
    u = np.where(t < 0.05, 5.0, 0.0)  # fast fill, then a closed hold
    inputs = make_inputs(t, u)
    base = _sim(Model([]), closable_params, inputs, rig, P_ATM, _tight())
    heat = _sim(Model(["heat_transfer"]), dict(closable_params, heat_transfer_rate_per_s=rate,
                                               heat_transfer_coupling=1.0),
                inputs, rig, P_ATM, _tight())
    hold = t >= 0.051
    assert np.all(base[hold] == base[hold][0])  # eq. 5 alone: nothing changes when closed
    h = heat[hold]
    assert h[0] > 2e5  # the fill worked
    assert np.all(np.diff(h) < 0)  # cooling: the pressure falls ...
    assert h[-1] < h[0] - 0.02 * RANGE  # ... noticeably
    # closed chamber: dT/dt = rate (T_w - T) and p / T fixed, so p - p_inf ~ exp(-rate t)
    i = [100, 300, 500]  # samples (1 ms) into the hold
    d1, d2 = h[i[0]] - h[i[1]], h[i[1]] - h[i[2]]
    assert d1 / d2 == pytest.approx(math.exp(rate * 0.2), rel=1e-3)
    # heating during the fill: the heated model ends the fill at a higher pressure
    # than its relaxed value, and the final value approaches p_hold * T_w / T_fill < p_hold
    p_inf = h[i[2]] - d2 * math.exp(-rate * 0.2) / (1 - math.exp(-rate * 0.2))
    assert p_inf < h[-1] and h[-1] - p_inf < 0.01 * (h[0] - p_inf)


def _wall_area_over_volume(rig, vol):
    """A_w / V of a cylinder: two end caps 2 A and the barrel pi D V / A."""
    d = 2.0 * math.sqrt(rig.bore_area_m2 / math.pi)
    return (2.0 * rig.bore_area_m2 + math.pi * d * vol / rig.bore_area_m2) / vol


def test_convective_heat_relaxes_at_its_closed_form_rate(rig, closable_params, make_inputs,
                                                         hand):
    """Fill fast, then hold shut: with no flow, p / T stays fixed, so
    dT/dt = (kappa - 1) h (A_w / V) (T_w - T) T / p relaxes at the constant rate
    r = (kappa - 1) h (A_w / V) T_w / p_inf, with p_inf the pressure once T = T_w."""
    h = 30.0
    t = np.arange(1501) * 1e-3
    u = np.where(t < 0.05, 5.0, 0.0)
    model = Model([make_effect("heat_transfer", form="convective")])
    got = _sim(model, dict(closable_params, heat_transfer_coefficient_W_per_m2_K=h,
                           heat_transfer_coupling=1.0),
               make_inputs(t, u), rig, P_ATM, _tight())
    hold = got[t >= 0.051]
    assert hold[0] > 2e5 and np.all(np.diff(hold) < 0)
    i = [100, 300, 500]
    d1, d2 = hold[i[0]] - hold[i[1]], hold[i[1]] - hold[i[2]]
    q = d2 / d1  # exp(-r 0.2)
    p_inf = hold[i[2]] - d2 * q / (1.0 - q)
    gas = hand.gas()
    vol = closable_params["dead_volume_m3"]  # make_inputs holds the piston at 0
    rate = ((gas.kappa - 1.0) * h * _wall_area_over_volume(rig, vol) * gas.T / p_inf)
    assert -math.log(q) / 0.2 == pytest.approx(rate, rel=2e-3)


@pytest.mark.parametrize("form, strength", [("rate", 20.0), ("convective", 60.0)])
def test_heat_transfer_passes_continuously_through_eq5_at_zero_coupling(
        rig, valve_params, hand, form, strength):
    """The plain model is the effect at zero strength: at coupling 0 the pressure is
    eq. 5 to the bit (whatever the exchange), at 1e-6 within a pascal of it, first order
    in the coupling near 0, and the pressure moves steadily away as the coupling grows,
    to the energy equation at 1
    (a fill, a hold and a vent of a small chamber, where the adiabatic chamber differs
    from eq. 5 by kilopascals)."""
    key = {"rate": "heat_transfer_rate_per_s",
           "convective": "heat_transfer_coefficient_W_per_m2_K"}[form]
    n = 601
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(12), n, 1e-3, hold_s=(0.02, 0.08))
    inputs = Inputs(t, u, np.full(n, 0.01), np.full(n, P_SUP))
    params = dict(valve_params, dead_volume_m3=2.4e-7)
    plain = _sim(Model([]), params, inputs, rig, P_ATM, _tight())
    model = Model([make_effect("heat_transfer", form=form)])

    def gap(coupling):
        got = _sim(model, dict(params, **{key: strength, "heat_transfer_coupling": coupling}),
                   inputs, rig, P_ATM, _tight())
        return float(np.max(np.abs(got - plain)))

    assert gap(0.0) == 0.0
    gaps = [gap(c) for c in (1e-6, 1e-4, 1e-3, 0.25, 0.5, 1.0)]
    assert gaps[0] < 1.0
    assert gaps[1] == pytest.approx(0.1 * gaps[2], rel=0.1)  # first order in c near 0
    assert gaps[-1] > 5e3
    assert gaps[2] < gaps[3] < gaps[4] < gaps[5]


@pytest.mark.parametrize("form, strength", [("rate", 20.0), ("convective", 60.0)])
def test_a_partial_heat_coupling_agrees_with_the_reference_solver(rig, valve_params, hand,
                                                                  form, strength):
    """At coupling 0.5 (a moving piston, fast steps, a small chamber and a leak) the
    compiled step and scipy's Radau on the reference right-hand side agree to 1e-4 of
    the range, and from 10x to 100x tighter the error falls at least 5x (the
    coupling's entries of the (p, T) Jacobian keep the method's order; measured 13x,
    as at coupling 1)."""
    key = {"rate": "heat_transfer_rate_per_s",
           "convective": "heat_transfer_coefficient_W_per_m2_K"}[form]
    n = 301
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(43), n, 1e-3, hold_s=(0.01, 0.05))
    inputs = Inputs(t, u, hand.moving_position(t, freq=3.0), np.full(n, P_SUP))
    model = Model(["cylinder_leak", make_effect("heat_transfer", form=form)])
    params = dict(valve_params, dead_volume_m3=1.5e-7, leak_area_m2=3e-9,
                  **{key: strength, "heat_transfer_coupling": 0.5})
    ref = reference_simulate(model, params, inputs, rig, P_ATM, rtol=1e-10)
    std = SolverConfig.standard()
    err = [np.sqrt(np.mean((_sim(model, params, inputs, rig, P_ATM, s) - ref) ** 2))
           for s in (std.tightened(10.0), std.tightened(100.0))]
    assert np.ptp(ref) > 0.5 * RANGE
    assert np.max(np.abs(_sim(model, params, inputs, rig, P_ATM) - ref)) <= 1e-4 * RANGE
    assert err[1] <= err[0] / 5.0, f"RMS error {err[0]:.2f} -> {err[1]:.2f} Pa"


def test_convective_heat_tends_to_isothermal_and_off_is_adiabatic(rig, closable_params, hand):
    """A shut chamber compressed 2.2x in 0.5 s: p V^kappa = const at h = 0 (eq. 5) and
    p V = const once h is large (wall time constant << the compression)."""
    t = np.arange(501) * 1e-3
    x = 0.025 - 0.015 * t / t[-1]
    inputs = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    model = Model([make_effect("heat_transfer", form="convective")])
    closable_params = dict(closable_params, dead_volume_m3=1.5e-7)
    vol = closable_params["dead_volume_m3"] + rig.bore_area_m2 * x
    gas = hand.gas()
    p0 = 1.5e5
    adiabatic = _sim(model, dict(closable_params, heat_transfer_coefficient_W_per_m2_K=0.0,
                                 heat_transfer_coupling=1.0),
                     inputs, rig, p0, _tight())
    np.testing.assert_allclose(adiabatic * vol ** gas.kappa, p0 * vol[0] ** gas.kappa,
                               rtol=1e-6)
    iso = _sim(model, dict(closable_params, heat_transfer_coefficient_W_per_m2_K=1000.0,
                           heat_transfer_coupling=1.0),
               inputs, rig, p0, _tight())
    assert iso[-1] * vol[-1] == pytest.approx(p0 * vol[0], rel=0.01)
    assert adiabatic[-1] * vol[-1] > 1.3 * p0 * vol[0]


# ---------------------------------------------------------------- supply fluctuation
@pytest.mark.parametrize("gain", [0.0, 0.5, 1.0])
def test_supply_gain_scales_the_settled_pressure(rig, valve_params, make_inputs, gain, hand):
    t = np.arange(1001) * 1e-3
    high = 1.1 * P_SUP
    inputs = make_inputs(t, np.full(t.size, 5.0), supply=high)
    p = _sim(Model(["supply_fluctuation"]), dict(valve_params, supply_gain=gain), inputs, rig,
             P_ATM)
    seen = P_SUP + gain * (high - P_SUP)
    assert p[-1] == pytest.approx(hand.equilibrium(valve_params, supply=seen), abs=1.0)
    if gain == 1.0:
        nominal = hand.equilibrium(valve_params, supply=P_SUP)
        assert p[-1] - nominal == pytest.approx(0.1 * P_SUP, rel=0.01)


def test_supply_fluctuation_bench_perturbation(rig):
    eff = make_effect("supply_fluctuation")
    t = np.arange(20001) * 1e-3
    s = eff.perturb_inputs(t, np.full(t.size, P_SUP), rig, np.random.default_rng(4))
    assert s.shape == t.shape and np.all(np.isfinite(s))
    assert 1e3 < np.std(s) < 1e5
    assert abs(np.mean(s) - P_SUP) < 0.1 * RANGE
    # the same seed gives the same supply
    again = eff.perturb_inputs(t, np.full(t.size, P_SUP), rig, np.random.default_rng(4))
    assert np.array_equal(s, again)


def test_supply_hose_lag_filters_the_header_and_leaves_no_sub_millisecond_steps(rig):
    """The valve inlet sees the header through a first-order lag: the same header
    (same seed, lag 0) filtered by scipy's exact discretisation of 1/(1 + tau s) for a
    held input; and the lag removes the header's sub-millisecond content (its Brownian
    wander and instant load dips), which linear interpolation between 1-kHz samples,
    as a model reads a recording, cannot follow."""
    from scipy import signal

    from pneubayes.effects.supply_fluctuation import SupplyFluctuation

    dt, tau = 5e-5, 0.005
    t = np.arange(100_001) * dt  # 5 s on the bench's fine grid
    flat = np.full(t.size, P_SUP)
    header = SupplyFluctuation(load_step_rate_per_s=4.0, line_time_constant_s=0.0)
    hose = SupplyFluctuation(load_step_rate_per_s=4.0, line_time_constant_s=tau)
    raw = header.perturb_inputs(t, flat, rig, np.random.default_rng(9)) - P_SUP
    lagged = hose.perturb_inputs(t, flat, rig, np.random.default_rng(9)) - P_SUP
    a = math.exp(-dt / tau)
    expected = signal.lfilter([1.0 - a], [1.0, -a], raw[1:], zi=[a * raw[0]])[0]
    assert np.allclose(lagged[1:], expected, rtol=0.0, atol=1e-6)
    assert lagged[0] == raw[0]

    def between_samples(dev):  # RMS gap to linear interpolation of 1-kHz samples
        k = 20  # fine steps per ms
        n = (dev.size - 1) // k * k + 1
        lin = np.interp(t[:n], t[:n:k], dev[:n:k])
        return float(np.sqrt(np.mean((dev[:n] - lin) ** 2)))

    assert between_samples(raw) > 200.0
    assert between_samples(lagged) < 0.2 * between_samples(raw)
    with pytest.raises(ValueError, match="line_time_constant_s"):
        SupplyFluctuation(line_time_constant_s=-1.0)


_HEAT_FORMS = [("rate", {"heat_transfer_rate_per_s": 5.0, "heat_transfer_coupling": 1.0}),
               ("convective", {"heat_transfer_coefficient_W_per_m2_K": 30.0,
                               "heat_transfer_coupling": 1.0})]


@pytest.mark.slow
@pytest.mark.parametrize("form,strength", _HEAT_FORMS, ids=[f for f, _ in _HEAT_FORMS])
def test_heat_transfer_converges_at_the_integrators_order(rig, valve_params, hand, form,
                                                          strength):
    """A 10x tighter tolerance must cut the error against Radau (rtol 1e-10) at least
    5x on a small chamber (1.5e-7 m^3, moving piston, fast steps). Stepping the
    temperature with a diagonal Jacobian left the method first order in the p-T
    coupling: the error fell 2.5x per decade and the log-density of a 60-window
    posterior jittered by 16 nat between tolerances."""
    n = 401
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(41), n, 1e-3, hold_s=(0.01, 0.05))
    inputs = Inputs(t, u, hand.moving_position(t, freq=3.0), np.full(n, P_SUP))
    model = Model([make_effect("heat_transfer", form=form)])
    params = dict(valve_params, dead_volume_m3=1.5e-7, **strength)
    ref = reference_simulate(model, params, inputs, rig, P_ATM, rtol=1e-10)
    std = SolverConfig.standard()
    err = [np.sqrt(np.mean((_sim(model, params, inputs, rig, P_ATM, s) - ref) ** 2))
           for s in (std, std.tightened(10.0))]
    assert np.ptp(ref) > 0.5 * RANGE  # the steps swept the range
    assert err[1] <= err[0] / 5.0, f"RMS error {err[0]:.2f} -> {err[1]:.2f} Pa"


def test_start_sensitivity_with_heat_transfer_matches_finite_differences(rig, hand):
    """dp/dp0 carries the temperature: a higher start pressure changes how the chamber
    heats and cools, which feeds back on p. The kernel's propagator of (p, T) must
    agree with central differences of the simulation."""
    model = Model([make_effect("heat_transfer", form="rate")])
    params = valve_preset("valve1").parameters()
    params.update(dead_volume_m3=1.5e-7, heat_transfer_rate_per_s=5.0, heat_transfer_coupling=1.0)
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(4), n, 1e-3, levels=(-1.0, 1.0)),
                    hand.moving_position(t, freq=3.0), np.full(n, 6.0e5))
    starts = np.array([0, 200, 400])
    p0 = np.array([2.0e5, 3.0e5, 4.0e5])
    tight = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=1e-7, max_step_s=1e-3,
                         min_step_s=1e-14, max_steps_per_s=5e6)
    _, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 400, p0, tight)
    d = 20.0
    up = simulate_windows(model, params, inputs, rig, starts, 400, p0 + d, tight)
    dn = simulate_windows(model, params, inputs, rig, starts, 400, p0 - d, tight)
    fd = (up - dn) / (2 * d)
    assert np.all(sens[..., 0] == 1.0)
    assert np.max(np.abs(sens - fd)) < 0.03, np.max(np.abs(sens - fd))


@pytest.mark.parametrize("name", sorted(CATALOGUE))
def test_every_effect_declares_a_start_inside_its_bounds_in_every_form(name):
    """The plug-in contract's start: each effect, in each form, names only its own
    parameters and starts them inside their bounds."""
    cls = CATALOGUE[name]
    for options in ([{"form": f} for f in cls.forms] or [{}]):
        effect = cls(**options)
        start = effect.start_values()
        assert set(start) <= set(effect.parameter_names()), (name, options)
        for p in effect.parameters():
            if p.name in start:
                assert p.lower <= start[p.name] <= p.upper, (name, options, p.name)


def _every_form(cls):
    return [cls(**o) for o in ([{"form": f} for f in cls.forms] or [{}])]


@pytest.mark.parametrize("name", sorted(CATALOGUE))
def test_every_effect_declares_its_library_terms_in_its_own_parameters(name):
    """The plug-in contract's search side: each effect, in each form, offers the
    library at least one term per trial strength, of a kind the library computes, whose
    start names the effect's own parameters inside their bounds."""
    from pneubayes.effects.discovery import FormTrialTerm, InputLagTerm, RelaxationTerm, TrialTerm

    if not CATALOGUE[name].library_searched:  # never searched: no terms at any strength
        for effect in _every_form(CATALOGUE[name]):
            assert not effect.library_strengths and not effect.opt_in_strengths
            assert effect.library_terms((1.0, 2.0)) == ()
        return
    for effect in _every_form(CATALOGUE[name]):
        # an effect searched only when asked offers its terms at the strengths it
        # documents, and none by default
        strengths = effect.library_strengths or effect.opt_in_strengths
        assert not (effect.library_strengths and effect.opt_in_strengths), name
        assert effect.library_terms(()) == ()
        terms = effect.library_terms(strengths)
        assert len(terms) == len(strengths) >= 1, (name, effect)
        assert len({t.label for t in terms}) == len(terms)
        # a term may stand for another form of the effect (the leak's laminar law)
        any_form = {p.name: p for e in _every_form(CATALOGUE[name]) for p in e.parameters()}
        own = {p.name: p for p in effect.parameters()}
        for t in terms:
            assert isinstance(t, (TrialTerm, FormTrialTerm, InputLagTerm, RelaxationTerm))
            for k, v in t.start.items():
                assert k in any_form and any_form[k].lower <= v <= any_form[k].upper, t
            if isinstance(t, TrialTerm):
                assert set(t.values) <= set(own) and t.values, (name, t)
            if isinstance(t, FormTrialTerm):
                assert t.effect.name == name and set(t.values) <= set(
                    t.effect.parameter_names())
            if isinstance(t, InputLagTerm):
                assert t.lag_s > 0
            if isinstance(t, RelaxationTerm):
                assert t.rate_per_s > 0
    # labels are unique over the whole catalogue: a term names its effect on its own
    labels = [t.label for cls in CATALOGUE.values()
              for t in cls().library_terms(cls.library_strengths or cls.opt_in_strengths)]
    assert len(labels) == len(set(labels))


@pytest.mark.parametrize("name", sorted(CATALOGUE))
def test_every_effect_proposes_candidates_that_start_inside_their_bounds(name, rig):
    """The plug-in contract's fit side: a named effect proposes forms of itself, whose
    start values name their own parameters and lie inside their bounds, from its best
    term's start or from its fallback; what it refines first are the model's
    parameters."""
    from pneubayes.discovery.candidates import effect_candidates, first_free
    from pneubayes.discovery.verification import StepFit
    from pneubayes.physics.valve import valve_preset

    params = dict(valve_preset("valve1").parameters(), dead_volume_m3=2e-6)
    fit = StepFit(Model(), params, 1.0, 1.0, np.zeros(1), np.zeros(1), 500.0, 0.0)
    effect = CATALOGUE[name]()
    for term in (None, *effect.library_terms(effect.library_strengths
                                             or effect.opt_in_strengths)):
        evidence = {"best_term_start": None if term is None else term.start}
        cands = effect_candidates(fit, name, evidence, rig,
                                  FormSettings(tube_line_segments=3, tube_line_form="line"))
        assert cands, name
        for model, start in cands:
            assert model.effect_names == (name,)
            assert set(start) == set(model.parameter_names)
            assert not model.out_of_bounds(start), (name, start)
            free = first_free(model, name)
            assert free is None or set(free) <= set(model.parameter_names)


@pytest.mark.parametrize("name", sorted(n for n, c in CATALOGUE.items() if c.forms))
def test_a_cards_form_follows_from_its_parameter_names(name):
    """A model card without the ``form`` option: each effect reads its form from the
    card's parameter names."""
    cls = CATALOGUE[name]
    base = Model().parameter_names
    seen = {}
    for form in cls.forms:
        own = cls(form=form).parameter_names()
        names = (*base, *own)
        # a form with the same parameters as an earlier one (tube_delay's wave and line)
        # is told apart only by the card's form option: without it, the earlier form
        assert cls.form_from_parameters(names) == seen.get(tuple(sorted(own)), form)
        seen.setdefault(tuple(sorted(own)), form)


def test_what_the_fits_and_the_loop_ask_of_an_effect_is_on_the_effect():
    """Warm-up windows, the line's company and a lagged reading's lead are the effect's
    own declarations: no code outside ``effects/`` names the effect to ask."""
    assert {n for n, c in CATALOGUE.items() if c.needs_warmup} == {"heat_transfer"}
    assert {n for n, c in CATALOGUE.items() if not c.beside_line} == {
        "closure", "volume_closure", "volume_play", "loaded_wall", "port_restriction",
        "supply_restriction"}
    for form in ("first_order", "second_order", "pressure_dependent"):
        lag = make_effect("sensor_lag", form=form)
        assert lag.reading_lead_parameter() in lag.parameter_names()
    assert all(make_effect(n).reading_lead_parameter() is None for n in CATALOGUE
               if n != "sensor_lag")
