"""What the discovery loop's stages read and change: the data, the ledger, a round's state.

The loop (:class:`~pneubayes.discovery.loop.Discovery`) runs rounds; in each, its
search names candidate effects, their trials are fitted and verified, and then each
stage of its pipeline (:mod:`pneubayes.discovery.stages`) may try more. Everything a
stage needs is here, passed in explicitly: :class:`LoopData` (fixed for the run),
:class:`Ledger` (the run's record) and :class:`RoundState` (the round so far).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

from pneubayes.discovery.verification import StepFit
from pneubayes.inference.windows import WindowSet


@dataclass(frozen=True)
class LoopData:
    """The data every fit of one run is scored on.

    Attributes
    ----------
    train, held : tuple of Recording
        The prepared recordings (or their parts) fitted on and held out.
    train_ws, held_ws : WindowSet
        Their prediction windows (``held_ws`` scores the held-out stretch only).
    data_key : str
        A fingerprint of the data, part of every cached fit's key.
    noise_Pa : float
        The recordings' white-noise floor, Pa.
    """

    train: tuple
    held: tuple
    train_ws: WindowSet
    held_ws: WindowSet
    data_key: str
    noise_Pa: float

    def rig(self):
        """The rig the recordings describe (one rig a run)."""
        return self.train[0].rig()


class Ledger:
    """The run's record: one event a step, numbered in order (saved in discovery.json).

    Each event is a mapping with ``step``, ``action`` and the action's own fields;
    :meth:`record` is the one way to add one."""

    def __init__(self):
        self._events: list[dict] = []

    def record(self, action: str, **fields) -> dict:
        """Append the event ``action`` with ``fields``; returns it."""
        event = {"step": len(self._events), "action": action, **fields}
        self._events.append(event)
        return event

    def __len__(self) -> int:
        return len(self._events)

    def __iter__(self) -> Iterator[dict]:
        return iter(self._events)

    def events(self) -> tuple:
        """Every event so far, in order."""
        return tuple(self._events)


@dataclass
class RoundState:
    """One round of the loop, as its stages see and change it.

    Attributes
    ----------
    number : int
        The round, from 1.
    current : StepFit
        The current fit (a trial's control that fits better in training replaces it).
    search : GroupedSINDy
        The round's fitted search: ``evidence_`` per group and ``ranking_``.
    supported, tentative : list of str
        Groups the search supports, and the weakly supported ones tried because the
        held-out error is far above the noise floor.
    started_far : bool
        The held-out error was ``gap_ratio`` x the noise floor or more at the round's
        start (and ``gap_ratio`` > 0).
    gap_ratio, noise_Pa : float
        The test of :meth:`far`: ratio to the noise floor, and the floor (Pa).
    search_step : int
        The ledger step of the round's search.
    counts : dict
        Run-wide counters a stage keeps across rounds (e.g. form swaps so far).
    candidates : list of str
        Groups whose trials the round has fitted so far, as first candidates or as
        the overflow of the supported ones.
    tried : dict
        Each effect's fitted forms this round, ``[(model, fit, start), ...]``, the
        lowest training RMSE first.
    passing : list
        Trials that passed verification: ``(held-out RMSE, group or pair, fit, score
        gain, p-value)``.
    replacement : StepFit or None
        Set by a stage that reshapes the model (another form of a named effect): the
        round ends and the next starts from it.
    exhausted : bool
        Nothing supported and no stage opened the round: only reshaping stages run.
    evidence : dict
        Evidence of candidates a stage proposed that the search's groups do not hold
        (group -> ``{"inclusion_probability", "t_max", "best_term", ...}``).
    """

    number: int
    current: StepFit
    search: object
    supported: list
    tentative: list
    started_far: bool
    gap_ratio: float
    noise_Pa: float
    search_step: int
    counts: dict
    candidates: list = field(default_factory=list)
    tried: dict = field(default_factory=dict)
    passing: list = field(default_factory=list)
    replacement: StepFit | None = None
    exhausted: bool = False
    evidence: dict = field(default_factory=dict)

    def evidence_of(self, group: str) -> dict:
        """The evidence behind ``group``: a stage's own, else the search's."""
        return self.evidence[group] if group in self.evidence else self.search.evidence_[group]

    def far(self) -> bool:
        """Whether the held-out error is still far above the noise floor: it was at the
        round's start and the current fit's is above ``gap_ratio`` x the floor."""
        return self.started_far and self.current.heldout_rmse_Pa > self.gap_ratio * self.noise_Pa
