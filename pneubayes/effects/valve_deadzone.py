"""Valve dead band (paper IV-B and Fig. 4): the spool's overlap.

The area maps see ``u' = sign(s) max(|s| - w, 0)`` for spool position s (in command
volts) and half-width w: no change of area for |s| < w, continuous outside it.
"""

from __future__ import annotations

from pneubayes.effects.base import DirectEffect, Parameter
from pneubayes.effects.discovery import TrialTerm


class ValveDeadzone(DirectEffect):
    """Dead band of half-width ``deadzone_halfwidth_V`` applied before eq. 11."""

    name = "valve_deadzone"
    slot = "deadband_halfwidth_V"
    parameter = Parameter("deadzone_halfwidth_V", "V", 0.0, 1.5, "uniform",
                          "half-width of the spool dead band", neutral=0.0)
    bench_value = 0.3

    library_strengths = (0.05, 0.1, 0.2, 0.35, 0.6, 1.0)
    discovery_fallback = {"deadzone_halfwidth_V": 0.2}

    def library_terms(self, strengths):
        """Dead bands of each trial half-width (V)."""
        return tuple(TrialTerm(f"dead band {v:g} V", {"deadzone_halfwidth_V": v},
                               values={"deadzone_halfwidth_V": v}) for v in strengths)
