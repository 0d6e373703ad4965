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

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.5,
                 search: ReadingSearch | None = None):
        super().__init__(min_noise_ratio, compete_below_gap_closed)
        self.search = search

    def options(self):
        s = self.search
        return {"min_noise_ratio": self.min_noise_ratio,
                "compete_below_gap_closed": self.compete_below_gap_closed,
                "search": None if s is None else {
                    "time_constants_s": [float(v) for v in s.time_constants_s],
                    "max_terms": s.max_terms,
                    "min_explained_fraction": s.min_explained_fraction, "min_t": s.min_t}}

    def _residual(self, state: RoundState, runner) -> list[ReadingWindows]:
        """The training windows as the current model predicts them
        (:func:`~pneubayes.discovery.openform.reading.reading_windows`)."""
        return reading_windows(runner.data.train_ws, state.current.model,
                               state.current.params, runner.settings.fit.refine_solver)

    def _search(self, state, runner):
        s = self.search if self.search is not None else ReadingSearch()
        return type(s)(time_constants_s=s.time_constants_s, max_terms=s.max_terms,
                       min_explained_fraction=s.min_explained_fraction,
                       min_t=s.min_t).fit(self._residual(state, runner))

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

    def _term_record(self, t) -> dict:
        return {"gain": t.gain, "time_constant_s": t.time_constant_s,
                "explained_fraction": t.explained, "t": t.t}
