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
from a generic start, as wide as the valve's largest port. A fitted restriction
without a check valve has the search's cracks tried on it as a second start. It runs
before the volume's forms and challenges a passing trial unless that closes 90 % of the gap
(``compete_below_gap_closed``).
"""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.openform.port_restriction import (
    PortRestrictionProblem,
    PortRestrictionSearch,
    RestrictionTerm,
    with_check_valve,
)
from pneubayes.discovery.stages.volume_form import VolumeComponentForm
from pneubayes.effects.port_restriction import (
    CRACK,
    FILL,
    INVERSE_AREA_BOUNDS_PER_M2,
    VENT,
    PortRestriction,
)
from pneubayes.errors import FIT_FAILURES

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

    def _fit(self, state, runner, terms):
        """:meth:`ComponentForm._fit`; then, where the fitted restriction's directions
        differ and it has no check valve, the search's cracks tried on it over the
        training windows (:func:`with_check_valve`) and the best refitted, kept where its
        training RMSE is lower (a second start: from no crack the fit sees the crack only
        over its first difference step, the area's slope in it being zero there)."""
        fit = super()._fit(state, runner, terms)
        if fit is None:
            return None
        p = fit.params
        s = self.search if self.search is not None else self.search_class()
        cracks = np.asarray(s.crack_shares, dtype=np.float64)
        if p[CRACK] > 0.0 or p[FILL] == p[VENT] or not cracks.size:
            return fit
        base = {k: v for k, v in p.items() if k not in (FILL, VENT, CRACK)}
        problem = PortRestrictionProblem(runner.data.train_ws, state.current.model, base,
                                         runner.settings.fit.refine_solver)
        centre = ((p[FILL], p[VENT], 0.0), 1.0)
        shares = np.asarray(s.area_shares, dtype=np.float64)
        step = float(shares[1] / shares[0]) if shares.size > 1 else 2.0
        cracked, sse = with_check_valve(problem, centre, cracks, step)
        if cracked is None or np.sum(sse) >= np.sum(problem.window_sse([[centre[0]]])[0]):
            return fit
        start = {**p, FILL: cracked[0][0], VENT: cracked[0][1], CRACK: cracked[0][2]}
        try:
            again = runner.fit(fit.model, start)
        except FIT_FAILURES as exc:
            runner.log(f"discover: {self.label} with a check valve: {type(exc).__name__}: "
                       f"{str(exc).splitlines()[0]}")
            return fit
        runner.log(f"discover: {self.label} with a check valve cracking at "
                   f"{again.params[CRACK]:.3g} Pa: training RMSE {fit.train_rmse_Pa:.0f} -> "
                   f"{again.train_rmse_Pa:.0f} Pa, held-out {fit.heldout_rmse_Pa:.0f} -> "
                   f"{again.heldout_rmse_Pa:.0f} Pa")
        return again if again.train_rmse_Pa < fit.train_rmse_Pa else fit
