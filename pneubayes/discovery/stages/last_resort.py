"""Stage: every other group of the library, while the held-out error is far above the
noise floor and nothing (or too little) passed."""

from __future__ import annotations

from pneubayes.discovery.rounds import last_resort_reason
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.state import RoundState


class LastResort(Stage):
    """While the held-out error is far above the noise floor (:meth:`RoundState.far`)
    and no trial passed, or the best that passed closes under ``best_gap_closed`` of
    the gap, fit and verify every group of the library the round has not tried (ledger
    action ``last resort``). A slow effect's one-step evidence can be near zero while
    its 2-s error is large.

    Parameters
    ----------
    min_gap_closed : float
        Share of the held-out RMSE's gap above the noise floor such a group must close.
    best_gap_closed : float
        The stage also runs when the best trial that passed closes less than this
        share (0: only when none passed).
    """

    name = "last_resort"
    #: The ledger's action for the stage's trials.
    action = "last resort"

    def __init__(self, min_gap_closed: float = 0.25, best_gap_closed: float = 0.25):
        for name, share in (("min_gap_closed", min_gap_closed),
                            ("best_gap_closed", best_gap_closed)):
            if not 0.0 <= share <= 1.0:
                raise ValueError(f"{type(self).__name__}: {name} must be in [0, 1], got "
                                 f"{share}")
        self.min_gap_closed = min_gap_closed
        self.best_gap_closed = best_gap_closed

    def options(self):
        return {"min_gap_closed": self.min_gap_closed, "best_gap_closed": self.best_gap_closed}

    def opens_empty_round(self, state: RoundState) -> bool:
        return state.started_far

    def _in_zone(self, state: RoundState) -> bool:
        """Whether the held-out error is where this stage acts: far above the noise."""
        return state.far()

    def run(self, state: RoundState, runner) -> None:
        noise = state.noise_Pa
        rest = [g for g in state.search.ranking_ if g not in state.candidates]
        why, closed = last_resort_reason([t[0] for t in state.passing],
                                         state.current.heldout_rmse_Pa, noise,
                                         self.best_gap_closed)
        if not (why and self._in_zone(state) and rest):
            return
        ratio = state.current.heldout_rmse_Pa / noise
        runner.log(f"discover: {self.action}: the held-out error is {ratio:.2f} x the noise "
                   f"floor and {why}: trying the rest ({', '.join(rest)}), each to close "
                   f"{self.min_gap_closed:.0%} of the gap")
        runner.ledger.record(self.action, round=state.number, groups=rest,
                             heldout_over_noise=ratio, best_gap_closed_before=closed)
        state.passing = state.passing + runner.trials(rest, state, self.min_gap_closed)
        state.candidates = state.candidates + rest
