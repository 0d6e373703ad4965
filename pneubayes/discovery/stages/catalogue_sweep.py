"""Stage: the catalogue's untried groups, while the held-out error is above the noise
floor but not far above it and nothing (or little) passed."""

from __future__ import annotations

from pneubayes.discovery.rounds import last_resort_reason
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.state import RoundState


class CatalogueSweep(Stage):
    """Below the last resort's zone (:meth:`RoundState.far`) and above
    ``min_noise_ratio`` x the noise floor, when no trial of the round passed or the best
    that passed closes under ``best_gap_closed`` of the gap, fit and verify the
    catalogue's groups the round has not tried, in the order of the search's evidence
    (ledger action ``catalogue sweep``).

    Beside a larger effect a small one (a clearance leak beside a spool lag or a tube)
    can fall under the search's inclusion threshold once the larger is added: its signal
    is a slow drift the one-step residual barely shows. Without this stage such a round
    supports nothing and the loop stops above the noise, or an open-form stage (which
    runs from 1.5 x) absorbs the effect in generic terms. The catalogue stays the first
    resort: the open form then competes with what passed here.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs while the held-out RMSE exceeds this x the noise floor (>= 1).
    min_gap_closed : float
        Share of the held-out RMSE's gap above the noise floor a group must close: a
        missing catalogue effect near the noise closes most of what is left, a stand-in
        a part of it.
    best_gap_closed : float
        The stage also runs when the best passing trial closes less than this share
        (0: only when none passed).
    """

    name = "catalogue_sweep"

    def __init__(self, min_noise_ratio: float = 1.1, min_gap_closed: float = 0.5,
                 best_gap_closed: float = 0.25):
        if not min_noise_ratio >= 1.0:
            raise ValueError(f"CatalogueSweep: min_noise_ratio must be >= 1, got "
                             f"{min_noise_ratio}")
        if not 0.0 <= min_gap_closed <= 1.0:
            raise ValueError(f"CatalogueSweep: min_gap_closed must be in [0, 1], got "
                             f"{min_gap_closed}")
        if not 0.0 <= best_gap_closed <= 1.0:
            raise ValueError(f"CatalogueSweep: best_gap_closed must be in [0, 1], got "
                             f"{best_gap_closed}")
        self.min_noise_ratio = min_noise_ratio
        self.min_gap_closed = min_gap_closed
        self.best_gap_closed = best_gap_closed

    def options(self):
        return {"min_noise_ratio": self.min_noise_ratio,
                "min_gap_closed": self.min_gap_closed, "best_gap_closed": self.best_gap_closed}

    def _above(self, state: RoundState) -> bool:
        return state.current.heldout_rmse_Pa > self.min_noise_ratio * state.noise_Pa

    def opens_empty_round(self, state: RoundState) -> bool:
        return self._above(state) and not state.far()

    def run(self, state: RoundState, runner) -> None:
        if state.far() or not self._above(state):
            return
        why, closed = last_resort_reason([t[0] for t in state.passing],
                                         state.current.heldout_rmse_Pa, state.noise_Pa,
                                         self.best_gap_closed)
        rest = [g for g in state.search.ranking_ if g not in state.candidates]
        if not (why and rest):
            return
        ratio = state.current.heldout_rmse_Pa / state.noise_Pa
        runner.log(f"discover: {why} at {ratio:.2f} x the noise floor: trying the "
                   f"catalogue's untried groups ({', '.join(rest)}), each to close "
                   f"{self.min_gap_closed:.0%} of the gap")
        runner.ledger.record("catalogue sweep", round=state.number, groups=rest,
                             heldout_over_noise=ratio, best_gap_closed_before=closed)
        state.passing = state.passing + runner.trials(rest, state, self.min_gap_closed)
        state.candidates = state.candidates + rest
