"""Stage: an open-form term on the chamber's volume with memory, friction-held walls,
when neither the catalogue nor the volume's hinges close the gap.

A wall held by friction (a braided sleeve, a rolling diaphragm, a clamped hose) gives
only once the pressure has moved past its friction band: its volume over the pressure is
a loop, which the volume's hinges (a function of the pressure) can only average; a give
that saturates while held (a stop) is the same loop turned the other way. This stage
searches the training windows' residual for plays and stops of the chamber's volume
(:class:`~pneubayes.discovery.openform.volume_play.VolumePlaySearch`) and adds the kept
ones as one :class:`~pneubayes.effects.volume_play.VolumePlay`, fitted, pruned and
weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm` does. It
runs after the hinges' stage and challenges a passing trial unless that closes 90 % of
the gap (``compete_below_gap_closed`` 0.9 by default, where the other open forms take
0.5): a hinge that averages a loop, or a catalogue effect that stands in for it, is
replaced where the wall predicts the held-out windows better.
"""

from __future__ import annotations

from pneubayes.discovery.openform.volume_play import VolumePlayProblem, VolumePlaySearch
from pneubayes.discovery.stages.volume_form import VolumeComponentForm
from pneubayes.effects.volume_play import VolumePlay, compliance_name, held_compliance_name

#: The component's name in a model and in the ledger.
VOLUME_PLAY = "volume_play"


class VolumePlayForm(VolumeComponentForm):
    """Search the training windows' residual for friction-held walls of the chamber and
    add them as a volume play (when it runs:
    :class:`~pneubayes.discovery.stages.component_form.ComponentForm`). Beside what the
    simulator cannot step with a compliant chamber (heat transfer, the tube's acoustic
    line, a tank, a second compartment, a compliant rig card, a volume closure) it logs
    itself not possible; beside the transmission-line tube it runs.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor.
    search : VolumePlaySearch or None
        The residual search (its settings); None: ``VolumePlaySearch()``.
    """

    name = "volume_play_form"
    component = VOLUME_PLAY
    label = "volume play form"
    term_word = "friction-held wall"
    excludes = ("volume_closure",)  # (both lay the chamber's volume table)
    search_class = VolumePlaySearch
    problem_class = VolumePlayProblem

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.9,
                 search=None):
        super().__init__(min_noise_ratio, compete_below_gap_closed, search)

    def _component(self, terms: int):
        return VolumePlay(terms=terms)

    def _strength_names(self, k: int) -> tuple[str, ...]:
        return compliance_name(k), held_compliance_name(k)
