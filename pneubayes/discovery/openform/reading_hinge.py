"""The open-form search at the reading, static: knees of the reading in the prediction
windows' residual.

A reading hinge (:class:`~pneubayes.effects.reading_hinge.ReadingHinge`) reads a
window's pressure last through ``r = z + c max(0, z - theta)``. Its effect on a window's
prediction, to first order in ``c``, is ``max(0, p - theta)`` along the predicted
pressure less the chamber's start moved by ``max(0, r0 - theta)`` along the start
sensitivity (:meth:`~pneubayes.discovery.openform.reading.ReadingWindows.hinge_column`).
:class:`HingeSearch` is :class:`~pneubayes.discovery.openform.reading.ReadingSearch`
over a grid of knees instead of time constants, the grid spread over the pressures the
windows predict (a knee outside them has nothing to bend): the same greedy pick,
refinement, joint refinement of two and keeping rule. It searches knees above
(``max``) and knees below (``min``, a floor) apart and keeps the side whose terms
explain more (a component's knees bend one side).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.reading import ReadingSearch, hinge_columns
from pneubayes.effects.reading_hinge import HINGE_MAX_TERMS, HINGE_THRESHOLD_BOUNDS_PA

#: The sides a knee may bend the reading on.
SIDES = ("above", "below")


@dataclass(frozen=True)
class HingeTerm:
    """A kept knee: ``gain`` (-, the change of the reading's slope above it, or below it
    where ``below``), ``threshold_Pa`` (Pa absolute), the share of the residual's
    uncentred sum of squares it explains on its own (``explained``) and its gain over its
    window-clustered standard error (``t``)."""

    gain: float
    threshold_Pa: float
    explained: float
    t: float
    below: bool = False

    def __str__(self) -> str:
        side = "min" if self.below else "max"
        return (f"{self.gain:+.4g} {side}(0, p - theta), knee theta = "
                f"{self.threshold_Pa:.5g} Pa")


class HingeSearch(ReadingSearch):
    """Greedy search of the reading's knees in the windows' residual (scikit-learn
    contract).

    Parameters
    ----------
    thresholds_Pa : sequence of float or None
        The knees searched (Pa absolute, within the reading hinge's bounds); None:
        ``n_thresholds`` spread geometrically between the ``quantiles`` of the windows'
        predicted pressures. The best is refined between its neighbours.
    n_thresholds : int
        The data grid's size (with ``thresholds_Pa`` None).
    quantiles : (float, float)
        The predicted pressures' quantiles the data grid spans.
    max_terms : int
        Most terms kept (1..2, the reading hinge's room).
    sides : sequence of str
        The knees searched: ``"above"`` (bending the reading above them), ``"below"``
        (below them: a floor), or both (each apart, the one that explains more kept).
    min_explained_fraction, min_t : float
        As :class:`~pneubayes.discovery.openform.reading.ReadingSearch`'s.

    Attributes
    ----------
    terms_ : list of HingeTerm
    explained_fraction_ : float
    best_ : HingeTerm or None
    thresholds_searched_ : ndarray
        The grid searched, Pa (empty where the predictions span no range).
    """

    max_terms_allowed = HINGE_MAX_TERMS

    def __init__(self, thresholds_Pa: Sequence[float] | None = None, n_thresholds: int = 30,
                 quantiles: tuple[float, float] = (0.02, 0.98),
                 max_terms: int = HINGE_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0, sides: Sequence[str] = SIDES):
        self.sides = sides
        self.thresholds_Pa = thresholds_Pa
        self.n_thresholds = n_thresholds
        self.quantiles = quantiles
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"thresholds_Pa": self.thresholds_Pa, "n_thresholds": self.n_thresholds,
                "quantiles": self.quantiles, "max_terms": self.max_terms,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t,
                "sides": self.sides}

    def fit(self, blocks) -> "HingeSearch":
        """Search the windows' residual, one
        :class:`~pneubayes.discovery.openform.reading.ReadingWindows` per recording."""
        self._check_blocks(blocks)
        if isinstance(self.sides, str) or not len(self.sides) \
                or any(s not in SIDES for s in self.sides):
            raise ValueError(f"sides must be a non-empty sequence of {SIDES}, got "
                             f"{self.sides!r}")
        self.thresholds_searched_ = self._grid(blocks)
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        if self.thresholds_searched_.size == 0:  # (nothing to bend: no range)
            return self
        found = []
        for side in dict.fromkeys(self.sides):
            self._below = side == "below"
            super().fit(blocks)
            found.append((self.explained_fraction_ if self.terms_ else 0.0,
                          self.best_.explained if self.best_ is not None else 0.0,
                          self.terms_, self.best_, self.explained_fraction_))
        best = max(found, key=lambda f: (f[0], f[1]))
        self.terms_, self.best_, self.explained_fraction_ = best[2:]
        return self

    def _grid(self, blocks) -> np.ndarray:
        """The knees searched: the given ones, or the data grid."""
        lo, hi = HINGE_THRESHOLD_BOUNDS_PA
        if self.thresholds_Pa is not None:
            return np.asarray(self.thresholds_Pa, dtype=np.float64)
        n, (q0, q1) = self.n_thresholds, self.quantiles
        if isinstance(n, bool) or not isinstance(n, int) or n < 3 \
                or not 0.0 <= q0 < q1 <= 1.0:
            raise ValueError(f"n_thresholds must be an integer >= 3 and quantiles two "
                             f"increasing values in [0, 1], got {n!r}, {self.quantiles!r}")
        p = np.concatenate([np.asarray(b.predicted_Pa, np.float64).ravel() for b in blocks])
        p = p[np.isfinite(p)]
        if p.size < 2:
            return np.asarray([], dtype=np.float64)
        a, b = np.clip(np.quantile(p, [q0, q1]), lo, hi)
        if not b > a * (1.0 + 1e-6):
            return np.asarray([], dtype=np.float64)
        return np.geomspace(a, b, n)

    def _checked_grid(self) -> np.ndarray:
        th = np.asarray(self.thresholds_searched_, dtype=np.float64)
        lo, hi = HINGE_THRESHOLD_BOUNDS_PA
        if th.ndim != 1 or th.size < 3 or np.any(np.diff(th) <= 0) or th[0] < lo \
                or th[-1] > hi:
            raise ValueError(f"thresholds_Pa must be at least 3 increasing values within "
                             f"[{lo}, {hi}] Pa, got {self.thresholds_Pa!r}")
        return th

    # (the side being searched: set by fit before each side's search)
    def _columns(self, blocks, value):
        return hinge_columns(blocks, value, self._below)

    def _new_term(self, gain, value, explained, t):
        return HingeTerm(gain, value, explained, t, self._below)

    @staticmethod
    def _value_of(term):
        return term.threshold_Pa

