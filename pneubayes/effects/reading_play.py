"""An open-form term at the reading: a reading with backlash (rate-independent
hysteresis).

Some sensors report a pressure that lags a reversal by a fixed amount however slowly
it comes: a diaphragm or a bourdon tube with play in its linkage, a seal that holds a
gauge's element until the force on it exceeds its friction. No relaxation
(:mod:`pneubayes.effects.reading_closure`) is rate-independent; this component adds
``J`` plays (backlash operators) of the chamber pressure p to its reading::

    r = p + sum_j h_j (p - y_j),    y_j = min(p + w_j, max(p - w_j, y_j(before))),

``h_j`` (``reading_play_gain_{j}``, -) and ``w_j`` (``reading_play_width_{j}``, Pa,
the half-width). ``h = -1`` is a reading that is the play itself (it stands still
until the pressure has moved ``w`` back); ``-1 < h < 0`` a reading with part of it.
Every gain 0 is the reading without the component, whatever the widths.

The chamber's physics is unchanged: the simulator applies the plays to each simulated
window's pressure after the kernel (:mod:`pneubayes.simulation.reading_play`), each
play starting where the recorded reading's play stands at the window's start. The
discovery library never searches for it: the open-form stage at the reading
(:class:`~pneubayes.discovery.stages.reading_form.ReadingPlayForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.reading_closure import named_pairs
from pneubayes.rig import Rig

#: The most plays one component carries.
PLAY_MAX_TERMS = 2
#: A gain's bounds (-): down to a reading that is 90 % the play (the reading at a
#: window's start must still tell the chamber's pressure, ``1 + sum h > 0``), up to a
#: reading that overshoots a reversal by the width.
PLAY_GAIN_BOUNDS = (-0.9, 1.0)
#: A half-width's bounds and start, Pa.
WIDTH_BOUNDS_PA = (10.0, 1.0e5)
WIDTH_START_PA = 1000.0


def play_gain_name(j: int) -> str:
    """Play ``j``'s gain parameter."""
    return f"reading_play_gain_{j}"


def play_width_name(j: int) -> str:
    """Play ``j``'s half-width parameter."""
    return f"reading_play_width_{j}"


class ReadingPlay(Effect):
    """``terms`` plays of the reading, ``r = p + sum_j h_j (p - y_j)``
    (``reading_play_gain_{j}``, ``reading_play_width_{j}``)."""

    name = "reading_play"
    acts_on = ()  # (the simulator applies it after the kernel, on the windows' pressure)
    library_searched = False
    cheap_forms = True
    relaxes_reading = True

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) \
                or not 1 <= terms <= PLAY_MAX_TERMS:
            raise ValueError(f"reading_play: option 'terms' must be an integer in "
                             f"1..{PLAY_MAX_TERMS}, got {terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def parameters(self):
        lo, hi = WIDTH_BOUNDS_PA
        out = []
        for j in range(self.terms):
            out.append(Parameter(play_gain_name(j), "-", *PLAY_GAIN_BOUNDS, "uniform",
                                 f"reading play {j}: its gain h, the reading being "
                                 "p + h (p - y)", neutral=0.0))
            out.append(Parameter(play_width_name(j), "Pa", lo, hi, "log-uniform",
                                 f"reading play {j}: the half-width w the pressure moves "
                                 "back before the play y follows (the term vanishes with "
                                 "its gain whatever its width)", neutral=WIDTH_START_PA))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {}  # (no slot of the kernel: see the module's docstring)

    def reading_plays(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray]:
        """``(gains, half-widths)``, each ``(B, terms)``, of a batch of values."""
        return self.plays_named(values, [play_gain_name(j) for j in range(self.terms)],
                                [play_width_name(j) for j in range(self.terms)])

    @staticmethod
    def plays_named(values: Mapping[str, np.ndarray], gains: list[str],
                    widths: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """``(gains, half-widths)``, each ``(B, J)``, read from ``values`` under the
        parameter names ``gains`` and ``widths`` (one per play)."""
        return named_pairs(values, gains, widths)

    def bench_defaults(self):
        """A reading with half of a 2-kPa play (a second: a quarter of a 500-Pa one)."""
        out = {play_gain_name(0): -0.5, play_width_name(0): 2000.0}
        if self.terms > 1:
            out.update({play_gain_name(1): -0.25, play_width_name(1): 500.0})
        return out
