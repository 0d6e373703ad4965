"""Realistic alternative forms of the catalogue effects, for the high-fidelity plant.

The catalogue effects (:mod:`pneubayes.effects`) are the forms the models fit. A
discovery loop tuned on data planted with exactly those forms may not recognise an
effect built differently, as it is in outside recordings. Each class here is a
physically different, more detailed form of one catalogue effect, simulated by the
independent plant of :mod:`pneubayes.bench.plant`; ``catalogue_name`` names the effect
a discovery run should report for it.

The *out-of-catalogue* forms are effects no catalogue effect expresses: their
``catalogue_name`` is None, meaning a discovery run should name *no* catalogue effect
for them (an open-form closure term may describe them). They test the open-form stage
blind, in two sets drawn once each: the first (:class:`BladderVolume`,
:class:`SpoolHysteresis`, :class:`ReliefValve`, :class:`InletFlowForce`,
:class:`LipSealLeak`) and, built after the open-form stage had been developed against
the first, the second (:class:`ExhaustSilencer`, :class:`ScoredBarrelLeak`,
:class:`CreepingWall`, :class:`PilotInletValve`), and, built after the stage had been
developed against the second, the third (:class:`Iso6358Ports`, :class:`SpoolSlewLimit`,
:class:`SpoolUnderlap`, :class:`MeterOutThrottle`), and, built after the stage had been
developed against the third, the fourth (:class:`SupplyHose`, :class:`LowReynoldsPorts`,
:class:`SpoolStiction`, :class:`SensorBow`); the later sets' forms are listed in
:data:`FORMS` in the order they were written (the eighth: :class:`QuickExhaustValve`,
:class:`GasAccumulator`, :class:`SpoolLandLeak`, :class:`SensorThermalShock`; the ninth:
:class:`PwmValve`, :class:`ZohDriver`, :class:`SensorHysteresis`,
:class:`SealSpeedLeak`; the tenth: :class:`BraidFriction`, :class:`SolenoidGroundShift`,
:class:`PressureHeldSolenoid`, :class:`InletJetAtSensor`; the eleventh, a check of the
volume's plays on a loop that is not one: :class:`BoucWenWall`; the twelfth, a wall that
carries a load: :class:`LoadedWall`; the thirteenth, readings logged through a rail and
late: :class:`SaturatingSensor`, :class:`SkewedPressureChannel`; the fourteenth, a
spool pushed back by its delivered pressure through a pilot: :class:`PilotFedSpool`).
:class:`ArmatureDeadTime` and :class:`HeldArmatureDeadTime` are realistic forms of the
catalogue's ``valve_dead_time`` (an armature the supply drives, or holds back).
:class:`Iso6358Ports`, out of the catalogue in the third set, is a realistic form of
``critical_ratio`` since that effect was added (ISO 6358's ellipse and subsonic index
against the effect's stretched eq. 3).

Every form is a small frozen dataclass with SI units in its field names, validating its
fields on construction; :meth:`PlantForm.to_dict` gives the record written to
``truth.json``, :func:`form_from_dict` reads it back.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import fields

from pneubayes.bench.forms.base import AIR_VISCOSITY_PA_S, PlantForm
from pneubayes.bench.forms.catalogue import (
    AcousticTube,
    ClearanceLeak,
    RegulatorDroop,
    RoundedDeadzone,
    SecondOrderSpool,
    WallHeatTransfer,
)
from pneubayes.bench.forms.chamber import (
    BladderVolume,
    BoucWenWall,
    BraidFriction,
    CreepingWall,
    EndCushion,
    EnergisedSealLeak,
    GasAccumulator,
    LipSealLeak,
    LoadedWall,
    PistonSealBypass,
    ReliefValve,
    ScoredBarrelLeak,
    SealSpeedLeak,
)
from pneubayes.bench.forms.ports import (
    ExhaustCheckValve,
    ExhaustSilencer,
    MeterOutThrottle,
    QuickExhaustValve,
    SupplyHose,
)
from pneubayes.bench.forms.reading import (
    CapillarySensorPort,
    InletJetAtSensor,
    LaggingPositionSensor,
    SaturatingSensor,
    SensorBow,
    SensorHysteresis,
    SensorThermalShock,
    SensorZeroDrift,
    SkewedPressureChannel,
    SolenoidGroundShift,
)
from pneubayes.bench.forms.valve import (
    ArmatureDeadTime,
    HeldArmatureDeadTime,
    InletFlowForce,
    InletFlowLimiter,
    Iso6358Ports,
    LowReynoldsPorts,
    PilotFedSpool,
    PilotInletValve,
    PressureHeldSolenoid,
    PwmValve,
    ReleaseDelay,
    SeatLeak,
    SpoolHysteresis,
    SpoolLandLeak,
    SpoolSlewLimit,
    SpoolStiction,
    SpoolUnderlap,
    SpringReturnSpool,
    WarmingCoil,
    ZohDriver,
)
from pneubayes.effects import CATALOGUE
from pneubayes.physics.cylinder import cylinder_preset
from pneubayes.physics.gas import GasConstants

FORMS: dict[str, type[PlantForm]] = {
    cls.__name__: cls for cls in (AcousticTube, RoundedDeadzone, ClearanceLeak, RegulatorDroop,
                                  SecondOrderSpool, WallHeatTransfer, BladderVolume,
                                  SpoolHysteresis, ReliefValve, InletFlowForce, LipSealLeak,
                                  ExhaustSilencer, ScoredBarrelLeak, CreepingWall,
                                  PilotInletValve, Iso6358Ports, SpoolSlewLimit,
                                  SpoolUnderlap, MeterOutThrottle, SupplyHose,
                                  LowReynoldsPorts, SpoolStiction, SensorBow,
                                  SpringReturnSpool, WarmingCoil, CapillarySensorPort,
                                  LaggingPositionSensor, ExhaustCheckValve, SeatLeak,
                                  InletFlowLimiter, ReleaseDelay, PistonSealBypass,
                                  EnergisedSealLeak, SensorZeroDrift, EndCushion,
                                  QuickExhaustValve, GasAccumulator, SpoolLandLeak,
                                  SensorThermalShock, PwmValve, ZohDriver, SensorHysteresis,
                                  SealSpeedLeak, BraidFriction, SolenoidGroundShift,
                                  PressureHeldSolenoid, InletJetAtSensor, BoucWenWall,
                                  LoadedWall, SaturatingSensor, SkewedPressureChannel,
                                  ArmatureDeadTime, HeldArmatureDeadTime, PilotFedSpool)
}
#: The out-of-catalogue forms (``catalogue_name`` None), by class name.
OUT_OF_CATALOGUE: tuple[str, ...] = tuple(n for n, c in FORMS.items()
                                          if c.catalogue_name is None)


def form_from_dict(record: Mapping) -> PlantForm:
    """Rebuild a form from :meth:`PlantForm.to_dict` output (e.g. truth.json's record)."""
    if not isinstance(record, Mapping) or "form" not in record:
        raise ValueError(f"form record must be an object with key 'form', got {record!r}")
    try:
        cls = FORMS[record["form"]]
    except (KeyError, TypeError):
        raise ValueError(f"form record: unknown form {record['form']!r}; known "
                         f"{sorted(FORMS)}") from None
    names = {f.name for f in fields(cls)}
    values = {k: v for k, v in record.items() if k not in ("form", "catalogue_name")}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ValueError(f"form record {record['form']}: unknown field(s) {unknown}")
    if record.get("catalogue_name", cls.catalogue_name) != cls.catalogue_name:
        raise ValueError(f"form record {record['form']}: catalogue_name "
                         f"{record['catalogue_name']!r} should be {cls.catalogue_name!r}")
    return cls(**values)


def check_forms(forms: Sequence[PlantForm], effect_names: Sequence[str] = ()) -> tuple:
    """Validate a forms tuple: PlantForm objects, each catalogue effect at most once
    among the forms and the catalogue ``effect_names`` planted beside them, each
    out-of-catalogue form at most once."""
    forms = tuple(forms)
    for f in forms:
        if not isinstance(f, PlantForm):
            raise TypeError(f"forms: {f!r} is not a plant form (one of {sorted(FORMS)})")
    seen = list(effect_names)
    kinds = [type(f).__name__ for f in forms]
    for k in set(kinds):
        if kinds.count(k) > 1:
            raise ValueError(f"forms: {k} planted {kinds.count(k)} times; plant each form once")
    for f in forms:
        if f.catalogue_name is None:
            continue
        if f.catalogue_name in seen:
            raise ValueError(f"forms: {type(f).__name__} is a form of {f.catalogue_name!r}, "
                             f"which is already planted (as an effect or another form); "
                             f"plant each catalogue effect once")
        seen.append(f.catalogue_name)
    return forms


#: Catalogue scale of the leak per cylinder (the bench's CYLINDER_TRUTH leak_scale).
_LEAK_SCALE = {"AIR37": 1.0, "AIR200": 1.0, "SMC": 0.05, "PRN": 0.05}
#: The catalogue's laminar bench conductance (CylinderLeak("laminar").bench_defaults()).
_LAMINAR_BENCH_K = 1.9e-16


def forms_from_names(names: Sequence[str], cylinder: str = "AIR37",
                     gas: GasConstants | None = None) -> tuple[PlantForm, ...]:
    """Realistic default forms for catalogue effect names, on ``cylinder``'s rig.

    - ``tube_delay``: a 1 m tube of 2 mm, 8 cells (L/c = 2.9 ms);
    - ``valve_deadzone``: 0.3 V half-width with 0.1 V rounding;
    - ``cylinder_leak``: a 4 mm seal lengthening to 6 mm over the stroke, with the gap
      that gives at position 0 the catalogue's laminar bench conductance (1.9e-16
      kg/(s Pa^2), the orifice default's flow at about 3 bar) times the rig's leak
      scale: about 10 um on the AIRPELs;
    - ``supply_fluctuation``: droop 40 kPa per g/s (20-35 kPa at the Table II valves'
      full inlet flow) with a 50 ms regulator time constant;
    - ``spool_lag``: 125 Hz natural frequency (the valve's bandwidth), damping 0.7;
    - ``heat_transfer``: wall convection h = 30 W/(m^2 K) (a wall time constant of
      about 0.1 s in a small chamber at 3 bar);
    - ``valve_dead_time``: a supply-driven armature, 2 ms of coil and 8 ms of travel at 5
      bar gauge;
    - ``critical_ratio``: both ports by ISO 6358 at b = 0.3 and a subsonic index of
      0.45 (the catalogue's form has 1/2).
    """
    cyl = cylinder_preset(cylinder)
    gas = gas or GasConstants()
    out = []
    for n in names:
        if n == "tube_delay":
            out.append(AcousticTube(length_m=1.0, diameter_m=0.002, segments=8))
        elif n == "valve_deadzone":
            out.append(RoundedDeadzone(halfwidth_V=0.3, rounding_V=0.1))
        elif n == "cylinder_leak":
            k = _LAMINAR_BENCH_K * _LEAK_SCALE.get(cylinder, 1.0)
            seal = 0.004
            rs_t = gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
            gap = (k * 24.0 * AIR_VISCOSITY_PA_S * seal * rs_t / (math.pi * cyl.bore_m)) ** (1 / 3)
            out.append(ClearanceLeak(gap_m=float(gap), seal_length_m=seal,
                                     seal_length_slope=0.002 / cyl.stroke_m))
        elif n == "supply_fluctuation":
            out.append(RegulatorDroop(droop_Pa_per_g_per_s=40_000.0, time_constant_s=0.05))
        elif n == "spool_lag":
            out.append(SecondOrderSpool(natural_frequency_Hz=125.0, damping=0.7))
        elif n == "heat_transfer":
            out.append(WallHeatTransfer(h_W_per_m2_K=30.0))
        elif n == "valve_dead_time":
            out.append(ArmatureDeadTime(travel_s=8e-3))
        elif n == "critical_ratio":
            out.append(Iso6358Ports(critical_pressure_ratio=0.3, subsonic_index=0.45))
        else:
            raise ValueError(f"forms_from_names: unknown effect {n!r}; the catalogue has "
                             f"{sorted(CATALOGUE)}")
    return check_forms(out)


def catalogue_names_of(forms: Sequence[PlantForm]) -> list[str]:
    """The catalogue effects the forms are versions of (out-of-catalogue forms: none),
    i.e. what a discovery run should name for them."""
    return [f.catalogue_name for f in forms if f.catalogue_name is not None]


def out_of_catalogue_defaults(name: str, cylinder: str = "AIR37",
                              atmospheric_pressure_Pa: float = 101_325.0) -> PlantForm:
    """Realistic default of out-of-catalogue form ``name`` (a class name) on ``cylinder``:
    each form at a typical size for the rig (the values are in the code below, each
    form's docstring says what they mean; e.g. ``BladderVolume`` 10 % of the swept
    volume with a 150-kPa scale, ``ReliefValve`` cracking at 3.5 bar gauge with 1 g/s at
    1 bar overpressure, ``ZohDriver`` updating every 10 ms, 2 ms late), so that each is
    visible on the bench's recordings without dominating them.
    """
    cyl = cylinder_preset(cylinder)
    if name == "BladderVolume":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BladderVolume(dV_max_m3=0.1 * swept, pressure_scale_Pa=150_000.0)
    if name == "SpoolHysteresis":
        return SpoolHysteresis(half_band_V=0.15, time_constant_s=2e-4)
    if name == "ReliefValve":
        return ReliefValve(crack_pressure_Pa=atmospheric_pressure_Pa + 350_000.0,
                           flow_coefficient_kg_per_s_Pa1p5=3.2e-11)
    if name == "InletFlowForce":
        return InletFlowForce(flow_force_coefficient=0.1)
    if name == "LipSealLeak":
        return LipSealLeak(seal_pressure_Pa=atmospheric_pressure_Pa + 200_000.0,
                           conductance_kg_per_s_Pa2=4.8e-16)
    if name == "ExhaustSilencer":
        return ExhaustSilencer(back_pressure_Pa=100_000.0, laminar_fraction=0.5,
                               volume_m3=2e-6)
    if name == "ScoredBarrelLeak":
        return ScoredBarrelLeak(start_m=0.30 * cyl.stroke_m, end_m=0.55 * cyl.stroke_m,
                                area_m2=8e-8, edge_m=0.05 * cyl.stroke_m)
    if name == "CreepingWall":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return CreepingWall(compliance_m3_per_Pa=0.08 * swept / 450_000.0,
                            time_constant_s=0.2)
    if name == "PilotInletValve":
        return PilotInletValve(min_pressure_difference_Pa=40_000.0, transition_fraction=0.5)
    if name == "Iso6358Ports":
        return Iso6358Ports(critical_pressure_ratio=0.3, subsonic_index=0.5)
    if name == "SpoolSlewLimit":
        return SpoolSlewLimit(slew_rate_V_per_s=300.0, time_constant_s=5e-4)
    if name == "SpoolUnderlap":
        return SpoolUnderlap(area_m2=5e-8, width_V=0.5)
    if name == "MeterOutThrottle":
        return MeterOutThrottle(needle_area_m2=2e-7, check_area_m2=1e-6,
                                crack_pressure_Pa=10e3, volume_m3=5e-7)
    if name == "SupplyHose":
        return SupplyHose(restriction_area_m2=1e-6, volume_m3=5e-5)
    if name == "LowReynoldsPorts":
        return LowReynoldsPorts(critical_reynolds=500.0)
    if name == "SpoolStiction":
        return SpoolStiction(breakaway_V=0.15, stop_V=0.05)
    if name == "SensorBow":
        return SensorBow(bow_Pa=3000.0, span_Pa=1.0e6)
    if name == "SpringReturnSpool":
        return SpringReturnSpool(rise_time_constant_s=6e-4, fall_time_constant_s=2.4e-3)
    if name == "WarmingCoil":
        return WarmingCoil(resistance_rise=0.08, time_constant_s=5.0)
    if name == "CapillarySensorPort":
        return CapillarySensorPort(time_constant_s=2e-3)
    if name == "LaggingPositionSensor":
        return LaggingPositionSensor(time_constant_s=5e-3)
    if name == "ExhaustCheckValve":
        return ExhaustCheckValve(crack_pressure_Pa=30e3)
    if name == "SeatLeak":
        return SeatLeak(area_m2=3e-8)
    if name == "InletFlowLimiter":
        return InletFlowLimiter(max_flow_kg_per_s=5e-4)
    if name == "ReleaseDelay":
        return ReleaseDelay(delay_s=4e-3)
    if name == "PistonSealBypass":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return PistonSealBypass(conductance_kg_per_s_Pa2=2e-16, vent_area_m2=3e-8,
                                opposite_volume_m3=1.2 * swept)
    if name == "EnergisedSealLeak":
        return EnergisedSealLeak(conductance_kg_per_s_Pa2=8e-15, energising_pressure_Pa=1.5e5)
    if name == "SensorZeroDrift":
        return SensorZeroDrift(drift_Pa=5e3, time_constant_s=10.0)
    if name == "EndCushion":
        return EndCushion(length_m=0.1 * cyl.stroke_m, needle_area_m2=5e-8,
                          edge_m=0.02 * cyl.stroke_m)
    if name == "QuickExhaustValve":
        return QuickExhaustValve(exhaust_area_m2=1.5e-6)
    if name == "GasAccumulator":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return GasAccumulator(volume_m3=0.5 * swept,
                              precharge_Pa=atmospheric_pressure_Pa + 200_000.0)
    if name == "SpoolLandLeak":
        return SpoolLandLeak(conductance_kg_per_s_Pa2=1e-16)
    if name == "SensorThermalShock":
        return SensorThermalShock(gain=0.03)
    if name == "PwmValve":
        return PwmValve(frequency_Hz=50.0)
    if name == "ZohDriver":
        return ZohDriver(update_period_s=0.01, latency_s=2e-3)
    if name == "SensorHysteresis":
        return SensorHysteresis(half_width_Pa=2000.0)
    if name == "SealSpeedLeak":
        return SealSpeedLeak(conductance_kg_per_s_Pa2=1e-16)
    if name == "BraidFriction":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BraidFriction(compliance_m3_per_Pa=0.1 * swept / 450_000.0,
                             friction_band_Pa=30e3)
    if name == "SolenoidGroundShift":
        return SolenoidGroundShift(shift_Pa=3000.0, time_constant_s=5e-3)
    if name == "BoucWenWall":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BoucWenWall(elastic_compliance_m3_per_Pa=0.05 * swept / 450_000.0,
                           loop_volume_m3=0.05 * swept, memory_Pa=50e3)
    if name == "LoadedWall":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return LoadedWall(compliance_m3_per_Pa=0.1 * swept / 450_000.0)
    if name == "PressureHeldSolenoid":
        return PressureHeldSolenoid(time_constant_s=5e-4, slowing_per_atm=1.5)
    if name == "PilotFedSpool":
        return PilotFedSpool(feedback_V_per_bar=0.15, preload_Pa=1.0e5,
                             pilot_time_constant_s=5e-3)
    if name == "InletJetAtSensor":
        return InletJetAtSensor(shift_Pa=3000.0, reference_flow_kg_per_s=5e-4)
    if name == "SaturatingSensor":
        return SaturatingSensor(full_scale_Pa=3.5e5, knee_Pa=5e3)
    if name == "SkewedPressureChannel":
        return SkewedPressureChannel(delay_s=5e-3)
    raise ValueError(f"out_of_catalogue_defaults: unknown form {name!r}; known "
                     f"{list(OUT_OF_CATALOGUE)}")
