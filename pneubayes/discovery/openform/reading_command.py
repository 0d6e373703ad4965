"""The open-form search at the reading driven by the command: lags of the command's
magnitude in the prediction windows' residual.

A reading command lag (:class:`~pneubayes.effects.reading_command.ReadingCommand`) adds
``c l`` to a window's reading, ``l`` the first-order lag of ``|u|`` warm from the
recording's start. Its effect on a window's prediction is that term plus the chamber's
start moved by ``-c l(start)`` along the start sensitivity
(:meth:`~pneubayes.discovery.openform.reading.ReadingWindows.command_column`; linear in
``c``). :class:`CommandLagSearch` is
:class:`~pneubayes.discovery.openform.reading.ReadingSearch` over the lags' time
constants: the same greedy pick, refinement, joint refinement of two and keeping rule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.reading import ReadingSearch, command_columns
from pneubayes.effects.reading_command import COMMAND_MAX_TERMS, COMMAND_TIME_CONSTANT_BOUNDS_S


@dataclass(frozen=True)
class CommandLagTerm:
    """A kept lag: ``gain`` (Pa per command unit), ``time_constant_s`` (s), the share of
    the residual's uncentred sum of squares it explains on its own (``explained``) and
    its gain over its window-clustered standard error (``t``)."""

    gain: float
    time_constant_s: float
    explained: float
    t: float

    def __str__(self) -> str:
        return (f"{self.gain:+.4g} Pa per command unit x l, l the lag of |u| with tau = "
                f"{self.time_constant_s:.4g} s")


class CommandLagSearch(ReadingSearch):
    """Greedy search of lags of the command's magnitude in the windows' residual
    (scikit-learn contract).

    Parameters
    ----------
    time_constants_s : sequence of float
        The time constants searched (s, within the component's bounds); the best is
        refined between its neighbours.
    max_terms : int
        Most terms kept (1..2, the component's room).
    min_explained_fraction, min_t : float
        As :class:`~pneubayes.discovery.openform.reading.ReadingSearch`'s.

    Attributes
    ----------
    terms_ : list of CommandLagTerm
    explained_fraction_ : float
    best_ : CommandLagTerm or None
    """

    max_terms_allowed = COMMAND_MAX_TERMS

    def __init__(self, time_constants_s: Sequence[float] = tuple(np.geomspace(3e-4, 10.0, 30)),
                 max_terms: int = COMMAND_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0):
        self.time_constants_s = time_constants_s
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t

    def _checked_grid(self) -> np.ndarray:
        taus = np.asarray(self.time_constants_s, dtype=np.float64)
        lo, hi = COMMAND_TIME_CONSTANT_BOUNDS_S
        if taus.ndim != 1 or taus.size < 3 or np.any(np.diff(taus) <= 0) \
                or taus[0] < lo or taus[-1] > hi:
            raise ValueError(f"time_constants_s must be at least 3 increasing values within "
                             f"[{lo}, {hi}] s, got {self.time_constants_s!r}")
        return taus

    @staticmethod
    def _columns(blocks, value):
        return command_columns(blocks, value)

    @staticmethod
    def _new_term(gain, value, explained, t):
        return CommandLagTerm(gain, value, explained, t)
