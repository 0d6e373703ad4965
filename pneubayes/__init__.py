"""pneubayes: thin-port pneumatic actuator models with fast simulation, Bayesian
identification and discovery of missing physical effects.

Layers (imported in one direction only):
``physics`` (pure functions) <- ``effects`` and ``model`` (composition, parameters)
<- ``simulation`` (compiled integrator) <- ``io``, ``bench``, inference, discovery,
CLI. Nothing here imports matplotlib; plotting lives in :mod:`pneubayes.plotting`.
"""

from pneubayes.compile_cache import clear_stale_package_cache

# numba's cache misses edits to code a cached kernel calls from other files: clear it
# when the compiled packages' sources changed (before any compiled function loads)
clear_stale_package_cache()

from pneubayes.errors import (  # noqa: E402
    ModelCardError,
    ParameterError,
    PneubayesError,
    RecordingError,
    SimulationError,
)
from pneubayes.model import Model  # noqa: E402
from pneubayes.physics.gas import GasConstants  # noqa: E402

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
