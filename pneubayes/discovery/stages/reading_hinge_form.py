"""Stage: a static open-form term at the reading (a knee), when neither the catalogue nor
another form closes the gap.

A sensor driven past its range bends into a rail; a gauge's spring stiffens at the end
of its travel. Its reading is a static map of the pressure whose slope breaks at a
knee, which neither the catalogue's curvature (a parabola over the whole range) nor any
dynamics of the reading expresses. This stage searches the training windows' residual
for knees of the reading
(:class:`~pneubayes.discovery.openform.reading_hinge.HingeSearch`) and adds the kept
ones as one :class:`~pneubayes.effects.reading_hinge.ReadingHinge`, fitted, pruned and
weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm` does. It
also runs when the round's best trial is the catalogue's curvature of the reading (its
rival), and replaces it only by beating it on the held-out windows.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading import ReadingWindows, reading_windows
from pneubayes.discovery.openform.reading_hinge import HingeSearch
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.discovery.state import RoundState
from pneubayes.effects.reading_hinge import (
    ReadingHinge,
    hinge_gain_name,
    hinge_threshold_name,
)

#: The component's name in a model and in the ledger.
HINGE = "reading_hinge"


class ReadingHingeForm(ComponentForm):
    """Search the training windows' residual for knees of the reading and add them as a
    reading hinge (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio, compete_below_gap_closed : float
        As :class:`ComponentForm`'s.
    search : HingeSearch or None
        The residual search (its settings); None: ``HingeSearch()``.
    """

    name = "reading_hinge_form"
    component = HINGE
    label = "reading hinge form"
    term_word = "knee of the reading"
    search_class = HingeSearch
    #: (the catalogue's curvature is a static map of the reading too: a rail it stands
    #: in for is tried as knees, and the better on held-out windows kept)
    rivals = ("sensor_nonlinearity",)

    def _search_data(self, state: RoundState, runner) -> list[ReadingWindows]:
        """The training windows as the current model predicts them
        (:func:`~pneubayes.discovery.openform.reading.reading_windows`)."""
        return reading_windows(runner.data.train_ws, state.current.model,
                               state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        return ReadingHinge(terms=terms)

    def _component_for(self, terms):
        """Knees on the side the search kept them."""
        return ReadingHinge(terms=len(terms), below=bool(terms[0].below))

    def _one_term(self, component, k: int):
        return ReadingHinge(terms=1, below=component.below)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return hinge_gain_name(k), hinge_threshold_name(k)

    def _searched_values(self, terms, params) -> dict[str, float]:
        out = {}
        for k, t in enumerate(terms):
            out[hinge_gain_name(k)] = t.gain
            out[hinge_threshold_name(k)] = t.threshold_Pa
        return out
