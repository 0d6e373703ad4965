"""The open-form blind sets: hidden effects that no catalogue effect expresses, drawn at
random, run once and reported once, never looked at while the open-form stage is tuned.

    python experiments/openform_blind.py --list                  # the cases, no runs
    python experiments/openform_blind.py --out results/openform  # run (resumes), report
    python experiments/openform_blind.py --out /tmp/of --smoke   # a short tuning-draw check
    python experiments/openform_blind.py --out results/openform --case o03   # one case
    python experiments/openform_blind.py --set 2 --out results/blind2 --case n00

The hidden effects are the out-of-catalogue plant forms of
:mod:`pneubayes.bench.forms` (``catalogue_name`` None), in fourteen sets (``--set``, each
drawn once from its own seed, :data:`SET_SEEDS`). Set 1 (the default; seed 69069, run
on 2026-12-01 and since spent on the stage's development): a compliant bladder volume,
spool play (backlash), a relief valve, inlet flow forces and a lip-seal leak, cases
``o00``-``o11``. Set 2 (seed 1796182831, drawn from the clock on 2026-12-02 and recorded
before any run): a porous exhaust silencer with its own volume, a leak over a scored
section of the barrel, a creeping (viscoelastic) chamber wall and a pilot-operated inlet
that needs a minimum pressure difference, cases ``n00``-``n09``. Set 3 (seed 1796214872,
drawn from the clock on 2026-12-02 and recorded before any run): valve ports that follow
the ISO 6358 flow law, a spool whose speed saturates (slew limit), an underlapped spool
that leaks through the null, and a meter-out speed controller (needle and check valve)
at the cylinder's port, cases ``t00``-``t09``. Set 4 (seed 1796227429, drawn from the
clock on 2026-12-02 and recorded before any run): a supply hose behind a restriction
that starves the valve (the supply sensor at the regulator), ports whose discharge falls
at low Reynolds numbers, a sticking spool, and a pressure sensor whose reading bows off
its straight line, cases ``q00``-``q09``. Set 5 (seed 1796247339, drawn from the clock on
2026-12-02 and recorded before its forms were written or any case ran): a spool
returned by its spring slower than its solenoid drives it, a voltage-driven solenoid
whose coil warms, a pressure sensor behind a capillary, and a length sensor that lags
the piston, cases ``v00``-``v09``. Set 6 (seed 1796267760, drawn from the clock on
2026-12-03 and recorded before its forms were written or any case ran): a check valve
in the exhaust line, a worn inlet seat that leaks at the incompressible law, a flow
limiter at the inlet, and a solenoid that releases late, cases ``w00``-``w09``. Set 7
(seed 1796286123, drawn from the clock on 2026-12-03 and recorded before its forms were
written or any case ran): a worn piston seal into the cylinder's other chamber behind a
breather, a pressure-energised seal whose leak peaks at low pressure, a pressure
sensor whose zero drifts as it warms, and an end-of-stroke cushion, cases
``x00``-``x09``. Set 8 (seed 1796395770, drawn from the clock on 2026-12-04 and recorded
before its forms were written or any case ran): a quick-exhaust valve at the chamber's
port, a gas-charged accumulator on the chamber, laminar leaks across the spool's lands,
and a pressure sensor whose diaphragm's temperature transient overshoots a step, cases
``y00``-``y09``. Set 9 (seed 1796427610, drawn from the clock on 2026-12-04 and recorded
before its forms were written or any case ran): on/off valves driven by pulse-width
modulation of the command, a valve driver that samples and holds the command at a low
rate with a latency, a pressure sensor with play in its diaphragm (hysteresis), and a
piston seal whose leak grows with the piston's speed, cases ``z00``-``z09``. Set 10 (seed
1796445175, drawn from the clock on 2026-12-05 and recorded before its forms were written
or any case ran): a flexible wall whose give is held by friction (a hysteretic volume), a
sensor grounded through the solenoid driver's return (its zero moves with the coil's
current), a solenoid held shut by the inlet's drop (it opens slower into an empty
chamber) and a sensor port facing the inlet's jet, cases ``k00``-``k09``. Sets 11 and 12
are one form each, on both rigs beside the two controls: a wall with a Bouc-Wen loop
(seed 1796458249, cases ``m00``-``m03``) and a wall that carries a load, a mass on a
spring (seed 1796499138, drawn from the clock on 2026-12-05 and recorded before its form
was written or any case ran; cases ``j00``-``j03``). Set 13 (two forms: readings
logged through a rail and late) has cases ``g00``-``g05``; set 14 (seed 1796657361,
drawn from the clock on 2026-12-07 before its form was written) one form, a spool
pushed back by its delivered pressure through a pilot, cases ``f00``-``f03``. Each form
is planted
on two rigs (AIR37 / valve 1 and SMC / valve 2) with its parameters drawn from wide
physical ranges (:func:`draw_openform`) from ``--seed`` (default: the set's, recorded);
two null controls hide nothing. Every case runs the bench (``discovery_study``'s six
recordings, or the first ``--recordings`` of them, ``--duration`` s each; the bench's
declared zero-phase DAQ filter, so the sensor chain has no real lag to find) and
``pneubayes discover`` from the plain model. ``--setting KEY.PATH=VALUE`` (repeatable;
the value read as TOML, else as text) sets one :class:`DiscoverySettings` key, e.g.
``stages.open_form_min_noise_ratio=0`` to switch the open-form stage off; the settings
are recorded.

Reported per case: the catalogue effects named, the open-form terms found (the
discovery document's ``found_terms``, from an effect named ``closure``, and its
``found_reading_terms``, relaxations, plays and command lags of the reading, and
``found_volume_terms``, hinges and walls of the chamber's volume, and
``found_command_terms``, a valve driver's clock; none when the loop has no
open-form stage), the held-out RMSE before and after (Pa), the noise floor, the gap
shrink and final / noise. The issue's floors: out-of-catalogue cases name no
catalogue stand-in in >= 8 of 10, median gap shrink >= 70 %, median final <= 2 x the
noise floor; null controls find no open-form term and name nothing beyond the sensor
chain's real lags (none here). Cases are cached in OUT/cases/NAME.json (an interrupted
run resumes); OUT/summary.json and OUT/summary.md hold the report with the seed, git
revision and versions. ``--case NAME`` runs only those cases into the cache (a second
process can take a second core); rerun without it to report. ``--report`` reports from
the cache alone, runs nothing and lists the cases without a result as not finished (a
set stopped at its deadline).

``--smoke`` runs one short case (a relief valve, 13-s recordings, four of them) drawn
from a different seed -- a tuning draw, not the blind set -- to check the plumbing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from discovery_study import cached_cases, results_root, six_recordings

from pneubayes.atomic import write_json_atomic, write_text_atomic
from pneubayes.bench.bench import ATMOSPHERE_PA, SUPPLY_PA
from pneubayes.bench.forms import (
    OUT_OF_CATALOGUE,
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
    check_forms,
)
from pneubayes.bench.sensors import SensorChain
from pneubayes.discovery.report import run_discover
from pneubayes.discovery.settings import DiscoverySettings, PosteriorSettings, SearchSettings
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.physics.cylinder import cylinder_preset
from pneubayes.provenance import provenance
from pneubayes.settings_tree import assignment, override, table_of

OPENFORM_SEED = 69069
#: Set 2's seed: ``date +%s`` at 2026-12-02 03:40:31 UTC, fixed before any case ran.
OPENFORM_SEED_2 = 1796182831
#: Set 3's seed: ``date +%s`` at 2026-12-02 12:34:32 UTC, fixed before any case ran.
OPENFORM_SEED_3 = 1796214872
#: Set 4's seed: ``date +%s`` at 2026-12-02 16:03:49 UTC, fixed before any case ran.
OPENFORM_SEED_4 = 1796227429
#: Set 5's seed: ``date +%s`` at 2026-12-02 21:35:39 UTC, fixed before its forms were
#: written or any case ran.
OPENFORM_SEED_5 = 1796247339
#: Set 6's seed: ``date +%s`` at 2026-12-03 03:16:00 UTC, fixed before its forms were
#: written or any case ran.
OPENFORM_SEED_6 = 1796267760
#: Set 7's seed: ``date +%s`` at 2026-12-03 08:22:03 UTC, fixed before its forms were
#: written or any case ran.
OPENFORM_SEED_7 = 1796286123
#: Set 8's seed: ``date +%s`` at 2026-12-04 14:49:30 UTC, fixed before its forms were
#: written or any case ran.
OPENFORM_SEED_8 = 1796395770
#: Set 9's seed: ``date +%s`` at 2026-12-04 23:40:10 UTC, fixed before its forms were
#: written or any case ran.
OPENFORM_SEED_9 = 1796427610
#: Set 10's seed: ``date +%s`` at 2026-12-05 04:32:55 UTC, fixed before its forms were
#: written or any case ran.
OPENFORM_SEED_10 = 1796445175
#: Set 11's seed (a check of the volume's plays on a loop no play sum is: one form on
#: the two rigs and the controls): ``date +%s`` at 2026-12-05 08:10:49 UTC, fixed before
#: its form was written or any case ran.
OPENFORM_SEED_11 = 1796458249
#: Set 12's seed (one form, a wall that carries a load, on the two rigs and the
#: controls): ``date +%s`` at 2026-12-05 19:32:18 UTC, fixed before its form was written
#: or any case ran.
OPENFORM_SEED_12 = 1796499138
#: Set 13's seed (two forms of the logged reading, a rail and a late channel, on the two
#: rigs and the controls): ``date +%s`` at 2026-12-05 21:54:27 UTC, fixed before its
#: forms were written or any case ran.
OPENFORM_SEED_13 = 1796507667
#: Set 14's seed (one form, a spool pushed back by its delivered pressure through a
#: pilot, on the two rigs and the controls): ``date +%s`` at 2026-12-07 15:29:21 UTC,
#: fixed before its form was written or any case ran.
OPENFORM_SEED_14 = 1796657361
SMOKE_SEED = 11
#: The out-of-catalogue forms of each blind set, and the set's seed and case prefix.
SET_FORMS = {1: ("BladderVolume", "SpoolHysteresis", "ReliefValve", "InletFlowForce",
                 "LipSealLeak"),
             2: ("ExhaustSilencer", "ScoredBarrelLeak", "CreepingWall", "PilotInletValve"),
             3: ("Iso6358Ports", "SpoolSlewLimit", "SpoolUnderlap", "MeterOutThrottle"),
             4: ("SupplyHose", "LowReynoldsPorts", "SpoolStiction", "SensorBow"),
             5: ("SpringReturnSpool", "WarmingCoil", "CapillarySensorPort",
                 "LaggingPositionSensor"),
             6: ("ExhaustCheckValve", "SeatLeak", "InletFlowLimiter", "ReleaseDelay"),
             7: ("PistonSealBypass", "EnergisedSealLeak", "SensorZeroDrift", "EndCushion"),
             8: ("QuickExhaustValve", "GasAccumulator", "SpoolLandLeak", "SensorThermalShock"),
             9: ("PwmValve", "ZohDriver", "SensorHysteresis", "SealSpeedLeak"),
             10: ("BraidFriction", "SolenoidGroundShift", "PressureHeldSolenoid",
                  "InletJetAtSensor"),
             11: ("BoucWenWall",), 12: ("LoadedWall",),
             13: ("SaturatingSensor", "SkewedPressureChannel"), 14: ("PilotFedSpool",)}
SET_SEEDS = {1: OPENFORM_SEED, 2: OPENFORM_SEED_2, 3: OPENFORM_SEED_3, 4: OPENFORM_SEED_4,
             5: OPENFORM_SEED_5, 6: OPENFORM_SEED_6, 7: OPENFORM_SEED_7, 8: OPENFORM_SEED_8,
             9: OPENFORM_SEED_9, 10: OPENFORM_SEED_10, 11: OPENFORM_SEED_11,
             12: OPENFORM_SEED_12, 13: OPENFORM_SEED_13, 14: OPENFORM_SEED_14}
SET_PREFIX = {1: "o", 2: "n", 3: "t", 4: "q", 5: "v", 6: "w", 7: "x", 8: "y", 9: "z",
              10: "k", 11: "m", 12: "j", 13: "g", 14: "f"}
#: Each out-of-catalogue form is planted on both rigs.
RIGS = ("AIR37:valve1", "SMC:valve2")
N_CONTROLS = 2
#: The sensor chain's real lags a control may name: none (the bench's DAQ filter is
#: zero-phase and declared to the fits).
CONTROL_ALLOWED: tuple[str, ...] = ()
#: The six recordings' preference when fewer are asked for: fixed +-5 V at 50 %, the
#: first moving one, fixed +-0.5 V at 90 %, the second moving one, then the rest
#: (indices into ``discovery_study.six_recordings``'s list).
RECORDING_ORDER = (0, 4, 3, 5, 1, 2)
#: The issue's floors.
FLOORS = {"no_stand_in_cases": 8, "gap_shrink_median": 0.70, "final_over_noise_median": 2.0}


def _log_uniform(rng, lo, hi) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _full_inlet_flow(valve: str) -> float:
    """The valve's inlet mass flow (kg/s) at its full command (+5 V) from the bench's
    supply into the atmosphere (choked; eqs. 1-3 with the Table II map)."""
    from pneubayes.physics.gas import GasConstants
    from pneubayes.physics.orifice import flow_terms
    from pneubayes.physics.valve import valve_preset

    area = float(valve_preset(valve).inlet.area(5.0))
    g = GasConstants()
    return float(area * flow_terms(SUPPLY_PA, ATMOSPHERE_PA, g.alpha_s_per_m, g.beta_s_per_m,
                                   g.theta, g.heat_capacity_ratio)[0])


def draw_openform(name: str, cylinder: str, rng, valve: str = "valve1"):
    """An out-of-catalogue plant form (class name ``name``) with parameters drawn from
    wide physical ranges for ``cylinder`` and ``valve``.

    - BladderVolume: dV_max 5-30 % of the swept volume, pressure scale 80-300 kPa;
    - SpoolHysteresis: half-band 0.08-0.3 V, smoothing 0.1-0.5 ms;
    - ReliefValve: cracking at 2.5-3.8 bar gauge (the supply is 4.5 bar gauge),
      1-10 x 1e-11 kg/(s Pa^1.5) (0.3-3 g/s at 1 bar overpressure);
    - InletFlowForce: 0.05-0.3 per atm of drop across the inlet;
    - LipSealLeak: lifting at 1-3 bar gauge, leaking 0.02-0.1 g/s at the supply;
    - ExhaustSilencer (set 2): back-pressure 30-300 kPa at 1 g/s (log-uniform: a
      miniature or partly clogged sintered element of about 1-3 x the exhaust port's
      area), its viscous share 0.2-0.8, a body of 0.5-5 cm^3 (log-uniform);
    - ScoredBarrelLeak (set 2): the score starting at 10-70 % of the stroke, 10-30 % of
      it long, edges 2-5 % of it, an orifice of 2e-8-2e-7 m^2 (log-uniform; about
      0.02-0.2 g/s at 4 bar);
    - CreepingWall (set 2): the wall gives 2-15 % of the swept volume at 4.5 bar gauge
      (log-uniform), with a time constant of 0.05-1 s (log-uniform);
    - PilotInletValve (set 2): a minimum pressure difference of 20-100 kPa
      (log-uniform), the transition 0.3-1 x it;
    - Iso6358Ports (set 3): critical pressure ratio 0.15-0.45, subsonic index 0.35-0.75;
    - SpoolSlewLimit (set 3): 100-1000 V/s (a full 10-V swing in 10-100 ms), a
      small-step lag of 0.2-1 ms (both log-uniform);
    - SpoolUnderlap (set 3): 2e-8-1.5e-7 m^2 per port at the null (about 2-25 % of the
      Table II valves' full ports), gone beyond 0.2-1 V;
    - MeterOutThrottle (set 3): a needle of 1e-7-5e-7 m^2 (about 10-80 % of the
      exhausts' full area), a check of 1e-6-3e-6 m^2 cracking at 5-30 kPa, a fitting of
      0.2-2 cm^3 (all log-uniform);
    - SupplyHose (set 4): a restriction of 6e-7-3e-6 m^2 (about 0.7-5 x the Table II
      valves' full inlet) into a hose of 10-100 cm^3 (both log-uniform);
    - LowReynoldsPorts (set 4): a critical Reynolds number of 200-2000 (log-uniform);
    - SpoolStiction (set 4): breaking away at 0.05-0.3 V, stopping 0-0.6 x that short;
    - SensorBow (set 4): a 6- or 10-bar (gauge) sensor bowing by 0.1-0.5 % of its span
      (log-uniform) at mid-range, either sign;
    - SpringReturnSpool (set 5): rising with a 0.3-1.5 ms time constant, falling 2-6 x
      slower (both log-uniform);
    - WarmingCoil (set 5): the coil's resistance 3-15 % higher at the full command's
      steady heat (about 8-40 K), a thermal time constant of 2-20 s (both log-uniform);
    - CapillarySensorPort (set 5): a lag of 0.5-4 ms at the supply (log-uniform; about
      5 x it at the atmosphere);
    - LaggingPositionSensor (set 5): a lag of 2-15 ms (log-uniform);
    - ExhaustCheckValve (set 6): cracking at 10-80 kPa (log-uniform);
    - SeatLeak (set 6): C A of 5e-9-5e-8 m^2 (log-uniform; about 0.01-0.12 g/s at 4.5
      bar across it);
    - InletFlowLimiter (set 6): 0.3-1 x the valve's full choked inlet flow at the
      supply (log-uniform);
    - ReleaseDelay (set 6): falls acting 1-8 ms late (log-uniform);
    - PistonSealBypass (set 7): k of 5e-17-4e-16 kg/(s Pa^2) (about 0.01-0.1 g/s at 4
      bar gauge), a vent of 1e-8-1e-7 m^2 (both log-uniform), the other chamber
      1.05-1.4 x the swept volume;
    - EnergisedSealLeak (set 7): the gap halved at 0.8-3 bar gauge, leaking 0.02-0.1
      g/s at half that pressure (both log-uniform);
    - SensorZeroDrift (set 7): 2-15 kPa (log-uniform, either sign) with a 3-30 s time
      constant (log-uniform);
    - EndCushion (set 7): over the last 5-20 % of the stroke, a needle of 2e-8-2e-7 m^2
      (log-uniform; about 3-30 % of the Table II exhausts), edges of 1-3 % of it;
    - QuickExhaustValve (set 8): its exhaust 1-4 x the valve's full exhaust area and its
      passage 1-3 x the valve's full inlet area (log-uniform), switching over 5-30 kPa,
      a line of 0.2-2 cm^3 (log-uniform);
    - GasAccumulator (set 8): 20-100 % of the swept volume (log-uniform), precharged at
      1-3 bar gauge, n 1.0-1.4;
    - SpoolLandLeak (set 8): 0.01-0.05 g/s at the null into 3 bar (log-uniform), the
      sealing length doubled 0.2-1 V from the null;
    - SensorThermalShock (set 8): an overshoot of 1-5 % of a step (log-uniform, either
      sign), settling in 0.1-1 s (log-uniform);
    - PwmValve (set 9): 20-100 Hz, opening 1.5-6 ms, closing 1-4 ms late (log-uniform);
    - ZohDriver (set 9): every 4-25 ms (log-uniform), 0-10 ms late, any phase;
    - SensorHysteresis (set 9): a half-width of 1-6 kPa (log-uniform);
    - SealSpeedLeak (set 9): 0.01-0.08 g/s at 0.1 m/s and 4 bar gauge (log-uniform);
    - BraidFriction (set 10): the wall gives 5-25 % of the swept volume over 4.5 bar
      (log-uniform), held by a band of 10-60 kPa (log-uniform);
    - SolenoidGroundShift (set 10): 1-8 kPa at full current (log-uniform, either sign),
      the coil's L / R 2-20 ms (log-uniform);
    - PressureHeldSolenoid (set 10): 0.3-1 ms, slowed by 0.5-3 per atm of drop (both
      log-uniform: opening 1.7-14 x slower at the full drop);
    - InletJetAtSensor (set 10): 1-8 kPa at 0.5 g/s (log-uniform, either sign);
    - BoucWenWall (set 11): an elastic give of 1-10 % of the swept volume over 4.5 bar
      and a loop of 3-15 % of it (both log-uniform), a memory of 20-100 kPa
      (log-uniform), an exponent of 1-3 (uniform);
    - LoadedWall (set 12): a static give of 5-30 % of the swept volume over 4.5 bar, a
      natural frequency of 6-40 Hz and a damping ratio of 0.05-0.5 (all log-uniform);
    - SaturatingSensor (set 13): a rail at 55-90 % of the supply's 4.5 bar gauge, a knee of
      2-20 kPa (both log-uniform);
    - SkewedPressureChannel (set 13): the pressure logged 2-15 ms late (log-uniform);
    - PilotFedSpool (set 14): 0.05-0.3 V of spool per bar (log-uniform) above a preload of
      0.3-2.5 bar (uniform), the pilot's lag 1-20 ms (log-uniform).
    """
    if name == "BladderVolume":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BladderVolume(dV_max_m3=swept * _log_uniform(rng, 0.05, 0.3),
                             pressure_scale_Pa=_log_uniform(rng, 80e3, 300e3))
    if name == "SpoolHysteresis":
        return SpoolHysteresis(half_band_V=rng.uniform(0.08, 0.3),
                               time_constant_s=_log_uniform(rng, 1e-4, 5e-4))
    if name == "ReliefValve":
        return ReliefValve(crack_pressure_Pa=ATMOSPHERE_PA + rng.uniform(2.5e5, 3.8e5),
                           flow_coefficient_kg_per_s_Pa1p5=_log_uniform(rng, 1e-11, 1e-10))
    if name == "InletFlowForce":
        return InletFlowForce(flow_force_coefficient=_log_uniform(rng, 0.05, 0.3))
    if name == "LipSealLeak":
        seal = ATMOSPHERE_PA + rng.uniform(1e5, 3e5)
        at_supply = _log_uniform(rng, 2e-5, 1e-4)  # kg/s at the supply pressure
        return LipSealLeak(seal_pressure_Pa=seal,
                           conductance_kg_per_s_Pa2=at_supply / (SUPPLY_PA - seal) ** 2)
    if name == "ExhaustSilencer":
        return ExhaustSilencer(back_pressure_Pa=_log_uniform(rng, 30e3, 300e3),
                               laminar_fraction=rng.uniform(0.2, 0.8),
                               volume_m3=_log_uniform(rng, 0.5e-6, 5e-6))
    if name == "ScoredBarrelLeak":
        stroke = cylinder_preset(cylinder).stroke_m
        start = rng.uniform(0.1, 0.7) * stroke
        return ScoredBarrelLeak(start_m=start, end_m=start + rng.uniform(0.1, 0.3) * stroke,
                                edge_m=rng.uniform(0.02, 0.05) * stroke,
                                area_m2=_log_uniform(rng, 2e-8, 2e-7))
    if name == "CreepingWall":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return CreepingWall(
            compliance_m3_per_Pa=swept * _log_uniform(rng, 0.02, 0.15) / 450e3,
            time_constant_s=_log_uniform(rng, 0.05, 1.0))
    if name == "PilotInletValve":
        return PilotInletValve(min_pressure_difference_Pa=_log_uniform(rng, 20e3, 100e3),
                               transition_fraction=rng.uniform(0.3, 1.0))
    if name == "Iso6358Ports":
        return Iso6358Ports(critical_pressure_ratio=rng.uniform(0.15, 0.45),
                            subsonic_index=rng.uniform(0.35, 0.75))
    if name == "SpoolSlewLimit":
        return SpoolSlewLimit(slew_rate_V_per_s=_log_uniform(rng, 100.0, 1000.0),
                              time_constant_s=_log_uniform(rng, 2e-4, 1e-3))
    if name == "SpoolUnderlap":
        return SpoolUnderlap(area_m2=_log_uniform(rng, 2e-8, 1.5e-7),
                             width_V=rng.uniform(0.2, 1.0))
    if name == "MeterOutThrottle":
        return MeterOutThrottle(needle_area_m2=_log_uniform(rng, 1e-7, 5e-7),
                                check_area_m2=_log_uniform(rng, 1e-6, 3e-6),
                                crack_pressure_Pa=_log_uniform(rng, 5e3, 30e3),
                                volume_m3=_log_uniform(rng, 2e-7, 2e-6))
    if name == "SupplyHose":
        return SupplyHose(restriction_area_m2=_log_uniform(rng, 6e-7, 3e-6),
                          volume_m3=_log_uniform(rng, 1e-5, 1e-4))
    if name == "LowReynoldsPorts":
        return LowReynoldsPorts(critical_reynolds=_log_uniform(rng, 200.0, 2000.0))
    if name == "SpoolStiction":
        breakaway = rng.uniform(0.05, 0.3)
        return SpoolStiction(breakaway_V=breakaway, stop_V=breakaway * rng.uniform(0.0, 0.6))
    if name == "SensorBow":
        span = float(rng.choice([6e5, 1e6]))
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        return SensorBow(bow_Pa=sign * span * _log_uniform(rng, 1e-3, 5e-3), span_Pa=span)
    if name == "SpringReturnSpool":
        rise = _log_uniform(rng, 3e-4, 1.5e-3)
        return SpringReturnSpool(rise_time_constant_s=rise,
                                 fall_time_constant_s=rise * _log_uniform(rng, 2.0, 6.0))
    if name == "WarmingCoil":
        return WarmingCoil(resistance_rise=_log_uniform(rng, 0.03, 0.15),
                           time_constant_s=_log_uniform(rng, 2.0, 20.0))
    if name == "CapillarySensorPort":
        return CapillarySensorPort(time_constant_s=_log_uniform(rng, 5e-4, 4e-3),
                                   reference_pressure_Pa=SUPPLY_PA)
    if name == "LaggingPositionSensor":
        return LaggingPositionSensor(time_constant_s=_log_uniform(rng, 2e-3, 1.5e-2))
    if name == "ExhaustCheckValve":
        return ExhaustCheckValve(crack_pressure_Pa=_log_uniform(rng, 10e3, 80e3))
    if name == "SeatLeak":
        return SeatLeak(area_m2=_log_uniform(rng, 5e-9, 5e-8))
    if name == "InletFlowLimiter":
        return InletFlowLimiter(max_flow_kg_per_s=_full_inlet_flow(valve) * _log_uniform(
            rng, 0.3, 1.0))
    if name == "ReleaseDelay":
        return ReleaseDelay(delay_s=_log_uniform(rng, 1e-3, 8e-3))
    if name == "PistonSealBypass":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return PistonSealBypass(conductance_kg_per_s_Pa2=_log_uniform(rng, 5e-17, 4e-16),
                                vent_area_m2=_log_uniform(rng, 1e-8, 1e-7),
                                opposite_volume_m3=swept * rng.uniform(1.05, 1.4))
    if name == "EnergisedSealLeak":
        p_e = _log_uniform(rng, 0.8e5, 3e5)
        half = ATMOSPHERE_PA + 0.5 * p_e
        at_half = _log_uniform(rng, 2e-5, 1e-4)  # kg/s at half the energising pressure
        return EnergisedSealLeak(
            conductance_kg_per_s_Pa2=at_half * 1.5**3 / (half**2 - ATMOSPHERE_PA**2),
            energising_pressure_Pa=p_e)
    if name == "SensorZeroDrift":
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        return SensorZeroDrift(drift_Pa=sign * _log_uniform(rng, 2e3, 15e3),
                               time_constant_s=_log_uniform(rng, 3.0, 30.0))
    if name == "QuickExhaustValve":
        from pneubayes.physics.valve import valve_preset

        maps = valve_preset(valve)
        return QuickExhaustValve(
            exhaust_area_m2=float(maps.exhaust.area(-5.0)) * _log_uniform(rng, 1.0, 4.0),
            passage_area_m2=float(maps.inlet.area(5.0)) * _log_uniform(rng, 1.0, 3.0),
            switch_band_Pa=rng.uniform(5e3, 30e3),
            line_volume_m3=_log_uniform(rng, 2e-7, 2e-6))
    if name == "GasAccumulator":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return GasAccumulator(volume_m3=swept * _log_uniform(rng, 0.2, 1.0),
                              precharge_Pa=ATMOSPHERE_PA + rng.uniform(1e5, 3e5),
                              polytropic_index=rng.uniform(1.0, 1.4))
    if name == "SpoolLandLeak":
        at_null = _log_uniform(rng, 1e-5, 5e-5)  # kg/s into a chamber at 3 bar
        return SpoolLandLeak(conductance_kg_per_s_Pa2=at_null / (SUPPLY_PA**2 - 3e5**2),
                             overlap_scale_V=rng.uniform(0.2, 1.0))
    if name == "SensorThermalShock":
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        return SensorThermalShock(gain=sign * _log_uniform(rng, 0.01, 0.05),
                                  time_constant_s=_log_uniform(rng, 0.1, 1.0))
    if name == "EndCushion":
        stroke = cylinder_preset(cylinder).stroke_m
        return EndCushion(length_m=rng.uniform(0.05, 0.2) * stroke,
                          needle_area_m2=_log_uniform(rng, 2e-8, 2e-7),
                          edge_m=rng.uniform(0.01, 0.03) * stroke)
    if name == "PwmValve":
        return PwmValve(frequency_Hz=_log_uniform(rng, 20.0, 100.0),
                        opening_delay_s=_log_uniform(rng, 1.5e-3, 6e-3),
                        closing_delay_s=_log_uniform(rng, 1e-3, 4e-3))
    if name == "ZohDriver":
        return ZohDriver(update_period_s=_log_uniform(rng, 4e-3, 25e-3),
                         latency_s=rng.uniform(0.0, 10e-3), phase=rng.uniform(0.0, 1.0))
    if name == "SensorHysteresis":
        return SensorHysteresis(half_width_Pa=_log_uniform(rng, 1e3, 6e3))
    if name == "SealSpeedLeak":
        at_ref = _log_uniform(rng, 1e-5, 8e-5)  # kg/s at 0.1 m/s and 4 bar gauge
        p = ATMOSPHERE_PA + 4e5
        return SealSpeedLeak(conductance_kg_per_s_Pa2=at_ref / (p**2 - ATMOSPHERE_PA**2))
    if name == "BraidFriction":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BraidFriction(compliance_m3_per_Pa=swept * _log_uniform(rng, 0.05, 0.25) / 4.5e5,
                             friction_band_Pa=_log_uniform(rng, 10e3, 60e3))
    if name == "SolenoidGroundShift":
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        return SolenoidGroundShift(shift_Pa=sign * _log_uniform(rng, 1e3, 8e3),
                                   time_constant_s=_log_uniform(rng, 2e-3, 20e-3))
    if name == "PressureHeldSolenoid":
        return PressureHeldSolenoid(time_constant_s=_log_uniform(rng, 3e-4, 1e-3),
                                    slowing_per_atm=_log_uniform(rng, 0.5, 3.0))
    if name == "BoucWenWall":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BoucWenWall(
            elastic_compliance_m3_per_Pa=swept * _log_uniform(rng, 0.01, 0.1) / 4.5e5,
            loop_volume_m3=swept * _log_uniform(rng, 0.03, 0.15),
            memory_Pa=_log_uniform(rng, 20e3, 100e3), exponent=rng.uniform(1.0, 3.0))
    if name == "LoadedWall":
        cyl = cylinder_preset(cylinder)
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return LoadedWall(compliance_m3_per_Pa=swept * _log_uniform(rng, 0.05, 0.3) / 4.5e5,
                          natural_frequency_Hz=_log_uniform(rng, 6.0, 40.0),
                          damping_ratio=_log_uniform(rng, 0.05, 0.5))
    if name == "SaturatingSensor":
        return SaturatingSensor(full_scale_Pa=4.5e5 * _log_uniform(rng, 0.55, 0.9),
                                knee_Pa=_log_uniform(rng, 2e3, 20e3))
    if name == "SkewedPressureChannel":
        return SkewedPressureChannel(delay_s=_log_uniform(rng, 2e-3, 15e-3))
    if name == "PilotFedSpool":
        return PilotFedSpool(feedback_V_per_bar=_log_uniform(rng, 0.05, 0.3),
                             preload_Pa=rng.uniform(0.3e5, 2.5e5),
                             pilot_time_constant_s=_log_uniform(rng, 1e-3, 20e-3))
    if name == "InletJetAtSensor":
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        return InletJetAtSensor(shift_Pa=sign * _log_uniform(rng, 1e3, 8e3),
                                reference_flow_kg_per_s=5e-4)
    raise ValueError(f"draw_openform: unknown out-of-catalogue form {name!r}; known "
                     f"{list(OUT_OF_CATALOGUE)}")


def draw_cases(seed: int, blind_set: int = 1) -> list[dict]:
    """Blind set ``blind_set``: each of its out-of-catalogue forms (:data:`SET_FORMS`)
    on each of :data:`RIGS`, then :data:`N_CONTROLS` null controls (alternating rigs),
    each with drawn form parameters and bench seed (JSON-ready but for ``_objects``)."""
    rng = np.random.default_rng(seed)
    plan = [(form, rig) for form in SET_FORMS[blind_set] for rig in RIGS]
    plan += [(None, RIGS[i % len(RIGS)]) for i in range(N_CONTROLS)]
    cases = []
    for i, (form, rig) in enumerate(plan):
        cylinder, valve = rig.split(":")
        obj = draw_openform(form, cylinder, rng, valve) if form else None
        cases.append({"name": f"{SET_PREFIX[blind_set]}{i:02d}_{cylinder}_{valve}_"
                              f"{form or 'none'}",
                      "seed": seed, "blind_set": blind_set, "cylinder": cylinder, "valve": valve,
                      "hidden": [form] if form else [],
                      "bench_seed": int(rng.integers(1000, 100000)),
                      "forms": {form: obj.to_dict()} if form else {},
                      "_objects": (obj,) if obj else ()})
    return cases


def realigned(case: dict, alignment: float) -> dict:
    """``case`` with its PWM valves' pulses at ``alignment`` (a development variant, named
    with an ``-a<alignment>`` suffix); a case without one as it is."""
    if not any(isinstance(o, PwmValve) for o in case["_objects"]):
        return case
    objs = tuple(replace(o, alignment=alignment) if isinstance(o, PwmValve) else o
                 for o in case["_objects"])
    return {**case, "name": f"{case['name']}-a{alignment:g}",
            "forms": {type(o).__name__: o.to_dict() for o in objs}, "_objects": objs}


def _public(case: dict) -> dict:
    """The case's JSON-ready record (without its form objects)."""
    return {k: v for k, v in case.items() if not k.startswith("_")}


def _is_case(case: dict, key: str) -> bool:
    """Whether ``key`` names ``case``: its full name or its ``oNN`` / ``nNN`` prefix."""
    return case["name"] == key or case["name"].split("_")[0] == key


def parse_settings(pairs) -> dict:
    """``KEY.PATH=VALUE`` strings as a table of DiscoverySettings overrides (VALUE as a
    TOML value, else text; :func:`pneubayes.settings_tree.assignment`)."""
    return table_of([assignment(item) for item in pairs])


def settings_for(case: dict, args, sensor: SensorChain) -> DiscoverySettings:
    """The discovery settings of a case (as ``blind_study.py``'s), with ``--setting``."""
    seed = case["bench_seed"]
    settings = DiscoverySettings(
        posterior=PosteriorSettings(method="none"), seed=seed,
        search=SearchSettings(n_bags=40),
        fit=FitSettings(sampler=SamplerSettings(n_walkers=32, max_steps=400, seed=seed),
                        pressure_filter=sensor.declared_filter()))
    return override(settings, args.settings, "--setting") if args.settings else settings


def classify(named: list[str], found_terms: list, hidden: list[str], kept=()) -> dict:
    """What a case's discovery named, against what it should: catalogue effects (an
    effect named ``closure`` is the open-form stage's and counts as found terms), the
    stand-ins among them (for an out-of-catalogue case, every catalogue effect but the
    sensor chain's real lags; for a control the same), and the open-form terms. ``kept``:
    the effects kept in the model at a bound, not named (a control with one is not
    clean)."""
    catalogue = [n for n in named if n not in ("closure", "reading_closure")]
    stand_ins = [n for n in catalogue if n not in CONTROL_ALLOWED]
    terms = [t.get("term", str(t)) if isinstance(t, dict) else str(t)
             for t in (found_terms or [])]
    return {"named_catalogue": catalogue, "stand_ins": stand_ins, "found_terms": terms,
            "no_stand_in": not stand_ins,
            "clean_control": None if hidden else (not stand_ins and not terms
                                                  and not [k for k in kept
                                                           if k not in CONTROL_ALLOWED])}


def run_case(case: dict, args, root: Path) -> dict:
    work = root / "work" / case["name"]
    sensor = SensorChain()
    plant = check_forms(case["_objects"])
    paths, _ = six_recordings(case["cylinder"], case["valve"], case["bench_seed"], work,
                              effects=(), forms=plant, duration_s=args.duration,
                              sensor=sensor)
    keep = sorted(RECORDING_ORDER[:args.recordings])
    recs = [read_recording(paths[i]) for i in keep]
    settings = settings_for(case, args, sensor)
    t0 = time.perf_counter()
    doc = run_discover(recs, settings, work / "run", log=lambda m: None, figures=False)
    named = [e["name"] for e in doc["effects"]]
    kept = [e["name"] for e in doc.get("stand_ins", [])]  # in the model, not named
    noise = doc["noise_floor_Pa"]
    gap0 = max(doc["rmse_base_Pa"] - noise, 0.0)
    gap1 = max(doc["rmse_final_Pa"] - noise, 0.0)
    return _public(case) | {
        "recordings": [paths[i].name for i in keep], "named": named, "kept_at_bound": kept,
        **classify(named, doc.get("found_terms", []) + [
            f"reading: {t['formula'].split(',')[0]}"
            for t in doc.get("found_reading_terms", [])] + [
            f"volume: {t['formula'].split(' (')[0]}"
            for t in doc.get("found_volume_terms", [])] + [
            f"command: {t['term']}" for t in doc.get("found_command_terms", [])] + [
            f"port: {t['term']}" for t in doc.get("found_port_terms", [])],
            case["hidden"], kept),
        "found_terms_detail": (doc.get("found_terms", []) + doc.get("found_reading_terms", [])
                               + doc.get("found_volume_terms", [])
                               + doc.get("found_command_terms", [])
                               + doc.get("found_port_terms", [])),
        "rmse_base_Pa": doc["rmse_base_Pa"], "rmse_final_Pa": doc["rmse_final_Pa"],
        "noise_floor_Pa": noise, "gap_shrink": None if gap0 <= 0 else 1.0 - gap1 / gap0,
        "final_over_noise": doc["rmse_final_Pa"] / noise,
        "wall_time_s": time.perf_counter() - t0, "ledger": doc["ledger"]}


def summarise(results: list[dict]) -> tuple[dict, str]:
    """The issue's floors over the set, and a per-case table."""
    ooc = [r for r in results if r["hidden"] and "error" not in r]
    ctl = [r for r in results if not r["hidden"] and "error" not in r]
    floors: dict = {}
    if ooc:
        shrink = [r["gap_shrink"] for r in ooc if r["gap_shrink"] is not None]
        clean = sum(r["no_stand_in"] for r in ooc)
        need = math.ceil(FLOORS["no_stand_in_cases"] / 10 * len(ooc))
        med = float(np.median(shrink)) if shrink else None
        fon = float(np.median([r["final_over_noise"] for r in ooc]))
        floors["out_of_catalogue"] = {
            "cases": len(ooc), "errors": sum(bool(r["hidden"]) and "error" in r
                                             for r in results),
            "no_stand_in_cases": clean, "no_stand_in_needed": need,
            "kept_at_bound_cases": sum(bool(r.get("kept_at_bound")) for r in ooc),
            "with_found_terms": sum(bool(r["found_terms"]) for r in ooc),
            "gap_shrink_median": med, "final_over_noise_median": fon,
            "meets": {"no_stand_in": clean >= need,
                      "gap_shrink": med is not None and med >= FLOORS["gap_shrink_median"],
                      "final_over_noise": fon <= FLOORS["final_over_noise_median"]}}
    if ctl:
        floors["control"] = {
            "cases": len(ctl), "errors": sum(not r["hidden"] and "error" in r
                                             for r in results),
            "clean": sum(r["clean_control"] for r in ctl),
            "meets": all(r["clean_control"] for r in ctl)}
    lines = ["| case | rig | hidden | catalogue named | open-form terms | held-out RMSE base "
             "-> final (Pa) | noise (Pa) | gap shrink | final / noise |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        rig = f"{r['cylinder']}/{r['valve']}"
        hidden = ", ".join(r["hidden"]) or "-"
        if "error" in r:
            lines.append(f"| {r['name']} | {rig} | {hidden} | error: {r['error']} "
                         f"| | | | | |")
            continue
        sh = "-" if r["gap_shrink"] is None else f"{100 * r['gap_shrink']:.0f} %"
        kept = r.get("kept_at_bound") or []
        kept_note = f" (kept at a bound, not named: {', '.join(kept)})" if kept else ""
        lines.append(f"| {r['name']} | {rig} | {hidden} | "
                     f"{', '.join(r['named_catalogue']) or '-'}"
                     f"{kept_note} | "
                     f"{'; '.join(r['found_terms']) or '-'} | "
                     f"{r['rmse_base_Pa']:.0f} -> {r['rmse_final_Pa']:.0f} | "
                     f"{r['noise_floor_Pa']:.0f} | {sh} | {r['final_over_noise']:.2f} |")
    lines += ["", "| kind | cases | floor check |", "|---|---|---|"]
    if "out_of_catalogue" in floors:
        d = floors["out_of_catalogue"]
        med = d["gap_shrink_median"]
        lines.append(
            f"| out of catalogue | {d['cases']} | no catalogue stand-in in "
            f"{d['no_stand_in_cases']} of {d['cases']} (floor {d['no_stand_in_needed']}; "
            f"{d['kept_at_bound_cases']} with a stand-in kept at a bound, not named), "
            f"open-form terms found in {d['with_found_terms']}, median gap shrink "
            f"{'n/a' if med is None else f'{100 * med:.0f} %'} (floor 70 %), median final "
            f"/ noise {d['final_over_noise_median']:.2f} (floor 2) |")
    if "control" in floors:
        d = floors["control"]
        lines.append(f"| null control | {d['cases']} | no open-form term and nothing named "
                     f"beyond the sensor chain's real lags in {d['clean']} of {d['cases']} "
                     f"(floor: all) |")
    return floors, "\n".join(lines) + "\n"


def _run_cached(cases, args, root: Path) -> list[dict]:
    """Each case's result from ROOT/cases (run and cached when missing)."""
    return cached_cases(
        [(c["name"], c) for c in cases], root, lambda name, c: run_case(c, args, root),
        lambda name, c, error: _public(c) | {"error": error, "named": []},
        lambda res: "done" if "error" not in res else f"error: {res['error']}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="results folder (cases cached there)")
    ap.add_argument("--set", type=int, choices=sorted(SET_FORMS), default=1, dest="blind_set",
                    help="the blind set, each with its recorded seed ("
                         + ", ".join(f"{k}: {v}" for k, v in SET_SEEDS.items())
                         + "); default 1")
    ap.add_argument("--seed", type=int, default=None,
                    help="the draw's seed (default: the set's, SET_SEEDS)")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per recording")
    ap.add_argument("--recordings", type=int, default=6, metavar="N",
                    help="recordings per case, 1-6 (default 6: discovery_study's set); the "
                         "loop needs at least 7 held-out 2-s windows in all (a third of "
                         "each recording is held out)")
    ap.add_argument("--list", action="store_true", help="print the cases and stop")
    ap.add_argument("--case", action="append", default=[], metavar="NAME",
                    help="run only this case (full name or oNN prefix; repeatable) into "
                         "the cache, without a summary")
    ap.add_argument("--setting", action="append", default=[], metavar="KEY=VALUE",
                    help="a DiscoverySettings field (VALUE as JSON; repeatable)")
    ap.add_argument("--report", action="store_true",
                    help="report from the cached cases only (run nothing; cases without a "
                         "result are listed as not finished)")
    ap.add_argument("--smoke", action="store_true",
                    help="one short case from a tuning draw (not the blind set)")
    ap.add_argument("--pwm-alignment", type=float, default=None, metavar="A",
                    help="development: the draw's PWM valves with their pulses at alignment "
                         "A (0 from the period's start, as drawn; 0.5 centred); the cases "
                         "are named with a '-aA' suffix (not the blind set)")
    args = ap.parse_args(argv)
    if args.smoke:  # a tuning draw of set 1's forms
        args.seed, args.duration, args.recordings = SMOKE_SEED, 13.0, 4
        args.blind_set = 1
    if args.seed is None:
        args.seed = SET_SEEDS[args.blind_set]
    if not 1 <= args.recordings <= len(RECORDING_ORDER):
        ap.error(f"--recordings: must be 1-{len(RECORDING_ORDER)}, got {args.recordings}")
    if not args.duration > 0:
        ap.error(f"--duration: must be > 0 s, got {args.duration}")
    try:
        args.settings = parse_settings(args.setting)
    except ValueError as exc:
        ap.error(str(exc))
    cases = draw_cases(args.seed, args.blind_set)
    if args.pwm_alignment is not None:
        try:
            cases = [realigned(c, args.pwm_alignment) for c in cases]
        except ValueError as exc:
            ap.error(f"--pwm-alignment: {exc}")
    if args.smoke:
        cases = [c for c in cases if c["hidden"] == ["ReliefValve"]][:1]
    root = results_root(ap, args, cases, _public)
    if root is None:
        return 0
    if args.case:
        missing = [k for k in args.case if not any(_is_case(c, k) for c in cases)]
        if missing:
            ap.error(f"--case: no case {missing} in the draw of seed {args.seed} "
                     f"(--list shows them)")
        _run_cached([c for c in cases if any(_is_case(c, k) for k in args.case)], args, root)
        return 0
    t_all = time.perf_counter()
    if args.report:
        cached = {c["name"]: root / "cases" / f"{c['name']}.json" for c in cases}
        results = [json.loads(cached[c["name"]].read_text()) for c in cases
                   if cached[c["name"]].exists()]
        unfinished = [c["name"] for c in cases if not cached[c["name"]].exists()]
    else:
        results, unfinished = _run_cached(cases, args, root), []
    floors, md = summarise(results)
    if unfinished:
        md += f"\nNot finished (no result when the set was reported): {', '.join(unfinished)}.\n"
    write_json_atomic(root / "summary.json", {
        "blind_set": args.blind_set, "seed": args.seed, "duration_s": args.duration,
        "recordings": args.recordings,
        "smoke": args.smoke, "settings_overrides": args.settings, "floors": floors,
        "not_finished": unfinished,
        "cases": results, "wall_time_s": time.perf_counter() - t_all,
        "provenance": provenance()})
    write_text_atomic(root / "summary.md",
                      f"Open-form blind set {args.blind_set}, seed {args.seed}"
                      f"{' (smoke: a tuning draw)' if args.smoke else ''}, "
                      f"{args.recordings} recordings of {args.duration:g} s per case.\n\n"
                      + md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
