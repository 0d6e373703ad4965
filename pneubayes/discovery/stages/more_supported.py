"""Stage: the round's other supported groups, when none of its first trials passed."""

from __future__ import annotations

from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.state import RoundState


class MoreSupported(Stage):
    """When none of the round's first ``max_trials_per_round`` trials passed, try the
    round's other supported groups (ledger action ``more supported``): the search's
    ranking orders its evidence, not the 2-s gain, and a supported effect never tried
    is not one the data rule out."""

    name = "more_supported"

    def run(self, state: RoundState, runner) -> None:
        overflow = [g for g in state.supported if g not in state.candidates]
        if state.passing or not overflow:
            return
        runner.log(f"discover: none of the round's first trials passed: trying the "
                   f"other supported groups ({', '.join(overflow)})")
        runner.ledger.record("more supported", round=state.number, groups=overflow)
        state.passing = runner.trials(overflow, state)
        state.candidates = state.candidates + overflow
