"""Stage: an open-form term on the chamber's volume with inertia, a wall that carries a
load, when neither the catalogue nor the volume's static and hysteretic forms close the
gap.

A flexible wall with a payload (a soft finger's skin, a bellows on a sprung mass, a
muscle pulling a limb through a tendon) gives as a mass on a spring: the volume lags the
pressure and rings. The volume's hinges (a function of the pressure), its plays (a
rate-independent loop) and the closure's first-order relaxations can only average that.
This stage searches the training windows' residual for a loaded wall
(:class:`~pneubayes.discovery.openform.loaded_wall.LoadedWallSearch`) and adds it as one
:class:`~pneubayes.effects.loaded_wall.LoadedWall`, fitted and weighed as
:class:`~pneubayes.discovery.stages.component_form.ComponentForm` does. It runs after the
volume's plays and challenges a passing trial unless that closes 90 % of the gap
(``compete_below_gap_closed``): a relaxation or a catalogue effect that stands in for a
ring is replaced where the wall predicts the held-out windows better.
"""

from __future__ import annotations

from pneubayes.discovery.openform.loaded_wall import LoadedWallProblem, LoadedWallSearch
from pneubayes.discovery.stages.volume_form import VolumeComponentForm
from pneubayes.effects.loaded_wall import LoadedWall

#: The component's name in a model and in the ledger.
LOADED_WALL = "loaded_wall"


class LoadedWallForm(VolumeComponentForm):
    """Search the training windows' residual for a loaded wall of the chamber and add it
    (when it runs: :class:`~pneubayes.discovery.stages.component_form.ComponentForm`).
    Beside what the simulator cannot step with a
    moving wall (a compliant chamber or rig card, a volume closure or play, the tube's
    acoustic line, a tank, a second compartment) it logs itself not possible; beside the
    transmission-line tube and heat transfer it runs.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor.
    search : LoadedWallSearch or None
        The residual search (its settings); None: ``LoadedWallSearch()``.
    """

    name = "loaded_wall_form"
    component = LOADED_WALL
    label = "loaded wall form"
    term_word = "loaded wall"
    excludes = ("volume_closure", "volume_play")  # (a moving wall on a rigid chamber)
    search_class = LoadedWallSearch
    problem_class = LoadedWallProblem

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.9,
                 search=None):
        super().__init__(min_noise_ratio, compete_below_gap_closed, search)

    def _component(self, terms: int):
        return LoadedWall(terms=terms)
