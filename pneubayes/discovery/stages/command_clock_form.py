"""Stage: an open-form term on the command, a valve driver on its own clock, when the
catalogue does not close the gap.

A driver that takes the command at the ticks of a clock the recording does not carry (a
fieldbus output, a control loop slower than the logger, a pulse-width-modulated on/off
valve) makes every command change wait a share of a period that depends on where it
falls between the ticks: no delay or lag of the catalogue expresses it, and a sensor lag
or a spool lag stands in for its mean. This stage reads the clock from the training
windows (:class:`~pneubayes.discovery.openform.command_clock.CommandClockSearch`) and
adds the found driver as one :class:`~pneubayes.effects.command_clock.CommandClock`,
fitted and weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm`
does. It runs first among the open forms and challenges a passing trial that closes
under 90 % of the gap (``compete_below_gap_closed``), replacing it where the driver
predicts the held-out windows better.
"""

from __future__ import annotations

from pneubayes.discovery.openform.command_clock import CommandClockProblem, CommandClockSearch
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.effects.command_clock import LATENCY, PERIOD, PHASE, CommandClock

#: The component's name in a model and in the ledger.
COMMAND_CLOCK = "command_clock"


class CommandClockForm(ComponentForm):
    """Read a valve driver's clock from the training windows' residual and add it as a
    command clock (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor.
    search : CommandClockSearch or None
        The residual search (its settings); None: ``CommandClockSearch()``.
    """

    name = "command_clock_form"
    component = COMMAND_CLOCK
    label = "command clock form"
    term_word = "driver clock"
    search_class = CommandClockSearch

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.9,
                 search=None):
        super().__init__(min_noise_ratio, compete_below_gap_closed, search)

    def _search_data(self, state, runner) -> CommandClockProblem:
        return CommandClockProblem(runner.data.train_ws, state.current.model,
                                   state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        return CommandClock()

    def _component_for(self, terms):
        return CommandClock(terms[0].form)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return PERIOD, PHASE, LATENCY

    def _strength_names(self, k: int) -> tuple[str, ...]:
        return PERIOD, LATENCY

    def _searched_values(self, terms, params) -> dict[str, float]:
        return terms[0].values()
