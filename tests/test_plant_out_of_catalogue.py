"""Out-of-catalogue plant forms (pneubayes.bench.forms): effects no catalogue effect
expresses, for the open-form blind sets. Zero strength is the plain plant; each has a
visible, physically right-signed effect; closed-chamber mass balance where cheap."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.bench.forms import (
    OUT_OF_CATALOGUE,
    ArmatureDeadTime,
    BladderVolume,
    BoucWenWall,
    BraidFriction,
    CapillarySensorPort,
    CreepingWall,
    EndCushion,
    EnergisedSealLeak,
    ExhaustCheckValve,
    ExhaustSilencer,
    GasAccumulator,
    HeldArmatureDeadTime,
    InletFlowForce,
    InletFlowLimiter,
    InletJetAtSensor,
    Iso6358Ports,
    LaggingPositionSensor,
    LipSealLeak,
    LoadedWall,
    LowReynoldsPorts,
    MeterOutThrottle,
    PilotFedSpool,
    PilotInletValve,
    PistonSealBypass,
    PressureHeldSolenoid,
    PwmValve,
    QuickExhaustValve,
    ReleaseDelay,
    ReliefValve,
    SaturatingSensor,
    ScoredBarrelLeak,
    SealSpeedLeak,
    SeatLeak,
    SensorBow,
    SensorHysteresis,
    SensorThermalShock,
    SensorZeroDrift,
    SkewedPressureChannel,
    SolenoidGroundShift,
    SpoolHysteresis,
    SpoolLandLeak,
    SpoolSlewLimit,
    SpoolStiction,
    SpoolUnderlap,
    SpringReturnSpool,
    SupplyHose,
    WarmingCoil,
    ZohDriver,
    catalogue_names_of,
    check_forms,
    form_from_dict,
    forms_from_names,
    out_of_catalogue_defaults,
)
from pneubayes.bench.plant import (
    PlantConfig,
    forchheimer_flow,
    iso6358_flow,
    low_reynolds_flow,
    simulate_plant,
)
from pneubayes.physics.orifice import flow_terms
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs

P_ATM, P_SUP, BORE, STROKE = 101_325.0, 551_325.0, 0.009, 0.0375
REF = PlantConfig.reference()
DT = 1e-4
#: Valve shut at commands within +-1.5 V (as tests/test_plant.py): closed chamber at 0 V,
#: the inlet exactly shut at -5 V.
CLOSABLE = {
    "inlet_offset_m2": 0.0, "inlet_a_m2": 5.5e-7, "inlet_b": 3.5, "inlet_c_per_V": 20.0,
    "inlet_d_V": -3.0, "exhaust_offset_m2": 0.0, "exhaust_a_m2": 6e-7, "exhaust_b": 3.5,
    "exhaust_c_per_V": -20.0, "exhaust_d_V": 3.0}
VOLUME = 1.5e-7 + np.pi / 4 * BORE**2 * 0.5 * STROKE  # chamber at half stroke, m^3


@pytest.fixture(scope="module")
def rig():
    return Rig(BORE, P_ATM, P_SUP)


@pytest.fixture(scope="module")
def base():
    return dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)


def _held(duration_s, levels, at=(0.0,)):
    """Fixed piston at half stroke; command ``levels[i]`` from time ``at[i]``."""
    t = np.arange(int(round(duration_s / DT)) + 1) * DT
    u = np.empty(t.size)
    for level, start in zip(levels, at):
        u[t >= start - 1e-12] = level
    return Inputs(t, u, np.full(t.size, 0.5 * STROKE), np.full(t.size, P_SUP))


def _run(params, forms, inputs, rig, p0=P_ATM):
    return simulate_plant(params, forms, inputs, rig, p0, REF).pressure_Pa


def _moving(duration_s=0.6, seed=4):
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration_s / DT)) + 1) * DT
    u = np.repeat(rng.uniform(-5, 5, int(np.ceil(t.size / 500))), 500)[:t.size]
    x = 0.5 * STROKE + 0.4 * STROKE * np.sin(2 * np.pi * 3.0 * t)
    return Inputs(t, u, x, np.full(t.size, P_SUP))


# ---------------------------------------------------------------- the forms themselves
def test_out_of_catalogue_forms_name_no_catalogue_effect_and_round_trip():
    assert set(OUT_OF_CATALOGUE) == {"BladderVolume", "SpoolHysteresis", "ReliefValve",
                                     "InletFlowForce", "LipSealLeak", "ExhaustSilencer",
                                     "ScoredBarrelLeak", "CreepingWall", "PilotInletValve",
                                     "SpoolSlewLimit", "SpoolUnderlap",
                                     "MeterOutThrottle", "SupplyHose", "LowReynoldsPorts",
                                     "SpoolStiction", "SensorBow", "SpringReturnSpool",
                                     "WarmingCoil", "CapillarySensorPort",
                                     "LaggingPositionSensor", "ExhaustCheckValve",
                                     "SeatLeak", "InletFlowLimiter", "ReleaseDelay",
                                     "PistonSealBypass", "EnergisedSealLeak",
                                     "SensorZeroDrift", "EndCushion", "QuickExhaustValve",
                                     "GasAccumulator", "SpoolLandLeak",
                                     "SensorThermalShock", "PwmValve", "ZohDriver",
                                     "SensorHysteresis", "SealSpeedLeak", "BraidFriction",
                                     "SolenoidGroundShift", "PressureHeldSolenoid",
                                     "InletJetAtSensor", "BoucWenWall", "LoadedWall",
                                     "SaturatingSensor", "SkewedPressureChannel",
                                     "PilotFedSpool"}
    for cyl in ("AIR37", "SMC"):
        forms = [out_of_catalogue_defaults(n, cyl) for n in OUT_OF_CATALOGUE]
        assert check_forms(forms) == tuple(forms)  # all of them together: no clash
        assert catalogue_names_of(forms) == []
        for f in forms:
            d = json.loads(json.dumps(f.to_dict()))
            assert d["catalogue_name"] is None and form_from_dict(d) == f
    mixed = forms_from_names(["tube_delay"]) + (ReliefValve(5e5, 1e-11),)
    assert catalogue_names_of(mixed) == ["tube_delay"]
    with pytest.raises(ValueError, match="ReliefValve planted 2 times"):
        check_forms([ReliefValve(5e5, 1e-11), ReliefValve(4e5, 1e-11)])
    with pytest.raises(ValueError, match="catalogue_name 'cylinder_leak' should be None"):
        form_from_dict(dict(LipSealLeak(3e5, 1e-16).to_dict(), catalogue_name="cylinder_leak"))
    with pytest.raises(ValueError, match="unknown form 'Nope'"):
        out_of_catalogue_defaults("Nope")


@pytest.mark.parametrize("cls, kwargs, field", [
    (BladderVolume, {"dV_max_m3": -1e-7}, "dV_max_m3"),
    (BladderVolume, {"dV_max_m3": 1e-7, "pressure_scale_Pa": 0.0}, "pressure_scale_Pa"),
    (SpoolHysteresis, {"half_band_V": float("nan")}, "half_band_V"),
    (SpoolHysteresis, {"half_band_V": 0.1, "time_constant_s": -1.0}, "time_constant_s"),
    (ReliefValve, {"crack_pressure_Pa": 0.0, "flow_coefficient_kg_per_s_Pa1p5": 1e-11},
     "crack_pressure_Pa"),
    (ReliefValve, {"crack_pressure_Pa": 4e5, "flow_coefficient_kg_per_s_Pa1p5": -1.0},
     "flow_coefficient_kg_per_s_Pa1p5"),
    (InletFlowForce, {"flow_force_coefficient": True}, "flow_force_coefficient"),
    (LipSealLeak, {"seal_pressure_Pa": "3e5", "conductance_kg_per_s_Pa2": 1e-16},
     "seal_pressure_Pa"),
    (LipSealLeak, {"seal_pressure_Pa": 3e5, "conductance_kg_per_s_Pa2": float("inf")},
     "conductance_kg_per_s_Pa2"),
    (ExhaustSilencer, {"back_pressure_Pa": -1.0}, "back_pressure_Pa"),
    (ExhaustSilencer, {"back_pressure_Pa": 5e4, "laminar_fraction": 1.5},
     "laminar_fraction"),
    (ExhaustSilencer, {"back_pressure_Pa": 5e4, "volume_m3": 0.0}, "volume_m3"),
    (ScoredBarrelLeak, {"start_m": 0.01, "end_m": 0.02, "area_m2": -1e-8}, "area_m2"),
    (CreepingWall, {"compliance_m3_per_Pa": float("nan")}, "compliance_m3_per_Pa"),
    (CreepingWall, {"compliance_m3_per_Pa": 1e-12, "time_constant_s": 0.0},
     "time_constant_s"),
    (PilotInletValve, {"min_pressure_difference_Pa": -5.0}, "min_pressure_difference_Pa"),
    (PilotInletValve, {"min_pressure_difference_Pa": 4e4, "transition_fraction": 2.5},
     "transition_fraction"),
    (SupplyHose, {"restriction_area_m2": -1e-6}, "restriction_area_m2"),
    (SupplyHose, {"restriction_area_m2": 1e-6, "volume_m3": 0.0}, "volume_m3"),
    (LowReynoldsPorts, {"critical_reynolds": float("nan")}, "critical_reynolds"),
    (SpoolStiction, {"breakaway_V": -0.1}, "breakaway_V"),
    (SpoolStiction, {"breakaway_V": 0.1, "stop_V": 0.2}, "stop_V"),
    (SensorBow, {"bow_Pa": float("inf")}, "bow_Pa"),
    (SaturatingSensor, {"full_scale_Pa": 0.0}, "full_scale_Pa"),
    (SaturatingSensor, {"full_scale_Pa": float("nan")}, "full_scale_Pa"),
    (SaturatingSensor, {"full_scale_Pa": 3e5, "knee_Pa": 0.0}, "knee_Pa"),
    (SkewedPressureChannel, {"delay_s": -1e-3}, "delay_s"),
    (SensorBow, {"bow_Pa": 1e3, "span_Pa": 0.0}, "span_Pa"),
    (SpringReturnSpool, {"rise_time_constant_s": -1e-3}, "rise_time_constant_s"),
    (SpringReturnSpool, {"rise_time_constant_s": 1e-3}, "fall_time_constant_s"),
    (WarmingCoil, {"resistance_rise": float("nan")}, "resistance_rise"),
    (WarmingCoil, {"resistance_rise": 0.1, "time_constant_s": 0.0}, "time_constant_s"),
    (WarmingCoil, {"resistance_rise": 0.1, "command_min_V": float("inf")}, "command_min_V"),
    (CapillarySensorPort, {"time_constant_s": -1.0}, "time_constant_s"),
    (CapillarySensorPort, {"time_constant_s": 1e-3, "reference_pressure_Pa": 0.0},
     "reference_pressure_Pa"),
    (LaggingPositionSensor, {"time_constant_s": float("nan")}, "time_constant_s"),
    (ExhaustCheckValve, {"crack_pressure_Pa": -1.0}, "crack_pressure_Pa"),
    (SeatLeak, {"area_m2": float("inf")}, "area_m2"),
    (SeatLeak, {"area_m2": 1e-8, "laminar_drop_Pa": 0.0}, "laminar_drop_Pa"),
    (InletFlowLimiter, {"max_flow_kg_per_s": -1e-4}, "max_flow_kg_per_s"),
    (ReleaseDelay, {"delay_s": float("nan")}, "delay_s"),
    (ArmatureDeadTime, {"travel_s": -1e-3}, "travel_s"),
    (HeldArmatureDeadTime, {"travel_s": 1e-3, "limit_gauge_Pa": float("nan")},
     "limit_gauge_Pa"),
    (ArmatureDeadTime, {"travel_s": 1e-3, "reference_gauge_Pa": 0.0}, "reference_gauge_Pa"),
    (PistonSealBypass, {"conductance_kg_per_s_Pa2": 1e-16, "vent_area_m2": -1e-8,
                        "opposite_volume_m3": 1e-6}, "vent_area_m2"),
    (EnergisedSealLeak, {"conductance_kg_per_s_Pa2": 1e-15, "energising_pressure_Pa": 0.0},
     "energising_pressure_Pa"),
    (EndCushion, {"length_m": 0.005, "needle_area_m2": 1e-7, "edge_m": 0.0}, "edge_m"),
    (QuickExhaustValve, {"exhaust_area_m2": -1e-6}, "exhaust_area_m2"),
    (QuickExhaustValve, {"exhaust_area_m2": 1e-6, "line_volume_m3": 0.0}, "line_volume_m3"),
    (GasAccumulator, {"volume_m3": float("nan")}, "volume_m3"),
    (GasAccumulator, {"volume_m3": 1e-6, "polytropic_index": 1.6}, "polytropic_index"),
    (SpoolLandLeak, {"conductance_kg_per_s_Pa2": -1e-16}, "conductance_kg_per_s_Pa2"),
    (SpoolLandLeak, {"conductance_kg_per_s_Pa2": 1e-16, "overlap_scale_V": 0.0},
     "overlap_scale_V"),
    (SensorThermalShock, {"gain": float("inf")}, "gain"),
    (PwmValve, {"frequency_Hz": -50.0}, "frequency_Hz"),
    (PwmValve, {"frequency_Hz": 50.0, "full_command_V": 0.0}, "full_command_V"),
    (ZohDriver, {"update_period_s": float("nan")}, "update_period_s"),
    (ZohDriver, {"update_period_s": 0.01, "phase": 1.0}, "phase"),
    (SensorHysteresis, {"half_width_Pa": -1.0}, "half_width_Pa"),
    (SensorHysteresis, {"half_width_Pa": 1e3, "plays": 2.0}, "plays"),
    (SealSpeedLeak, {"conductance_kg_per_s_Pa2": float("inf")}, "conductance_kg_per_s_Pa2"),
    (SealSpeedLeak, {"conductance_kg_per_s_Pa2": 1e-16, "reference_speed_m_per_s": 0.0},
     "reference_speed_m_per_s"),
    (SensorThermalShock, {"gain": 0.02, "time_constant_s": -0.1}, "time_constant_s"),
    (BraidFriction, {"compliance_m3_per_Pa": -1e-12}, "compliance_m3_per_Pa"),
    (BraidFriction, {"compliance_m3_per_Pa": 1e-12, "friction_band_Pa": 0.0},
     "friction_band_Pa"),
    (BoucWenWall, {"elastic_compliance_m3_per_Pa": -1e-12, "loop_volume_m3": 1e-7},
     "elastic_compliance_m3_per_Pa"),
    (BoucWenWall, {"elastic_compliance_m3_per_Pa": 0.0, "loop_volume_m3": 1e-7,
                   "memory_Pa": 0.0}, "memory_Pa"),
    (BoucWenWall, {"elastic_compliance_m3_per_Pa": 0.0, "loop_volume_m3": 1e-7,
                   "exponent": 0.5}, "exponent"),
    (SolenoidGroundShift, {"shift_Pa": float("nan")}, "shift_Pa"),
    (SolenoidGroundShift, {"shift_Pa": 1e3, "time_constant_s": 0.0}, "time_constant_s"),
    (PressureHeldSolenoid, {"time_constant_s": -1e-3}, "time_constant_s"),
    (PressureHeldSolenoid, {"time_constant_s": 1e-3, "slowing_per_atm": float("inf")},
     "slowing_per_atm"),
    (InletJetAtSensor, {"shift_Pa": float("inf")}, "shift_Pa"),
    (InletJetAtSensor, {"shift_Pa": 1e3, "reference_flow_kg_per_s": 0.0},
     "reference_flow_kg_per_s"),
    (LoadedWall, {"compliance_m3_per_Pa": -1e-12}, "compliance_m3_per_Pa"),
    (LoadedWall, {"compliance_m3_per_Pa": 1e-12, "damping_ratio": 0.0}, "damping_ratio"),
    (PilotFedSpool, {"feedback_V_per_bar": -0.1}, "feedback_V_per_bar"),
    (PilotFedSpool, {"feedback_V_per_bar": 0.1, "pilot_time_constant_s": 0.0},
     "pilot_time_constant_s"),
])
def test_forms_validate_their_fields_by_name(cls, kwargs, field):
    with pytest.raises(ValueError, match=rf"{cls.__name__}\.{field} must be"):
        cls(**kwargs)


def test_bench_plants_no_catalogue_effect_for_an_out_of_catalogue_form(tmp_path):
    relief = out_of_catalogue_defaults("ReliefValve")
    forms = (forms_from_names(["tube_delay"])[0], relief)
    res = run_bench(BenchConfig("AIR37", "valve1", protocol="fixed", duration_s=0.3,
                                positions=(0.5,), ranges_V=(5.0,), forms=forms), tmp_path)
    bench = json.loads(res.truth_path.read_text())["bench"]
    assert bench["planted_effects"] == ["tube_delay"]
    assert bench["out_of_catalogue_forms"] == ["ReliefValve"]
    assert form_from_dict(bench["planted_forms"][1]) == relief


# ---------------------------------------------------------------- zero strength
@pytest.mark.parametrize("form", [
    BladderVolume(dV_max_m3=0.0), SpoolHysteresis(half_band_V=0.0),
    ReliefValve(crack_pressure_Pa=2e5, flow_coefficient_kg_per_s_Pa1p5=0.0),
    InletFlowForce(flow_force_coefficient=0.0),
    LipSealLeak(seal_pressure_Pa=2e5, conductance_kg_per_s_Pa2=0.0),
    ExhaustSilencer(back_pressure_Pa=0.0),
    ScoredBarrelLeak(start_m=0.3 * STROKE, end_m=0.6 * STROKE, area_m2=0.0),
    CreepingWall(compliance_m3_per_Pa=0.0), PilotInletValve(min_pressure_difference_Pa=0.0),
    SpoolSlewLimit(slew_rate_V_per_s=0.0), SpoolUnderlap(area_m2=0.0),
    MeterOutThrottle(needle_area_m2=0.0), SupplyHose(restriction_area_m2=0.0),
    LowReynoldsPorts(critical_reynolds=0.0), SpoolStiction(breakaway_V=0.0),
    SpringReturnSpool(rise_time_constant_s=0.0), WarmingCoil(resistance_rise=0.0),
    ExhaustCheckValve(crack_pressure_Pa=0.0), SeatLeak(area_m2=0.0),
    InletFlowLimiter(max_flow_kg_per_s=0.0), ReleaseDelay(delay_s=0.0),
    PistonSealBypass(conductance_kg_per_s_Pa2=0.0, vent_area_m2=3e-8,
                     opposite_volume_m3=3e-6),
    EnergisedSealLeak(conductance_kg_per_s_Pa2=0.0, energising_pressure_Pa=1.5e5),
    EndCushion(length_m=0.1 * STROKE, needle_area_m2=0.0, edge_m=0.02 * STROKE),
    QuickExhaustValve(exhaust_area_m2=0.0), GasAccumulator(volume_m3=0.0),
    SpoolLandLeak(conductance_kg_per_s_Pa2=0.0), PwmValve(frequency_Hz=0.0),
    ZohDriver(update_period_s=0.0), SealSpeedLeak(conductance_kg_per_s_Pa2=0.0),
    BraidFriction(compliance_m3_per_Pa=0.0), PressureHeldSolenoid(time_constant_s=0.0),
    BoucWenWall(elastic_compliance_m3_per_Pa=0.0, loop_volume_m3=0.0),
    LoadedWall(compliance_m3_per_Pa=0.0), PilotFedSpool(feedback_V_per_bar=0.0)],
    ids=lambda f: type(f).__name__)
def test_zero_strength_is_the_plant_without_the_form(rig, base, form):
    inputs = _moving()
    plain = _run(base, (), inputs, rig)
    np.testing.assert_array_equal(_run(base, (form,), inputs, rig), plain)
    default = out_of_catalogue_defaults(type(form).__name__)
    assert np.max(np.abs(_run(base, (default,), inputs, rig) - plain)) > 2e3  # it matters


# ---------------------------------------------------------------- physical behaviour
def _time_to(p, level):
    return int(np.argmax(p >= level)) * DT


def test_relief_valve_caps_a_full_inlet_fill_near_its_cracking_pressure(rig, base):
    relief = out_of_catalogue_defaults("ReliefValve")
    inputs = _held(1.0, (5.0,))
    plain, capped = _run(base, (), inputs, rig), _run(base, (relief,), inputs, rig)
    assert plain[-1] > P_SUP - 5e3  # without: the chamber reaches the supply
    pc = relief.crack_pressure_Pa
    assert pc < capped[-1] < pc + 60e3  # with: held a little above the cracking pressure
    below = plain < pc - 1e3
    # shut below cracking (to the solver's tolerance: a step may straddle the crossing)
    np.testing.assert_allclose(capped[below], plain[below], rtol=0, atol=0.01)


@pytest.mark.parametrize("name", ["ReliefValve", "LipSealLeak"])
def test_a_closed_chamber_vents_to_the_threshold_at_the_forms_mass_flow(rig, name):
    """Valve shut: the pressure falls only above the threshold, never below it, at
    dp/dt = -kappa Rs T mdot(p) / V (eq. 5, adiabatic, fixed volume)."""
    form = out_of_catalogue_defaults(name)
    threshold = getattr(form, "crack_pressure_Pa", None) or form.seal_pressure_Pa
    inputs = _held(0.5, (0.0,))
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    below = _run(params, (form,), inputs, rig, p0=threshold - 20e3)
    np.testing.assert_allclose(below, threshold - 20e3, rtol=0, atol=1e-6)
    p = _run(params, (form,), inputs, rig, p0=threshold + 80e3)
    assert np.all(np.diff(p) <= 1e-6) and threshold < p[-1] < threshold + 40e3
    gas = rig.gas
    over = 0.5 * (p[0] + p[1]) - threshold  # the first step's midpoint
    mdot = (form.flow_coefficient_kg_per_s_Pa1p5 * over**1.5 if name == "ReliefValve"
            else form.conductance_kg_per_s_Pa2 * over**2)
    want = -gas.heat_capacity_ratio * gas.specific_gas_constant_J_per_kg_K \
        * gas.temperature_K * mdot / VOLUME
    got = (p[1] - p[0]) / DT
    assert got == pytest.approx(want, rel=0.01)


def test_lip_seal_leaks_only_above_its_lift_pressure_on_a_fill(rig, base):
    inputs = _held(1.0, (5.0,))
    plain = _run(base, (), inputs, rig)
    tight = LipSealLeak(seal_pressure_Pa=P_SUP + 1e4, conductance_kg_per_s_Pa2=1e-14)
    np.testing.assert_array_equal(_run(base, (tight,), inputs, rig), plain)
    leaky = _run(base, (out_of_catalogue_defaults("LipSealLeak"),), inputs, rig)
    # the leak (0.03 g/s) holds the filled chamber below the supply, by more than the
    # bench's 500 Pa noise even against the full inlet
    assert plain[-1] - leaky[-1] > 500.0


def test_bladder_slows_the_fill_and_keeps_its_end_and_its_mass(rig, base):
    inputs = _held(1.0, (5.0,))
    bladder = out_of_catalogue_defaults("BladderVolume")
    plain, soft = _run(base, (), inputs, rig), _run(base, (bladder,), inputs, rig)
    half = P_ATM + 0.5 * (P_SUP - P_ATM)
    assert _time_to(soft, half) > 1.2 * _time_to(plain, half)
    assert soft[-1] == pytest.approx(plain[-1], abs=2e3)  # same steady state: the supply
    # closed chamber at fixed piston: p V(p)^kappa is conserved (adiabatic, no flow)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    t = np.arange(2001) * DT
    x = 0.5 * STROKE + 0.3 * STROKE * np.sin(2 * np.pi * 5.0 * t)
    moving = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    p = _run(params, (bladder,), moving, rig, p0=3e5)
    dv = bladder.dV_max_m3 * (1 - np.exp(-(p - P_ATM) / bladder.pressure_scale_Pa))
    inv = p * (1.5e-7 + np.pi / 4 * BORE**2 * x + dv) ** rig.gas.heat_capacity_ratio
    assert np.ptp(p) > 5e4 and np.ptp(inv) / inv[0] < 1e-5


@pytest.mark.slow
def test_inlet_flow_force_slows_the_fill_and_leaves_the_exhaust(rig):
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    ff = out_of_catalogue_defaults("InletFlowForce")
    fill = _held(0.5, (5.0,))
    plain, forced = _run(params, (), fill, rig), _run(params, (ff,), fill, rig)
    half = P_ATM + 0.5 * (P_SUP - P_ATM)
    assert _time_to(forced, half) > 1.15 * _time_to(plain, half)
    # at -5 V the inlet is exactly shut: the flow force has nothing to act on
    vent = _held(0.5, (-5.0,))
    np.testing.assert_array_equal(_run(params, (ff,), vent, rig, p0=5e5),
                                  _run(params, (), vent, rig, p0=5e5))


def test_spool_play_holds_inside_its_band_and_remembers_the_direction(rig, base):
    play = out_of_catalogue_defaults("SpoolHysteresis")  # half-band 0.15 V
    # a command step smaller than the band moves nothing
    small = _held(0.6, (0.5, 0.6), at=(0.0, 0.2))
    steady = _held(0.6, (0.5,))
    np.testing.assert_allclose(_run(base, (play,), small, rig),
                               _run(base, (play,), steady, rig), rtol=0, atol=1.0)
    assert np.max(np.abs(_run(base, (), small, rig) - _run(base, (), steady, rig))) > 1e3
    # the same final command approached from below and from above: without play the
    # same end, with play the spool stays b short of it on the side it came from
    up, down = _held(1.5, (-2.0, 0.3), at=(0.0, 0.5)), _held(1.5, (2.0, 0.3), at=(0.0, 0.5))
    assert _run(base, (), up, rig)[-1] == pytest.approx(_run(base, (), down, rig)[-1], abs=500)
    from_below, from_above = _run(base, (play,), up, rig)[-1], _run(base, (play,), down, rig)[-1]
    assert from_above - from_below > 1e4  # more inlet opening when it came from above


def test_bladder_below_atmosphere_collapses_stiffer_and_bounded(rig):
    """Valve shut while the piston draws the chamber open from atmosphere: the pressure
    falls below it, less deep with the bladder (it gives volume back, at most a quarter
    of dV_max), and p V^kappa still holds."""
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    t = np.arange(3001) * DT
    x = 0.3 * STROKE + 0.3 * STROKE * np.sin(np.pi * t / 0.6) ** 2
    inputs = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    bladder = BladderVolume(dV_max_m3=7e-7, pressure_scale_Pa=80e3)  # the drawn extremes
    plain, soft = _run(params, (), inputs, rig), _run(params, (bladder,), inputs, rig)
    assert plain.min() < 0.6 * P_ATM
    assert plain.min() + 5e3 < soft.min() < P_ATM
    y = (soft - P_ATM) / bladder.pressure_scale_Pa
    dv = bladder.dV_max_m3 * y / (1 - 4 * y)
    assert np.all(dv > -bladder.dV_max_m3 / 4)
    inv = soft * (1.5e-7 + np.pi / 4 * BORE**2 * x + dv) ** rig.gas.heat_capacity_ratio
    assert np.ptp(inv) / inv[0] < 1e-5


# ---------------------------------------------------------------- the second blind set
def test_silencer_slows_the_exhaust_and_its_element_law_inverts():
    sil = out_of_catalogue_defaults("ExhaustSilencer")
    r_l, r_t = sil.resistances
    for m in (-2e-3, -1e-4, 0.0, 3e-5, 1e-3, 5e-3):
        assert forchheimer_flow(r_l * m + r_t * m * abs(m), r_l, r_t) == pytest.approx(m, abs=1e-15)
    assert r_l * 1e-3 + r_t * 1e-6 == pytest.approx(sil.back_pressure_Pa)


@pytest.mark.slow  # the bench's fine plant over seconds: ~30-50 s
def test_silencer_back_pressure_slows_a_vent_to_the_same_end_and_spares_the_fill(rig):
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    sil = ExhaustSilencer(back_pressure_Pa=150e3, laminar_fraction=0.5, volume_m3=2e-6)
    vent = _held(1.0, (-5.0,))
    plain, muffled = _run(params, (), vent, rig, p0=5e5), _run(params, (sil,), vent, rig, p0=5e5)
    # the port is choked down to about twice the body's pressure: the back-pressure
    # tells at the vent's end, which it slows
    level = P_ATM + 0.01 * (5e5 - P_ATM)
    assert _time_to(-muffled, -level) > 1.05 * _time_to(-plain, -level)
    assert np.all(muffled >= plain - 1.0)  # never below the plain vent: back-pressure
    assert np.max(muffled - plain) > 2e3
    assert muffled[-1] == pytest.approx(P_ATM, abs=300.0)  # and still to the atmosphere
    # at +5 V the exhaust is shut: the silencer has nothing to act on
    fill = _held(0.3, (5.0,))
    np.testing.assert_allclose(_run(params, (sil,), fill, rig), _run(params, (), fill, rig),
                               rtol=0, atol=0.05)


def test_scored_barrel_leaks_on_the_score_only_at_the_orifice_law(rig):
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    score = ScoredBarrelLeak(start_m=0.4 * STROKE, end_m=0.6 * STROKE, area_m2=1e-7,
                             edge_m=0.02 * STROKE)
    assert score.window(0.5 * STROKE) == 1.0 and score.window(0.2 * STROKE) == 0.0
    assert 0.0 < score.window(0.4 * STROKE) < 1.0
    with pytest.raises(ValueError, match=r"ScoredBarrelLeak.end_m \(0.0105\) must exceed"):
        ScoredBarrelLeak(start_m=0.01, end_m=0.0105, area_m2=1e-8)
    # valve shut at 0 V, piston on the score (half stroke): the chamber vents at
    # dp/dt = -kappa Rs T a f(p, P_atm) / V
    inputs = _held(0.3, (0.0,))
    p = _run(params, (score,), inputs, rig, p0=4e5)
    assert np.all(np.diff(p) <= 0.01) and p[-1] < 4e5 - 5e4
    g = rig.gas
    mid = 0.5 * (p[0] + p[1])
    f = flow_terms(mid, P_ATM, g.alpha_s_per_m, g.beta_s_per_m, g.theta,
                   g.heat_capacity_ratio)[0]
    want = -g.heat_capacity_ratio * g.specific_gas_constant_J_per_kg_K * g.temperature_K \
        * score.area_m2 * f / VOLUME
    assert (p[1] - p[0]) / DT == pytest.approx(want, rel=0.01)
    # off the score the barrel is sound: the chamber holds its pressure exactly
    t = inputs.time_s
    off = Inputs(t, inputs.command_V, np.full(t.size, 0.2 * STROKE), inputs.supply_pressure_Pa)
    np.testing.assert_array_equal(_run(params, (score,), off, rig, p0=4e5),
                                  _run(params, (), off, rig, p0=4e5))


@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_creeping_wall_sags_after_a_fill_recovers_after_a_vent_and_rests_in_equilibrium(rig):
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    wall = CreepingWall(compliance_m3_per_Pa=0.1 * np.pi / 4 * BORE**2 * STROKE / 4.5e5,
                        time_constant_s=0.1)
    # closed from the start, in equilibrium with its pressure: nothing moves
    rest = _run(params, (wall,), _held(0.3, (0.0,)), rig, p0=4e5)
    np.testing.assert_allclose(rest, 4e5, rtol=0, atol=1e-3)
    # filled for 0.15 s, then shut: the plain chamber holds, the wall gives and the
    # pressure sags monotonically towards a new equilibrium
    fill = _held(1.0, (5.0, 0.0), at=(0.0, 0.15))
    plain, soft = _run(params, (), fill, rig), _run(params, (wall,), fill, rig)
    shut = int(round(0.16 / DT))
    assert np.ptp(plain[shut:]) < 10.0
    assert np.all(np.diff(soft[shut:]) <= 1e-6) and soft[shut] - soft[-1] > 5e3
    assert abs(soft[-1] - soft[-200]) < 0.05 * (soft[shut] - soft[-1])  # settled
    # vented from 4 bar, then shut: the wall springs back and the pressure rises
    vent = _held(1.0, (-5.0, 0.0), at=(0.0, 0.02))
    p = _run(params, (wall,), vent, rig, p0=4e5)
    shut = int(round(0.03 / DT))
    assert np.all(np.diff(p[shut:]) >= -1e-6) and p[-1] - p[shut] > 2e3


@pytest.mark.slow  # the bench's fine plant over seconds: ~30-50 s
def test_pilot_inlet_stalls_a_fill_short_of_the_supply_and_spares_the_exhaust(rig):
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    pilot = PilotInletValve(min_pressure_difference_Pa=50e3, transition_fraction=0.5)
    assert pilot.opening(0.0) == 0.0 and pilot.opening(80e3) == 1.0
    assert pilot.opening(-80e3) == 1.0 and 0.0 < pilot.opening(50e3) < 1.0
    fill = _held(1.0, (5.0,))
    plain, piloted = _run(params, (), fill, rig), _run(params, (pilot,), fill, rig)
    assert plain[-1] > P_SUP - 2e3
    # stalled inside the transition band below the supply
    assert P_SUP - 50e3 - 12.5e3 < piloted[-1] < P_SUP - 50e3 + 12.5e3
    assert np.all(piloted <= plain + 1.0)
    # at -5 V the inlet is exactly shut: the pilot stage has nothing to act on
    vent = _held(0.5, (-5.0,))
    np.testing.assert_array_equal(_run(params, (pilot,), vent, rig, p0=5e5),
                                  _run(params, (), vent, rig, p0=5e5))


@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_iso6358_ports_choke_at_their_critical_ratio_and_fill_slower_near_the_supply(rig):
    """The ISO 6358 law: beta p_up at ratios <= b, its ellipse above (0 at ratio 1),
    reversed flow swapping the ends; b = 0.528, m = 0.5 within 6 % of the isentropic
    eqs. 1-3 over the subsonic range; with b = 0.3 a fill approaches the supply later."""
    g = rig.gas
    beta = g.beta_s_per_m
    assert iso6358_flow(5e5, 1e5, beta, 0.3, 0.5) == pytest.approx(beta * 5e5, rel=1e-12)
    assert iso6358_flow(5e5, 5e5, beta, 0.3, 0.5) == 0.0
    assert iso6358_flow(3e5, 4e5, beta, 0.3, 0.5) == -iso6358_flow(4e5, 3e5, beta, 0.3, 0.5)
    r = 0.3 + 0.7 * np.array([0.25, 0.5, 0.75])
    z = (r - 0.3) / 0.7
    np.testing.assert_allclose([iso6358_flow(5e5, 5e5 * q, beta, 0.3, 0.5) for q in r],
                               beta * 5e5 * np.sqrt(1 - z * z), rtol=1e-12)
    for q in np.linspace(0.53, 0.98, 10):
        thin = flow_terms(5e5, 5e5 * q, g.alpha_s_per_m, beta, g.theta, g.heat_capacity_ratio)[0]
        assert iso6358_flow(5e5, 5e5 * q, beta, 0.528, 0.5) == pytest.approx(thin, rel=0.06,
                                                                            abs=0.02 * beta * 5e5)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    fill = _held(0.06, (5.0,))  # (short: a chamber at the supply makes the solver crawl)
    plain = _run(params, (), fill, rig)
    iso = _run(params, (Iso6358Ports(critical_pressure_ratio=0.3),), fill, rig)
    assert _time_to(iso, P_SUP - 20e3) > 1.08 * _time_to(plain, P_SUP - 20e3)  # (1.10 x)


@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_slew_limited_spool_is_the_plain_valve_under_a_ramped_command(rig):
    """A large step through a spool that slews at r (with a negligible small-step lag)
    is the plain valve under the command ramped at r."""
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    r = 100.0
    slew = SpoolSlewLimit(slew_rate_V_per_s=r, time_constant_s=2e-5)
    step = _held(0.15, (-5.0, 5.0), at=(0.0, 0.02))
    t = step.time_s
    ramp = np.clip(-5.0 + r * (t - 0.02), -5.0, 5.0)
    ramped = Inputs(t, np.where(t < 0.02, -5.0, ramp), step.position_m,
                    step.supply_pressure_Pa)
    limited, plain_ramp = _run(params, (slew,), step, rig), _run(params, (), ramped, rig)
    plain_step = _run(params, (), step, rig)
    span = np.ptp(plain_step)
    assert np.max(np.abs(limited - plain_ramp)) < 0.02 * span
    assert np.max(np.abs(limited - plain_step)) > 0.3 * span  # the ramp matters
    with pytest.raises(ValueError, match="SpoolSlewLimit is the spool's stage"):
        _run(params, (slew, forms_from_names(["spool_lag"])[0]), step, rig)


def test_underlapped_spool_holds_a_chamber_between_supply_and_atmosphere(rig):
    """At the null both ports leak equally: the chamber settles where the inflow from
    the supply equals the outflow to the atmosphere (closed form by root finding); away
    from the null the underlap is gone and the plain valve is exact."""
    from scipy.optimize import brentq

    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    under = SpoolUnderlap(area_m2=5e-8, width_V=0.5)
    assert under.opening(0.0) == 5e-8 and under.opening(0.6) == 0.0
    g = rig.gas
    args = (g.alpha_s_per_m, g.beta_s_per_m, g.theta, g.heat_capacity_ratio)
    p_star = brentq(lambda q: flow_terms(P_SUP, q, *args)[0] - flow_terms(q, P_ATM, *args)[0],
                    P_ATM + 1.0, P_SUP - 1.0)
    for p0 in (P_ATM, P_SUP - 1e3):
        p = _run(params, (under,), _held(1.5, (0.0,)), rig, p0=p0)
        assert p[-1] == pytest.approx(p_star, abs=50.0)
    away = _held(0.2, (2.0,))  # beyond the underlap's width, the ports still shut
    np.testing.assert_array_equal(_run(params, (under,), away, rig, p0=3e5),
                                  _run(params, (), away, rig, p0=3e5))


@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_meter_out_throttle_slows_the_vent_not_the_fill_and_keeps_the_mass(rig):
    """The vent leaves through the needle (much slower), the fill through the open check
    (a little slower); both end where the plain valve does; a closed chamber and
    fitting at rest stay at rest."""
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    mo = MeterOutThrottle(needle_area_m2=1e-7, check_area_m2=2e-6, crack_pressure_Pa=10e3,
                          volume_m3=5e-7)
    assert mo.check_opening(0.0) == 0.0 and mo.check_opening(20e3) == 1.0
    fill = _held(0.05, (5.0,))  # (short: a chamber at the supply makes the solver crawl)
    plain, thr = _run(params, (), fill, rig), _run(params, (mo,), fill, rig)
    level = P_SUP - 30e3
    assert _time_to(plain, level) <= _time_to(thr, level) < 1.5 * _time_to(plain, level)
    assert abs(thr[-1] - plain[-1]) < 15e3  # the check's cracking pressure short at most
    vent = _held(0.1, (-5.0,))
    plain_v, thr_v = _run(params, (), vent, rig, p0=5e5), _run(params, (mo,), vent, rig,
                                                                 p0=5e5)
    down = lambda p: int(np.argmax(p <= 2e5)) * DT  # noqa: E731
    assert thr_v[-1] < 2e5 and down(thr_v) > 3.0 * down(plain_v)  # (6 x)
    rest = _run(params, (mo,), _held(0.2, (0.0,)), rig, p0=3e5)
    np.testing.assert_allclose(rest, 3e5, rtol=0, atol=1e-3)
    with pytest.raises(ValueError, match="beside an AcousticTube"):
        _run(params, (mo, forms_from_names(["tube_delay"])[0]), fill, rig)


# ---------------------------------------------------------------- the fourth set's forms
@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_a_supply_hose_starves_a_fill_unseen_by_the_supply_sensor(rig):
    """A full-inlet fill through a hose is slower than through the regulator alone and
    ends at the supply; the supply column stays the regulator's; a restriction 18 x the
    valve's port is nearly no hose at all (0.05 % of the span)."""
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    fill = _held(0.04, (5.0,))
    plain = simulate_plant(params, (), fill, rig, P_ATM, REF)
    hose = SupplyHose(restriction_area_m2=4e-7, volume_m3=2e-6)
    starved = simulate_plant(params, (hose,), fill, rig, P_ATM, REF)
    level = P_SUP - 50e3
    assert _time_to(starved.pressure_Pa, level) > 1.3 * _time_to(plain.pressure_Pa, level)
    assert starved.pressure_Pa[-1] > P_SUP - 5e3
    np.testing.assert_allclose(starved.supply_at_valve_Pa, P_SUP, rtol=0, atol=1e-6)
    # (a wide restriction into a small hose is stiff enough to make the solver crawl)
    wide = _run(params, (SupplyHose(restriction_area_m2=1e-5, volume_m3=5e-5),), fill, rig)
    assert np.max(np.abs(wide - plain.pressure_Pa)) < 1e-3 * (P_SUP - P_ATM)


def test_low_reynolds_ports_lose_the_small_flows_and_slow_the_approach(rig, base):
    """The factor Re / (Re + Re_c): a half at Re = Re_c, near 1 far above; a fill's
    choked start is barely slowed, its last approach to the supply much more (the flow
    falls as the square of the thin port's there)."""
    mu, area, re_c = 1.81e-5, 1e-7, 400.0
    q_c = re_c * np.pi * mu * np.sqrt(4 * area / np.pi) / 4
    assert low_reynolds_flow(q_c, area, re_c, mu) == pytest.approx(0.5 * q_c, rel=1e-12)
    assert low_reynolds_flow(-q_c, area, re_c, mu) == pytest.approx(-0.5 * q_c, rel=1e-12)
    assert low_reynolds_flow(1e3 * q_c, area, re_c, mu) == pytest.approx(1e3 * q_c, rel=2e-3)
    assert low_reynolds_flow(0.0, area, re_c, mu) == 0.0
    fill = _held(0.3, (5.0,))
    plain = _run(base, (), fill, rig)
    slow = _run(base, (LowReynoldsPorts(critical_reynolds=2000.0),), fill, rig)
    early = P_ATM + 150e3
    assert _time_to(slow, early) < 1.1 * _time_to(plain, early)
    assert P_SUP - slow[-1] > 1.5 * (P_SUP - plain[-1]) > 0.0  # (520 against 260 Pa short)


@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_a_sticking_spool_ignores_small_steps_and_stops_short_of_large_ones(rig):
    stick = SpoolStiction(breakaway_V=0.15, stop_V=0.05)
    got = stick.targets([0.0, 0.1, 0.2, 1.0, 0.95, -1.0, -1.0])
    np.testing.assert_allclose(got, [0.0, 0.0, 0.15, 0.95, 0.95, -0.95, -0.95], atol=1e-12)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    # the inlet opens steeply about 3 V (1.7e-8 m^2 at 3 V, 4e-7 at 3.12): a step
    # 3.0 -> 3.12 V stays stuck at 3 V, one to 3.3 V slides to 3.25 V
    small = _held(0.05, (3.0, 3.12), at=(0.0, 0.01))
    stuck = _run(params, (stick,), small, rig, p0=2e5)
    np.testing.assert_array_equal(stuck, _run(params, (), _held(0.05, (3.0,)), rig, p0=2e5))
    assert np.max(np.abs(_run(params, (), small, rig, p0=2e5) - stuck)) > 20e3
    large = _held(0.05, (3.0, 3.3), at=(0.0, 0.01))
    short = Inputs(large.time_s, np.where(large.time_s < 0.01 - 1e-12, 3.0, 3.25),
                   large.position_m, large.supply_pressure_Pa)
    np.testing.assert_array_equal(_run(params, (stick,), large, rig, p0=2e5),
                                  _run(params, (), short, rig, p0=2e5))


def _read_plain_and_through(tmp_path, form, duration_s=1.5):
    """Noise-free AIR37 / valve 1 recordings of one fixed-piston plan (50 % of the stroke,
    +-5 V), read plainly and through the reading ``form`` (the supply hose off in both):
    ``(plain, through)``."""
    from pneubayes.bench.sensors import SensorChain
    from pneubayes.io import read_recording

    quiet = SensorChain(pressure_noise_Pa=0.0, supply_noise_Pa=0.0, position_noise_m=0.0)
    kw = dict(protocol="fixed", duration_s=duration_s, positions=(0.5,), ranges_V=(5.0,),
              sensor=quiet, forms=(SupplyHose(restriction_area_m2=0.0),))
    res = [run_bench(BenchConfig("AIR37", "valve1", **kw), tmp_path / "plain"),
           run_bench(BenchConfig("AIR37", "valve1", **dict(kw, forms=(form,))),
                     tmp_path / "through")]
    return tuple(read_recording(r.recordings[0]) for r in res)


def test_a_bowed_sensor_reads_true_at_its_ends_and_off_at_mid_range(tmp_path):
    bow = SensorBow(bow_Pa=-2000.0, span_Pa=6e5)
    p = np.array([P_ATM - 1e4, P_ATM, P_ATM + 1.5e5, P_ATM + 3e5, P_ATM + 6e5, P_ATM + 7e5])
    np.testing.assert_allclose(bow.read(p, P_ATM) - p, [0, 0, -1500, -2000, 0, 0], atol=1e-9)
    # the bench reads its recordings through it (noise-free: the difference is the bow)
    a, b = _read_plain_and_through(tmp_path, bow)
    np.testing.assert_allclose(b.pressure_Pa, bow.read(a.pressure_Pa, P_ATM), atol=5.0)
    assert np.max(np.abs(b.pressure_Pa - a.pressure_Pa)) > 500.0


# ---------------------------------------------------------------- the thirteenth set's
def test_a_saturating_sensor_reads_true_below_its_rail_and_flat_above(tmp_path):
    """Below the knee the reading is the pressure (to w e^-(F - y)/w), far above it the
    rail, monotone between; the bench reads its recordings through it."""
    rail = SaturatingSensor(full_scale_Pa=3e5, knee_Pa=5e3)
    p = P_ATM + np.array([0.0, 1e5, 2.5e5, 3e5, 3.5e5, 6e5])
    r = rail.read(p, P_ATM)
    np.testing.assert_allclose(r[:3], p[:3], atol=5e3 * np.exp(-10.0) + 1e-6)
    assert r[3] == pytest.approx(P_ATM + 3e5 - 5e3 * np.log(2.0), rel=1e-12)
    np.testing.assert_allclose(r[-1], P_ATM + 3e5, atol=1e-6)
    fine = P_ATM + np.linspace(0.0, 6e5, 2001)
    rise = np.diff(rail.read(fine, P_ATM))
    assert np.all(rise >= 0.0) and np.all(rise[fine[1:] < P_ATM + 3.5e5] > 0.0)
    assert np.all(rail.read(fine, P_ATM) <= fine + 1e-6)
    np.testing.assert_array_equal(SaturatingSensor(float("inf")).read(p, P_ATM), p)
    a, b = _read_plain_and_through(tmp_path, rail)
    assert a.pressure_Pa.max() > P_ATM + 4e5  # the fill reaches past the rail
    assert b.pressure_Pa.max() < P_ATM + 3e5 + 500.0  # (the DAQ filter rings a little)
    # the bench reads the rail before its DAQ filter: they differ only at the fastest edges
    miss = np.abs(b.pressure_Pa - rail.read(a.pressure_Pa, P_ATM))
    assert miss.max() < 300.0 and np.median(miss) < 1.0


def test_a_skewed_channel_logs_the_pressure_late(tmp_path):
    """The logged pressure at t is the sensor's at t - d (its first value before the
    record); d = 0 is the sensor's own; on the bench a recording is the unskewed one
    shifted by d (the skew a whole number of output samples here)."""
    t = np.arange(0.0, 0.1, 1e-4)
    p = P_ATM + 1e5 * (t >= 0.05) + 2e5 * t
    late = SkewedPressureChannel(delay_s=0.01).read(t, p)
    np.testing.assert_allclose(late[t >= 0.01 + 1e-9], np.interp(t[t >= 0.01 + 1e-9] - 0.01,
                                                                 t, p), atol=1e-9)
    np.testing.assert_array_equal(late[t < 0.01 - 1e-9], p[0])
    assert np.argmax(np.diff(late)) == np.argmax(np.diff(p)) + 100
    np.testing.assert_array_equal(SkewedPressureChannel(0.0).read(t, p), p)
    a, b = _read_plain_and_through(tmp_path, SkewedPressureChannel(delay_s=0.004))
    k = int(round(0.004 / (a.time_s[1] - a.time_s[0])))
    np.testing.assert_allclose(b.pressure_Pa[k + 3:], a.pressure_Pa[3:-k], atol=30.0)
    assert np.max(np.abs(b.pressure_Pa - a.pressure_Pa)) > 1e4


# ---------------------------------------------------------------- the fifth set's forms
@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_a_spring_returned_spool_rises_and_falls_as_first_order_lags_of_its_own(rig):
    """A rising step sees only the rise time constant, a falling one only the fall's:
    each is the catalogue's first-order spool lag at that time constant, bit for bit."""
    from pneubayes.effects import make_effect

    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    spring = SpringReturnSpool(rise_time_constant_s=5e-4, fall_time_constant_s=3e-3)
    lag = (make_effect("spool_lag"),)
    for levels, p0, tau in (((-5.0, 5.0), P_ATM, 5e-4), ((5.0, -5.0), P_SUP - 1e3, 3e-3)):
        step = _held(0.1, levels, at=(0.0, 0.01))
        got = _run(params, (spring,), step, rig, p0=p0)
        first = simulate_plant(dict(params, spool_time_constant_s=tau), (), step, rig, p0,
                               REF, effects=lag).pressure_Pa
        np.testing.assert_array_equal(got, first)
    with pytest.raises(ValueError, match="SpringReturnSpool is the spool's stage"):
        _run(params, (spring, forms_from_names(["spool_lag"])[0]), _held(0.02, (1.0,)), rig)


def test_a_warming_coil_drifts_a_held_valve_to_its_steady_heats_command(rig, base):
    """A held command on a coil with a short thermal time constant ends where the plain
    valve does under the command of the coil's steady heat theta* (theta* (1 + k
    theta*) = d^2, d the drive fraction), not where it does under the command itself."""
    coil = WarmingCoil(resistance_rise=0.15, time_constant_s=0.02)
    u = 0.4
    d = (u - coil.command_min_V) / coil.command_span_V
    k = coil.resistance_rise
    theta = (-1.0 + np.sqrt(1.0 + 4.0 * k * d * d)) / (2.0 * k)
    u_star = coil.command_min_V + (u - coil.command_min_V) / (1.0 + k * theta)
    held = _held(0.6, (u,))
    warm = _run(base, (coil,), held, rig, p0=3e5)
    plain_star = _run(base, (), _held(0.6, (u_star,)), rig, p0=3e5)
    plain = _run(base, (), held, rig, p0=3e5)
    assert abs(warm[-1] - plain_star[-1]) < 100.0
    assert abs(warm[-1] - plain[-1]) > 20 * abs(warm[-1] - plain_star[-1])
    assert warm[0] == plain[0]  # a cold coil: the plain valve at the start


def test_a_capillary_sensor_lags_more_at_low_pressure_and_matches_an_ode_solver():
    from scipy.integrate import solve_ivp

    cap = CapillarySensorPort(time_constant_s=2e-3, reference_pressure_Pa=P_SUP)
    t = np.arange(4001) * 1e-5
    p = 3e5 + 2e5 * np.sin(2 * np.pi * 40.0 * t)
    c = 1.0 / (2.0 * P_SUP * 2e-3)
    ref = solve_ivp(lambda tt, r: c * (np.interp(tt, t, p) ** 2 - r ** 2), (0, t[-1]),
                    [p[0]], t_eval=t, rtol=1e-10, atol=1e-6, max_step=1e-5).y[0]
    np.testing.assert_allclose(cap.read(t, p), ref, atol=2.0)  # of a 400-kPa swing
    # a small step's 63 % time: tau near the supply, tau p_ref / p near the atmosphere
    for level in (P_ATM, P_SUP):
        t = np.arange(20001) * 1e-5
        step = np.where(t < 1e-3, level, level * 1.01)
        r = cap.read(t, step)
        t63 = t[np.argmax(r - level >= 0.632 * 0.01 * level)] - 1e-3
        assert t63 == pytest.approx(2e-3 * P_SUP / level, rel=0.03)
    assert np.array_equal(CapillarySensorPort(0.0).read(t, step), step)


def test_a_lagging_length_sensor_trails_a_ramp_by_its_time_constant():
    lag = LaggingPositionSensor(time_constant_s=5e-3)
    t = np.arange(2001) * 1e-4
    x = 0.01 + 0.2 * t  # a ramp at 0.2 m/s from rest
    y = lag.read(t, x)
    exact = 0.01 + 0.2 * t - 0.2 * 5e-3 * (1.0 - np.exp(-t / 5e-3))
    np.testing.assert_allclose(y, exact, atol=1e-12)
    assert y[-1] == pytest.approx(x[-1] - 1e-3, abs=1e-7)  # A tau dx/dt behind
    assert np.array_equal(LaggingPositionSensor(0.0).read(t, x), x)


def test_the_bench_reads_through_a_capillary_and_a_lagging_length_sensor(tmp_path):
    """Noise-free recordings with the two reading-side forms: the pressure is the plain
    recording's read through the capillary, the position the plain one's lagged (on the
    recordings' own 1-kHz grid, so to a tolerance); the chamber itself is unchanged."""
    from pneubayes.bench.sensors import SensorChain
    from pneubayes.io import read_recording

    quiet = SensorChain(pressure_noise_Pa=0.0, supply_noise_Pa=0.0, position_noise_m=0.0)
    cap, lag = CapillarySensorPort(time_constant_s=3e-3), LaggingPositionSensor(8e-3)
    kw = dict(protocol="moving", duration_s=1.0, count=1, sensor=quiet,
              forms=(SupplyHose(restriction_area_m2=0.0),))
    res = [run_bench(BenchConfig("SMC", "valve2", **kw), tmp_path / "a"),
           run_bench(BenchConfig("SMC", "valve2", **dict(kw, forms=(cap, lag))),
                     tmp_path / "b")]
    a, b = (read_recording(r.recordings[0]) for r in res)
    span = np.ptp(a.pressure_Pa)
    assert np.max(np.abs(b.pressure_Pa - a.pressure_Pa)) > 0.05 * span
    np.testing.assert_allclose(b.pressure_Pa, cap.read(a.time_s, a.pressure_Pa),
                               atol=0.01 * span)
    assert np.max(np.abs(b.position_m - a.position_m)) > 5e-4
    np.testing.assert_allclose(b.position_m, lag.read(a.time_s, a.position_m), atol=2e-5)


# ---------------------------------------------------------------- the sixth blind set
@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_an_exhaust_check_valve_vents_only_down_to_its_cracking_pressure(rig):
    """Inlet shut, exhaust open (-5 V): the chamber vents to the atmosphere without the
    check, to its cracking pressure with it, at the orifice law against the raised
    back-pressure; at 0 V (both ports shut) a chamber below the crack keeps its
    pressure (nothing enters through the exhaust)."""
    check = out_of_catalogue_defaults("ExhaustCheckValve")
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    inputs = _held(1.0, (-5.0,))
    plain = _run(params, (), inputs, rig, p0=4e5)
    held = _run(params, (check,), inputs, rig, p0=4e5)
    assert plain[-1] < P_ATM + 500.0
    stop = P_ATM + check.crack_pressure_Pa
    assert stop - 1.0 < held[-1] < stop + 2e3 and np.all(held > stop - 1.0)  # (tolerance)
    g = rig.gas
    a_ex = CLOSABLE["exhaust_a_m2"]  # the exhaust's full area at -5 V (its offset 0)
    mid = 0.5 * (held[0] + held[1])
    mdot = a_ex * flow_terms(mid, stop, g.alpha_s_per_m, g.beta_s_per_m, g.theta,
                             g.heat_capacity_ratio)[0]
    want = -g.heat_capacity_ratio * g.specific_gas_constant_J_per_kg_K * g.temperature_K \
        * mdot / VOLUME
    assert (held[1] - held[0]) / DT == pytest.approx(want, rel=0.01)
    shut = _run(params, (check,), _held(0.3, (0.0,)), rig, p0=P_ATM + 10e3)
    np.testing.assert_allclose(shut, P_ATM + 10e3, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match="beside an ExhaustSilencer"):
        _run(params, (check, out_of_catalogue_defaults("ExhaustSilencer")), inputs, rig)


def test_a_worn_seat_fills_a_shut_chamber_at_the_incompressible_law(rig):
    """Valve shut (0 V): the chamber rises from the atmosphere at dp/dt = kappa Rs T
    C A sqrt(2 rho_s (p_s - p)) / V, and keeps rising to the supply."""
    seat = out_of_catalogue_defaults("SeatLeak")
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    p = _run(params, (seat,), _held(0.5, (0.0,)), rig)
    gas = rig.gas
    rt = gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
    mid = 0.5 * (p[0] + p[1])
    mdot = seat.area_m2 * np.sqrt(2.0 * P_SUP / rt * (P_SUP - mid))
    want = gas.heat_capacity_ratio * rt * mdot / VOLUME
    assert (p[1] - p[0]) / DT == pytest.approx(want, rel=0.01)
    assert np.all(np.diff(p) >= -1e-3) and p[-1] > P_SUP - 1e3
    plain = _run(params, (), _held(0.5, (0.0,)), rig)
    np.testing.assert_allclose(plain, P_ATM, rtol=0, atol=1e-6)


@pytest.mark.slow  # (a spent blind set's form; the fast tier's budget)
def test_a_flow_limiter_caps_a_full_fill_at_its_flow_and_spares_the_exhaust(rig, base):
    limiter = InletFlowLimiter(max_flow_kg_per_s=2e-4)
    fill = _held(0.3, (5.0,))
    p = _run(base, (limiter,), fill, rig)
    gas = rig.gas
    rt_k = gas.heat_capacity_ratio * gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
    # far below the supply the inlet's own flow is several times the cap: dp/dt at most
    # kappa Rs T m_max / V, and within a few per cent of it
    rate = (p[1] - p[0]) / DT
    assert 0.9 * rt_k * 2e-4 / VOLUME < rate <= rt_k * 2e-4 / VOLUME
    plain = _run(base, (), fill, rig)
    assert (plain[1] - plain[0]) / DT > 2 * rate
    vent = _held(0.3, (-5.0,))  # (the closable valve: its inlet exactly shut at -5 V)
    closable = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    np.testing.assert_allclose(_run(closable, (limiter,), vent, rig, p0=4e5),
                               _run(closable, (), vent, rig, p0=4e5), rtol=0, atol=1e-6)


def test_a_late_release_moves_falls_not_rises_and_a_quick_rise_cancels_a_fall(rig, base):
    rel = ReleaseDelay(delay_s=3e-3)
    t = np.arange(6) * 1e-3
    times, values = rel.switches(t, [0.0, 2.0, 1.0, 1.0, 3.0, 3.0])
    # the rise at 1 ms on time; the fall at 2 ms due at 5 ms, overtaken by the rise at
    # 4 ms, so it never acts
    np.testing.assert_allclose(times, [-np.inf, 1e-3, 4e-3])
    np.testing.assert_array_equal(values, [0.0, 2.0, 3.0])
    times, _ = rel.switches(t, [0.0, 2.0, 1.0, 1.0, 1.0, 1.0], shared_delay_s=1e-3)
    np.testing.assert_allclose(times, [-np.inf, 2e-3, 6e-3])
    # the plant: a fill then a vent; with the delay the vent is the plain plant's vent
    # commanded 40 samples (4 ms) later
    late = _run(base, (ReleaseDelay(delay_s=40 * DT),), _held(0.2, (5.0, -5.0), (0.0, 0.1)),
                rig)
    shifted = _run(base, (), _held(0.2, (5.0, -5.0), (0.0, 0.1 + 40 * DT)), rig)
    np.testing.assert_allclose(late, shifted, rtol=0, atol=1.0)
    plain = _run(base, (), _held(0.2, (5.0, -5.0), (0.0, 0.1)), rig)
    assert np.max(np.abs(late - plain)) > 10e3


def test_a_supply_driven_armature_acts_later_at_a_lower_supply(rig, base):
    arm = ArmatureDeadTime(travel_s=8e-3, coil_s=2e-3, reference_gauge_Pa=5e5)
    assert arm.catalogue_name == "valve_dead_time" and arm.acts
    assert not ArmatureDeadTime(travel_s=0.0, coil_s=0.0).acts
    t = np.arange(6) * 1e-3
    times, values = arm.switches(t, [0.0, 2.0, 2.0, 0.0, 0.0, 0.0],
                                 supply_gauge_at=lambda tau: 5e5 if tau < 2.5e-3 else 20e5)
    # the rise at 1 ms is due 2 + 8 ms later; the fall at 3 ms, at 4 x the gauge supply,
    # 2 + 4 ms later, overtakes it
    np.testing.assert_allclose(times, [-np.inf, 9e-3], atol=1e-12)
    np.testing.assert_array_equal(values, [0.0, 0.0])
    times, values = arm.switches(t, [0.0, 2.0, 2.0, 0.0, 0.0, 0.0],
                                 supply_gauge_at=lambda tau: 5e5)
    np.testing.assert_allclose(times, [-np.inf, 11e-3, 13e-3], atol=1e-12)
    with pytest.raises(ValueError, match="gauge supply at"):
        arm.switches(t, [0.0, 2.0, 2.0, 2.0, 2.0, 2.0], supply_gauge_at=lambda tau: 0.0)
    # the plant at the rig's supply (gauge 5 bar = the reference): the plain plant's vent
    # commanded 10 ms later (the fill, held from the start, is no change)
    gauge = rig.supply_pressure_Pa - rig.atmospheric_pressure_Pa
    arm = ArmatureDeadTime(travel_s=8e-3, coil_s=2e-3, reference_gauge_Pa=gauge)
    late = _run(base, (arm,), _held(0.2, (5.0, -5.0), (0.0, 0.1)), rig)
    shifted = _run(base, (), _held(0.2, (5.0, -5.0), (0.0, 0.11)), rig)
    np.testing.assert_allclose(late, shifted, rtol=0, atol=1.0)
    plain = _run(base, (), _held(0.2, (5.0, -5.0), (0.0, 0.1)), rig)
    assert np.max(np.abs(late - plain)) > 10e3
    # at 4 x the reference the travel halves: 2 + 4 ms
    quarter = ArmatureDeadTime(travel_s=8e-3, coil_s=2e-3, reference_gauge_Pa=gauge / 4)
    later = _run(base, (quarter,), _held(0.2, (5.0, -5.0), (0.0, 0.1)), rig)
    shifted = _run(base, (), _held(0.2, (5.0, -5.0), (0.0, 0.106)), rig)
    np.testing.assert_allclose(later, shifted, rtol=0, atol=1.0)


def test_a_held_armature_acts_later_at_a_higher_supply(rig, base):
    held = HeldArmatureDeadTime(travel_s=8e-3, coil_s=2e-3, reference_gauge_Pa=5e5,
                                limit_gauge_Pa=1e6)
    assert held.catalogue_name == "valve_dead_time"
    assert held.travel_factor(5e5) == pytest.approx(1.0)
    assert held.travel_factor(7.5e5) == pytest.approx(np.sqrt(2.0))
    assert held.travel_factor(2.5e5) < 1.0
    with pytest.raises(ValueError, match="holds the valve shut"):
        held.travel_factor(1e6)
    with pytest.raises(ValueError, match="limit_gauge_Pa must exceed"):
        HeldArmatureDeadTime(travel_s=1e-3, reference_gauge_Pa=5e5, limit_gauge_Pa=4e5)
    # the plant at the rig's 4.5-bar gauge supply, limit 7 bar, reference 2.5 bar: the
    # travel is 8 ms x sqrt(4.5 / 2.5); the vent acts 2 ms + that late
    late_s = 2e-3 + 8e-3 * np.sqrt(4.5 / 2.5)
    arm = HeldArmatureDeadTime(travel_s=8e-3, coil_s=2e-3, reference_gauge_Pa=2.5e5,
                               limit_gauge_Pa=7e5)
    got = _run(base, (arm,), _held(0.2, (5.0, -5.0), (0.0, 0.1)), rig)
    times, _ = arm.switches(np.arange(3) * 1e-3, [5.0, -5.0, -5.0],
                            supply_gauge_at=lambda tau: 4.5e5)
    np.testing.assert_allclose(times, [-np.inf, 1e-3 + late_s], atol=1e-12)
    plain = _run(base, (), _held(0.2, (5.0, -5.0), (0.0, 0.1)), rig)
    assert np.max(np.abs(got - plain)) > 10e3


def _rate0(p, volume_m3, rig, mdot_kg_per_s):
    """(measured initial dp/dt, eq. 5's kappa Rs T mdot / V), Pa/s."""
    g = rig.gas
    return ((p[1] - p[0]) / DT, g.heat_capacity_ratio * g.specific_gas_constant_J_per_kg_K
            * g.temperature_K * mdot_kg_per_s / volume_m3)


def test_a_worn_piston_seal_fills_the_other_chamber_and_keeps_the_mass(rig):
    """Valve shut (0 V), piston held: the chamber loses k (p^2 - P_atm^2) at first; with a
    sealed vent the two chambers' p V (mass x kappa Rs T) is conserved and they meet at
    one pressure; with a vent both end at the atmosphere."""
    swept = np.pi / 4 * BORE**2 * STROKE
    sealed = PistonSealBypass(conductance_kg_per_s_Pa2=2e-16, vent_area_m2=0.0,
                              opposite_volume_m3=1.2 * swept)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    p0 = 4e5
    p = _run(params, (sealed,), _held(2.0, (0.0,)), rig, p0=p0)
    got, want = _rate0(p, VOLUME, rig, -2e-16 * ((0.5 * (p[0] + p[1])) ** 2 - P_ATM**2))
    assert got == pytest.approx(want, rel=0.01)
    v_b = 1.2 * swept - np.pi / 4 * BORE**2 * 0.5 * STROKE
    meet = (p0 * VOLUME + P_ATM * v_b) / (VOLUME + v_b)
    assert p[-1] == pytest.approx(meet, abs=50.0)  # (equal pressures: no more flow)
    vented = _run(params, (replace(sealed, vent_area_m2=3e-8),), _held(2.0, (0.0,)),
                  rig, p0=p0)
    assert vented[-1] < P_ATM + 2e3 and np.all(np.diff(vented) < 1e-6)
    with pytest.raises(ValueError, match="other chamber's volume"):
        _run(params, (replace(sealed, opposite_volume_m3=0.4 * swept),),
             _held(0.01, (0.0,)), rig)


def test_an_energised_seal_leaks_most_at_low_pressure(rig):
    """Valve shut: the initial leak follows k (p^2 - P_atm^2) / (1 + g / p_e)^3, so a
    chamber at 0.75 bar gauge loses pressure faster than one at 4 bar."""
    seal = out_of_catalogue_defaults("EnergisedSealLeak")
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    rates = []
    for p0 in (P_ATM + 0.5 * seal.energising_pressure_Pa, P_ATM + 4e5):
        p = _run(params, (seal,), _held(0.01, (0.0,)), rig, p0=p0)
        mid = 0.5 * (p[0] + p[1])
        mdot = seal.conductance_kg_per_s_Pa2 * (mid**2 - P_ATM**2) / (
            1.0 + (mid - P_ATM) / seal.energising_pressure_Pa) ** 3
        got, want = _rate0(p, VOLUME, rig, -mdot)
        assert got == pytest.approx(want, rel=0.01)
        rates.append(-got)
    assert rates[0] > 1.2 * rates[1]  # (1.26 x: the gap's cube against p^2 - P_atm^2)
    np.testing.assert_allclose(_run(params, (seal,), _held(0.1, (0.0,)), rig), P_ATM,
                               rtol=0, atol=1e-6)


def test_the_bench_reads_through_a_drifting_sensor(tmp_path):
    """Noise-free fixed-piston recordings with and without a drifting zero: they differ
    by the drift (the DAQ's zero-phase filter passes its slow rise; the log's 0.1 Pa)."""
    drift = SensorZeroDrift(drift_Pa=2e3, time_constant_s=0.2)
    a, b = _read_plain_and_through(tmp_path, drift, duration_s=0.5)
    want = 2e3 * -np.expm1(-(a.time_s - a.time_s[0]) / 0.2)
    np.testing.assert_allclose(b.pressure_Pa - a.pressure_Pa, want, atol=2.0)


def test_a_drifting_sensor_reads_true_at_the_start_and_off_by_its_drift_later():
    drift = SensorZeroDrift(drift_Pa=-4e3, time_constant_s=5.0)
    t = np.linspace(2.0, 32.0, 301)  # (a recording need not start at 0 s)
    p = np.full(t.size, 3e5)
    r = drift.read(t, p)
    assert r[0] == p[0]
    np.testing.assert_allclose(r - p, -4e3 * (1 - np.exp(-(t - 2.0) / 5.0)), rtol=1e-12)
    assert r[-1] == pytest.approx(3e5 - 4e3, abs=10.0)
    with pytest.raises(ValueError, match="time_constant_s"):
        SensorZeroDrift(drift_Pa=1e3, time_constant_s=0.0)


def test_an_end_cushion_throttles_the_vent_near_the_end_only(rig, base):
    """Venting (-5 V) with the piston inside the cushion: the exhaust's flow is that of
    a_ex and the needle in series; at half stroke, and filling inside it, the plain
    plant's."""
    cushion = EndCushion(length_m=0.2 * STROKE, needle_area_m2=1e-7, edge_m=0.01 * STROKE)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)

    def at(x, u, p0, n):
        t = np.arange(n) * DT
        inputs = Inputs(t, np.full(t.size, u), np.full(t.size, x), np.full(t.size, P_SUP))
        return (_run(params, (cushion,), inputs, rig, p0=p0),
                _run(params, (), inputs, rig, p0=p0))

    inside, plain = at(0.05 * STROKE, -5.0, 4e5, 11)  # (the first step's rate)
    a_ex, a_n = CLOSABLE["exhaust_a_m2"], 1e-7
    g = rig.gas
    volume = 1.5e-7 + np.pi / 4 * BORE**2 * 0.05 * STROKE
    for p, area in ((inside, a_ex * a_n / np.hypot(a_ex, a_n)), (plain, a_ex)):
        mid = 0.5 * (p[0] + p[1])
        mdot = area * flow_terms(mid, P_ATM, g.alpha_s_per_m, g.beta_s_per_m, g.theta,
                                 g.heat_capacity_ratio)[0]
        got, want = _rate0(p, volume, rig, -mdot)
        assert got == pytest.approx(want, rel=0.01)
    outside, plain = at(0.5 * STROKE, -5.0, 4e5, 301)  # (to the atmosphere)
    np.testing.assert_allclose(outside, plain, rtol=0, atol=1e-6)
    # (full by 2.7 ms; at the supply the solvers' 0.1 Pa, and many steps: 6 ms)
    fill, plain = at(0.05 * STROKE, 5.0, P_ATM, 61)
    np.testing.assert_allclose(fill, plain, rtol=0, atol=0.5)
    with pytest.raises(ValueError, match="EndCushion cannot be planted beside"):
        _run(params, (cushion, out_of_catalogue_defaults("MeterOutThrottle")),
             _held(0.01, (0.0,)), rig)


def test_a_quick_exhaust_valve_vents_the_chamber_itself_and_keeps_the_limits(rig):
    """Shut (0 V): line and chamber keep their pressure. Venting (-5 V) from 4 bar: the
    valve empties the small line, the QEV opens and the chamber falls at the rate of its
    own exhaust a_q f(p, P_atm), faster than through the valve's port, to the atmosphere.
    Full inlet (+5 V): the chamber fills through the line, a little behind the plain
    port (the passage in series)."""
    qev = QuickExhaustValve(exhaust_area_m2=1.5e-6, passage_area_m2=1.5e-6,
                            switch_band_Pa=1e4, line_volume_m3=2e-7)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    shut = _run(params, (qev,), _held(0.05, (0.0,)), rig, p0=4e5)
    np.testing.assert_allclose(shut, 4e5, rtol=0, atol=1e-3)
    # (the QEV vents to the atmosphere in 11 ms, the valve's port in 19 ms)
    vent, plain = (_run(params, f, _held(0.03, (-5.0,)), rig, p0=4e5) for f in ((qev,), ()))
    g = rig.gas
    k = int(0.001 / DT)  # (the line is empty and the QEV open within 0.5 ms)
    mid = 0.5 * (vent[k] + vent[k + 1])
    mdot = -1.5e-6 * flow_terms(mid, P_ATM, g.alpha_s_per_m, g.beta_s_per_m, g.theta,
                                g.heat_capacity_ratio)[0]
    got = (vent[k + 1] - vent[k]) / DT
    _, want = _rate0(vent, VOLUME, rig, mdot)
    assert got == pytest.approx(want, rel=0.02)
    assert _time_to(-vent, -(P_ATM + 5e4)) < 0.7 * _time_to(-plain, -(P_ATM + 5e4))
    assert vent[-1] == pytest.approx(P_ATM, abs=50.0)
    fill, plain = (_run(params, f, _held(0.008, (5.0,)), rig) for f in ((qev,), ()))
    assert np.all(np.diff(fill) > 0) and 0.8 * (plain[-1] - P_ATM) < fill[-1] - P_ATM < (
        plain[-1] - P_ATM)
    with pytest.raises(ValueError, match="QuickExhaustValve cannot be planted beside"):
        _run(params, (qev, out_of_catalogue_defaults("EndCushion")), _held(0.01, (0.0,)), rig)


def test_a_gas_accumulator_adds_its_compliance_above_its_precharge_only(rig):
    """Full inlet from two starts at the same inflow: below the precharge the rate is the
    plain chamber's; above it eq. 5 with V + V_a (1 - (p0/p)^(1/n)) and dV/dp solved in."""
    acc = GasAccumulator(volume_m3=2e-7, precharge_Pa=2.5e5, polytropic_index=1.2)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    inputs = _held(0.002, (5.0,))
    below = _run(params, (acc,), inputs, rig, p0=2e5)
    np.testing.assert_allclose(below[:3], _run(params, (), inputs, rig, p0=2e5)[:3],
                               rtol=0, atol=1e-6)
    p0 = 3e5
    with_acc, plain = _run(params, (acc,), inputs, rig, p0=p0), _run(params, (), inputs,
                                                                      rig, p0=p0)
    r = (2.5e5 / p0) ** (1 / 1.2)
    v_tot = VOLUME + 2e-7 * (1 - r)
    dvdp = 2e-7 * r / (1.2 * p0)
    kappa = rig.gas.heat_capacity_ratio
    ratio = (with_acc[1] - with_acc[0]) / (plain[1] - plain[0])
    assert ratio == pytest.approx(VOLUME / (v_tot + kappa * p0 * dvdp), rel=0.01)
    assert with_acc[-1] < plain[-1]


def test_spool_land_leaks_settle_a_shut_chamber_between_supply_and_atmosphere(rig):
    """At the null (0 V, both ports shut) the two land leaks k (p_s^2 - p^2) and
    k (p^2 - P_atm^2) balance at p^2 = (p_s^2 + P_atm^2) / 2, from either side; at -2 V
    the inlet land is 1 + 2 / s_L times longer and the balance moves down."""
    lands = SpoolLandLeak(conductance_kg_per_s_Pa2=4e-15, overlap_scale_V=0.5)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    settle = np.sqrt((P_SUP**2 + P_ATM**2) / 2)
    for p0 in (P_ATM, P_SUP):
        p = _run(params, (lands,), _held(1.0, (0.0,)), rig, p0=p0)
        assert p[-1] == pytest.approx(settle, abs=100.0)
    p = _run(params, (lands,), _held(0.02, (0.0,)), rig, p0=3e5)
    mid = 0.5 * (p[0] + p[1])
    got, want = _rate0(p, VOLUME, rig, 4e-15 * (P_SUP**2 + P_ATM**2 - 2 * mid**2))
    assert got == pytest.approx(want, rel=0.01)
    low = _run(params, (lands,), _held(1.0, (-1.2,)), rig, p0=3e5)  # (ports still shut)
    k_in = 1.0 / (1.0 + 1.2 / 0.5)
    assert low[-1] == pytest.approx(np.sqrt((k_in * P_SUP**2 + P_ATM**2) / (1 + k_in)),
                                    abs=100.0)


def test_a_thermally_shocked_sensor_overshoots_a_step_and_settles():
    """A pressure step of D read through the transient: (1 + g) D at once, then back to
    D as exp(-t / tau); no change, no transient; gain 0 reads true."""
    shock = SensorThermalShock(gain=0.04, time_constant_s=0.2)
    t = np.linspace(0.0, 2.0, 2001)
    p = np.where(t >= 0.5, 4e5, 1e5)
    r = shock.read(t, p)
    np.testing.assert_array_equal(r[t < 0.5], 1e5)
    after = t >= 0.5
    want = 4e5 + 0.04 * 3e5 * np.exp(-(t[after] - t[after][0]) / 0.2)
    # (the low-pass sees the step as linear over its one sample interval)
    np.testing.assert_allclose(r[after][1:], want[1:], rtol=0, atol=0.04 * 3e5 * 0.003)
    np.testing.assert_array_equal(SensorThermalShock(gain=0.0).read(t, p), p)


# ---------------------------------------------------------------- the ninth blind set
def test_a_pwm_driver_pulses_by_duty_drops_short_pulses_and_holds_full_duty_open(rig, base):
    """At 100 Hz with 1-ms opening and 0.5-ms closing: 2.5 V is half of each period
    (1 to 5.5 ms), 0.05 V's 0.1-ms pulse never opens the valve, full duty stays open
    across periods, and a pulse of the other sign opens the exhaust."""
    pwm = PwmValve(frequency_Hz=100.0, opening_delay_s=1e-3, closing_delay_s=5e-4)
    t = np.arange(50) * 1e-3
    u = np.full(t.size, 2.5)
    u[20:], u[35:], u[40:] = 5.0, -0.05, -5.0
    times, values = pwm.switches(t, u)
    np.testing.assert_allclose(times[:7], [-np.inf, 1e-3, 5.5e-3, 11e-3, 15.5e-3, 21e-3,
                                           40.5e-3])
    np.testing.assert_array_equal(values[:8], [0.0, 5.0, 0.0, 5.0, 0.0, 5.0, 0.0, -5.0])
    assert pwm.switches(t, np.full(t.size, 0.05))[0].size == 1  # never opens
    # the plant: a full command is the plain valve at 5 V, opening 1 ms late
    full = _run(base, (pwm,), _held(0.05, (5.0,)), rig)
    late = _run(base, (), _held(0.05, (0.0, 5.0), (0.0, 1e-3)), rig)
    np.testing.assert_allclose(full, late, rtol=0, atol=1.0)
    # half duty fills slower than full, in steps: between pulses the closable valve is
    # shut and the pressure holds
    shut = dict(CLOSABLE, dead_volume_m3=3e-6)
    half = _run(shut, (pwm,), _held(0.05, (2.5,)), rig)
    assert P_ATM + 5e3 < half[-1] < _run(shut, (pwm,), _held(0.05, (5.0,)), rig)[-1] - 5e3
    rate = np.diff(half)
    assert np.sum(np.abs(rate) < 0.5) > 0.3 * rate.size


def test_a_sampling_driver_acts_at_its_next_update_after_its_latency(rig, base):
    """Updates every 10 ms from 3 ms (phase 0.3), 2 ms latency: a step at 23.5 ms acts
    at 35 ms, a blip between two updates never acts; the plant is the plain valve
    commanded then."""
    zoh = ZohDriver(update_period_s=0.01, latency_s=2e-3, phase=0.3)
    t = np.arange(60) * 1e-3
    u = np.zeros(t.size)
    u[24:], u[44:46] = 4.0, -4.0
    times, values = zoh.switches(t, u)
    np.testing.assert_allclose(times, [-np.inf, 35e-3])
    np.testing.assert_array_equal(values, [0.0, 4.0])
    got = _run(base, (zoh,), _held(0.06, (0.0, 4.0), (0.0, 0.0234)), rig)
    want = _run(base, (), _held(0.06, (0.0, 4.0), (0.0, 0.035)), rig)
    np.testing.assert_allclose(got, want, rtol=0, atol=1.0)


def test_a_hysteretic_sensor_trails_a_rise_leads_a_fall_and_ignores_the_rate():
    """Four plays of half-widths b/4 .. b: on a long ramp the reading trails by the mean
    half-width (5 b / 8), after the turn it holds until the pressure has come back by
    2 b / 4 per play, then leads by as much; the same ramp sampled 10 x finer reads the
    same at the shared samples; width 0 reads true."""
    b = 2000.0
    hyst = SensorHysteresis(half_width_Pa=b)
    p = np.concatenate([np.linspace(1e5, 3e5, 201), np.linspace(3e5, 1e5, 201)[1:]])
    r = hyst.read(p)
    np.testing.assert_allclose(r[100], p[100] - 5 * b / 8)
    np.testing.assert_allclose(r[300], p[300] + 5 * b / 8)
    assert r[201] == r[200]  # just after the turn nothing moves
    fine = np.concatenate([np.linspace(1e5, 3e5, 2001), np.linspace(3e5, 1e5, 2001)[1:]])
    np.testing.assert_allclose(hyst.read(fine)[::10], r, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(SensorHysteresis(half_width_Pa=0.0).read(p), p)


def test_a_speed_lifted_seal_leaks_only_while_the_piston_moves(rig):
    """Valve shut (0 V on the closable valve): with the piston held the chamber keeps its
    pressure; moving at 0.2 m/s it loses k (v / v_ref)^1.5 (p^2 - P_atm^2) more than the
    plain chamber (eq. 5's rate)."""
    seal = SealSpeedLeak(conductance_kg_per_s_Pa2=2e-16, reference_speed_m_per_s=0.1)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    held = _run(params, (seal,), _held(0.02, (0.0,)), rig, p0=4e5)
    np.testing.assert_allclose(held, 4e5, rtol=0, atol=1e-3)
    t = np.arange(21) * DT
    x = 0.2 * STROKE + 0.2 * t  # (1 mm in 2 ms: not yet the stroke's end)
    inputs = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    got = _run(params, (seal,), inputs, rig, p0=4e5)
    plain = _run(params, (), inputs, rig, p0=4e5)
    volume = 1.5e-7 + np.pi / 4 * BORE**2 * 0.5 * (x[0] + x[1])  # (mid-step)
    mid = 0.5 * (got[0] + got[1])
    leak = 2e-16 * 2.0**1.5 * (mid**2 - P_ATM**2)
    g = rig.gas
    want = (g.heat_capacity_ratio * g.specific_gas_constant_J_per_kg_K * g.temperature_K
            * leak / volume)
    assert (plain[1] - got[1]) / DT == pytest.approx(want, rel=0.02)


# ---------------------------------------------------------------- the tenth blind set
def test_a_friction_held_wall_gives_only_past_its_band_and_keeps_p_v_kappa(rig):
    """Valve shut, the piston pushed in and drawn back to where it started: a closed,
    adiabatic chamber, ``dp/dt = -kappa p A dx/dt / (V + kappa p C g)`` and ``dy/dt = g
    dp/dt`` with g the smoothed gate of the play (an independent two-state reference,
    solved here), so p (V + C y)^kappa stays at its start; the rigid chamber returns to
    its pressure, the friction-held one does not (the wall ends displaced); until the
    pressure first nears the band's edge it is the rigid chamber."""
    from scipy.integrate import solve_ivp

    c, w = 2e-12, 30e3
    wall = BraidFriction(compliance_m3_per_Pa=c, friction_band_Pa=w)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    t = np.arange(4001) * 1e-4
    omega = np.pi / t[-1]
    x = 0.6 * STROKE - 0.4 * STROKE * np.sin(omega * t) ** 2  # in and back
    inputs = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    p0 = 2e5
    got = _run(params, (wall,), inputs, rig, p0=p0)
    stuck = 1.5e-7 + c * (p0 - P_ATM)  # the wall's give at the start: V_0 + C y_0
    rigid = _run(dict(params, dead_volume_m3=stuck), (), inputs, rig, p0=p0)
    area, kappa = np.pi / 4 * BORE**2, rig.gas.heat_capacity_ratio

    def rhs(tau, state):
        p, y = state
        xdot = -0.4 * STROKE * omega * np.sin(2 * omega * tau)
        x_now = 0.6 * STROKE - 0.4 * STROKE * np.sin(omega * tau) ** 2
        lead = (p - P_ATM - y) * (1.0 if xdot < 0 else -1.0)  # compressing: p rises
        z = min(max((lead - w) / (0.1 * w) + 0.5, 0.0), 1.0)
        g = z * z * (3 - 2 * z) if xdot != 0 and lead > 0 else 0.0
        dp = -kappa * p * area * xdot / (1.5e-7 + area * x_now + c * y + kappa * p * c * g)
        return [dp, g * dp]

    ref = solve_ivp(rhs, (0, t[-1]), [p0, p0 - P_ATM], t_eval=t, rtol=1e-10, atol=1e-6,
                    method="LSODA", max_step=1e-4)
    np.testing.assert_allclose(got, ref.y[0], rtol=2e-5)
    invariant = ref.y[0] * (1.5e-7 + area * x + c * ref.y[1]) ** kappa
    np.testing.assert_allclose(invariant, invariant[0], rtol=1e-6)
    before = slice(0, int(np.argmax(rigid > p0 + 0.9 * w)))  # until it first nears w
    np.testing.assert_allclose(got[before], rigid[before], rtol=0, atol=1.0)
    assert abs(rigid[-1] - p0) < 1.0
    assert got[-1] < p0 - 0.2 * w  # the wall gave on the way in and holds on the way out


def test_a_shared_ground_shifts_the_reading_with_the_coils_current():
    """A step from 0 to 5 V at 10 ms: the reading shifts by s (1 - exp(-(t - 10 ms) /
    tau)) after it; at half command half as far; shift 0 reads true."""
    t = np.arange(400) * 1e-4
    p = np.full(t.size, 3e5)
    u = np.where(t >= 0.01 - 1e-12, 5.0, 0.0)
    shift = SolenoidGroundShift(shift_Pa=-4000.0, time_constant_s=4e-3, full_command_V=5.0)
    after = t >= 0.01 - 1e-12
    want = p - 4000.0 * np.where(after, -np.expm1(-(t - 0.01) / 4e-3), 0.0)
    np.testing.assert_allclose(shift.read(t, u, p), want, rtol=0, atol=1e-6)
    half = shift.read(t, np.full(t.size, -2.5), p)  # either coil: |u|
    np.testing.assert_allclose(half, p - 2000.0, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(SolenoidGroundShift(shift_Pa=0.0).read(t, u, p), p)


def test_a_pressure_held_solenoid_opens_slower_into_an_empty_chamber(rig):
    """Without slowing it is the catalogue's first-order spool lag, bit for bit; with it
    an opening step into the empty chamber fills later, a closing step (the spring and
    the pressure together) is the plain lag's, bit for bit."""
    from pneubayes.effects import make_effect

    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    lag = (make_effect("spool_lag"),)
    # (steps at 3 ms; the held one is full 30 ms after it, the closing's empty in 24 ms)
    opening = _held(0.035, (-5.0, 5.0), at=(0.0, 0.003))
    closing = _held(0.03, (5.0, -5.0), at=(0.0, 0.003))
    plain = PressureHeldSolenoid(time_constant_s=1e-3, slowing_per_atm=0.0)
    held = PressureHeldSolenoid(time_constant_s=1e-3, slowing_per_atm=2.0)
    first = simulate_plant(dict(params, spool_time_constant_s=1e-3), (), opening, rig,
                           P_ATM, REF, effects=lag).pressure_Pa
    np.testing.assert_array_equal(_run(params, (plain,), opening, rig), first)
    slow = _run(params, (held,), opening, rig)
    k = int(round(0.006 / DT))
    assert slow[k] < first[k] - 20e3  # 3 ms after the step the held one lags far behind
    np.testing.assert_allclose(slow[-1], first[-1], rtol=0, atol=500.0)  # both full
    np.testing.assert_array_equal(_run(params, (held,), closing, rig, p0=P_SUP - 1e3),
                                  _run(params, (plain,), closing, rig, p0=P_SUP - 1e3))
    with pytest.raises(ValueError, match="PressureHeldSolenoid is the spool's stage"):
        _run(params, (held, forms_from_names(["spool_lag"])[0]), _held(0.02, (1.0,)), rig)


def test_a_sensor_facing_the_inlets_jet_reads_the_square_of_the_inflow(rig, base):
    """The plant returns the inlet's mass flow (eqs. 1-3 at the sampled pressures); the
    reading adds s (q / q_ref)^2 of the inflow only; shift 0 reads true."""
    inputs = _held(0.05, (5.0, -5.0), at=(0.0, 0.025))
    traj = simulate_plant(base, (), inputs, rig, P_ATM, REF)
    from pneubayes.physics.valve import gompertz_scalar

    area = gompertz_scalar(5.0, *(base[n] for n in ("inlet_offset_m2", "inlet_a_m2",
                                                    "inlet_b", "inlet_c_per_V",
                                                    "inlet_d_V")))
    g = rig.gas
    want = [area * flow_terms(P_SUP, p, g.alpha_s_per_m, g.beta_s_per_m, g.theta,
                              g.heat_capacity_ratio)[0] for p in traj.pressure_Pa[1:200]]
    np.testing.assert_allclose(traj.inlet_flow_kg_per_s[1:200], want, rtol=1e-9)
    jet = InletJetAtSensor(shift_Pa=2000.0, reference_flow_kg_per_s=5e-4)
    r = jet.read(traj.inlet_flow_kg_per_s, traj.pressure_Pa)
    q = np.maximum(traj.inlet_flow_kg_per_s, 0.0)
    np.testing.assert_allclose(r - traj.pressure_Pa, 2000.0 * (q / 5e-4) ** 2, rtol=0,
                               atol=1e-9)  # (r - p: p's rounding, ~1e-11 Pa)
    assert (r - traj.pressure_Pa)[10] > 100.0  # filling: a visible shift
    np.testing.assert_array_equal(InletJetAtSensor(shift_Pa=0.0).read(q, traj.pressure_Pa),
                                  traj.pressure_Pa)


def test_a_bouc_wen_wall_conserves_a_shut_chamber_s_gas_and_keeps_a_loop(rig):
    """Valve shut, the piston pushed in and drawn back: an independent two-state
    reference (p and z, solved here) with ``p (V + C_e y + V_h z / z_max)^kappa``
    conserved; the wall's hysteretic part ends displaced (a loop), never past its
    memory, where a purely elastic wall returns to its start."""
    from scipy.integrate import solve_ivp

    ce, vh, zm, n = 1e-12, 3e-7, 40e3, 2.0
    wall = BoucWenWall(elastic_compliance_m3_per_Pa=ce, loop_volume_m3=vh, memory_Pa=zm,
                       exponent=n)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    t = np.arange(4001) * 1e-4
    omega = np.pi / t[-1]
    x = 0.6 * STROKE - 0.4 * STROKE * np.sin(omega * t) ** 2  # in and back
    inputs = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    p0 = 2e5
    got = _run(params, (wall,), inputs, rig, p0=p0)
    area, kappa = np.pi / 4 * BORE**2, rig.gas.heat_capacity_ratio

    def volume(tau, p, z):
        x_now = 0.6 * STROKE - 0.4 * STROKE * np.sin(omega * tau) ** 2
        return 1.5e-7 + area * x_now + ce * (p - P_ATM) + vh * z / zm

    def rhs(tau, state):
        p, z = state
        xdot = -0.4 * STROKE * omega * np.sin(2 * omega * tau)
        rising = xdot < 0  # compressing: p rises
        g = 1.0 - (abs(z) / zm) ** n if (z > 0) == rising and z != 0 else 1.0
        dp = -kappa * p * area * xdot / (volume(tau, p, z) + kappa * p * (ce + vh * g / zm))
        return [dp, g * dp]

    ref = solve_ivp(rhs, (0, t[-1]), [p0, 0.0], t_eval=t, rtol=1e-10, atol=1e-6,
                    method="LSODA", max_step=1e-4)
    np.testing.assert_allclose(got, ref.y[0], rtol=2e-5)
    invariant = ref.y[0] * np.array([volume(a, b, c) for a, b, c in
                                     zip(t, ref.y[0], ref.y[1])]) ** kappa
    np.testing.assert_allclose(invariant, invariant[0], rtol=1e-6)
    assert np.max(np.abs(ref.y[1])) < zm
    assert abs(ref.y[1][-1]) > 0.2 * zm and abs(got[-1] - p0) > 1e3  # displaced: a loop
    elastic = _run(params, (BoucWenWall(elastic_compliance_m3_per_Pa=ce,
                                        loop_volume_m3=0.0),), inputs, rig, p0=p0)
    assert abs(elastic[-1] - p0) < 1.0


def test_a_loaded_wall_rings_and_conserves_a_shut_chamber_s_gas(rig):
    """Valve shut, the piston pushed in and drawn back: an independent three-state
    reference (p, the give and its rate, solved here) with ``p (V + dV)^kappa``
    conserved; after the piston stops the give rings at the wall's damped frequency
    about its static give, which a rigid wall does not."""
    from scipy.integrate import solve_ivp

    c, f, z = 2e-12, 20.0, 0.1
    wall = LoadedWall(compliance_m3_per_Pa=c, natural_frequency_Hz=f, damping_ratio=z)
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    t = np.arange(4001) * 1e-4
    x = np.where(t < 0.05, 0.6 * STROKE - 0.3 * STROKE * np.sin(np.pi * t / 0.1) ** 2,
                 0.3 * STROKE)  # pushed in over 50 ms, then held
    inputs = Inputs(t, np.zeros(t.size), x, np.full(t.size, P_SUP))
    p0 = 2e5
    got = _run(params, (wall,), inputs, rig, p0=p0)
    area, kappa, w = np.pi / 4 * BORE**2, rig.gas.heat_capacity_ratio, 2 * np.pi * f

    def position(tau):
        if tau >= 0.05:
            return 0.3 * STROKE, 0.0
        return (0.6 * STROKE - 0.3 * STROKE * np.sin(np.pi * tau / 0.1) ** 2,
                -0.3 * STROKE * np.pi / 0.1 * np.sin(2 * np.pi * tau / 0.1))

    def rhs(tau, state):
        p, dv, rate = state
        xx, xdot = position(tau)
        vol = 1.5e-7 + area * xx + dv
        return [-kappa * p * (area * xdot + rate) / vol, rate,
                w * w * (c * (p - P_ATM) - dv) - 2 * z * w * rate]

    ref = solve_ivp(rhs, (0, t[-1]), [p0, c * (p0 - P_ATM), 0.0], t_eval=t, rtol=1e-10,
                    atol=[1e-6, 1e-18, 1e-15], method="LSODA", max_step=1e-4)
    np.testing.assert_allclose(got, ref.y[0], rtol=2e-5)
    vols = 1.5e-7 + area * np.array([position(a)[0] for a in t]) + ref.y[1]
    invariant = ref.y[0] * vols ** kappa
    np.testing.assert_allclose(invariant, invariant[0], rtol=1e-6)
    late = got[t > 0.06] - np.mean(got[t > 0.3])
    crossings = np.count_nonzero(np.diff(np.sign(late)) != 0)
    assert crossings >= 4  # it rings (20 Hz, lightly damped) after the piston stops
    rigid = _run(params, (), inputs, rig, p0=p0)
    assert np.ptp(rigid[t > 0.06]) < 1.0


def test_a_pilot_fed_spool_stalls_a_fill_where_its_shift_shuts_the_inlet(rig):
    """A full command (5 V) on a valve whose inlet shuts below about 2.7 V: with 1 V of
    spool per bar above a 1-bar preload the fill stalls between 2.9 and 3.5 bar gauge
    (where the shift shuts the inlet), far below the supply the plain valve reaches, and
    below the preload it fills as the plain valve does. A slower pilot (50 ms) shifts the
    spool only after the small chamber has filled far past that stall, and then shuts
    the inlet without opening the exhaust: the chamber is held above it."""
    params = dict(CLOSABLE, dead_volume_m3=1.5e-7)
    fill = _held(0.6, (5.0,))
    plain = _run(params, (), fill, rig)
    fed = PilotFedSpool(feedback_V_per_bar=1.0, preload_Pa=1e5, pilot_time_constant_s=1e-3)
    got = _run(params, (fed,), fill, rig)
    assert plain[-1] > P_SUP - 1e3
    assert 2.9e5 < got[-1] - P_ATM < 3.5e5
    below = got - P_ATM < 0.9e5
    assert below.sum() > 5
    np.testing.assert_allclose(got[below], plain[below], rtol=1e-6)
    slow = _run(params, (replace(fed, pilot_time_constant_s=0.05),), fill, rig)
    assert slow[-1] > got[-1] + 5e4
    assert np.ptp(slow[-1000:]) < 1.0  # (shut: held for the last 0.1 s)
