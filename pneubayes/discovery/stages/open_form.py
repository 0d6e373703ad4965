"""Stage: an open-form closure term, when no catalogue effect closes the gap.

The second resort after the named catalogue (:mod:`pneubayes.discovery.openform`): the
current model's one-step residual, as the mass flow into the chamber it lacks, is
regressed on physically typed features of the model's own signal path; the terms the
search keeps enter the model as one :class:`~pneubayes.effects.closure.Closure`
component, are refitted through the simulator on the training trajectories, pruned term
by term, and verified on the held-out windows with the test a named effect passes.
Where the one-step searches keep nothing that passes, the same search runs on the
training windows' residual, each candidate entering as its first-order effect on the
predicted pressure (:mod:`~pneubayes.discovery.openform.trajectory`).
"""

from __future__ import annotations

import inspect

import numpy as np

from pneubayes.discovery.openform.closure_model import (
    CLOSURE,
    beside_closure,
    closure_model,
    existing_terms,
    families_at_bounds,
    newly_at_bounds,
    reach,
    without_term,
)
from pneubayes.discovery.openform.linear_hinge import ValuedTerm, linear_terms
from pneubayes.discovery.openform.residual import one_step_residual, window_residual
from pneubayes.discovery.openform.search import OpenFormSearch
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.stages.weighing import competes, weigh
from pneubayes.discovery.state import RoundState
from pneubayes.discovery.trials import NESTED_TOLERANCE
from pneubayes.effects.closure import Closure
from pneubayes.effects.closure_features import PORT_FEATURES
from pneubayes.effects.closure_terms import CLOSURE_MAX_TERMS
from pneubayes.effects.discovery import inside_bounds
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.errors import FIT_FAILURES, SimulationError

#: The search source whose rows are the prediction windows' residual.
WINDOWS = "windows"


def _at_bounds(trial, current) -> list[str]:
    """The parameters a passing trial ``(held-out RMSE, group, fit, ...)`` drove to a
    bound (none without its fit)."""
    fit = trial[2]
    return [] if fit is None else newly_at_bounds(fit, current)


class OpenForm(Stage):
    """Search the residual for open-form terms and add them as a closure.

    Runs when the held-out error is above ``min_noise_ratio`` x the noise floor and no
    catalogue trial of the round passed, or the best that passed closes under
    ``compete_below_gap_closed`` of the gap or drives a parameter to a bound: a possible
    stand-in, which the closure replaces only if it beats it on the held-out windows.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing catalogue trial, the stage runs only if the best closes less than
        this share of the held-out gap above the noise floor (0: never then).
    search : OpenFormSearch or None
        The residual search (its settings); None: ``OpenFormSearch()`` with the loop's
        seed and block.
    prune : bool
        Drop each term whose removal the held-out test cannot tell apart.
    coefficient_reach : float
        A term whose searched coefficient times this exceeds the closure's default
        bound gets its bounds widened to +- this x the searched coefficient.
    retries : int
        Searches again, each without the families of the last closure, when that
        closure was rejected with its parameters at a bound (a stand-in); before that,
        a hinge threshold at a bound beyond its signal is written as its line, refitted
        and verified once (:mod:`~pneubayes.discovery.openform.linear_hinge`).
    long_block : int
        Sample intervals per row of a second search when the first (the search's
        block) keeps no term or its closure is rejected; 0 or not above the block: none.
    window_rows : int
        Rows per training window of a last search on the prediction windows' residual
        (:mod:`~pneubayes.discovery.openform.trajectory`), run when the one-step
        searches keep no term or their closures are rejected; 0: none.
    refit_base : bool
        Search beside the current model's own parameter sensitivities
        (:func:`~pneubayes.discovery.openform.signals.parameter_flows`): a fit that has
        bent its valve maps towards the missing effect leaves the effect minus the bend.
    """

    name = "open_form"

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.5,
                 search: OpenFormSearch | None = None, prune: bool = True,
                 coefficient_reach: float = 10.0, retries: int = 1, long_block: int = 25,
                 window_rows: int = 40, refit_base: bool = True):
        if min_noise_ratio < 1.0:
            raise ValueError(f"OpenForm: min_noise_ratio must be >= 1, got {min_noise_ratio}")
        if not 0.0 <= compete_below_gap_closed <= 1.0:
            raise ValueError("OpenForm: compete_below_gap_closed must be in [0, 1], got "
                             f"{compete_below_gap_closed}")
        self.min_noise_ratio = min_noise_ratio
        self.compete_below_gap_closed = compete_below_gap_closed
        self.search = search
        self.prune = prune
        if not coefficient_reach >= 1.0:
            raise ValueError(f"OpenForm: coefficient_reach must be >= 1, got "
                             f"{coefficient_reach}")
        self.coefficient_reach = coefficient_reach
        if not (isinstance(retries, int) and retries >= 0):
            raise ValueError(f"OpenForm: retries must be an integer >= 0, got {retries!r}")
        self.retries = retries
        if not (isinstance(long_block, int) and long_block >= 0):
            raise ValueError(f"OpenForm: long_block must be an integer >= 0, got "
                             f"{long_block!r}")
        self.long_block = long_block
        if not (isinstance(window_rows, int) and window_rows >= 0):
            raise ValueError(f"OpenForm: window_rows must be an integer >= 0, got "
                             f"{window_rows!r}")
        self.window_rows = window_rows
        self.refit_base = bool(refit_base)

    def options(self):
        search = None if self.search is None else _settings_of(self.search)
        return {"min_noise_ratio": self.min_noise_ratio,
                "compete_below_gap_closed": self.compete_below_gap_closed,
                "search": search, "prune": self.prune,
                "coefficient_reach": self.coefficient_reach, "retries": self.retries,
                "long_block": self.long_block, "window_rows": self.window_rows,
                "refit_base": self.refit_base}

    # ------------------------------------------------------------------ when
    def _applies(self, state: RoundState, noise: float):
        """``(runs, the best passing catalogue trial or None)``."""
        current = state.current
        if current.heldout_rmse_Pa <= self.min_noise_ratio * noise:
            return False, None
        if len(existing_terms(current.model)) >= CLOSURE_MAX_TERMS:
            return False, None
        return competes(state, noise, self.compete_below_gap_closed)

    def run(self, state: RoundState, runner) -> None:
        noise = runner.data.noise_Pa
        runs, best = self._applies(state, noise)
        if not runs:
            return
        at = _at_bounds(best, state.current) if best is not None else []
        if at:
            runner.log(f"discover: open form: the round's best catalogue trial ({best[1]}) "
                       f"fits with {', '.join(at)} at a bound: a possible stand-in, the "
                       "open form competes with it")
        try:
            self._run(state, runner, best)
        except (ValueError, FloatingPointError, SimulationError) as exc:
            # a rig this stage cannot express (a state the closure's signals or the
            # simulator do not carry): the loop goes on without it, and says so
            why = f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
            runner.log(f"discover: open form: not possible beside this model ({why})")
            runner.ledger.record("open form failed", round=state.number, error=why)

    def _run(self, state: RoundState, runner, best) -> None:
        search = self.search if self.search is not None else OpenFormSearch(
            block=runner.settings.search.block, seed=runner.settings.seed)
        if _has_wave_tube(state.current, runner.data.rig()):
            # the valve sits at the tube's far end: a closure beside it reads no port
            search = _clone(search, without_features=tuple(sorted(
                {*search.without_features, *PORT_FEATURES})))
            runner.log("discover: open form: beside the wave tube the search leaves out "
                       "the features of the valve's ports (the tube puts them at its far "
                       "end)")
        data: dict = {}  # source -> (signals, targets, row maps or None, nuisance)
        shortest = min(rec.n_samples for rec in runner.data.train)
        # the one-step residual in blocks; a longer block (the one-step residual of a
        # small chamber is mostly noise, which sums away over more intervals); the
        # prediction windows' residual, where a slow term accumulates
        sources: list = [search.block] + (
            [self.long_block] if search.block < self.long_block < shortest else []) + (
            [WINDOWS] if self.window_rows else [])
        tried: set = set()  # the closures fitted (a source that proposes one again: next)
        excluded: tuple[str, ...] = ()
        retries, i = 0, 0
        while i < len(sources):
            source = sources[i]
            if source not in data:
                # (the path's signals, the per-interval target and the nuisance do not
                # depend on the rows: the first source's serve the others)
                if source == WINDOWS:
                    first = data[sources[0]]
                    data[source] = self._window_residual(state, runner, first[0], first[3])
                elif data:
                    data[source] = data[sources[0]]
                else:
                    data[source] = self._residual(state, runner)
            signals, targets, maps, nuisance = data[source]
            search = _clone(search, exclude=tuple(dict.fromkeys((*search.exclude,
                                                                 *excluded))),
                            **({"chunk_rows": maps[0].rows_per_window} if maps else
                               {"block": source}))
            terms, search = self._search(search, signals, targets, maps, state.current,
                                         nuisance)
            runner.ledger.record("open form search", round=state.number,
                                 terms=[_term_record(t) for t in terms],
                                 explained_fraction=getattr(search, "explained_fraction_",
                                                            None),
                                 candidates=getattr(search, "n_candidates_", None),
                                 excluded=list(search.exclude), block=source)
            spec = "; ".join(sorted(str(t.term) for t in terms))
            if not terms or spec in tried:
                i += 1
                continue
            tried.add(spec)
            runner.log(f"discover: open form: the search ({_source_label(source)}) proposes "
                       + ", ".join(f"{t.term} ({t.share:.0%} of the explained residual)"
                                   for t in terms))
            fit = self._fit(state, runner, terms, signals)
            if fit is None:
                i += 1
                continue
            if self.prune and runner.better(fit, state.current)[0]:
                # (pruning weighs each term against the closure without it, which means
                # something only for a closure that beats the current model)
                fit = self._prune(fit, state, runner)
            passed, bounded = self._verify(fit, state, runner, best, search)
            if passed:
                return
            if bounded:
                linear = self._linearized(fit, bounded, signals, state, runner)
                if linear is not None and self._verify(linear, state, runner, best,
                                                       search)[0]:
                    return
                if retries < self.retries:
                    # a closure that fits only at its bounds stands in for what its terms
                    # cannot express: the search's next terms may (those families out)
                    retries += 1
                    excluded = excluded + families_at_bounds(fit, bounded, terms)
                    runner.log("discover: open form: searching again without "
                               + ", ".join(excluded))
                    continue
            i += 1
        if not tried:
            runner.log("discover: open form: no term of the residual's search is supported")

    # ------------------------------------------------------------------ search
    def _residual(self, state: RoundState, runner):
        """The one-step residual of the training recordings
        (:func:`~pneubayes.discovery.openform.residual.one_step_residual`)."""
        return one_step_residual(state.current.model, state.current.params,
                                 runner.data.train, runner.settings.search.solver,
                                 self.refit_base)

    def _window_residual(self, state: RoundState, runner, path, path_nuisance=None):
        """The training windows' residual
        (:func:`~pneubayes.discovery.openform.residual.window_residual`)."""
        return window_residual(state.current.model, state.current.params, runner.data.train,
                               runner.data.train_ws, runner.settings.fit.refine_solver, path,
                               self.window_rows, path_nuisance)

    def _search(self, search, signals, targets, maps, current, nuisance=None):
        """``(terms, search)``: the search fitted (beside ``nuisance``), its terms as
        many as the closure has room for beside ``current``'s."""
        search.fit(signals, targets, row_maps=maps, nuisance=nuisance)
        free = CLOSURE_MAX_TERMS - len(existing_terms(current.model))
        return list(search.terms_)[:max(free, 0)], search

    # ------------------------------------------------------------------ fit
    def _fit(self, state: RoundState, runner, terms, signals):
        """The current model with the closure extended by ``terms``, refitted from the
        search's values and from zero strength (the current fit: the trial contains the
        current model), the lower training RMSE kept; a hinge's threshold bounds reach
        its signal's range on ``signals`` (the training recordings')."""
        current = state.current
        old = existing_terms(current.model)
        spec = "; ".join([*(str(t) for t, _ in old), *(str(t.term) for t in terms)])
        closure = Closure(terms=spec)
        base = current.model.without(CLOSURE) if current.model.has(CLOSURE) else current.model
        base, plainer = beside_closure(
            base, {k: current.params[k] for k in base.parameter_names}, runner.data.rig(),
            [t for t, _ in old] + [t.term for t in terms])
        if plainer:
            runner.log("discover: open form: a closure cannot sit beside the line state of "
                       f"{', '.join(plainer)} (an acoustic line, or a wave tube beside a "
                       "term that reads the valve's ports); the trial has its plainest form")
        model = base.with_effect(closure)
        earlier = {k: v for k, v in current.model.bound_overrides.items()
                   if k.startswith("closure_")}  # an earlier term's widened bounds
        wide = {**earlier, **reach(
            model, {len(old) + j: t.coefficient for j, t in enumerate(terms)},
            [t for t, _ in old] + [t.term for t in terms], self.coefficient_reach, signals)}
        if len(wide) > len(earlier):
            runner.log("discover: open form: bounds widened to reach the searched values "
                       "and the hinges' signals: "
                       + ", ".join(f"{k} [{v[0]:.3g}, {v[1]:.3g}]" for k, v in wide.items()
                                   if k not in earlier))
        if wide:
            model = model.with_bounds(wide)
        searched = {k: v for k, v in current.params.items() if k in model.parameter_names}
        searched.update({k: v for k, v in closure.neutral_values().items()
                         if k not in searched})
        for j, t in enumerate(terms):
            k = len(old) + j
            name = f"closure_coefficient_{k}"
            searched[name] = inside_bounds(model, name, t.coefficient)
            for side in t.term.hinges():
                name = f"closure_threshold_{k}_{side}"
                searched[name] = inside_bounds(model, name, getattr(t, f"threshold_{side}"))
        zero = dict(searched)
        for j in range(len(terms)):
            zero[f"closure_coefficient_{len(old) + j}"] = 0.0
        fits, failures = [], []
        for label, start in (("the search's values", searched), ("zero strength", zero)):
            start = {k: start[k] for k in model.parameter_names}
            try:
                fits.append(runner.fit(model, start))
            except FIT_FAILURES as exc:
                why = f"from {label}: {type(exc).__name__}: {str(exc).splitlines()[0]}"
                failures.append(why)
                runner.log(f"discover: open form {why}")
        if not fits:
            # (a closure whose fit or held-out simulation failed from every start: the
            # ledger says so, not only the log, which a quiet run does not keep)
            runner.ledger.record("open form failed", round=state.number, terms=spec,
                                 error="; ".join(failures))
            return None
        fit = min(fits, key=lambda f: f.train_rmse_Pa)
        runner.log(f"discover: open form: closure '{spec}' fitted, training RMSE "
                   f"{current.train_rmse_Pa:.0f} -> {fit.train_rmse_Pa:.0f} Pa, held-out "
                   f"{current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa")
        if fit.train_rmse_Pa > current.train_rmse_Pa * (1.0 + NESTED_TOLERANCE):
            # it contains the current model: a fit that ends worse failed, and says
            # nothing of the terms
            runner.log("discover: open form: the closure's fit ended worse in training "
                       "than the model it contains; a failed fit")
            runner.ledger.record("open form failed", round=state.number,
                                 error=f"training RMSE {fit.train_rmse_Pa:.0f} Pa above the "
                                       f"current model's {current.train_rmse_Pa:.0f} Pa")
            return None
        return fit

    def _prune(self, fit, state: RoundState, runner):
        """Drop, one at a time, each term the held-out test cannot tell apart from the
        closure without it, as long as the closure without it still passes that test
        against the current model (pruning never turns a closure that beats the current
        model into one that does not; the last term is weighed in the verification)."""
        while True:
            terms = existing_terms(fit.model)
            if len(terms) <= 1:
                return fit
            dropped = False
            for k in range(len(terms)):
                reduced, start = without_term(fit, k)
                try:
                    smaller = runner.fit(reduced, start)
                except FIT_FAILURES:
                    continue
                needed = (runner.better(fit, smaller)[0]
                          or not runner.better(smaller, state.current)[0])
                if needed:
                    continue
                runner.log(f"discover: open form: term {terms[k][0]} pruned (held-out "
                           f"{fit.heldout_rmse_Pa:.0f} -> {smaller.heldout_rmse_Pa:.0f} Pa "
                           "without it)")
                runner.ledger.record("open form prune", term=str(terms[k][0]),
                                     heldout_rmse_before_Pa=fit.heldout_rmse_Pa,
                                     heldout_rmse_after_Pa=smaller.heldout_rmse_Pa)
                fit, dropped = smaller, True
                break
            if not dropped:
                return fit

    def _linearized(self, fit, bounded: list[str], signals, state: RoundState, runner):
        """``fit`` refitted with each hinge whose threshold is in ``bounded`` written
        without it (:func:`~pneubayes.discovery.openform.linear_hinge.linear_terms`),
        started from the same closure re-expressed; None when no such rewrite exists or
        its fit fails."""
        terms = existing_terms(fit.model)
        sides = [(k, name[-1]) for k, (_, names) in enumerate(terms)
                 for name in names[1:] if name in bounded]  # (closure_threshold_{k}_{a|b})
        if not sides:
            return None
        valued = [ValuedTerm(t, fit.params[names[0]],
                             *(fit.params.get(f"closure_threshold_{k}_{side}", 0.0)
                               for side in ("a", "b")))
                  for k, (t, names) in enumerate(terms)]
        new = linear_terms(valued, sides, signals)
        if new is None:
            return None
        model, start = closure_model(fit, new, self.coefficient_reach, signals)
        spec = "; ".join(str(t.term) for t in new)
        thresholds = [f"closure_threshold_{k}_{side}" for k, side in sides]
        runner.log(f"discover: open form: {', '.join(thresholds)} at a bound beyond the "
                   f"hinge's signal; refitting as '{spec}'")
        try:
            linear = runner.fit(model, start)
        except FIT_FAILURES as exc:
            runner.log(f"discover: open form: the linear closure failed to fit "
                       f"({type(exc).__name__})")
            return None
        runner.ledger.record("open form linearized", round=state.number, terms=spec,
                             bounded=thresholds,
                             train_rmse_before_Pa=fit.train_rmse_Pa,
                             train_rmse_Pa=linear.train_rmse_Pa,
                             heldout_rmse_Pa=linear.heldout_rmse_Pa)
        if self.prune and runner.better(linear, state.current)[0]:
            linear = self._prune(linear, state, runner)
        return linear

    # ------------------------------------------------------------------ verify
    def _verify(self, fit, state: RoundState, runner, best, search):
        """Weigh the closure's fit against the current model (and the round's best
        passing catalogue trial, :func:`~pneubayes.discovery.stages.weighing.weigh`);
        ``(passed, parameters newly at a bound)``."""
        w = weigh(fit, state, runner, best, CLOSURE)
        terms = existing_terms(fit.model)
        runner.ledger.record(
            "open form pass" if w.passed else "open form reject", effect=CLOSURE,
            terms=[{"term": str(t), **{n: fit.params[n] for n in names}}
                   for t, names in terms],
            **w.record(fit, state.current, best))
        why = w.reasons(best)
        runner.log(f"discover: {'passes' if w.passed else 'reject'} open form: held-out RMSE "
                   f"{state.current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa, "
                   f"better in {int(np.sum(w.window_gains > 0))}/{w.window_gains.size} "
                   f"windows (p = {w.p_value:.2g})"
                   + ("" if w.passed or not why else "; " + "; ".join(why)))
        if not w.passed:
            return False, w.bounded
        if best is not None:
            runner.log(f"discover: open form: the closure explains the residual better "
                       f"than {best[1]}, which it replaces as the round's candidate")
        state.evidence[CLOSURE] = {
            "inclusion_probability": float(min(t.inclusion_probability
                                               for t in search.terms_)) if search.terms_
            else 0.0,
            "t_max": None, "best_term": "; ".join(str(t) for t, _ in terms),
            "best_term_start": None}
        state.passing = [(fit.heldout_rmse_Pa, CLOSURE, fit, w.gain, w.p_value)]
        return True, w.bounded


def _source_label(source) -> str:
    """A search's rows, in words."""
    return ("prediction windows" if source == WINDOWS
            else f"one-step residual in blocks of {source}")


def _settings_of(search) -> dict:
    """A search's constructor arguments, by name (its settings, not its fitted state)."""
    return {k: getattr(search, k)
            for k in inspect.signature(type(search).__init__).parameters if k != "self"}


def _has_wave_tube(fit, rig) -> bool:
    """Whether ``fit``'s model steps the tube as waves (``tube_delay`` form ``"wave"``)."""
    slots = fit.model.lower(fit.model.vector(fit.params)[None, :], rig)[0]
    return bool(slots[SLOT_INDEX["wave_length_m"]] > 0)


def _clone(search, **changes):
    """A new, unfitted search with ``search``'s settings and ``changes``."""
    return type(search)(**{**_settings_of(search), **changes})


def _term_record(t) -> dict:
    """A found term for the ledger."""
    return {"term": str(t.term), "coefficient": t.coefficient, "unit": t.term.unit,
            "threshold_a": t.threshold_a, "threshold_b": t.threshold_b,
            "inclusion_probability": t.inclusion_probability, "share": t.share}


