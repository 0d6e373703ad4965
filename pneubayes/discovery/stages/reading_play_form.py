"""Stage: a rate-independent open-form term at the reading (backlash), when neither the
catalogue, the closure's mass flow nor a relaxation of the reading closes the gap.

A sensor whose reading stands still after a reversal until the pressure has come back
some pascals (play in a gauge's linkage, a diaphragm held by friction) lags by the same
amount however slowly the pressure turns: no relaxation expresses it. This stage
searches the training windows' residual for plays of the reading
(:class:`~pneubayes.discovery.openform.reading_play.PlaySearch`) and adds the kept ones
as one :class:`~pneubayes.effects.reading_play.ReadingPlay`, fitted, pruned and weighed
as :class:`~pneubayes.discovery.stages.component_form.ComponentForm` does.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading import ReadingWindows, reading_windows
from pneubayes.discovery.openform.reading_play import PlaySearch
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.discovery.state import RoundState
from pneubayes.effects.reading_play import ReadingPlay, play_gain_name, play_width_name

#: The component's name in a model and in the ledger.
PLAY = "reading_play"


class ReadingPlayForm(ComponentForm):
    """Search the training windows' residual for plays of the reading and add them as a
    reading play (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio, compete_below_gap_closed : float
        As :class:`ComponentForm`'s.
    search : PlaySearch or None
        The residual search (its settings); None: ``PlaySearch()``.
    """

    name = "reading_play_form"
    component = PLAY
    label = "reading play form"
    term_word = "play of the reading"
    search_class = PlaySearch

    def _search_data(self, state: RoundState, runner) -> list[ReadingWindows]:
        """The training windows as the current model predicts them
        (:func:`~pneubayes.discovery.openform.reading.reading_windows`)."""
        return reading_windows(runner.data.train_ws, state.current.model,
                               state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        return ReadingPlay(terms=terms)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return play_gain_name(k), play_width_name(k)

    def _searched_values(self, terms, params) -> dict[str, float]:
        out = {}
        for k, t in enumerate(terms):
            out[play_gain_name(k)] = t.gain
            out[play_width_name(k)] = t.width_Pa
        return out
