"""The shared part of the stages that add one open-form component with a few parametric
terms (the reading's relaxations, the volume's hinges): when they run, how the
component is fitted, pruned and weighed.

A subclass searches the training windows' residual for its terms (:meth:`_search`) and
says how its component is built (:meth:`_component`) and which parameters term ``k``
has (:meth:`_term_names`, its strength first: 0 switches the term off). This base fits
the component through the simulator from the search's values and from zero strength (a
trial contains the current model: a fit that ends worse failed), reduces two terms to
one where the held-out test cannot tell them apart, and weighs the result with the test
every trial passes (:func:`~pneubayes.discovery.stages.weighing.weigh`).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import asdict
from typing import ClassVar

import numpy as np

from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.stages.weighing import competes, weigh
from pneubayes.discovery.state import RoundState
from pneubayes.discovery.trials import NESTED_TOLERANCE
from pneubayes.errors import FIT_FAILURES, SimulationError


class ComponentForm(Stage):
    """Base of a stage that adds one open-form component of 1..2 terms.

    Runs when the held-out error is above ``min_noise_ratio`` x the noise floor, the
    model has no such component yet (nor one it ``excludes``), and no trial of the round
    passed, or the best that passed closes under ``compete_below_gap_closed`` of the gap,
    drives a parameter to a bound or is one of its ``rivals`` (it then replaces that one
    only if it beats it on the held-out windows).
    """

    #: The component's name in a model and in the ledger.
    component: ClassVar[str]
    #: The ledger's and the log's word for the stage ("reading form") and for one term.
    label: ClassVar[str]
    term_word: ClassVar[str]
    #: The residual search a stage without its own ``search`` uses (default settings).
    search_class: ClassVar[type]
    #: Components the stage's cannot join (the stage does not run beside them).
    excludes: ClassVar[tuple[str, ...]] = ()
    #: Catalogue effects that express the same kind of term (a curvature of the reading
    #: beside its knees): when the round's best passing trial is one, the stage runs
    #: however much of the gap it closes, and replaces it only by beating it.
    rivals: ClassVar[tuple[str, ...]] = ()

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.5,
                 search=None):
        cls = type(self).__name__
        if min_noise_ratio < 1.0:
            raise ValueError(f"{cls}: min_noise_ratio must be >= 1, got {min_noise_ratio}")
        if not 0.0 <= compete_below_gap_closed <= 1.0:
            raise ValueError(f"{cls}: compete_below_gap_closed must be in [0, 1], got "
                             f"{compete_below_gap_closed}")
        self.min_noise_ratio = min_noise_ratio
        self.compete_below_gap_closed = compete_below_gap_closed
        self.search = search

    def options(self):
        s = self.search
        return {"min_noise_ratio": self.min_noise_ratio,
                "compete_below_gap_closed": self.compete_below_gap_closed,
                "search": None if s is None else {
                    k: [float(x) for x in v] if isinstance(v, (list, tuple, np.ndarray)) else v
                    for k, v in s.get_params().items()}}

    # ------------------------------------------------------------------ the subclass's
    @abstractmethod
    def _search_data(self, state: RoundState, runner):
        """What the search fits: the current model's training windows, as it reads them."""

    @abstractmethod
    def _component(self, terms: int):
        """The component with ``terms`` terms."""

    @abstractmethod
    def _term_names(self, k: int) -> tuple[str, ...]:
        """Term ``k``'s parameter names, its strength first."""

    def _component_for(self, terms):
        """The component for the search's kept ``terms`` (by default: with as many)."""
        return self._component(len(terms))

    def _one_term(self, component, k: int):
        """The component with term ``k`` of ``component`` alone, as its term 0 (by
        default: one term; its values are laid over from term ``k``'s)."""
        return self._component(1)

    def _fallback_terms(self, search) -> list:
        """Terms to fit when the search keeps none (by default none: the stage ends)."""
        return []

    def _search_record(self, search) -> dict:
        """What else of the fitted ``search`` the ledger records (by default nothing)."""
        return {}

    def _strength_names(self, k: int) -> tuple[str, ...]:
        """Term ``k``'s strengths (all 0 switches it off): its first name."""
        return self._term_names(k)[:1]

    @abstractmethod
    def _searched_values(self, terms, params) -> dict[str, float]:
        """The parameter values the search's kept ``terms`` stand for beside the current
        ``params`` (the component's, and any of the model's the search moved)."""

    # ------------------------------------------------------------------ shared
    def _applies(self, state: RoundState, noise: float):
        """``(runs, the best passing trial or None)``."""
        current = state.current
        if current.heldout_rmse_Pa <= self.min_noise_ratio * noise \
                or any(current.model.has(c) for c in (self.component, *self.excludes)):
            return False, None
        runs, best = competes(state, noise, self.compete_below_gap_closed)
        return runs or (best is not None and best[1] in self.rivals), best

    def run(self, state: RoundState, runner) -> None:
        runs, best = self._applies(state, runner.data.noise_Pa)
        if not runs:
            return
        try:
            self._run(state, runner, best)
        except (ValueError, FloatingPointError, SimulationError,
                np.linalg.LinAlgError) as exc:
            # a model the component cannot join (a state the simulator does not carry
            # beside it): the loop goes on without it, and says so
            why = f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
            runner.log(f"discover: {self.label}: not possible beside this model ({why})")
            runner.ledger.record(f"{self.label} failed", round=state.number, error=why)

    def _run(self, state: RoundState, runner, best) -> None:
        self._run_search(self._fitted_search(state, runner), state, runner, best)

    def _fitted_search(self, state: RoundState, runner):
        """A fresh copy of the stage's search (its settings), fitted on the training
        windows as :meth:`_search_data` gives them."""
        s = self.search if self.search is not None else self.search_class()
        return type(s)(**s.get_params()).fit(self._search_data(state, runner))

    def _run_search(self, search, state: RoundState, runner, best) -> None:
        """Record the fitted ``search``, then fit, prune and weigh its terms (or its
        fallback terms)."""
        terms = search.terms_
        runner.ledger.record(f"{self.label} search", round=state.number,
                             terms=[_term_record(t) for t in terms],
                             best={} if search.best_ is None else _term_record(search.best_),
                             explained_fraction=search.explained_fraction_,
                             **self._search_record(search))
        if not terms:
            b = search.best_
            terms = self._fallback_terms(search)
            runner.log(f"discover: {self.label}: no {self.term_word} is supported"
                       + ("" if b is None else f" (the best, {b}, explains "
                          f"{b.explained:.1%} at t = {b.t:.1f})")
                       + ("" if not terms else "; fitting " + ", ".join(map(str, terms))
                          + " from the search's generic start"))
            if not terms:
                return
        else:
            runner.log(f"discover: {self.label}: the search proposes "
                       + ", ".join(f"{t} ({t.explained:.0%} of the residual)"
                                   for t in terms))
        fit = self._fit(state, runner, terms)
        if fit is not None:
            self._verify(self._prune(fit, state, runner), state, runner, best, terms)

    def _fit(self, state: RoundState, runner, terms):
        """The current model with the component, refitted from the search's values and
        from zero strength; the lower training RMSE kept (None: both failed, or the fit
        ended worse than the model it contains)."""
        current = state.current
        model = current.model.with_effect(self._component_for(terms))
        searched = clipped_start(model, current.params,
                                 self._searched_values(terms, current.params))
        # the current fit itself beside the component at zero strength (the nested start)
        zero = {**searched, **current.params,
                **{n: 0.0 for k in range(len(terms)) for n in self._strength_names(k)}}
        fits = []
        for label, start in (("the search's values", searched), ("zero strength", zero)):
            try:
                fits.append(runner.fit(model, {k: start[k] for k in model.parameter_names}))
            except FIT_FAILURES as exc:
                runner.log(f"discover: {self.label} from {label}: {type(exc).__name__}: "
                           f"{str(exc).splitlines()[0]}")
        if not fits:
            runner.ledger.record(f"{self.label} failed", round=state.number,
                                 error="every start's fit failed")
            return None
        fit = min(fits, key=lambda f: f.train_rmse_Pa)
        runner.log(f"discover: {self.label}: {len(terms)} {self.term_word}(s) fitted, "
                   f"training RMSE {current.train_rmse_Pa:.0f} -> {fit.train_rmse_Pa:.0f} "
                   f"Pa, held-out {current.heldout_rmse_Pa:.0f} -> "
                   f"{fit.heldout_rmse_Pa:.0f} Pa")
        if fit.train_rmse_Pa > current.train_rmse_Pa * (1.0 + NESTED_TOLERANCE):
            runner.ledger.record(f"{self.label} failed", round=state.number,
                                 error=f"training RMSE {fit.train_rmse_Pa:.0f} Pa above the "
                                       f"current model's {current.train_rmse_Pa:.0f} Pa")
            return None
        return fit

    def _prune(self, fit, state: RoundState, runner):
        """With two terms, each alone, refitted from its fitted values: the better one
        that the held-out test cannot tell apart from the pair, and that still beats the
        current model, replaces the pair (the search's second term may be what its
        linearisation left of the first)."""
        if _terms(fit.model.effect(self.component)) < 2 \
                or not runner.better(fit, state.current)[0]:
            return fit
        alone = []
        for k in range(2):
            model = fit.model.without(self.component).with_effect(
                self._one_term(fit.model.effect(self.component), k))
            start = {n: fit.params[n] for n in model.parameter_names if n in fit.params}
            for mine, theirs in zip(self._term_names(0), self._term_names(k)):
                start[mine] = fit.params[theirs]
            try:
                alone.append(runner.fit(model, start))
            except FIT_FAILURES:
                continue
        kept = [a for a in alone if not runner.better(fit, a)[0]
                and runner.better(a, state.current)[0]]
        if not kept:
            return fit
        one = min(kept, key=lambda a: a.heldout_rmse_Pa)
        runner.log(f"discover: {self.label}: one {self.term_word} is enough (held-out "
                   f"{fit.heldout_rmse_Pa:.0f} -> {one.heldout_rmse_Pa:.0f} Pa without the "
                   "other)")
        runner.ledger.record(f"{self.label} prune", heldout_rmse_before_Pa=fit.heldout_rmse_Pa,
                             heldout_rmse_after_Pa=one.heldout_rmse_Pa)
        return one

    def _verify(self, fit, state: RoundState, runner, best, terms) -> bool:
        """Weigh the fit; on a pass it becomes the round's only passing trial."""
        w = weigh(fit, state, runner, best, self.component)
        n = _terms(fit.model.effect(self.component))
        fitted = [{name: fit.params[name] for name in self._term_names(k)} for k in range(n)]
        runner.ledger.record(f"{self.label} pass" if w.passed else f"{self.label} reject",
                             effect=self.component, fitted_terms=fitted,
                             **w.record(fit, state.current, best))
        why = w.reasons(best)
        runner.log(f"discover: {'passes' if w.passed else 'reject'} {self.label}: held-out "
                   f"RMSE {state.current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} "
                   f"Pa, better in {int(np.sum(w.window_gains > 0))}/"
                   f"{w.window_gains.size} windows (p = {w.p_value:.2g})"
                   + ("" if w.passed or not why else "; " + "; ".join(why)))
        if not w.passed:
            return False
        state.evidence[self.component] = {
            "inclusion_probability": None,
            "t_max": float(max(abs(t.t) for t in terms)),
            "best_term": "; ".join(str(t) for t in terms), "best_term_start": None}
        state.passing = [(fit.heldout_rmse_Pa, self.component, fit, w.gain, w.p_value)]
        return True


def clipped_start(model, params: dict, values: dict) -> dict:
    """``params`` with ``values`` laid over them, each clipped into ``model``'s bounds
    (a search's values where a refinement of ``model`` starts)."""
    start = dict(params)
    for name, v in values.items():
        p = model.parameter(name)
        start[name] = float(np.clip(v, p.lower, p.upper))
    return start


def _terms(component) -> int:
    """How many terms a component carries (one without a ``terms`` option)."""
    return getattr(component, "terms", 1)


def _term_record(t) -> dict:
    """A searched term (a dataclass with ``explained``) for the ledger."""
    return {("explained_fraction" if k == "explained" else k): v for k, v in asdict(t).items()}
