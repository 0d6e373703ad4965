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

from pneubayes.discovery.openform.volume import VolumeProblem, VolumeSearch, searched_values
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.effects.volume_closure import VolumeClosure, compliance_name, threshold_name

#: The component's name in a model and in the ledger.
VOLUME = "volume_closure"


class VolumeForm(ComponentForm):
    """Search the training windows' residual for hinges of the chamber's volume in its
    pressure and add them as a volume closure (when it runs: :class:`ComponentForm`).
    Beside what the simulator cannot step with a compliant chamber (heat transfer, the
    tube's line, a tank, a second compartment, a compliant rig card) it logs itself not
    possible.

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

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.5,
                 search: VolumeSearch | None = None):
        super().__init__(min_noise_ratio, compete_below_gap_closed)
        self.search = search

    def options(self):
        s = self.search
        return {"min_noise_ratio": self.min_noise_ratio,
                "compete_below_gap_closed": self.compete_below_gap_closed,
                "search": None if s is None else {
                    "thresholds": s.thresholds,
                    "compliance_shares": [float(v) for v in s.compliance_shares],
                    "dead_volume_scales": [float(v) for v in s.dead_volume_scales],
                    "max_terms": s.max_terms, "min_explained_fraction": s.min_explained_fraction,
                    "min_t": s.min_t}}

    def _search(self, state, runner):
        s = self.search if self.search is not None else VolumeSearch()
        problem = VolumeProblem(runner.data.train_ws, state.current.model, state.current.params,
                                runner.settings.fit.refine_solver)
        return type(s)(thresholds=s.thresholds, compliance_shares=s.compliance_shares,
                       dead_volume_scales=s.dead_volume_scales, max_terms=s.max_terms,
                       min_explained_fraction=s.min_explained_fraction,
                       min_t=s.min_t).fit(problem)

    def _component(self, terms: int):
        return VolumeClosure(terms=terms)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return compliance_name(k), threshold_name(k)

    def _searched_values(self, terms, params) -> dict[str, float]:
        return searched_values(terms, params)

    def _term_record(self, t) -> dict:
        return {"compliance_m3_per_Pa": t.compliance_m3_per_Pa, "threshold_Pa": t.threshold_Pa,
                "dead_volume_scale": t.dead_volume_scale, "explained_fraction": t.explained,
                "t": t.t}
