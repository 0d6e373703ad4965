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

from pneubayes.discovery.openform.reading import ReadingSearch, ReadingTerm, command_columns
from pneubayes.effects.reading_command import COMMAND_MAX_TERMS, COMMAND_TIME_CONSTANT_BOUNDS_S


@dataclass(frozen=True)
class CommandLagTerm(ReadingTerm):
    """A kept lag: ``gain`` (Pa per command unit), ``time_constant_s`` (s), the share of
    the residual's uncentred sum of squares it explains on its own (``explained``) and
    its gain over its window-clustered standard error (``t``)."""

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
    time_constant_bounds_s = COMMAND_TIME_CONSTANT_BOUNDS_S

    def __init__(self, time_constants_s: Sequence[float] = tuple(np.geomspace(3e-4, 10.0, 30)),
                 max_terms: int = COMMAND_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0):
        super().__init__(time_constants_s, max_terms, min_explained_fraction, min_t)

    @staticmethod
    def _columns(blocks, value):
        return command_columns(blocks, value)

    @staticmethod
    def _new_term(gain, value, explained, t):
        return CommandLagTerm(gain, value, explained, t)
