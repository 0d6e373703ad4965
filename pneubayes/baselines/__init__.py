"""Peer baselines: models a user would fit instead of the thin-port model (issue 5).

Each baseline is scored with the same 2-s window metric as ours
(:mod:`pneubayes.evaluation`).
"""

from pneubayes.baselines.tassa import (
    PARAMETER_NAMES,
    PUBLISHED_PARAMETERS,
    TassaInputs,
    TassaModel,
    simulate_windows,
    tassa_coefficients,
    tassa_rhs,
    zoh_step,
)

__all__ = [
    "PARAMETER_NAMES",
    "PUBLISHED_PARAMETERS",
    "TassaInputs",
    "TassaModel",
    "simulate_windows",
    "tassa_coefficients",
    "tassa_rhs",
    "zoh_step",
]
