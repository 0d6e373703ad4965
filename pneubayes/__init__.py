"""pneubayes: thin-port pneumatic actuator models with fast simulation, Bayesian
identification and discovery of missing physical effects.

Layers (imported in one direction only):
``physics`` (pure functions) <- ``effects`` and ``model`` (composition, parameters)
<- ``simulation`` (compiled integrator) <- ``io``, ``bench``, inference, discovery,
CLI. Nothing here imports matplotlib; plotting lives in :mod:`pneubayes.plotting`.
"""

from pneubayes.errors import (
    ModelCardError,
    ParameterError,
    PneubayesError,
    RecordingError,
    SimulationError,
)
from pneubayes.model import Model
from pneubayes.physics.gas import GasConstants

__all__ = [
    "GasConstants",
    "Model",
    "ModelCardError",
    "ParameterError",
    "PneubayesError",
    "RecordingError",
    "SimulationError",
]
__version__ = "0.1.0"
