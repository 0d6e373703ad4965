"""Stage: a valve's dead time that depends on the supply pressure, where the training
recordings ran at different supplies and the catalogue does not close the gap.

A solenoid valve's dead time changes with the pressure it switches (a pilot-operated
valve opens sooner at a higher supply, a direct-acting poppet later), so between runs at
different supplies the command's delay changes, which the tube's transit or a fixed
delay averages over. Recordings at one supply cannot show it: the stage asks
:class:`~pneubayes.discovery.openform.dead_time.DeadTimeSearch` whether their nominal
supplies differ, and where they do adds
:class:`~pneubayes.effects.valve_dead_time.ValveDeadTime` from the search's generic
start and from zero strength, fitted and weighed as
:class:`~pneubayes.discovery.stages.component_form.ComponentForm` does. Its fitted law
moves the dead time the tube's transit had carried into the valve, so the fit refits
the whole model.
"""

from __future__ import annotations

from pneubayes.discovery.openform.dead_time import DeadTimeSearch
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.discovery.state import RoundState
from pneubayes.effects.valve_dead_time import ValveDeadTime


class ValveDeadTimeForm(ComponentForm):
    """Add a supply-dependent valve dead time where the training supplies differ (when
    it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio, compete_below_gap_closed : float
        As :class:`ComponentForm`'s.
    search : DeadTimeSearch or None
        The supplies' reading (its settings); None: ``DeadTimeSearch()``.
    """

    name = "valve_dead_time_form"
    component = ValveDeadTime.name
    label = "valve dead time form"
    term_word = "dead time law"
    search_class = DeadTimeSearch

    def _run(self, state: RoundState, runner, best) -> None:
        """Say so and stop where the training supplies do not differ; else fit the law."""
        search = self._fitted_search(state, runner)
        if search.proposal_ is None:
            runner.log(f"discover: {self.label}: the training recordings' supplies spread "
                       f"by {search.supply_spread_:.1%} of their mean (under "
                       f"{search.min_supply_spread:.0%}): no law of the dead time in the "
                       "supply to tell from a fixed delay")
            return
        self._run_search(search, state, runner, best)

    def _search_data(self, state: RoundState, runner):
        """The training windows (the search reads their recordings' nominal supplies)."""
        return runner.data.train_ws

    def _component(self, terms: int):
        return ValveDeadTime()

    def _term_names(self, k: int) -> tuple[str, ...]:
        return ("valve_dead_time_s", "valve_dead_time_exponent")

    def _strength_names(self, k: int) -> tuple[str, ...]:
        """Both (0 and 0: no dead time)."""
        return self._term_names(k)

    def _fallback_terms(self, search) -> list:
        """The search's proposal, where the supplies differ."""
        return [] if search.proposal_ is None else [search.proposal_]

    def _search_record(self, search) -> dict:
        return {"supplies_gauge_Pa": [float(v) for v in search.supplies_gauge_Pa_],
                "supply_spread": search.supply_spread_}

    def _searched_values(self, terms, params) -> dict[str, float]:
        t = terms[0]
        return {"valve_dead_time_s": t.dead_time_s, "valve_dead_time_exponent": t.exponent}
