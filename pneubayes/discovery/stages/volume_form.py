"""Stage: an open-form term on the chamber's volume, when neither the catalogue nor the
closure's mass flow closes the gap.

The open-form closure adds mass to the chamber at a rate; a chamber that holds more gas
at a pressure than its fixed volume does (an accumulator above its precharge, a yielding
bladder or hose, a swelling muscle) it can only imitate with short relaxations of the
pressure. This stage searches the training windows' residual for hinges of the chamber's
volume in its pressure (:class:`~pneubayes.discovery.openform.volume.VolumeSearch`) and
adds the kept ones as one :class:`~pneubayes.effects.volume_closure.VolumeClosure`,
fitted, pruned and weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm`
does.
"""

from __future__ import annotations

from typing import ClassVar

from pneubayes.discovery.openform.volume import VolumeProblem, VolumeSearch, searched_values
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.effects.volume_closure import VolumeClosure

#: The component's name in a model and in the ledger.
VOLUME = "volume_closure"


class VolumeComponentForm(ComponentForm):
    """Base of the stages whose search simulates the training windows with a component
    on the chamber's volume (a :class:`~pneubayes.discovery.openform.volume.VolumeProblem`
    of ``problem_class``, whose ``term_names`` are the component's parameter names per
    term, the strength first)."""

    problem_class: ClassVar[type] = VolumeProblem

    def _search_data(self, state, runner) -> VolumeProblem:
        return self.problem_class(runner.data.train_ws, state.current.model,
                                  state.current.params, runner.settings.fit.refine_solver)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return tuple(name(k) for name in self.problem_class.term_names)

    def _searched_values(self, terms, params) -> dict[str, float]:
        return searched_values(terms, params, self.problem_class.term_names)


class VolumeForm(VolumeComponentForm):
    """Search the training windows' residual for hinges of the chamber's volume in its
    pressure and add them as a volume closure (when it runs: :class:`ComponentForm`).
    Beside what the simulator cannot step with a compliant chamber (heat transfer, the
    tube's acoustic line, a tank, a second compartment, a compliant rig card) it logs
    itself not possible; beside the transmission-line tube it runs.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor (0: never then).
    search : VolumeSearch or None
        The residual search (its settings); None: ``VolumeSearch()``.
    """

    name = "volume_form"
    component = VOLUME
    label = "volume form"
    term_word = "hinge of the chamber's volume"
    excludes = ("volume_play",)  # (both lay the chamber's volume table)
    search_class = VolumeSearch

    def _component(self, terms: int):
        return VolumeClosure(terms=terms)
