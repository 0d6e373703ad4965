"""Valve dead band (paper IV-B and Fig. 4): the spool's overlap.

The area maps see ``u' = sign(s) phi(|s| - w)`` for spool position s (in command
volts) and half-width w: no change of area for |s| < w, continuous outside it. Two
forms:

- ``form="hard"`` (default): ``phi(z) = max(z, 0)``, the paper's corner;
- ``form="rounded"``: the corners rounded over ``||s| - w| < r``, ``r = f w`` with the
  rounding fraction f in [0, 1]: the slope of the opening rises smoothly from 0 to 1
  across the corner (C2; :func:`pneubayes.simulation.rates.dead_band`), as real spool
  edges open gradually (edge radii, metering notches, radial clearance). Near the
  corner a hard band either opens too late or too early for small commands; f = 0 is
  the hard band.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.rig import Rig

_FORMS = ("hard", "rounded")
#: Rounding fraction a rounded candidate starts at (corners over half the half-width).
START_ROUNDING = 0.5


class ValveDeadzone(Effect):
    """Dead band of half-width ``deadzone_halfwidth_V`` applied before eq. 11, with hard
    or rounded (``deadzone_rounding_fraction``) corners."""

    name = "valve_deadzone"
    forms = _FORMS
    cheap_forms = True
    acts_on = ("deadband_halfwidth_V", "deadband_rounding_V")
    bench_value = 0.3

    def __init__(self, form: str = "hard"):
        self.form = form

    def options(self):
        # (the default form is left out: cards written before the option read alike)
        self._check()
        return {} if self.form == "hard" else {"form": self.form}

    def parameters(self):
        self._check()
        width = Parameter("deadzone_halfwidth_V", "V", 0.0, 1.5, "uniform",
                          "half-width of the spool dead band", neutral=0.0)
        if self.form == "hard":
            return (width,)
        return (width, Parameter("deadzone_rounding_fraction", "-", 0.0, 1.0, "uniform",
                                 "corner rounding r over the half-width w",
                                 neutral=0.0))

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        width = np.asarray(values["deadzone_halfwidth_V"], dtype=np.float64)
        if self.form == "hard":
            return {"deadband_halfwidth_V": width}
        frac = np.asarray(values["deadzone_rounding_fraction"], dtype=np.float64)
        return {"deadband_halfwidth_V": width, "deadband_rounding_V": frac * width}

    def bench_defaults(self):
        if self.form == "hard":
            return {"deadzone_halfwidth_V": self.bench_value}
        return {"deadzone_halfwidth_V": self.bench_value,
                "deadzone_rounding_fraction": START_ROUNDING}

    # ------------------------------------------------------------------ discovery
    library_strengths = (0.05, 0.1, 0.2, 0.35, 0.6, 1.0)
    discovery_fallback = {"deadzone_halfwidth_V": 0.2}

    def library_terms(self, strengths):
        """Hard dead bands of each trial half-width (V)."""
        return tuple(TrialTerm(f"dead band {v:g} V", {"deadzone_halfwidth_V": v},
                               values={"deadzone_halfwidth_V": v}) for v in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """The hard band at the best term's half-width, and the rounded band at the same
        half-width with corners over half of it."""
        start = self.candidate_start(ctx.term_start)
        out = [(self, start)]
        if self.form == "hard":
            width = start.get("deadzone_halfwidth_V",
                              self.discovery_fallback["deadzone_halfwidth_V"])
            out.append((ValveDeadzone(form="rounded"),
                        {"deadzone_halfwidth_V": width,
                         "deadzone_rounding_fraction": START_ROUNDING}))
        return out
