"""The virtual test bench: a high-fidelity simulation with a realistic sensor chain,
standing in for the hardware. It writes recordings in the shared format and, apart,
the truth (``truth.json``)."""

from pneubayes.bench.bench import BenchConfig, BenchResult, run_bench, truth_parameters
from pneubayes.bench.protocols import piston_motion, step_commands
from pneubayes.bench.sensors import SensorChain

__all__ = ["BenchConfig", "BenchResult", "SensorChain", "piston_motion", "run_bench",
           "step_commands", "truth_parameters"]
