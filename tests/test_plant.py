"""High-fidelity plant (pneubayes.bench.plant) and its realistic effect forms.

Agreement with the compiled simulator where the two describe the same physics, limits
of each form, closed forms and physical behaviour, and the bench integration.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.bench.forms import (
    AcousticTube,
    ClearanceLeak,
    RegulatorDroop,
    RoundedDeadzone,
    SecondOrderSpool,
    WallHeatTransfer,
    form_from_dict,
    forms_from_names,
)
from pneubayes.bench.plant import PlantConfig, rounded_deadband, simulate_plant
from pneubayes.effects import effects_from_names, make_effect
from pneubayes.errors import ParameterError
from pneubayes.io import check_recording, read_recording
from pneubayes.model import Model
from pneubayes.physics.orifice import flow_function
from pneubayes.physics.valve import gompertz_area, valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate

P_ATM, P_SUP, BORE, STROKE = 101_325.0, 551_325.0, 0.009, 0.0375
REF = PlantConfig.reference()
DT = 1e-4  # the bench's 10 kHz fine grid
#: Valve shut at commands within +-1.5 V: offsets 0, both Gompertz terms underflow to 0.
CLOSABLE = {
    "inlet_offset_m2": 0.0, "inlet_a_m2": 5.5e-7, "inlet_b": 3.5, "inlet_c_per_V": 20.0,
    "inlet_d_V": -3.0, "exhaust_offset_m2": 0.0, "exhaust_a_m2": 6e-7, "exhaust_b": 3.5,
    "exhaust_c_per_V": -20.0, "exhaust_d_V": 3.0}


@pytest.fixture(scope="module")
def rig():
    return Rig(BORE, P_ATM, P_SUP)


@pytest.fixture(scope="module")
def base():
    """Valve 1 of Table II and the AIR37 bench dead volume."""
    return dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)


def _steps(seed, n, levels=(-5.0, 5.0)):
    """Random step command on the fine grid: holds of 30-300 ms on a 1 ms clock."""
    rng = np.random.default_rng(seed)
    u, i = np.empty(n), 0
    while i < n:
        hold = 10 * int(rng.integers(30, 301))
        u[i:i + hold] = rng.uniform(*levels)
        i += hold
    return u


def _inputs(duration_s, seed, moving, levels=(-5.0, 5.0), position=0.5 * STROKE):
    t = np.arange(int(round(duration_s / DT)) + 1) * DT
    u = _steps(seed, t.size, levels)
    if moving:
        x = 0.5 * STROKE + 0.4 * STROKE * np.sin(2 * np.pi * 3.0 * t)
    else:
        x = np.full(t.size, position)
    return Inputs(t, u, x, np.full(t.size, P_SUP))


def _compiled(model, params, inputs, rig, p0=P_ATM):
    return simulate(model, params, inputs, rig, p0, SolverConfig.reference()).pressure_Pa[0]


# ---------------------------------------------------------------- agreement
@pytest.mark.parametrize("moving", [False, True], ids=["fixed", "moving"])
def test_without_forms_the_plant_agrees_with_the_compiled_simulator(rig, base, moving):
    inputs = _inputs(1.0, 1, moving)
    plant = simulate_plant(base, (), inputs, rig, P_ATM, REF)
    err = np.max(np.abs(plant.pressure_Pa - _compiled(Model(), base, inputs, rig)))
    assert err < 20.0, f"plant vs compiled: {err:.1f} Pa"
    assert np.ptp(plant.pressure_Pa) > 0.8 * (P_SUP - P_ATM)  # the whole range is exercised
    assert np.all(plant.supply_at_valve_Pa == P_SUP) and plant.chamber_temperature_K is None


@pytest.mark.parametrize("moving", [False, True], ids=["fixed", "moving"])
@pytest.mark.parametrize("segments, length_m, diameter_m", [(3, 1.0, 0.002), (1, 0.5, 0.004)])
def test_the_line_form_of_tube_delay_agrees_with_the_plants_acoustic_tube(
        rig, base, moving, segments, length_m, diameter_m):
    """The model's acoustic line (exponential Rosenbrock, full Jacobian) and the plant's
    AcousticTube (LSODA), written apart, solve the same lumped line."""
    tube = AcousticTube(length_m=length_m, diameter_m=diameter_m, segments=segments)
    inputs = _inputs(1.0, 1, moving)
    plant = simulate_plant(base, (tube,), inputs, rig, P_ATM, REF).pressure_Pa
    model = Model([make_effect("tube_delay", form="line", segments=segments)])
    params = dict(base, tube_delay_s=tube.transit_time_s(rig.gas), tube_diameter_m=diameter_m)
    params["dead_volume_m3"] += tube.volume_m3  # the model's dead volume holds the tube's
    err = np.max(np.abs(plant - _compiled(model, params, inputs, rig)))
    assert err < 20.0, f"plant vs compiled line: {err:.1f} Pa"
    bare = _compiled(Model(), dict(base, dead_volume_m3=params["dead_volume_m3"]), inputs, rig)
    assert np.max(np.abs(plant - bare)) > 2e3  # and the line matters (100x the agreement)


@pytest.mark.parametrize("leak", ["orifice", "laminar"])
def test_catalogue_effects_in_the_plant_agree_with_the_compiled_simulator(rig, base, leak):
    """The plant reads the catalogue's lowered slots with the model's meanings."""
    from pneubayes.bench.bench import truth_parameters

    model = Model(effects_from_names(["cylinder_leak", "tube_delay", "valve_deadzone",
                                      "supply_fluctuation", "heat_transfer", "spool_lag"],
                                     leak))
    truth = truth_parameters(model, "AIR37", "valve1", rig)
    inputs = _inputs(1.0, 2, True)
    t = inputs.time_s
    supply = P_SUP + 20_000.0 * np.sin(2 * np.pi * 1.3 * t)
    inputs = Inputs(t, inputs.command_V, inputs.position_m, supply)
    plant = simulate_plant(truth, (), inputs, rig, P_ATM, REF, effects=model.effects)
    err = np.max(np.abs(plant.pressure_Pa - _compiled(model, truth, inputs, rig)))
    assert err < 20.0, f"plant vs compiled with all six effects ({leak}): {err:.1f} Pa"
    assert np.allclose(plant.supply_at_valve_Pa, supply)  # supply_gain 1


def test_the_catalogues_warm_wall_in_the_plant_agrees_with_the_compiled_simulator(rig, base):
    """heat_transfer's rate form with its wall offset (bench defaults: 5 /s, 15 K): the
    plant, which starts its gas at the wall's temperature too, agrees with the compiled
    simulator, and the offset moves the pressure by 15 x their difference's bound."""
    model = Model([make_effect("heat_transfer", form="rate", wall_offset=True)])
    truth = dict(base, **model.effect("heat_transfer").bench_defaults())
    inputs = _inputs(1.0, 3, True)
    plant = simulate_plant(truth, (), inputs, rig, P_ATM, REF, effects=model.effects)
    err = np.max(np.abs(plant.pressure_Pa - _compiled(model, truth, inputs, rig)))
    assert err < 20.0, f"plant vs compiled, a warm wall: {err:.1f} Pa"
    cool = _compiled(model, dict(truth, heat_transfer_wall_offset_K=0.0), inputs, rig)
    assert np.max(np.abs(plant.pressure_Pa - cool)) > 300.0  # (measured 502 Pa)


def test_the_plant_refuses_a_partial_heat_coupling(rig, base):
    """The plant's chamber feels its whole temperature or none: the catalogue's
    heat_transfer at a coupling between is an error that says so, not a silent 1."""
    model = Model(effects_from_names(["heat_transfer"], "orifice"))
    params = dict(base, heat_transfer_rate_per_s=5.0, heat_transfer_coupling=0.4)
    with pytest.raises(ValueError, match="partial coupling"):
        simulate_plant(params, (), _inputs(0.05, 1, False), rig, P_ATM, REF,
                       effects=model.effects)


def test_reference_preset_converges_under_tighter_tolerances(rig, base):
    """Tube (the hardest form): the preset is within a few Pa of rtol 1e-11; a looser
    setting is further away."""
    forms = (AcousticTube(1.0),)
    inputs = _inputs(0.3, 3, True)
    tight = simulate_plant(base, forms, inputs, rig, P_ATM,
                           PlantConfig("LSODA", 1e-11, 1e-4, 1e-7, 1e-9, 0.005)).pressure_Pa
    ref = simulate_plant(base, forms, inputs, rig, P_ATM, REF).pressure_Pa
    loose = simulate_plant(base, forms, inputs, rig, P_ATM,
                           PlantConfig("LSODA", 1e-5, 10.0, 1e-3, 1e-4, 0.005)).pressure_Pa
    err_ref, err_loose = np.max(np.abs(ref - tight)), np.max(np.abs(loose - tight))
    assert err_ref < 5.0 and err_loose > 2 * err_ref, (err_ref, err_loose)


def test_the_tubes_unsteady_weighting_follows_zielkes_short_time_series():
    """Schohl's five exponentials within 6 % of Zielke's (1968) series of the laminar
    weighting function, exact for t' <= 0.02 (t' = nu t / R^2)."""
    from pneubayes.bench.plant import UNSTEADY_M, UNSTEADY_N

    tt = np.geomspace(1e-4, 2e-2, 40)
    series = (0.282095 / np.sqrt(tt) - 1.25 + 1.057855 * np.sqrt(tt) + 0.9375 * tt
              + 0.396696 * tt ** 1.5 - 0.351563 * tt ** 2)
    approx = np.exp(-np.outer(tt, UNSTEADY_N)) @ UNSTEADY_M
    assert np.max(np.abs(approx / series - 1.0)) < 0.06  # (its largest: 5.4 %)


def test_unsteady_friction_damps_a_tubes_ring_and_keeps_a_shut_tube_still(rig):
    """A valve that fills a 2-m line and a small chamber for 20 ms and shuts leaves the
    line ringing; Zielke's unsteady shear (unsteady_friction 1) damps that ring faster
    than the quasi-steady shear alone; a shut valve keeps the pressure either way."""
    t = np.arange(1201) * DT
    shut = dict(CLOSABLE, dead_volume_m3=2e-5)
    inputs = Inputs(t, np.where(t < 0.02, 5.0, 0.0), np.full(t.size, 0.5 * STROKE),
                    np.full(t.size, P_SUP))

    def run(weight, command=None):
        tube = AcousticTube(2.0, 0.004, segments=12, unsteady_friction=weight)
        inp = inputs if command is None else Inputs(t, command, inputs.position_m,
                                                    inputs.supply_pressure_Pa)
        return simulate_plant(shut, (tube,), inp, rig, 3e5, REF).pressure_Pa

    ring = {w: run(w)[t >= 0.08] for w in (0.0, 1.0)}
    left = {w: float(np.std(r)) for w, r in ring.items()}
    assert left[0.0] > 100.0 and left[1.0] < 0.75 * left[0.0], left
    still = run(1.0, np.zeros(t.size))
    assert np.max(np.abs(still - 3e5)) < 1.0
    with pytest.raises(ValueError, match="unsteady_friction must be a number >= 0"):
        AcousticTube(1.0, unsteady_friction=-0.5)


# ---------------------------------------------------------------- limits
def test_rounded_deadband_is_c1_and_hard_outside_its_corners():
    w, r = 0.3, 0.1
    s = np.linspace(-1.0, 1.0, 20001)
    soft = np.array([rounded_deadband(v, w, r) for v in s])
    hard = np.sign(s) * np.maximum(np.abs(s) - w, 0.0)
    outside = np.abs(np.abs(s) - w) >= r
    assert np.array_equal(soft[outside], hard[outside])
    assert np.all(soft[np.abs(s) <= w - r] == 0.0)
    assert rounded_deadband(w, w, r) == pytest.approx(r / 4)  # the corner is rounded
    slope = np.diff(soft) / np.diff(s)
    assert np.max(np.abs(np.diff(slope))) < 0.01  # no jump in slope anywhere (C1)
    assert np.max(np.abs(np.diff(hard) / np.diff(s) - slope)) > 0.4  # the hard one jumps
    for v in (-0.35, 0.31, 0.4):
        assert rounded_deadband(v, w, 1e-12) == pytest.approx(np.sign(v) * (abs(v) - w))


def test_rounded_deadzone_tends_to_the_catalogue_dead_band(rig, base):
    w = 0.4
    inputs = _inputs(1.0, 4, False, levels=(-1.5, 1.5))  # commands around the dead band
    model = Model(["valve_deadzone"])
    cat = _compiled(model, dict(base, deadzone_halfwidth_V=w), inputs, rig)
    sharp = simulate_plant(base, (RoundedDeadzone(w, 1e-9),), inputs, rig, P_ATM, REF)
    err = np.max(np.abs(sharp.pressure_Pa - cat))
    assert err < 20.0, f"rounding 1e-9 V vs catalogue dead band: {err:.1f} Pa"
    # a command parked on the corner sees the rounding
    t = np.arange(3001) * DT
    corner = Inputs.constant(t, w, 0.5 * STROKE, P_SUP)
    p_hard = _compiled(model, dict(base, deadzone_halfwidth_V=w), corner, rig, 3e5)
    p_round = simulate_plant(base, (RoundedDeadzone(w, 0.2),), corner, rig, 3e5,
                             REF).pressure_Pa
    assert p_round[-1] - p_hard[-1] > 5_000.0


def test_zero_droop_is_no_droop(rig, base):
    inputs = _inputs(1.0, 5, True)
    none = simulate_plant(base, (), inputs, rig, P_ATM, REF)
    zero = simulate_plant(base, (RegulatorDroop(0.0, 0.05),), inputs, rig, P_ATM, REF)
    assert np.all(zero.supply_at_valve_Pa == P_SUP)
    assert np.max(np.abs(zero.pressure_Pa - none.pressure_Pa)) < 5.0
    some = simulate_plant(base, (RegulatorDroop(40_000.0, 0.05),), inputs, rig, P_ATM, REF)
    assert some.supply_at_valve_Pa.min() < P_SUP - 1_000.0


def test_short_acoustic_tube_tends_to_its_volume_alone(rig, base):
    """As L -> 0 the tube is only its volume: compare with the compiled model whose dead
    volume includes the tube's. The gap (turbulent friction, inertia) shrinks like L."""
    inputs = _inputs(0.5, 6, True)
    errs = []
    for length in (0.1, 0.03, 0.01):
        tube = AcousticTube(length, segments=2)
        cat = _compiled(Model(), dict(base, dead_volume_m3=base["dead_volume_m3"]
                                      + tube.volume_m3), inputs, rig)
        p = simulate_plant(base, (tube,), inputs, rig, P_ATM, REF).pressure_Pa
        errs.append(np.max(np.abs(p - cat)))
    assert errs[1] < 0.5 * errs[0] and errs[2] < 0.5 * errs[1], errs  # about linear in L
    assert errs[2] < 3e-3 * (P_SUP - P_ATM), errs  # 0.3 % of the range at 1 cm


def test_clearance_leak_with_constant_seal_is_the_catalogue_laminar_leak(rig, base):
    form = ClearanceLeak(gap_m=1.0e-5, seal_length_m=0.004)
    k = form.conductance_kg_per_s_Pa2(BORE, rig.gas)
    assert k == pytest.approx(math.pi * BORE * 1e-15 / (24 * 1.81e-5 * 0.004 * 286.55 * 293.15),
                              rel=1e-3)
    inputs = _inputs(1.0, 7, True)
    model = Model([make_effect("cylinder_leak", form="laminar")])
    cat = _compiled(model, dict(base, leak_conductance_kg_per_s_Pa2=k), inputs, rig)
    p = simulate_plant(base, (form,), inputs, rig, P_ATM, REF).pressure_Pa
    no_leak = _compiled(Model(), base, inputs, rig)
    assert np.max(np.abs(p - cat)) < 20.0
    assert np.max(np.abs(p - no_leak)) > 5_000.0  # the leak matters


# ---------------------------------------------------------------- physics
def test_closed_valve_keeps_the_pressure_with_every_form_but_the_leak(rig):
    forms = (AcousticTube(1.0), RoundedDeadzone(0.3, 0.1), RegulatorDroop(40_000.0, 0.05),
             SecondOrderSpool(125.0, 0.7), WallHeatTransfer(30.0))
    inputs = _inputs(0.5, 8, False, levels=(-1.5, 1.5))  # the spool moves, the valve is shut
    for p0 in (1.5e5, 4.5e5):
        out = simulate_plant(dict(CLOSABLE, dead_volume_m3=1e-6), forms, inputs, rig, p0, REF)
        assert np.max(np.abs(out.pressure_Pa / p0 - 1.0)) < 1e-9
        assert np.max(np.abs(out.chamber_temperature_K - rig.gas.temperature_K)) < 1e-9
        assert np.all(out.supply_at_valve_Pa == P_SUP)


def test_closed_chamber_with_wall_heat_is_adiabatic_at_h0_and_isothermal_at_large_h(rig):
    t = np.arange(5001) * DT
    x = 0.5 * STROKE + 0.4 * STROKE * np.sin(2 * np.pi * 4.0 * t)
    inputs = Inputs.constant(t, 0.0, 0.0, P_SUP)
    inputs = Inputs(t, inputs.command_V, x, inputs.supply_pressure_Pa)
    params = dict(CLOSABLE, dead_volume_m3=2e-7)
    vol = 2e-7 + rig.bore_area_m2 * x
    adiabatic = simulate_plant(params, (WallHeatTransfer(0.0),), inputs, rig, 3e5, REF)
    inv = adiabatic.pressure_Pa * vol**1.4
    assert np.max(np.abs(inv / inv[0] - 1)) < 1e-6
    temp = adiabatic.chamber_temperature_K  # T V^(k-1) constant too
    assert np.max(np.abs(temp * vol**0.4 / (temp[0] * vol[0] ** 0.4) - 1)) < 1e-6
    iso = simulate_plant(params, (WallHeatTransfer(1e5),), inputs, rig, 3e5, REF)
    pv = iso.pressure_Pa * vol
    assert np.max(np.abs(pv / pv[0] - 1)) < 5e-3
    iso_inv = iso.pressure_Pa * vol**1.4
    assert np.ptp(iso_inv / iso_inv[0]) > 0.5  # the two limits are far apart here


def test_a_fills_jet_forces_convection_only_while_it_fills(rig):
    """A 30-ms fill of a small chamber, then a hold: with the inflow's jet stirring the
    gas (``jet_h_W_per_m2_K``) the fill ends cooler, so the hold's pressure falls less
    as the gas relaxes to the wall; a vent with nothing flowing in is unchanged by it."""
    t = np.arange(4001) * DT
    fill = Inputs(t, np.where(t < 0.03, 5.0, 0.0), np.full(t.size, 0.5 * STROKE),
                  np.full(t.size, P_SUP))
    params = dict(CLOSABLE, dead_volume_m3=2e-6)
    still, jet = WallHeatTransfer(10.0), WallHeatTransfer(10.0, jet_h_W_per_m2_K=300.0)
    a, b = (simulate_plant(params, (f,), fill, rig, P_ATM, REF) for f in (still, jet))
    end = int(round(0.032 / DT))
    assert b.chamber_temperature_K[end] < a.chamber_temperature_K[end] - 5.0
    drop_a, drop_b = (o.pressure_Pa[end] - o.pressure_Pa[-1] for o in (a, b))
    assert drop_a > 0.0 and drop_b < 0.8 * drop_a
    vent = Inputs(t, np.full(t.size, -5.0), fill.position_m, fill.supply_pressure_Pa)
    va, vb = (simulate_plant(params, (f,), vent, rig, 4e5, REF) for f in (still, jet))
    assert np.array_equal(va.pressure_Pa, vb.pressure_Pa)
    with pytest.raises(ValueError, match="jet_flow_kg_per_s"):
        WallHeatTransfer(10.0, jet_flow_kg_per_s=0.0)


def test_clearance_leak_matches_its_closed_form_at_a_position(rig):
    """Closed valve, fixed volume: dp/dt = -a (p^2 - P0^2), a = k(x) kappa Rs T / V, so
    (p - P0)/(p + P0) decays as exp(-2 a P0 t); the seal length at x sets k(x)."""
    form = ClearanceLeak(gap_m=1.2e-5, seal_length_m=0.004, seal_length_slope=0.002 / STROKE)
    x = 0.8 * STROKE
    t = np.arange(10001) * DT
    inputs = Inputs.constant(t, 0.0, x, P_SUP)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    p = simulate_plant(params, (form,), inputs, rig, 5e5, REF).pressure_Pa
    k = form.conductance_kg_per_s_Pa2(BORE, rig.gas, position_m=x)
    assert k == pytest.approx(form.conductance_kg_per_s_Pa2(BORE, rig.gas) * 0.004 / 0.0056,
                              rel=1e-12, abs=0)
    g = rig.gas
    a = k * g.heat_capacity_ratio * g.specific_gas_constant_J_per_kg_K * g.temperature_K / (
        1.5e-7 + rig.bore_area_m2 * x)
    r0 = (5e5 - P_ATM) / (5e5 + P_ATM)
    r = r0 * np.exp(-2 * a * P_ATM * t)
    exact = P_ATM * (1 + r) / (1 - r)
    assert exact[-1] < 3e5  # a real decay
    assert np.max(np.abs(p - exact)) < 5.0


@pytest.mark.parametrize("length", [0.5, 1.0])
def test_acoustic_tube_delays_the_chamber_response_by_length_over_c(rig, base, length):
    t = np.arange(3001) * 1e-5
    t_step = 0.005
    inputs = Inputs.constant(t, np.where(t >= t_step, 5.0, -5.0), 0.2 * STROKE, P_SUP)

    def first_rise(p):  # 5 kPa (about 1 % of the range) above the pre-step pressure
        i0 = int(np.searchsorted(t, t_step))
        return t[np.argmax(p - p[i0] > 5_000.0)]

    tube = AcousticTube(length)
    no_tube = simulate_plant(base, (), inputs, rig, P_ATM, REF).pressure_Pa
    with_tube = simulate_plant(base, (tube,), inputs, rig, P_ATM, REF).pressure_Pa
    delay = first_rise(with_tube) - first_rise(no_tube)
    ratio = delay / tube.transit_time_s(rig.gas)
    assert 0.85 < ratio < 1.15, f"delay {delay * 1e3:.3f} ms vs L/c " \
                                f"{tube.transit_time_s(rig.gas) * 1e3:.3f} ms"


def test_regulator_droop_lowers_the_inlet_supply_while_filling(base):
    """SMC-sized chamber filled from atmosphere: the valve-inlet supply droops and
    recovers, and the droop follows its first-order law driven by the inlet flow."""
    rig = Rig(0.032, P_ATM, P_SUP)
    t = np.arange(4001) * DT
    inputs = Inputs.constant(t, np.where(t >= 0.01, 5.0, -5.0), 0.0125, P_SUP)
    droop = RegulatorDroop(40_000.0, 0.05)
    out = simulate_plant(dict(base, dead_volume_m3=2e-6), (droop,), inputs, rig, P_ATM, REF)
    d = P_SUP - out.supply_at_valve_Pa
    assert d.max() > 10_000.0 and d[t < 0.01].max() < 200.0
    assert d[-1] < 0.2 * d.max()  # recovers once the chamber is full
    # d' = (k mdot_in - d) / tau with mdot_in from the recorded traces (trapezoid rule)
    vp = valve_preset("valve1").inlet
    a_in = gompertz_area(inputs.command_V, vp.offset_m2, vp.a_m2, vp.b, vp.c_per_V, vp.d_V)
    m_in = a_in * flow_function(out.supply_at_valve_Pa, out.pressure_Pa, rig.gas) * 1e3  # g/s
    rate = (droop.droop_Pa_per_g_per_s * m_in - d) / droop.time_constant_s
    i = t > 0.0101  # after the command step
    pred = d[i][0] + np.concatenate([[0], np.cumsum(0.5 * (rate[i][1:] + rate[i][:-1]) * DT)])
    assert np.max(np.abs(pred - d[i])) < 0.01 * d.max()


def test_second_order_spool_delays_the_fill_by_its_response_time(rig, base):
    t = np.arange(2001) * 1e-5
    inputs = Inputs.constant(t, np.where(t >= 0.002, 5.0, -5.0), 0.2 * STROKE, P_SUP)
    fast = simulate_plant(base, (), inputs, rig, P_ATM, REF).pressure_Pa
    spool = simulate_plant(base, (SecondOrderSpool(125.0, 0.7),), inputs, rig, P_ATM,
                           REF).pressure_Pa
    t_half = [t[np.argmax(p > 0.5 * (P_SUP + P_ATM))] for p in (fast, spool)]
    assert 0.5e-3 < t_half[1] - t_half[0] < 3e-3  # about a spool time constant later
    assert spool.max() < P_SUP + 1.0


# ---------------------------------------------------------------- validation
def test_forms_validate_their_fields_by_name():
    with pytest.raises(ValueError, match="length_m"):
        AcousticTube(-1.0)
    with pytest.raises(ValueError, match="segments"):
        AcousticTube(1.0, segments=0)
    with pytest.raises(ValueError, match="rounding_V"):
        RoundedDeadzone(0.1, 0.2)
    with pytest.raises(ValueError, match="gap_m"):
        ClearanceLeak(0.0, 0.004)
    with pytest.raises(ValueError, match="time_constant_s"):
        RegulatorDroop(1.0, 0.0)
    with pytest.raises(ValueError, match="damping"):
        SecondOrderSpool(125.0, float("nan"))
    with pytest.raises(ValueError, match="h_W_per_m2_K"):
        WallHeatTransfer(-1.0)
    with pytest.raises(ValueError, match="unknown effect"):
        forms_from_names(["tube_length"])


def test_simulate_plant_rejects_bad_arguments(rig, base):
    inputs = _inputs(0.01, 0, False)
    with pytest.raises(TypeError, match="PlantConfig"):
        simulate_plant(base, (), inputs, rig, P_ATM, SolverConfig.reference())
    with pytest.raises(ValueError, match="initial_pressure_Pa"):
        simulate_plant(base, (), inputs, rig, -1.0, REF)
    with pytest.raises(ParameterError, match="dead_volume_m3"):
        simulate_plant({k: v for k, v in base.items() if k != "dead_volume_m3"}, (), inputs,
                       rig, P_ATM, REF)
    with pytest.raises(ValueError, match="tube_delay"):
        simulate_plant(dict(base, tube_delay_s=0.003), (AcousticTube(1.0),), inputs, rig,
                       P_ATM, REF, effects=(make_effect("tube_delay"),))
    with pytest.raises(ValueError, match="seal length"):
        simulate_plant(base, (ClearanceLeak(1e-5, 0.004, seal_length_slope=-1.0),), inputs,
                       rig, P_ATM, REF)
    with pytest.raises(ValueError, match="method"):
        PlantConfig("RK45", 1e-8, 0.01, 1e-5, 1e-7, 0.005)
    with pytest.raises(ValueError, match="atol_Pa"):
        PlantConfig("LSODA", 1e-8, 0.0, 1e-5, 1e-7, 0.005)


def test_default_forms_are_realistic(rig):
    forms = {f.catalogue_name: f for f in forms_from_names(
        ["tube_delay", "valve_deadzone", "cylinder_leak", "supply_fluctuation", "spool_lag",
         "heat_transfer"], "AIR37")}
    assert forms["tube_delay"].length_m == 1.0 and forms["tube_delay"].diameter_m == 0.002
    leak = forms["cylinder_leak"]
    k = leak.conductance_kg_per_s_Pa2(BORE, rig.gas)
    assert k == pytest.approx(make_effect("cylinder_leak", form="laminar")
                              .bench_defaults()["leak_conductance_kg_per_s_Pa2"], rel=1e-9, abs=0)
    assert 5e-6 < leak.gap_m < 2e-5  # an air-gap cylinder's clearance
    for f in forms.values():
        assert form_from_dict(json.loads(json.dumps(f.to_dict()))) == f


# ---------------------------------------------------------------- bench
def test_bench_with_forms_writes_valid_recordings_and_names_the_effect(tmp_path):
    forms = forms_from_names(["tube_delay", "supply_fluctuation"], "SMC")
    cfg = BenchConfig("SMC", "valve1", effects_from_names(["cylinder_leak"]),
                      protocol="fixed", duration_s=1.0, seed=3, positions=(0.5,),
                      ranges_V=(5.0,), forms=forms)
    res = run_bench(cfg, tmp_path)
    assert len(res.recordings) == 1
    for p in res.recordings:
        assert check_recording(p) == []
        rec = read_recording(p)
        assert rec.supply_pressure_Pa.min() < P_SUP - 5_000.0  # the droop is measured
    bench = json.loads(res.truth_path.read_text())["bench"]
    assert bench["planted_effects"] == ["cylinder_leak", "tube_delay", "supply_fluctuation"]
    assert [f["form"] for f in bench["planted_forms"]] == ["AcousticTube", "RegulatorDroop"]
    assert bench["planted_forms"][0]["catalogue_name"] == "tube_delay"
    assert tuple(form_from_dict(f) for f in bench["planted_forms"]) == forms
    model, truth = Model.load_card(res.truth_path)
    assert model.effect_names == ("cylinder_leak",)
    tube = forms[0]
    assert truth["dead_volume_m3"] == pytest.approx(2.0e-6 + tube.volume_m3)
    assert bench["plant_dead_volume_m3"] == pytest.approx(2.0e-6)


def test_bench_refuses_an_effect_planted_twice():
    with pytest.raises(ValueError, match="tube_delay"):
        BenchConfig("AIR37", "valve1", effects_from_names(["tube_delay"]),
                    forms=(AcousticTube(1.0),))
    with pytest.raises(TypeError, match="plant form"):
        BenchConfig("AIR37", "valve1", (), forms=(make_effect("tube_delay"),))
