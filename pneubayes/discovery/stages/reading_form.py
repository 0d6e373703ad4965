"""Stage: an open-form term at the reading, when neither the catalogue nor the closure's
mass flow closes the gap.

The open-form closure (:mod:`~pneubayes.discovery.stages.open_form`) can only add mass
to the chamber. What acts on the sensor alone (a diaphragm that warms with the gas, a
transducer's creep, a cavity in front of the gauge) it cannot express. This stage
searches the training windows' residual for relaxations of the reading
(:class:`~pneubayes.discovery.openform.reading.ReadingSearch`), adds the kept ones as
one :class:`~pneubayes.effects.reading_closure.ReadingClosure`, refits it through the
simulator from the search's values and from zero strength (the trial contains the
current model: a fit that ends worse failed), and weighs it on the held-out windows
with the test a named effect and the closure pass
(:func:`~pneubayes.discovery.stages.weighing.weigh`).
"""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.openform.reading import (
    ReadingSearch,
    ReadingWindows,
    reading_windows,
)
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.stages.weighing import competes, weigh
from pneubayes.discovery.state import RoundState
from pneubayes.discovery.trials import NESTED_TOLERANCE
from pneubayes.effects.reading_closure import (
    ReadingClosure,
    gain_name,
    time_constant_name,
)
from pneubayes.errors import SimulationError

#: The component's name in a model and in the ledger.
READING = "reading_closure"


class ReadingForm(Stage):
    """Search the training windows' residual for relaxations of the reading and add them
    as a reading closure.

    Runs when the held-out error is above ``min_noise_ratio`` x the noise floor, the
    model has no reading closure yet, and no trial of the round passed, or the best that
    passed closes under ``compete_below_gap_closed`` of the gap or drives a parameter to
    a bound (it then replaces that one only if it beats it on the held-out windows).

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

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.5,
                 search: ReadingSearch | None = None):
        if min_noise_ratio < 1.0:
            raise ValueError(f"ReadingForm: min_noise_ratio must be >= 1, got "
                             f"{min_noise_ratio}")
        if not 0.0 <= compete_below_gap_closed <= 1.0:
            raise ValueError("ReadingForm: compete_below_gap_closed must be in [0, 1], got "
                             f"{compete_below_gap_closed}")
        self.min_noise_ratio = min_noise_ratio
        self.compete_below_gap_closed = compete_below_gap_closed
        self.search = search

    def options(self):
        s = self.search
        return {"min_noise_ratio": self.min_noise_ratio,
                "compete_below_gap_closed": self.compete_below_gap_closed,
                "search": None if s is None else {
                    "time_constants_s": [float(v) for v in s.time_constants_s],
                    "max_terms": s.max_terms,
                    "min_explained_fraction": s.min_explained_fraction, "min_t": s.min_t}}

    def _applies(self, state: RoundState, noise: float):
        """``(runs, the best passing trial or None)``."""
        current = state.current
        if current.heldout_rmse_Pa <= self.min_noise_ratio * noise \
                or current.model.has(READING):
            return False, None
        return competes(state, noise, self.compete_below_gap_closed)

    def run(self, state: RoundState, runner) -> None:
        runs, best = self._applies(state, runner.data.noise_Pa)
        if not runs:
            return
        try:
            self._run(state, runner, best)
        except (ValueError, FloatingPointError, SimulationError,
                np.linalg.LinAlgError) as exc:
            why = f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
            runner.log(f"discover: reading form: not possible beside this model ({why})")
            runner.ledger.record("reading form failed", round=state.number, error=why)

    def _residual(self, state: RoundState, runner) -> list[ReadingWindows]:
        """The training windows as the current model predicts them
        (:func:`~pneubayes.discovery.openform.reading.reading_windows`)."""
        return reading_windows(runner.data.train_ws, state.current.model,
                               state.current.params, runner.settings.fit.refine_solver)

    def _run(self, state: RoundState, runner, best) -> None:
        search = self.search if self.search is not None else ReadingSearch()
        search = type(search)(time_constants_s=search.time_constants_s,
                              max_terms=search.max_terms,
                              min_explained_fraction=search.min_explained_fraction,
                              min_t=search.min_t).fit(self._residual(state, runner))
        terms = search.terms_
        runner.ledger.record("reading form search", round=state.number,
                             terms=[_term_record(t) for t in terms],
                             best={} if search.best_ is None else _term_record(search.best_),
                             explained_fraction=search.explained_fraction_)
        if not terms:
            b = search.best_
            runner.log("discover: reading form: no relaxation of the reading is supported"
                       + ("" if b is None else f" (the best, tau = {b.time_constant_s:.3g} "
                          f"s, explains {b.explained:.1%} at t = {b.t:.1f})"))
            return
        runner.log("discover: reading form: the search proposes "
                   + ", ".join(f"{t} ({t.explained:.0%} of the residual)" for t in terms))
        fit = self._fit(state, runner, terms)
        if fit is not None:
            self._verify(self._prune(fit, state, runner), state, runner, best, search)

    def _prune(self, fit, state: RoundState, runner):
        """With two relaxations, each alone, refitted from its fitted values: the better
        one that the held-out test cannot tell apart from the pair, and that still beats
        the current model, replaces the pair (the search's second term may be what its
        linearisation left of the first)."""
        if fit.model.effect(READING).terms < 2 or not runner.better(fit, state.current)[0]:
            return fit
        model = fit.model.without(READING).with_effect(ReadingClosure(terms=1))
        alone = []
        for k in range(2):
            start = {n: fit.params[n] for n in model.parameter_names if n in fit.params}
            start[gain_name(0)] = fit.params[gain_name(k)]
            start[time_constant_name(0)] = fit.params[time_constant_name(k)]
            try:
                alone.append(runner.fit(model, start))
            except (FloatingPointError, SimulationError):
                continue
        kept = [a for a in alone if not runner.better(fit, a)[0]
                and runner.better(a, state.current)[0]]
        if not kept:
            return fit
        one = min(kept, key=lambda a: a.heldout_rmse_Pa)
        runner.log(f"discover: reading form: one relaxation is enough (held-out "
                   f"{fit.heldout_rmse_Pa:.0f} -> {one.heldout_rmse_Pa:.0f} Pa without the "
                   "other)")
        runner.ledger.record("reading form prune", heldout_rmse_before_Pa=fit.heldout_rmse_Pa,
                             heldout_rmse_after_Pa=one.heldout_rmse_Pa)
        return one

    def _fit(self, state: RoundState, runner, terms):
        """The current model with the reading closure, refitted from the search's values
        and from zero gains; the lower training RMSE kept (None: both failed, or the fit
        ended worse than the model it contains)."""
        current = state.current
        model = current.model.with_effect(ReadingClosure(terms=len(terms)))
        searched = dict(current.params)
        for k, t in enumerate(terms):
            searched[gain_name(k)] = float(np.clip(t.gain, *_bounds(model, gain_name(k))))
            searched[time_constant_name(k)] = float(np.clip(
                t.time_constant_s, *_bounds(model, time_constant_name(k))))
        zero = {**searched, **{gain_name(k): 0.0 for k in range(len(terms))}}
        fits = []
        for label, start in (("the search's values", searched), ("zero strength", zero)):
            try:
                fits.append(runner.fit(model, {k: start[k] for k in model.parameter_names}))
            except (FloatingPointError, SimulationError) as exc:
                runner.log(f"discover: reading form from {label}: {type(exc).__name__}: "
                           f"{str(exc).splitlines()[0]}")
        if not fits:
            runner.ledger.record("reading form failed", round=state.number,
                                 error="every start's fit failed")
            return None
        fit = min(fits, key=lambda f: f.train_rmse_Pa)
        runner.log(f"discover: reading form: {len(terms)} relaxation(s) fitted, training "
                   f"RMSE {current.train_rmse_Pa:.0f} -> {fit.train_rmse_Pa:.0f} Pa, held-out "
                   f"{current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa")
        if fit.train_rmse_Pa > current.train_rmse_Pa * (1.0 + NESTED_TOLERANCE):
            runner.ledger.record("reading form failed", round=state.number,
                                 error=f"training RMSE {fit.train_rmse_Pa:.0f} Pa above the "
                                       f"current model's {current.train_rmse_Pa:.0f} Pa")
            return None
        return fit

    def _verify(self, fit, state: RoundState, runner, best, search) -> bool:
        """Weigh the fit; on a pass it becomes the round's only passing trial."""
        w = weigh(fit, state, runner, best, READING)
        n = fit.model.effect(READING).terms
        relax = [{"gain": fit.params[gain_name(k)],
                  "time_constant_s": fit.params[time_constant_name(k)]} for k in range(n)]
        runner.ledger.record("reading form pass" if w.passed else "reading form reject",
                             effect=READING, relaxations=relax,
                             **w.record(fit, state.current, best))
        why = w.reasons(best)
        runner.log(f"discover: {'passes' if w.passed else 'reject'} reading form: held-out "
                   f"RMSE {state.current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} "
                   f"Pa, better in {int(np.sum(w.window_gains > 0))}/"
                   f"{w.window_gains.size} windows (p = {w.p_value:.2g})"
                   + ("" if w.passed or not why else "; " + "; ".join(why)))
        if not w.passed:
            return False
        state.evidence[READING] = {
            "inclusion_probability": None,
            "t_max": float(max(abs(t.t) for t in search.terms_)),
            "best_term": "; ".join(str(t) for t in search.terms_), "best_term_start": None}
        state.passing = [(fit.heldout_rmse_Pa, READING, fit, w.gain, w.p_value)]
        return True


def _bounds(model, name: str) -> tuple[float, float]:
    p = model.parameter(name)
    return p.lower, p.upper


def _term_record(t) -> dict:
    """A searched relaxation for the ledger."""
    return {"gain": t.gain, "time_constant_s": t.time_constant_s,
            "explained_fraction": t.explained, "t": t.t}
