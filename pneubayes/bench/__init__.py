"""The virtual test bench: a high-fidelity simulation with a realistic sensor chain,
standing in for the hardware. It writes recordings in the shared format and, apart,
the truth (``truth.json``). Realistic alternative forms of the effects
(:mod:`pneubayes.bench.forms`), and effects outside the catalogue, are simulated by an
independent plant (:mod:`pneubayes.bench.plant`)."""

from pneubayes.bench.bench import BenchConfig, BenchResult, run_bench, truth_parameters
from pneubayes.bench.forms import (
    AcousticTube,
    BladderVolume,
    ClearanceLeak,
    CreepingWall,
    ExhaustSilencer,
    InletFlowForce,
    LipSealLeak,
    PilotInletValve,
    PlantForm,
    RegulatorDroop,
    ReliefValve,
    RoundedDeadzone,
    ScoredBarrelLeak,
    SecondOrderSpool,
    SpoolHysteresis,
    WallHeatTransfer,
    form_from_dict,
    forms_from_names,
    out_of_catalogue_defaults,
)
from pneubayes.bench.plant import PlantConfig, PlantTrajectory, simulate_plant
from pneubayes.bench.protocols import piston_motion, step_commands
from pneubayes.bench.sensors import SensorChain

__all__ = ["AcousticTube", "BenchConfig", "BenchResult", "BladderVolume", "ClearanceLeak",
           "CreepingWall", "ExhaustSilencer", "InletFlowForce", "LipSealLeak",
           "PilotInletValve", "PlantConfig", "PlantForm", "PlantTrajectory",
           "RegulatorDroop", "ReliefValve", "RoundedDeadzone", "ScoredBarrelLeak",
           "SecondOrderSpool",
           "SensorChain", "SpoolHysteresis", "WallHeatTransfer", "form_from_dict",
           "forms_from_names", "out_of_catalogue_defaults", "piston_motion", "run_bench",
           "simulate_plant", "step_commands", "truth_parameters"]
