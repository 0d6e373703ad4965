"""Stage: an open-form term at the chamber's port, a restriction in series with the
valve, when the catalogue does not close the gap.

A fitting, a speed controller's needle or a one-way flow control between the valve and
the chamber slows the fill or the vent (or one of them only) where it is narrower than
the valve's port, and the valve's ports see the pressure between the two. The
catalogue's effects and the closure's terms can only bend the valve's maps or cap a
port's area. This stage searches the training windows' residual for a restriction
(:class:`~pneubayes.discovery.openform.port_restriction.PortRestrictionSearch`) and adds
it as one :class:`~pneubayes.effects.port_restriction.PortRestriction`, fitted and
weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm` does; where
the search keeps none (a base fit that narrowed the valve's maps and grew the dead
volume to the restriction leaves no residual a restriction on top explains), it fits one
from a generic start, as wide as the valve's largest port. It runs before the volume's
forms and challenges a passing trial unless that closes 90 % of the gap
(``compete_below_gap_closed``).
"""

from __future__ import annotations

from pneubayes.discovery.openform.port_restriction import (
    PortRestrictionProblem,
    PortRestrictionSearch,
    RestrictionTerm,
)
from pneubayes.discovery.stages.volume_form import VolumeComponentForm
from pneubayes.effects.port_restriction import INVERSE_AREA_BOUNDS_PER_M2, PortRestriction

#: The component's name in a model and in the ledger.
PORT_RESTRICTION = "port_restriction"


class PortRestrictionForm(VolumeComponentForm):
    """Search the training windows' residual for a restriction at the chamber's port and
    add it (when it runs: :class:`~pneubayes.discovery.stages.component_form.ComponentForm`).
    Beside the tube's acoustic or transmission line, a supply tank or a second
    compartment it logs itself not possible.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor.
    search : PortRestrictionSearch or None
        The residual search (its settings); None: ``PortRestrictionSearch()``.
    """

    name = "port_restriction_form"
    component = PORT_RESTRICTION
    label = "port restriction form"
    term_word = "port restriction"
    search_class = PortRestrictionSearch
    problem_class = PortRestrictionProblem

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.9,
                 search=None):
        super().__init__(min_noise_ratio, compete_below_gap_closed, search)

    def _strength_names(self, k: int) -> tuple[str, ...]:
        """Both inverse areas (0 and 0: no restriction)."""
        return self._term_names(k)

    def _component(self, terms: int):
        return PortRestriction(terms=terms)

    def _fallback_terms(self, search) -> list:
        """A restriction as wide as the valve's largest port in both directions: a base
        fit without it bends the maps and grows the dead volume towards a restriction it
        cannot express, where no restriction on top predicts better; the fit through the
        simulator moves them back (the held-out test still decides)."""
        a_max = search.port_area_m2_
        if not a_max > 0.0:
            return []
        k = float(min(1.0 / a_max, INVERSE_AREA_BOUNDS_PER_M2[1]))
        return [RestrictionTerm(k, k, 0.0, 0.0, 0.0)]
