"""Stage: groups that beat an earlier round's model but were not added."""

from __future__ import annotations

from pneubayes.discovery.rounds import runner_ups
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.state import RoundState


class RunnerUps(Stage):
    """When nothing passed this round, try again the groups whose trial in an earlier
    round beat that round's model significantly (beyond its control) but that were not
    added, and that no later trial failed (ledger action ``revisit``): the one-step
    search ranks what the *current* residual shows, and an effect can drop out of it
    once others are added.

    Parameters
    ----------
    min_gap_closed : float
        Share of the held-out RMSE's gap above the noise floor a revisited group must
        close (the search no longer supports it).
    """

    name = "runner_ups"

    def __init__(self, min_gap_closed: float = 0.25):
        self.min_gap_closed = min_gap_closed

    def options(self):
        return {"min_gap_closed": self.min_gap_closed}

    def run(self, state: RoundState, runner) -> None:
        if state.passing:
            return
        retry = runner_ups(runner.ledger, state.current.model.effect_names,
                           state.search_step, runner.settings.verify.max_p_value)
        if not retry:
            return
        runner.log(f"discover: nothing passed this round; revisiting "
                   f"{', '.join(retry)}, which beat an earlier model significantly "
                   "but were not added")
        runner.ledger.record("revisit", round=state.number, groups=retry)
        state.passing = runner.trials(retry, state, self.min_gap_closed)
