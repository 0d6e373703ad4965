"""Simulation layer: the compiled exponential integrator and its Python entry points."""

from pneubayes.simulation.config import SolverConfig
from pneubayes.simulation.drive import Inputs
from pneubayes.simulation.simulator import (
    Trajectory,
    combination_error,
    fresh_carry,
    rig_constants,
    simulate,
    simulate_carried,
    simulate_windows,
    simulate_windows_sensitivity,
)

__all__ = ["Inputs", "SolverConfig", "Trajectory", "combination_error", "fresh_carry",
           "rig_constants", "simulate", "simulate_carried", "simulate_windows",
           "simulate_windows_sensitivity"]
