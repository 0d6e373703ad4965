"""Stage: an open-form term at the reading, when neither the catalogue nor the closure's
mass flow closes the gap.

The open-form closure (:mod:`~pneubayes.discovery.stages.open_form`) can only add mass
to the chamber. What acts on the sensor alone (a diaphragm that warms with the gas, a
transducer's creep, a cavity in front of the gauge) it cannot express. This stage
searches the training windows' residual for relaxations of the reading
(:class:`~pneubayes.discovery.openform.reading.ReadingSearch`) and adds the kept ones as
one :class:`~pneubayes.effects.reading_closure.ReadingClosure`, fitted, pruned and
weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm` does.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading import (
    ReadingSearch,
    ReadingWindows,
    reading_windows,
)
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.discovery.state import RoundState
from pneubayes.effects.reading_closure import (
    ReadingClosure,
    gain_name,
    time_constant_name,
)

#: The component's name in a model and in the ledger.
READING = "reading_closure"


class ReadingForm(ComponentForm):
    """Search the training windows' residual for relaxations of the reading and add them
    as a reading closure (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor (0: never then).
    search : ReadingSearch or None
        The residual search (its settings); None: ``ReadingSearch()``.
    """

    name = "reading_form"
    component = READING
    label = "reading form"
    term_word = "relaxation of the reading"
    search_class = ReadingSearch

    def _search_data(self, state: RoundState, runner) -> list[ReadingWindows]:
        """The training windows as the current model predicts them
        (:func:`~pneubayes.discovery.openform.reading.reading_windows`)."""
        return reading_windows(runner.data.train_ws, state.current.model,
                               state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        return ReadingClosure(terms=terms)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return gain_name(k), time_constant_name(k)

    def _searched_values(self, terms, params) -> dict[str, float]:
        out = {}
        for k, t in enumerate(terms):
            out[gain_name(k)] = t.gain
            out[time_constant_name(k)] = t.time_constant_s
        return out
