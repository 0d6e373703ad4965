"""The virtual test bench: a high-fidelity simulation with a realistic sensor chain,
standing in for the hardware. It writes recordings in the shared format and, apart,
the truth (``truth.json``). Realistic alternative forms of the effects
(:mod:`pneubayes.bench.forms`) are simulated by an independent plant
(:mod:`pneubayes.bench.plant`)."""

from pneubayes.bench.bench import BenchConfig, BenchResult, run_bench, truth_parameters
from pneubayes.bench.forms import (
    AcousticTube,
    ClearanceLeak,
    PlantForm,
    RegulatorDroop,
    RoundedDeadzone,
    SecondOrderSpool,
    WallHeatTransfer,
    form_from_dict,
    forms_from_names,
)
from pneubayes.bench.plant import PlantConfig, PlantTrajectory, simulate_plant
from pneubayes.bench.protocols import piston_motion, step_commands
from pneubayes.bench.sensors import SensorChain

__all__ = ["AcousticTube", "BenchConfig", "BenchResult", "ClearanceLeak", "PlantConfig",
           "PlantForm", "PlantTrajectory", "RegulatorDroop", "RoundedDeadzone",
           "SecondOrderSpool", "SensorChain", "WallHeatTransfer", "form_from_dict",
           "forms_from_names", "piston_motion", "run_bench", "simulate_plant",
           "step_commands", "truth_parameters"]
