"""First-order spool dynamics (paper VI-A: 125 Hz bandwidth at full stroke).

``ds/dt = (u - s) / tau``; the area maps see the spool position s instead of the
command u. Within a sample interval the command is held, so s is integrated exactly.
"""

from __future__ import annotations

import math

from pneubayes.effects.base import DirectEffect, Parameter
from pneubayes.effects.discovery import InputLagTerm


class SpoolLag(DirectEffect):
    """Spool lag with time constant ``spool_time_constant_s``."""

    name = "spool_lag"
    slot = "spool_time_constant_s"
    parameter = Parameter("spool_time_constant_s", "s", 0.0, 0.02, "uniform",
                          "first-order spool time constant", neutral=0.0)
    #: 125 Hz bandwidth at full spool stroke (paper VI-A).
    bench_value = 1.0 / (2.0 * math.pi * 125.0)

    library_strengths = (0.001, 0.002, 0.004, 0.007, 0.012, 0.02)
    discovery_fallback = {"spool_time_constant_s": 0.003}

    def library_terms(self, strengths):
        """The command through a first-order lag of each trial time constant (s)."""
        return tuple(InputLagTerm(f"lag {1e3 * tau:g} ms", {"spool_time_constant_s": tau},
                                  lag_s=tau) for tau in strengths)
