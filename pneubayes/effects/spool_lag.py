"""First-order spool dynamics (paper VI-A: 125 Hz bandwidth at full stroke).

``ds/dt = (u - s) / tau``; the area maps see the spool position s instead of the
command u. Within a sample interval the command is held, so s is integrated exactly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig


class SpoolLag(Effect):
    """Spool lag with time constant ``spool_time_constant_s``."""

    name = "spool_lag"
    acts_on = ("spool_time_constant_s",)

    def parameters(self):
        return (Parameter("spool_time_constant_s", "s", 0.0, 0.02, "uniform",
                          "first-order spool time constant", neutral=0.0),)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {"spool_time_constant_s": values["spool_time_constant_s"]}

    def bench_defaults(self):
        return {"spool_time_constant_s": 1.0 / (2.0 * math.pi * 125.0)}
