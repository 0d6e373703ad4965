"""Fitting, scoring and verifying trials: the services the loop and its stages share.

A *trial* is the current model with one more effect (in each form the effect
proposes), refined on the training windows and verified on the held-out ones
(:func:`~pneubayes.discovery.verification.compare_heldout`: a one-sided signed-rank test
on the per-window squared-error reductions and a higher log predictive density). A
trial must also beat its *control*: refinement finds local optima, and a trial whose
refit only moved the other parameters to a basin that predicts better (an effect fitted
to zero strength) carries no gain of its own. The control is the current model refined
from the trial's other parameters; only a trial that beats the current fit gets one,
and a control that fits the training data better than the current fit becomes the
current fit.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np

from pneubayes.atomic import json_safe, write_json_atomic
from pneubayes.discovery.candidates import effect_candidates, first_free, follow_up, form_label
from pneubayes.discovery.rounds import (
    TrialFitFailed,
    choose_form,
    fit_round_forms,
    gain_shortfall,
    min_gain_Pa,
)
from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.discovery.state import Ledger, LoopData, RoundState
from pneubayes.discovery.verification import (
    StepFit,
    ar1_noise_mode,
    compare_heldout,
    crossfit_window_lpd,
)
from pneubayes.effects.discovery import inside_bounds
from pneubayes.errors import FIT_FAILURES
from pneubayes.inference.likelihood import ar1_sums
from pneubayes.inference.refine import TrajectoryRefiner, late_gain
from pneubayes.model import Model

#: A trial's training RMSE may exceed the current model's (which it contains) by this
#: share before it counts as a fit that ended worse (refinements stop within about a
#: tenth of a percent of an optimum; the demo's trials at the noise floor ended 1 Pa
#: above a 510-Pa current fit).
NESTED_TOLERANCE = 0.01


def effects_label(model: Model) -> str:
    """E.g. ``"valve_deadzone + tube_delay line/8"``."""
    return " + ".join(g + ("" if form_label(model, g) == "-" else f" {form_label(model, g)}")
                      for g in model.effect_names) or "plain"


def fingerprint(*parts) -> str:
    """A short hash of JSON-able ``parts`` (a cached fit's key)."""
    h = hashlib.sha256()
    for p in parts:
        h.update(json.dumps(json_safe(p), sort_keys=True).encode())
    return h.hexdigest()[:16]


class TrialRunner:
    """Fits and verifies models for one discovery run.

    Parameters
    ----------
    settings : DiscoverySettings
        The fit, verification and form settings.
    data : LoopData
        What every fit is scored on.
    ledger : Ledger
        The run's record; trials, controls and prunings are recorded here.
    out_dir : path or None
        Run folder: finished fits are cached in ``out_dir/steps`` (resume); None keeps
        nothing.
    log : callable
        Progress messages.
    deadline_s : float
        ``time.perf_counter()`` after which a trial's forms not yet fitted are not
        fitted (failed forms: the run's time budget, ``rounds.max_seconds``, is spent);
        inf: none.
    """

    def __init__(self, settings: DiscoverySettings, data: LoopData, ledger: Ledger,
                 out_dir=None, log=print, deadline_s: float = math.inf):
        self.settings = settings
        self.data = data
        self.ledger = ledger
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.log = log
        self.deadline_s = deadline_s

    # ------------------------------------------------------------------ one fit
    def _cache_path(self, key: str) -> Path | None:
        return None if self.out_dir is None else self.out_dir / "steps" / f"{key}.json"

    def fit(self, model: Model, start: dict, first=None, beat_Pa: float | None = None
            ) -> StepFit:
        """Refine ``model`` from ``start`` and score it on the training and held-out
        windows.

        Parameters
        ----------
        model : Model
            The model (the settings' bound overrides are applied to it).
        start : dict
            Parameter name -> start value.
        first : tuple of str or None
            Parameters refined on their own before all of them; the full refinement
            continues from that stage's point.
        beat_Pa : float or None
            With ``first``: a first stage whose training RMSE is not below this (Pa) ends
            the fit there (a screened-out form), scored at the stage's point.

        Returns
        -------
        StepFit
        """
        s, d = self.settings, self.data
        if s.data.bounds:
            model = model.with_bounds({k: tuple(v) for k, v in s.data.bounds.items()})
        key = fingerprint(model.to_card(start), s.fit.to_dict(), d.data_key,
                          *([list(first)] if first else []),
                          *([beat_Pa] if first and beat_Pa is not None else []))
        path = self._cache_path(key)
        t0 = time.perf_counter()
        if path is not None and path.exists():
            cached = json.loads(path.read_text())
            params = {k: float(v) for k, v in cached["params"].items()}
        else:
            params = self._refine(model, start, first, beat_Pa)
            if path is not None:
                write_json_atomic(path, {"model": model.to_card(params), "params": params})
        return self.score(model, params, t0)

    def score(self, model: Model, params: dict, t0: float | None = None) -> StepFit:
        """``model`` at ``params`` as it stands (no refinement), scored on the training
        and held-out windows; ``t0`` (a ``perf_counter`` reading) starts its wall time."""
        s, d = self.settings, self.data
        t0 = time.perf_counter() if t0 is None else t0
        theta = model.vector(params)[None]
        r_tr = d.train_ws.residuals(model, theta, s.fit.refine_solver)
        sig, rho = ar1_noise_mode(ar1_sums(r_tr)[0], r_tr[0].size)
        r_ho = d.held_ws.residuals(model, theta, s.fit.refine_solver)[0]
        return StepFit(model, params, float(np.sqrt(np.mean(r_tr**2))),
                       float(np.sqrt(np.mean(r_ho**2))),
                       crossfit_window_lpd(r_ho, s.verify.score_dof),
                       np.mean(r_ho**2, axis=1), sig, rho,
                       wall_time_s=time.perf_counter() - t0)

    def _refine(self, model: Model, start: dict, first, beat_Pa) -> dict:
        """The refined parameters: to convergence (a base model stopped early would make
        any extended model's extra refinement look like a gain of the effect), restarted
        while a run its budget ended still moved (``max_refine_restarts``,
        ``refine_restart_min_gain``)."""
        s = self.settings
        train_ws = self.data.train_ws

        def refiner(free=None):
            return TrajectoryRefiner(model, s.fit.refine_solver, free=free,
                                     max_nfev=s.fit.refine_max_nfev,
                                     jacobian_refresh=s.fit.refine_jacobian_refresh,
                                     uncertainty=False, stall=s.fit.stall())

        params, screened = start, False
        if first:
            stage = refiner(free=first).fit(train_ws, params)
            screened = beat_Pa is not None and not stage.rmse_Pa_ < beat_Pa
            # the full fit continues from the stage's point; a screened-out form is
            # scored there, not at its start
            params = stage.params_
            if screened:
                self.log(f"discover: {effects_label(model)}: screened out, its own "
                         f"parameters fit to {stage.rmse_Pa_:.0f} Pa in training, not "
                         f"below the screen ({beat_Pa:.0f} Pa)")
        for _ in range(0 if screened else s.rounds.max_refine_restarts + 1):
            ref = refiner().fit(train_ws, params)
            params = ref.params_
            if ref.success_:
                break
            crawl = late_gain(ref.rmse_trace_)
            if crawl < s.rounds.refine_restart_min_gain:
                self.log(f"discover: {effects_label(model)}: refinement ended on its "
                         f"budget at {ref.rmse_Pa_:.0f} Pa, its best RMSE {crawl:.1e} "
                         f"lower over its last half: crawling, not restarted")
                break
        return params

    def _fit_in_budget(self, group: str, model: Model, start: dict, current: StepFit,
                       beat_Pa: float | None) -> StepFit:
        """:meth:`fit_trial`, unless the run's time budget is spent (a failed form)."""
        if time.perf_counter() > self.deadline_s:
            raise TrialFitFailed("not fitted: the time budget (rounds.max_seconds) is "
                                 "spent")
        return self.fit_trial(group, model, start, current, beat_Pa)

    def fit_trial(self, group: str, model: Model, start: dict, current: StepFit,
                  beat_Pa: float | None = None) -> StepFit:
        """A trial that cannot lose: ``model`` (``current``'s model with ``group``'s
        effect) refined from ``start``; if it ends worse in training than ``current``
        (which it contains, the effect at zero strength) by more than
        :data:`NESTED_TOLERANCE` of its RMSE, refined again from the current
        fit with the effect neutral, the lower training RMSE kept. Still worse: a failed
        fit (:class:`~pneubayes.discovery.rounds.TrialFitFailed`), not a rejection. A
        screened form (``beat_Pa``) is scored where its screen stopped it.

        Returns
        -------
        StepFit
        """
        fit = self.fit(model, start, first_free(model, group), beat_Pa)
        # worse beyond the refinement's own spread (a share of the current RMSE)
        limit_Pa = current.train_rmse_Pa * (1.0 + NESTED_TOLERANCE)
        worse = fit.train_rmse_Pa > limit_Pa
        if beat_Pa is not None or not worse:
            return fit
        nested = {k: (current.params[k] if k in current.params
                      else inside_bounds(model, k, v))
                  for k, v in model.effect(group).neutral_values().items()}
        nested.update({k: current.params[k] for k in model.parameter_names
                       if k in current.params})
        nested = {k: nested[k] for k in model.parameter_names}
        label = f"{group} {form_label(model, group)}"
        self.log(f"discover: {label}: training RMSE {fit.train_rmse_Pa:.0f} Pa, above the "
                 f"current model's {current.train_rmse_Pa:.0f} Pa it contains: refitted from "
                 "the current fit with the effect at zero strength")
        again = self.fit(model, nested)
        if again.train_rmse_Pa < fit.train_rmse_Pa:
            fit = again
        if fit.train_rmse_Pa > limit_Pa:
            raise TrialFitFailed(f"its best training RMSE {fit.train_rmse_Pa:.0f} Pa stays "
                                 f"above the current model's {current.train_rmse_Pa:.0f} Pa")
        return fit

    def better(self, new: StepFit, old: StepFit, max_p_value: float | None = None):
        """The verification test of ``new`` against ``old`` on the held-out windows (at
        ``max_p_value``; None: the settings' ``verify.max_p_value``): ``(passes, score
        gain, p-value, per-window squared-error reductions)``."""
        return compare_heldout(new, old, self.settings.verify.max_p_value
                               if max_p_value is None else max_p_value)

    # ------------------------------------------------------------------ trials
    def trials(self, groups, state: RoundState, min_gap_closed: float | dict = 0.0) -> list:
        """Fit each of ``groups``' forms beside ``state.current``, control every trial
        that beats it (:meth:`controls`), and verify each against the final current fit.

        A trial that passes must also close ``min_gap_closed`` of the held-out RMSE's
        gap above the noise floor (one share for all, or per group, 0 for a group not
        listed; with no gap left, none can) and gain the least the settings ask
        (:func:`~pneubayes.discovery.rounds.min_gain_Pa`). Records each
        trial in the ledger, each effect's fitted forms in ``state.tried`` and may
        replace ``state.current`` (a better optimum of the current model).

        Returns
        -------
        list
            The passing trials, ``(held-out RMSE, group, fit, score gain, p-value)``.
        """
        s, d = self.settings, self.data
        evidence = state.search.evidence_
        current = state.current
        rig = d.rig()
        trials = []
        options = {g: effect_candidates(current, g, evidence[g], rig, s.forms)
                   for g in groups}
        # (passed in an earlier round, not added: every form in full)
        passed = {e["effect"] for e in self.ledger if e["action"] == "pass"} \
            - set(current.model.effect_names)
        round_forms, settled, failed, outpaced = fit_round_forms(
            options, lambda g, m, x, beat: self._fit_in_budget(g, m, x, current, beat),
            s.forms.settled_ratio * d.noise_Pa,
            follow=lambda g, m, f: follow_up(current, g, evidence[g], rig, m, f.params,
                                             s.forms),
            current_Pa=current.train_rmse_Pa, min_share=s.forms.later_min_share,
            screen_share=s.forms.later_screen_share,
            cheap={g for g, forms in options.items()
                   if forms and forms[0][0].effect(g).cheap_forms},
            passed=passed & set(groups))
        for g in groups:
            forms = round_forms[g]
            forms_info = self._forms_info(g, forms, options[g], failed[g], outpaced, settled)
            if not forms:
                self.log(f"discover: {g} has no form that fits beside "
                         f"{list(current.model.effect_names)}; skipped")
                continue
            # the effect's form that fits the training data best (never the held-out),
            # the simplest within the margin
            trial, model2, start2 = choose_form(forms, s.forms.nested_min_gain_share
                                                * d.noise_Pa)
            if len(forms) > 1:
                self.log(f"discover: {g}: form {model2.effect(g).options()} chosen "
                         "(training RMSE " + ", ".join(
                             f"{form_label(m, g)} {f.train_rmse_Pa:.0f} Pa"
                             for f, m, _ in forms) + ")")
            trials.append((g, model2, start2, trial, forms_info))
            state.tried[g] = sorted(((m, f, x) for f, m, x in forms),
                                    key=lambda mfx: mfx[1].train_rmse_Pa)
        # every trial against the final current fit, and against its own control (the
        # current model in the trial's basin, which may predict the held-out part better
        # than the current fit at no better training error: that gain is the basin's,
        # not the effect's); the best that passes both is added
        controls = self.controls([(t[0], t[3]) for t in trials], state)
        share = (min_gap_closed if isinstance(min_gap_closed, dict)
                 else {t[0]: min_gap_closed for t in trials})
        return [p for p in (self._verdict(t, control, state, share.get(t[0], 0.0))
                            for t, control in zip(trials, controls)) if p is not None]

    def _forms_info(self, g, forms, options, failed, outpaced, settled) -> dict:
        """The ledger's note of an effect's forms: fitted (training RMSE), not fitted and
        why, failed and why; logs the same."""
        s = self.settings
        tried = {id(m) for _, m, _ in forms} | {id(m) for m, _ in failed}
        info = {"train_rmse_Pa": {form_label(m, g): f.train_rmse_Pa for f, m, _ in forms},
                "not_fitted": [form_label(m, g) for m, _ in options if id(m) not in tried],
                "failed": {form_label(m, g): why for m, why in failed}}
        for m, why in failed:
            self.log(f"discover: {g}: form {m.effect(g).options()} failed ({why}); "
                     "a failed trial")
        if info["not_fitted"] and g in outpaced:
            mine, best = outpaced[g]
            info["not_fitted_why"] = (f"first-form gain {mine:.0f} Pa < "
                                      f"{s.forms.later_min_share:g} x the round's best "
                                      f"{best:.0f} Pa")
            self.log(f"discover: {g}: {len(info['not_fitted'])} later form(s) "
                     f"not fitted: its first form gains {mine:.0f} Pa in training, "
                     f"under {s.forms.later_min_share:g} x the round's best "
                     f"({best:.0f} Pa)")
        elif info["not_fitted"]:
            sg, sm, sf = settled
            self.log(f"discover: {g}: {len(info['not_fitted'])} later form(s) "
                     f"not fitted: {sg} form {sm.effect(sg).options()} fits at the "
                     f"noise floor (training RMSE {sf.train_rmse_Pa:.0f} Pa)")
        return info

    def _verdict(self, trial_info, control, state: RoundState, min_gap_closed: float):
        """Verify one trial against ``state.current`` and its control; record it.
        Returns the passing tuple or None."""
        s, noise = self.settings, self.data.noise_Pa
        g, model2, start2, trial, forms_info = trial_info
        current = state.current
        ok, gain, pval, diff = self.better(trial, current)
        basin = False
        if ok and control is not None and control is not current:
            basin = not self.better(trial, control)[0]
            if basin:
                self.log(f"discover: {g}: its held-out gain is its basin's: the current "
                         f"model refitted from the trial's point predicts "
                         f"{control.heldout_rmse_Pa:.0f} Pa against the trial's "
                         f"{trial.heldout_rmse_Pa:.0f} Pa")
        ok = ok and not basin
        gap_Pa = current.heldout_rmse_Pa - noise
        drop_Pa = current.heldout_rmse_Pa - trial.heldout_rmse_Pa
        least = min_gain_Pa(noise, gap_Pa, s)
        closed, short, under = gain_shortfall(drop_Pa, gap_Pa, min_gap_closed, least)
        small, tiny = ok and short, ok and under
        ok = ok and not small and not tiny
        names = model2.effect(g).parameter_names()
        self.ledger.record(
            "pass" if ok else "reject", effect=g,
            gap_closed=closed, short_of_gap=bool(small), gain_under_floor=bool(tiny),
            min_gain_Pa=least, min_gap_closed=min_gap_closed,
            effect_options=model2.effect(g).options(), forms=forms_info,
            start={k: start2[k] for k in names},
            fitted={k: trial.params[k] for k in names},
            heldout_rmse_before_Pa=current.heldout_rmse_Pa,
            heldout_rmse_after_Pa=trial.heldout_rmse_Pa,
            score_gain=gain, score_p_value=pval,
            control_heldout_rmse_Pa=None if control is None else control.heldout_rmse_Pa,
            not_better_than_control=basin,
            windows_improved=int(np.sum(diff > 0)), windows=int(diff.size),
            evidence=state.search.evidence_[g], wall_time_s=trial.wall_time_s)
        self.log(f"discover: {'passes' if ok else 'reject'} {g}: held-out RMSE "
                 f"{current.heldout_rmse_Pa:.0f} -> {trial.heldout_rmse_Pa:.0f} Pa, "
                 f"better in {int(np.sum(diff > 0))}/{diff.size} windows "
                 f"(p = {pval:.2g}), log predictive gain {gain:.1f}"
                 + (f"; it closes {100 * (closed or 0.0):.0f} % of the gap, under "
                    f"{100 * min_gap_closed:.0f} %" if small else "")
                 + (f"; it gains {drop_Pa:.1f} Pa, under {least:.1f} Pa (the larger of "
                    f"{s.verify.min_gain_noise_share:g} x the noise floor and "
                    f"{s.verify.min_gain_gap_share:g} x the gap)" if tiny else ""))
        return (trial.heldout_rmse_Pa, g, trial, gain, pval) if ok else None

    # ------------------------------------------------------------------ controls
    def controls(self, fits: list, state: RoundState) -> list:
        """The controls (:meth:`control`) of those of ``fits`` (``(label, fit)`` pairs)
        that beat ``state.current`` on the held-out windows; a fit that does not needs
        none. A control that becomes the current fit makes every fit without one be
        checked again, until each that beats the current fit has its control.

        Returns
        -------
        list
            One control a fit, None for a fit without one; ``state.current`` may have
            been replaced.
        """
        controls = [None] * len(fits)
        changed = True
        while changed:
            changed = False
            for i, (label, fit) in enumerate(fits):
                if controls[i] is None and self.better(fit, state.current)[0]:
                    before = state.current
                    controls[i], state.current = self.control(fit, state.current, label)
                    changed = changed or state.current is not before
        return controls

    def control(self, trial: StepFit, current: StepFit, label: str):
        """A trial's control: the current model refined from the trial's other
        parameters. Where it fits the training data better than ``current`` it becomes
        the current fit (ledger action ``refit current``).

        Returns
        -------
        (StepFit, StepFit)
            The control and the current fit.
        """
        try:
            # (a parameter the trial's model lacks, e.g. an effect's other form's,
            # keeps its current value)
            control = self.fit(current.model, {k: trial.params.get(k, current.params[k])
                                               for k in current.model.parameter_names})
        except FIT_FAILURES as exc:
            # the trial's point leaves the current model's simulable region: no better
            # optimum of the current model there
            self.log(f"discover: {label}: no control fit from the trial's point "
                     f"({type(exc).__name__})")
            return current, current
        if control.train_rmse_Pa < current.train_rmse_Pa - 1e-9:
            self.log(f"discover: a better optimum of the current model: train RMSE "
                     f"{current.train_rmse_Pa:.1f} -> {control.train_rmse_Pa:.1f} Pa "
                     f"({current.train_rmse_Pa - control.train_rmse_Pa:.2g} Pa lower; "
                     f"held-out {current.heldout_rmse_Pa:.0f} -> "
                     f"{control.heldout_rmse_Pa:.0f} Pa)")
            self.ledger.record("refit current", model=list(current.model.effect_names),
                               train_rmse_Pa=control.train_rmse_Pa,
                               heldout_rmse_Pa=control.heldout_rmse_Pa,
                               heldout_lpd=control.heldout_lpd)
            current = control
        return control, current

    # ------------------------------------------------------------------ pruning
    def prune(self, current: StepFit, accepted: list, newest: int = 1) -> StepFit:
        """Backward step: drop an earlier effect of ``accepted`` the ``newest`` added
        ones have made unnecessary (an effect that only stood in for a newcomer): one
        whose gain over the model without it is no longer significant at
        ``verify.remove_max_p_value``. Returns the current fit without them."""
        for a in list(accepted[:-newest]):
            name = a["name"]
            reduced = current.model.without(name)
            fit = self.fit(reduced, {k: current.params[k] for k in reduced.parameter_names})
            needed, gain, pval, _ = self.better(current, fit,
                                                self.settings.verify.remove_max_p_value)
            if needed:
                continue
            self.log(f"discover: REMOVE {name}: without it held-out RMSE "
                     f"{current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa "
                     f"(its gain is no longer significant, p = {pval:.2g})")
            self.ledger.record("remove", effect=name,
                               heldout_rmse_before_Pa=current.heldout_rmse_Pa,
                               heldout_rmse_after_Pa=fit.heldout_rmse_Pa,
                               score_gain=-gain, score_p_value=pval)
            accepted.remove(a)
            current = fit
        return current
