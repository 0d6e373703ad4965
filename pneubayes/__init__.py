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

#: The public face: what a user needs for the main jobs, imported on first use (so
#: ``import pneubayes`` stays light and the CLI starts fast). name -> module.
_PUBLIC = {
    "Rig": "pneubayes.rig",
    "Inputs": "pneubayes.simulation",
    "SolverConfig": "pneubayes.simulation",
    "simulate": "pneubayes.simulation",
    "simulate_windows": "pneubayes.simulation",
    "read_recording": "pneubayes.io",
    "write_recording": "pneubayes.io",
    "effects_from_names": "pneubayes.effects",
    "make_effect": "pneubayes.effects",
    "identify": "pneubayes.inference.fit",
    "Fit": "pneubayes.inference.fit",
    "write_fit": "pneubayes.inference.fit_folder",
    "read_fit": "pneubayes.inference.fit_folder",
    "FitSettings": "pneubayes.inference.fit",
    "SamplerSettings": "pneubayes.inference.sampler_settings",
    "PressurePredictor": "pneubayes.inference.predictive",
    "Discovery": "pneubayes.discovery.loop",
    "discover": "pneubayes.discovery.loop",
    "DiscoveryResult": "pneubayes.discovery.result",
    "DiscoverySettings": "pneubayes.discovery.settings",
    "DataSettings": "pneubayes.discovery.settings",
    "SearchSettings": "pneubayes.discovery.settings",
    "VerifySettings": "pneubayes.discovery.settings",
    "RoundSettings": "pneubayes.discovery.settings",
    "FormSettings": "pneubayes.discovery.settings",
    "StageSettings": "pneubayes.discovery.settings",
    "PosteriorSettings": "pneubayes.discovery.settings",
    "write_discovery": "pneubayes.discovery.report",
}

__all__ = [
    "GasConstants",
    "Model",
    "ModelCardError",
    "ParameterError",
    "PneubayesError",
    "RecordingError",
    "SimulationError",
    *sorted(_PUBLIC),
]
__version__ = "0.1.0"


def __getattr__(name):
    """The public names of :data:`_PUBLIC`, imported when first asked for."""
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'pneubayes' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC))
