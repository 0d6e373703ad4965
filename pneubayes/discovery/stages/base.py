"""The interface of a discovery stage: one step the loop may take after a round's trials.

A round of :class:`~pneubayes.discovery.loop.Discovery` searches the current model's
residual, fits and verifies the supported effects' trials, then runs its stages in
order. Each stage reads and changes the round's state
(:class:`~pneubayes.discovery.state.RoundState`): it may add passing trials
(``state.passing``), or set ``state.replacement`` to reshape the model (the round ends
and the next starts from it). With no stages the loop is the plain one: search, name,
add, refit, verify, until nothing passes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

from pneubayes.discovery.state import RoundState


class Stage(ABC):
    """One stage of the discovery loop's pipeline.

    Constructors only store the stage's knobs (:meth:`options`); :meth:`run` does the
    work with the loop's trial runner
    (:class:`~pneubayes.discovery.trials.TrialRunner`)."""

    #: The stage's name in logs and in the saved settings.
    name: ClassVar[str]
    #: Whether the stage reshapes the model (sets ``state.replacement``) rather than
    #: adding trials; such a stage also runs in a round whose search found nothing.
    reshapes: ClassVar[bool] = False

    def opens_empty_round(self, state: RoundState) -> bool:
        """Whether a round whose search supported no group goes on to the stages
        because of this one (the default: no)."""
        return False

    @abstractmethod
    def run(self, state: RoundState, runner) -> None:
        """Do the stage's work on the round ``state`` with ``runner`` (a
        :class:`~pneubayes.discovery.trials.TrialRunner`)."""

    def options(self) -> dict[str, Any]:
        """The stage's knobs, as saved with a result."""
        return {}

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"
