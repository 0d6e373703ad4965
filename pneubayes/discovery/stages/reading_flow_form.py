"""Stage: an open-form term at the reading that follows the valve's port flows, when
neither the catalogue, the closure's mass flow nor a relaxation, play or command lag of
the reading closes the gap.

A sensor on the valve's outlet, on a manifold before a fitting, or with its port facing
the inlet's jet reads the chamber's pressure plus something of the flow that passes:
a drop across what lies between (linear or quadratic in the flow) or a share of the
jet's dynamic pressure. This stage searches the training windows' residual for terms of
the inlet's and the exhaust's mass flows
(:class:`~pneubayes.discovery.openform.reading_flow.FlowSearch`) and adds the kept ones
as one :class:`~pneubayes.effects.reading_flow.ReadingFlow`, fitted, pruned and weighed
as :class:`~pneubayes.discovery.stages.component_form.ComponentForm` does.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading_flow import FlowSearch, FlowWindows, flow_windows
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.discovery.state import RoundState
from pneubayes.effects.reading_flow import FLOW_FEATURES, ReadingFlow, flow_gain_name

#: The component's name in a model and in the ledger.
FLOW = "reading_flow"


class ReadingFlowForm(ComponentForm):
    """Search the training windows' residual for terms of the port flows in the reading
    and add them as a reading flow component (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio, compete_below_gap_closed : float
        As :class:`ComponentForm`'s.
    search : FlowSearch or None
        The residual search (its settings); None: ``FlowSearch()``.
    """

    name = "reading_flow_form"
    component = FLOW
    label = "reading flow form"
    term_word = "port flow term in the reading"
    search_class = FlowSearch

    def _search_data(self, state: RoundState, runner) -> list[FlowWindows]:
        """The training windows as the current model predicts them, with the features of
        its port flows (:func:`~pneubayes.discovery.openform.reading_flow.flow_windows`)."""
        return flow_windows(runner.data.train_ws, state.current.model,
                            state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        """A component of the first ``terms`` features (a found one carries the search's:
        :meth:`_component_for`)."""
        return ReadingFlow(features=FLOW_FEATURES[:terms])

    def _component_for(self, terms):
        return ReadingFlow(features=[t.feature for t in terms])

    def _one_term(self, component, k: int):
        return ReadingFlow(features=(component.features[k],))

    def _term_names(self, k: int) -> tuple[str, ...]:
        return (flow_gain_name(k),)

    def _searched_values(self, terms, params) -> dict[str, float]:
        return {flow_gain_name(k): t.gain for k, t in enumerate(terms)}
