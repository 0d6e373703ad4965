"""Valve dead band (paper IV-B and Fig. 4): the spool's overlap.

The area maps see ``u' = sign(s) max(|s| - w, 0)`` for spool position s (in command
volts) and half-width w: no change of area for |s| < w, continuous outside it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig


class ValveDeadzone(Effect):
    """Dead band of half-width ``deadzone_halfwidth_V`` applied before eq. 11."""

    name = "valve_deadzone"
    acts_on = ("deadband_halfwidth_V",)

    def parameters(self):
        return (Parameter("deadzone_halfwidth_V", "V", 0.0, 1.5, "uniform",
                          "half-width of the spool dead band", neutral=0.0),)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {"deadband_halfwidth_V": values["deadzone_halfwidth_V"]}

    def bench_defaults(self):
        return {"deadzone_halfwidth_V": 0.3}
