"""Valve stiction: a valve held by static friction sees only the commands that move it.

The valve does not follow a command change smaller than its break-away band B; once the
command has moved B from where the valve stuck, it breaks free and slides to within
``(1 - f) B`` of the command (:mod:`pneubayes.simulation.stiction`), f the slip
fraction. Proportional valves quote it as hysteresis; a sticking spool, an O-ring
poppet or a worn pinch shows it as small command steps that change nothing, and a
pressure that lags a reversal. It acts on the command before the delay and the spool's
lag. Two forms:

- ``form="play"`` (default): f = 0, backlash of half-width B (the valve trails a moving
  command by B, from whichever side it came);
- ``form="stick_slip"``: f fitted in [0, 1] (``stiction_slip_fraction``): f = 1 jumps
  onto the command once it breaks free, the stick-slip of a dry-friction valve.

The command is held between samples, so the transform is exact on the sample grid;
with a continuously varying command the stick-slip form's jumps depend on the sample
rate, as a real valve's depend on how fast its drive moves.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.rig import Rig

_FORMS = ("play", "stick_slip")
#: Slip fraction a stick-slip candidate starts at (halfway between play and a jump).
START_SLIP = 0.5


class ValveStiction(Effect):
    """Valve stiction of break-away band ``stiction_band_V`` (play, or stick-slip with
    ``stiction_slip_fraction``)."""

    name = "valve_stiction"
    forms = _FORMS
    acts_on = ("stiction_band_V", "stiction_slip_fraction")
    bench_value = 0.1

    def __init__(self, form: str = "play"):
        self.form = form

    def options(self):
        self._check()
        return {"form": self.form}

    def parameters(self):
        self._check()
        band = Parameter("stiction_band_V", "command unit", 0.0, 1.5, "uniform",
                         "break-away band: how far the command moves before the valve "
                         "does", neutral=0.0)
        if self.form == "play":
            return (band,)
        return (band, Parameter("stiction_slip_fraction", "-", 0.0, 1.0, "uniform",
                                "slip: 0 stops a band short of the command (play), 1 "
                                "jumps onto it", neutral=0.0))

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        band = np.asarray(values["stiction_band_V"], dtype=np.float64)
        if self.form == "play":
            return {"stiction_band_V": band}
        return {"stiction_band_V": band,
                "stiction_slip_fraction": np.asarray(values["stiction_slip_fraction"],
                                                     dtype=np.float64)}

    def bench_defaults(self):
        if self.form == "play":
            return {"stiction_band_V": self.bench_value}
        return {"stiction_band_V": self.bench_value, "stiction_slip_fraction": START_SLIP}

    # ------------------------------------------------------------------ discovery
    library_strengths = (0.02, 0.05, 0.1, 0.2, 0.35, 0.6)
    discovery_fallback = {"stiction_band_V": 0.1}

    def library_terms(self, strengths):
        """Play of each trial band (command unit)."""
        return tuple(TrialTerm(f"stiction play {v:g}", {"stiction_band_V": v},
                               values={"stiction_band_V": v}) for v in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """Play at the best term's band, and stick-slip at the same band from
        :data:`START_SLIP`."""
        start = self.candidate_start(ctx.term_start)
        out = [(self, start)]
        if self.form == "play":
            band = start.get("stiction_band_V", self.discovery_fallback["stiction_band_V"])
            out.append((ValveStiction(form="stick_slip"),
                        {"stiction_band_V": band, "stiction_slip_fraction": START_SLIP}))
        return out
