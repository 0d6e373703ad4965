"""The open-form search at the reading, rate-independent: plays (backlash) of the
reading in the prediction windows' residual.

A reading play (:class:`~pneubayes.effects.reading_play.ReadingPlay`) adds ``h (p -
y)`` to a window's reading, ``y`` the play of half-width ``w`` of the pressure, where
the recorded reading's play stands at the window's start. Its effect on a window's
prediction, to first order in ``h``, is that term along the predicted pressure plus the
chamber's start moved by ``y(start) - r0`` along the start sensitivity
(:meth:`~pneubayes.discovery.openform.reading.ReadingWindows.play_column`).
:class:`PlaySearch` is :class:`~pneubayes.discovery.openform.reading.ReadingSearch`
over a grid of half-widths instead of time constants: the same greedy pick, refinement,
joint refinement of two and keeping rule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.reading import ReadingSearch, play_columns
from pneubayes.effects.reading_play import PLAY_MAX_TERMS, WIDTH_BOUNDS_PA


@dataclass(frozen=True)
class PlayTerm:
    """A kept play: ``gain`` (-), ``width_Pa`` (the half-width, Pa), the share of the
    residual's uncentred sum of squares it explains on its own (``explained``) and its
    gain over its window-clustered standard error (``t``)."""

    gain: float
    width_Pa: float
    explained: float
    t: float

    def __str__(self) -> str:
        return f"{self.gain:+.4g} (p - y), play half-width w = {self.width_Pa:.4g} Pa"


class PlaySearch(ReadingSearch):
    """Greedy search of reading plays in the windows' residual (scikit-learn contract).

    Parameters
    ----------
    widths_Pa : sequence of float
        The half-widths searched (Pa, within the reading play's bounds); the best is
        refined between its neighbours.
    max_terms : int
        Most terms kept (1..2, the reading play's room).
    min_explained_fraction, min_t : float
        As :class:`~pneubayes.discovery.openform.reading.ReadingSearch`'s.

    Attributes
    ----------
    terms_ : list of PlayTerm
    explained_fraction_ : float
    best_ : PlayTerm or None
    """

    max_terms_allowed = PLAY_MAX_TERMS

    def __init__(self, widths_Pa: Sequence[float] = tuple(np.geomspace(30.0, 5.0e4, 30)),
                 max_terms: int = PLAY_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0):
        self.widths_Pa = widths_Pa
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"widths_Pa": self.widths_Pa, "max_terms": self.max_terms,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t}

    def _checked_grid(self) -> np.ndarray:
        w = np.asarray(self.widths_Pa, dtype=np.float64)
        lo, hi = WIDTH_BOUNDS_PA
        if w.ndim != 1 or w.size < 3 or np.any(np.diff(w) <= 0) or w[0] < lo or w[-1] > hi:
            raise ValueError(f"widths_Pa must be at least 3 increasing values within "
                             f"[{lo}, {hi}] Pa, got {self.widths_Pa!r}")
        return w

    @staticmethod
    def _columns(blocks, value):
        return play_columns(blocks, value)

    @staticmethod
    def _new_term(gain, value, explained, t):
        return PlayTerm(gain, value, explained, t)

    @staticmethod
    def _value_of(term):
        return term.width_Pa
