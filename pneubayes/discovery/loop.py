"""The name-add-refit loop: fit, map the disagreement, search, name, add, verify, repeat.

Starting from the plain thin-port model (eqs. 1-5 with Gompertz maps):

1. **Fit** on the training part of every recording (the first ``1 - holdout_fraction``
   of its samples): the paper's least squares where possible, then 2-s multiple
   shooting (:mod:`pneubayes.inference`).
2. **Map** the disagreement (:mod:`disagreement`).
3. **Search**: grouped SINDy on the one-step residual (:mod:`library`, :mod:`sindy`).
4. **Name and add**: the ``max_trials_per_round`` best-supported effects (the
   catalogue's effect objects, started at the strength of their best terms) are each
   added and refitted. A named leak is fitted in the graded laminar form; a named heat
   exchange in both its forms (one rate, or a convective coefficient on the wall area),
   a named tube in both of its (transport delay, acoustic line), and the form with the
   lower *training* error goes on to verification; once any trial of the round fits at
   the noise floor, no later form is fitted (``form_settled_ratio``); an effect whose
   first form gains under a quarter of the round's best first-form gain in training gets
   no later form (``later_forms_min_share``), and a later form whose own parameters,
   fitted first, gain under half its effect's first form's gain over the current model
   is not refined further (``later_form_screen_share``; a line for a tube that is not
   there costs tens of minutes). While the held-out
   error is far above the noise, weakly supported groups are tried too (see
   ``gap_fallback_ratio``), and if none of those passes either, or the best that passes
   closes under a quarter of the gap (``last_resort_best_gap_closed``), every other
   group, as a last resort that must close a quarter of the gap (``try_all_on_gap``).
5. **Verify** on the held-out part (the last ``holdout_fraction`` of every recording):
   the 2-s prediction RMSE must drop, significantly -- the per-window reductions of the
   mean squared error (2-s windows are the independent units) must pass a one-sided
   Wilcoxon signed-rank test at ``max_p_value``, a rank test because the reductions
   are heavy-tailed -- *and* the held-out log predictive density must rise. Otherwise
   the effect is rejected. The trial must also beat its *control*, the current model
   refitted from the trial's other parameters, the same way: refinement finds local
   optima, and a trial whose refit only moved the other parameters to a basin that
   predicts better (an effect fitted to zero strength) carries no gain of its own
   (a control is fitted only for a trial that beats the current fit; one that fits
   the training data better than the current fit replaces it, and the trials are
   checked against it again). Of those that pass, the one with the lowest held-out
   RMSE is added.
6. **Prune**: once an effect is added, each earlier one is refitted away; if the model
   without it is not significantly worse (the same test), it only stood in for the
   newcomer and is removed.
7. **Repeat** with the extended model until no group is supported, or none of the
   groups tried in a round passes verification; a round whose first
   ``max_trials_per_round`` supported groups all fail tries its other supported groups
   before it stops (``try_all_supported``), and then the *runner-ups*: groups that beat
   an earlier round's model significantly but were not added (``revisit_runner_ups``;
   like the last resort's, they must close a quarter of the gap). If still nothing
   passed and the held-out error is far above the noise, the round's trials with the
   largest training gains are fitted in **pairs** (``pair_members``), each jointly from
   its members' fitted values: two effects can each fail alone (one fixes a regime and
   leaves the other's misfit to drift further) and pass together. A pair must pass as a
   single trial does and beat each member's own trial; the best adds both effects, and
   the earlier effects are pruned against the two. If nothing passes even then, each
   named effect is refitted in the other forms it proposes beside the rest of the model
   (``max_form_swaps``): a form chosen beside fewer effects need not be the best beside
   more (a tube paired with heat transfer can be a lumped line there, not the wave tube
   it was fitted as alone); a form that passes as a trial would replaces the named one
   and the loop searches again.

The final model gets an emcee posterior on the training data. A ledger records every
step; finished fits are cached in ``RUNDIR/steps`` so an interrupted run resumes.

The held-out score is a plug-in log predictive density: the refined parameters, each
held-out sample scored by a Student-t (``score_dof``) whose standard deviation is the RMS
error of the *other* held-out windows
(:func:`~pneubayes.discovery.verification.crossfit_window_lpd`). With thousands
of residuals per window set the parameter uncertainty is far below the noise, so the
plug-in is close to the full posterior predictive, at a fraction of the cost. Two
earlier forms failed on real cases: the noise taken from the *training* residuals (a
model missing an effect the held-out stretch shows more of fits training too tightly
and loses to a worse model), and a joint AR(1) density of each window (a large but
smooth error is a cheap random walk under a fitted AR(1); it kept a model with 2.4x the
held-out RMSE).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np

import pneubayes
from pneubayes.atomic import json_safe, write_json_atomic
from pneubayes.discovery.candidates import effect_candidates, first_free, follow_up
from pneubayes.discovery.controls import BasinControls
from pneubayes.discovery.disagreement import disagreement_map, flagged_bins
from pneubayes.discovery.library import build_library
from pneubayes.discovery.one_step import one_step_data
from pneubayes.discovery.result import DiscoveryResult
from pneubayes.discovery.rounds import (
    fit_round_forms,
    gain_shortfall,
    last_resort_reason,
    min_gain_Pa,
    runner_ups,
)
from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.discovery.sindy import GroupedSINDy
from pneubayes.discovery.stages import LaterStages, form_label
from pneubayes.discovery.verification import (
    StepFit,
    ar1_noise_mode,
    compare_heldout,
    crossfit_window_lpd,
    split_recordings,
)
from pneubayes.inference.chain_store import set_aside_other_chain
from pneubayes.inference.laplace import LaplaceIdentification
from pneubayes.inference.likelihood import ar1_sums
from pneubayes.inference.pipeline import starting_point
from pneubayes.inference.predictive import noise_floor_Pa
from pneubayes.inference.refine import TrajectoryRefiner, late_gain
from pneubayes.inference.sampler import BayesianIdentification
from pneubayes.inference.windows import WindowSet
from pneubayes.io.preprocess import prepare_recording
from pneubayes.model import Model


def _effects_label(model: Model) -> str:
    """E.g. ``"valve_deadzone + tube_delay line/8"``."""
    return " + ".join(g + ("" if form_label(model, g) == "-" else f" {form_label(model, g)}")
                      for g in model.effect_names) or "plain"


def _fingerprint(*parts) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(json.dumps(json_safe(p), sort_keys=True).encode())
    return h.hexdigest()[:16]


def _silent(message: str) -> None:
    """A log that drops its messages."""


class Discovery(BasinControls, LaterStages):
    """The loop (scikit-learn-style: configure, then :meth:`fit`, which returns the
    estimator with its answer in ``result_``, a :class:`DiscoveryResult`). The basin
    controls (:mod:`~pneubayes.discovery.controls`) and the pair and form stages
    (:mod:`~pneubayes.discovery.stages`) are its mixins.

    Parameters
    ----------
    settings : DiscoverySettings
    out_dir : path or None
        Run folder for the step cache (resume); None keeps everything in memory.
    log : callable or None
        Progress messages (None: silent).
    """

    def __init__(self, settings: DiscoverySettings, out_dir=None, log=print):
        self.settings = settings
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.log = log if log is not None else _silent

    # ------------------------------------------------------------------ fitting
    def _cache_path(self, key: str) -> Path | None:
        return None if self.out_dir is None else self.out_dir / "steps" / f"{key}.json"

    def _fit(self, model: Model, start: dict, train_ws: WindowSet, held_ws: WindowSet,
             data_key: str, first=None, beat_Pa: float | None = None) -> StepFit:
        """Refine ``model`` from ``start`` (``first``: parameters refined on their own
        before all of them, the full refinement continuing from the stage's point) and
        score it on the training and held-out windows. The settings' bound overrides
        apply to every model fitted here (the refiner starts inside them). With ``first`` and
        ``beat_Pa``, a first stage whose training RMSE is not below ``beat_Pa`` ends the
        fit there (a screened-out form: its own parameters do not beat the form it
        refines), scored at the stage's point."""
        s = self.settings
        if s.bounds:
            model = model.with_bounds({k: tuple(v) for k, v in s.bounds.items()})
        key = _fingerprint(model.to_card(start), s.fit.to_dict(), data_key,
                           *([list(first)] if first else []),
                           *([beat_Pa] if first and beat_Pa is not None else []))
        path = self._cache_path(key)
        t0 = time.perf_counter()
        if path is not None and path.exists():
            cached = json.loads(path.read_text())
            params = {k: float(v) for k, v in cached["params"].items()}
        else:
            # refine to convergence: a base model stopped early would make any extended
            # model's extra refinement look like a gain of the effect (the loop never
            # reads a fit's covariance: no uncertainty)
            def refiner(free=None):
                return TrajectoryRefiner(model, s.fit.refine_solver, free=free,
                                         max_nfev=s.fit.refine_max_nfev,
                                         jacobian_refresh=s.fit.refine_jacobian_refresh,
                                         uncertainty=False)

            params, screened = start, False
            if first:
                stage = refiner(free=first).fit(train_ws, params)
                screened = beat_Pa is not None and not stage.rmse_Pa_ < beat_Pa
                # the full fit continues from the stage's point; a screened-out form is
                # scored there, not at its start
                params = stage.params_
                if screened:
                    self.log(f"discover: {_effects_label(model)}: screened out, its own "
                             f"parameters fit to {stage.rmse_Pa_:.0f} Pa in training, not "
                             f"below the screen ({beat_Pa:.0f} Pa)")
            for _ in range(0 if screened else s.max_refine_restarts + 1):
                ref = refiner().fit(train_ws, params)
                params = ref.params_
                if ref.success_:
                    break
                crawl = late_gain(ref.rmse_trace_)
                if crawl < s.refine_restart_min_gain:
                    self.log(f"discover: {_effects_label(model)}: refinement ended on its "
                             f"budget at {ref.rmse_Pa_:.0f} Pa, its best RMSE {crawl:.1e} "
                             f"lower over its last half: crawling, not restarted")
                    break
            if path is not None:
                write_json_atomic(path, {"model": model.to_card(params), "params": params})
        theta = model.vector(params)[None]
        r_tr = train_ws.residuals(model, theta, s.fit.refine_solver)
        sig, rho = ar1_noise_mode(ar1_sums(r_tr)[0], r_tr[0].size)
        r_ho = held_ws.residuals(model, theta, s.fit.refine_solver)[0]
        return StepFit(model, params, float(np.sqrt(np.mean(r_tr**2))),
                       float(np.sqrt(np.mean(r_ho**2))),
                       crossfit_window_lpd(r_ho, s.score_dof),
                       np.mean(r_ho**2, axis=1), sig, rho,
                       wall_time_s=time.perf_counter() - t0)

    # ------------------------------------------------------------------ search
    def _search(self, fit: StepFit, train):
        s = self.settings
        data = [one_step_data(r, s.block) for r in train]
        lib = build_library(fit.model, fit.params, data, s.grid, s.library_solver)
        sindy = GroupedSINDy(threshold_t=s.threshold_t, n_models=s.n_bags,
                             chunk_rows=s.chunk_rows, seed=s.seed).fit(lib)
        return lib, sindy, data

    # ------------------------------------------------------------------ the loop
    def _data(self, recordings):
        """The recordings prepared as ``pneubayes fit`` prepares them (inputs low-passed,
        the pressure filter), split into fitting and held-out data: ``(recs, train, held,
        train_ws, held_ws, data_key)``."""
        s = self.settings
        recs = [prepare_recording(r, s.fit.preparation()) for r in recordings]
        if not recs:
            raise ValueError("discover: no recordings")
        if s.holdout_recordings:
            n_held = s.holdout_recordings
            if n_held >= len(recs):
                raise ValueError(f"discover: {n_held} recording(s) held out whole leave none "
                                 f"of the {len(recs)} to fit on")
            train, held = recs[:-n_held], recs[-n_held:]
            held_ws = WindowSet(held, s.fit.horizon_s, s.fit.stride_s)
            more = "more held-out recordings, or shorter windows (--horizon)"
            split = ("recordings", n_held)
        else:
            train, held = split_recordings(recs, s.holdout_fraction, s.fit.horizon_s)
            # the held-out windows are scored on the held-out stretch only; the recording
            # before it is history (warm-up windows carry a heat model's temperature in)
            held_ws = WindowSet(recs, s.fit.horizon_s, s.fit.stride_s,
                                score_from_s=[h.time_s[0] for h in held])
            more = "longer recordings or a larger holdout fraction"
            split = s.holdout_fraction
        train_ws = WindowSet(train, s.fit.horizon_s, s.fit.stride_s)
        if 0.5 ** held_ws.n_windows > s.max_p_value:
            raise ValueError(
                f"discover: only {held_ws.n_windows} held-out {s.fit.horizon_s:g}-s windows; "
                f"the signed-rank test cannot reach p <= {s.max_p_value:g} with fewer than "
                f"{math.ceil(math.log(s.max_p_value) / math.log(0.5))}: give {more}")
        data_key = _fingerprint([r.pressure_Pa.tobytes().hex()[:64] + str(r.n_samples)
                                 for r in recs], split)
        return recs, train, held, train_ws, held_ws, data_key

    def fit(self, recordings) -> "Discovery":
        s = self.settings
        t_start = time.perf_counter()
        recs, train, held, train_ws, held_ws, data_key = self._data(recordings)
        noise = noise_floor_Pa(recs)
        lo, hi = np.percentile(np.concatenate([r.pressure_Pa for r in recs]), [1, 99])
        span = float(hi - lo)  # measured, not the nominal supply's range
        card = recs[0].rig_card
        if any(r.rig_card != card for r in recs):
            raise ValueError("discover: the recordings describe different rigs (rig cards); "
                             "discover on one rig at a time")
        model = Model(rig_card=card)
        start, notes, how = starting_point(model, train, s.fit, noise)
        self.log("discover: base model ("
                 + ("eqs. 1-5, Gompertz maps" if card is None else f"rig card {card.name!r}")
                 + f") from {how}")
        current = self._fit(model, start, train_ws, held_ws, data_key)
        self.log(f"discover: base held-out {s.fit.horizon_s:g}-s RMSE "
                 f"{current.heldout_rmse_Pa:.0f} Pa "
                 f"(noise floor {noise:.0f} Pa)")
        base = current
        ledger = [{"step": 0, "action": "fit base", "model": list(model.effect_names),
                   "start": how, "train_rmse_Pa": current.train_rmse_Pa,
                   "heldout_rmse_Pa": current.heldout_rmse_Pa,
                   "heldout_lpd": current.heldout_lpd}]
        accepted: list[dict] = []
        maps, searches = [], []
        round_, adds, swaps = 0, 0, 0
        while adds < s.max_effects:
            round_ += 1
            sindy, supported, tentative, gap, round_step = self._round_search(
                current, round_, train, train_ws, noise, ledger, maps, searches)
            candidates = supported[: s.max_trials_per_round] + tentative
            ctx = (sindy, train, train_ws, held_ws, data_key, noise, ledger)
            far = (s.gap_fallback_ratio > 0
                   and current.heldout_rmse_Pa > s.gap_fallback_ratio * noise)
            if not candidates and not (gap and s.try_all_on_gap):
                swapped = (self._other_forms(current, ctx)
                           if swaps < s.max_form_swaps and far else None)
                if swapped is not None:
                    current, swaps = swapped, swaps + 1
                    continue
                self.log("discover: no effect is supported; stop")
                break
            tried: dict = {}  # the round's fitted forms: effect -> [(model, fit, start)]
            current, passing = self._trials(candidates, current, ctx, round_trials=tried)
            overflow = [g for g in supported if g not in candidates]
            if not passing and overflow and s.try_all_supported:
                self.log(f"discover: none of the round's first trials passed: trying the "
                         f"other supported groups ({', '.join(overflow)})")
                ledger.append({"step": len(ledger), "action": "more supported",
                               "round": round_, "groups": overflow})
                current, passing = self._trials(overflow, current, ctx, round_trials=tried)
                candidates = candidates + overflow
            rest = [g for g in sindy.ranking_ if g not in candidates]
            gap = gap and current.heldout_rmse_Pa > s.gap_fallback_ratio * noise
            why, closed = last_resort_reason([t[0] for t in passing],
                                             current.heldout_rmse_Pa, noise, s)
            if why and gap and s.try_all_on_gap and rest:
                self.log(f"discover: the held-out error is still "
                         f"{current.heldout_rmse_Pa / noise:.1f} x the noise floor and {why}: "
                         f"trying the rest ({', '.join(rest)})")
                ledger.append({"step": len(ledger), "action": "last resort",
                               "round": round_, "groups": rest,
                               "best_gap_closed_before": closed})
                current, more = self._trials(rest, current, ctx,
                                             s.last_resort_min_gap_closed, tried)
                passing = passing + more
            retry = (runner_ups(ledger, current.model.effect_names, round_step,
                                s.max_p_value)
                     if not passing and s.revisit_runner_ups else [])
            if retry:
                self.log(f"discover: nothing passed this round; revisiting "
                         f"{', '.join(retry)}, which beat an earlier model significantly "
                         "but were not added")
                ledger.append({"step": len(ledger), "action": "revisit", "round": round_,
                               "groups": retry})
                # the search no longer supports them: as in the last resort, a gain
                # must also close a share of the gap (a runner-up beside the tube that
                # explained it gained 0.2 Pa at p = 0.012 on a tuning case)
                current, passing = self._trials(retry, current, ctx,
                                                s.last_resort_min_gap_closed, tried)
            far = far and current.heldout_rmse_Pa > s.gap_fallback_ratio * noise
            if not passing and s.pair_members and far:
                current, passing = self._pairs(tried, current, ctx)
            if not passing and swaps < s.max_form_swaps and far:
                swapped = self._other_forms(current, ctx)
                if swapped is not None:
                    # a named effect in another form: search again beside it
                    current, swaps = swapped, swaps + 1
                    continue
            if not passing:
                self.log("discover: no supported effect passed verification; stop")
                break
            adds += 1
            current = self._add(passing, current, sindy, accepted, ledger, train_ws,
                                held_ws, data_key)
        params, estimate, post = self._estimate(current, train_ws)
        self.result_ = DiscoveryResult(
            settings=s, base=base, final=current, accepted=tuple(accepted),
            ledger=tuple(ledger), maps=tuple(maps), searches=tuple(searches),
            params=params, estimate=estimate, noise_floor_Pa=noise,
            range_Pa=float(recs[0].rig().working_range_Pa), span_Pa=span,
            train=tuple(train), held=tuple(held),
            wall_time_s=time.perf_counter() - t_start, **post)
        return self

    def _round_search(self, current: StepFit, round_: int, train, train_ws: WindowSet,
                      noise: float, ledger: list, maps: list, searches: list):
        """A round's search: the disagreement map and the sparse regression on the
        current model's residual (appended to ``maps``, ``searches`` and ``ledger``), and
        what it supports: ``(sindy, supported, tentative, gap, round_step)`` (tentative:
        the groups below the inclusion threshold tried when the held-out error is
        ``gap_fallback_ratio`` x the noise floor or more, ``gap``)."""
        s = self.settings
        lib, sindy, data = self._search(current, train)
        dmap = self._map(current, train_ws, train, data, noise)
        maps.append(dmap)
        searches.append({"round": round_, "model": list(current.model.effect_names),
                         "evidence": sindy.evidence_, "ranking": sindy.ranking_,
                         "labels": lib.labels, "groups": lib.groups})
        flags = flagged_bins(dmap, "prediction")[:3]
        self.log(f"discover: round {round_}: disagreement in "
                 + (", ".join(f"{f} = {b['bin']} (RMS {b['rms']:.0f} Pa)" for f, b in flags)
                    or "no regime"))
        self.log("discover: evidence " + ", ".join(
            f"{g} {sindy.evidence_[g]['inclusion_probability']:.2f}"
            for g in sindy.ranking_))
        supported = sindy.supported(s.min_inclusion)
        tentative = []
        gap = (s.gap_fallback_ratio > 0
               and current.heldout_rmse_Pa > s.gap_fallback_ratio * noise)
        if gap:
            tentative = [g for g in sindy.supported(s.fallback_min_inclusion)
                         if g not in supported][: s.max_trials_per_round]
            if tentative:
                self.log(f"discover: the held-out error is "
                         f"{current.heldout_rmse_Pa / noise:.1f} x the noise floor: also "
                         f"trying {', '.join(tentative)} (inclusion below "
                         f"{s.min_inclusion:g})")
        round_step = len(ledger)
        ledger.append({"step": len(ledger), "action": "search", "round": round_,
                       "supported": supported, "tentative": tentative,
                       "inclusion": {g: sindy.evidence_[g]["inclusion_probability"]
                                     for g in sindy.ranking_}})
        return sindy, supported, tentative, gap, round_step

    def _add(self, passing, current: StepFit, sindy, accepted: list, ledger: list,
             train_ws: WindowSet, held_ws: WindowSet, data_key) -> StepFit:
        """Add the passing trial with the largest held-out gain (an effect, or a pair),
        record it in ``ledger`` and ``accepted``, and prune what it made redundant."""
        _, g, trial, gain, pval = min(passing, key=lambda t: t[0])
        names = g if isinstance(g, tuple) else (g,)
        self.log(f"discover: ADD {' and '.join(names)} (the largest held-out "
                 "improvement)")
        for name in names:
            ledger.append({"step": len(ledger), "action": "add", "effect": name,
                           "heldout_rmse_before_Pa": current.heldout_rmse_Pa,
                           "heldout_rmse_after_Pa": trial.heldout_rmse_Pa,
                           "score_gain": gain, "score_p_value": pval,
                           **({"pair": list(names)} if len(names) > 1 else {})})
            accepted.append({"name": name, "evidence": sindy.evidence_[name],
                             "score_gain": gain, "score_p_value": pval,
                             "rmse_before_Pa": current.heldout_rmse_Pa,
                             "rmse_after_Pa": trial.heldout_rmse_Pa})
        return self._prune(trial, accepted, ledger, train_ws, held_ws, data_key,
                           newest=len(names))

    def _estimate(self, current: StepFit, train_ws: WindowSet):
        """The final model's parameters: ``(params, how they were estimated, the posterior
        fields of the result)``: the refined point, or with ``posterior`` the posterior
        median and the posterior itself."""
        s = self.settings
        if not s.posterior:
            return dict(current.params), "refined (multiple shooting)", {}
        bi = self._posterior(current, train_ws)
        params = bi.median_params()
        post = {"posterior": bi.inference_data({
                    "seed": s.seed, "pneubayes_version": pneubayes.__version__,
                    "model_card": json.dumps(current.model.to_card(params))}),
                "posterior_summary": bi.summary(),
                "posterior_info": {"method": s.posterior_method,
                                   "converged": bi.converged_,
                                   "steps": bi.diagnostics_["steps"],
                                   "sampling_solver": bi.diagnostics_["solver"],
                                   "solver_roughness_nats":
                                       bi.diagnostics_["solver_jitter_nats"],
                                   "importance_check":
                                       bi.diagnostics_.get("importance_check"),
                                   "mode_on_prior_bound":
                                       bi.diagnostics_.get("mode_on_prior_bound", [])}}
        return params, "posterior median", post

    def _trials(self, candidates, current: StepFit, ctx, min_gap_closed: float = 0.0,
                round_trials: dict | None = None):
        """Fit each candidate group's forms beside ``current``, refit the current model
        from the other parameters of each trial that beats it (a better basin is not the
        effect's gain; :meth:`_controls`), and verify every trial on the held-out
        windows against the final current fit;
        a trial that passes must also close ``min_gap_closed`` of the held-out RMSE's
        gap above the noise floor (with no gap left, none can), and lower the held-out
        RMSE by ``min_gain_noise_share`` of the noise floor and ``min_gain_gap_share``
        of the gap (:func:`~pneubayes.discovery.rounds.min_gain_Pa`). Appends to the ledger
        each effect's fitted forms to ``round_trials`` (effect -> ``[(model, fit, start),
        ...]``, the lowest training RMSE first); returns (current, passing trials)."""
        s = self.settings
        sindy, train, train_ws, held_ws, data_key, noise, ledger = ctx
        trials = []
        options = {g: effect_candidates(current, g, sindy.evidence_[g], train[0].rig(),
                                        s.tube_line_segments, s.tube_line_cutoff_Hz,
                                        s.tube_line_form)
                   for g in candidates}
        round_forms, settled, failed, outpaced = fit_round_forms(
            options, lambda g, m, x, beat: self._fit(m, x, train_ws, held_ws, data_key,
                                                     first_free(m, g), beat),
            s.form_settled_ratio * noise,
            follow=lambda g, m, f: follow_up(current, g, sindy.evidence_[g],
                                             train[0].rig(), m, f.params,
                                             s.tube_line_segments, s.tube_line_cutoff_Hz,
                                             s.tube_line_form),
            current_Pa=current.train_rmse_Pa, min_share=s.later_forms_min_share,
            screen_share=s.later_form_screen_share)
        for g in candidates:
            forms = round_forms[g]
            tried = {id(m) for _, m, _ in forms} | {id(m) for m, _ in failed[g]}
            forms_info = {"train_rmse_Pa": {form_label(m, g): f.train_rmse_Pa
                                            for f, m, _ in forms},
                          "not_fitted": [form_label(m, g) for m, _ in options[g]
                                         if id(m) not in tried],
                          "failed": {form_label(m, g): why for m, why in failed[g]}}
            for m, why in failed[g]:
                self.log(f"discover: {g}: form {m.effect(g).options()} failed ({why}); "
                         "a failed trial")
            if forms_info["not_fitted"] and g in outpaced:
                mine, best = outpaced[g]
                forms_info["not_fitted_why"] = (
                    f"first-form gain {mine:.0f} Pa < {s.later_forms_min_share:g} x the "
                    f"round's best {best:.0f} Pa")
                self.log(f"discover: {g}: {len(forms_info['not_fitted'])} later form(s) "
                         f"not fitted: its first form gains {mine:.0f} Pa in training, "
                         f"under {s.later_forms_min_share:g} x the round's best "
                         f"({best:.0f} Pa)")
            elif forms_info["not_fitted"]:
                sg, sm, sf = settled
                self.log(f"discover: {g}: {len(forms_info['not_fitted'])} later form(s) "
                         f"not fitted: {sg} form {sm.effect(sg).options()} fits at the "
                         f"noise floor (training RMSE {sf.train_rmse_Pa:.0f} Pa)")
            if not forms:
                self.log(f"discover: {g} has no form that fits beside "
                         f"{list(current.model.effect_names)}; skipped")
                continue
            # the effect's form that fits the training data best (never the held-out)
            trial, model2, start2 = min(forms, key=lambda f: f[0].train_rmse_Pa)
            if len(forms) > 1:
                self.log(f"discover: {g}: form {model2.effect(g).options()} fits best "
                         "(training RMSE " + ", ".join(
                             f"{form_label(m, g)} {f.train_rmse_Pa:.0f} Pa"
                             for f, m, _ in forms) + ")")
            trials.append((g, model2, start2, trial, forms_info))
            if round_trials is not None:
                round_trials[g] = sorted(((m, f, x) for f, m, x in forms),
                                         key=lambda mfx: mfx[1].train_rmse_Pa)
        # every trial against the final current fit, and against its own control (the
        # current model in the trial's basin, which may predict the held-out part better
        # than the current fit at no better training error: that gain is the basin's,
        # not the effect's); the best that passes both is added
        controls, current = self._controls([(t[0], t[3]) for t in trials], current, ctx)
        passing = []
        gap_Pa = current.heldout_rmse_Pa - noise
        for (g, model2, start2, trial, forms_info), control in zip(trials, controls):
            ok, gain, pval, diff = self._better(trial, current)
            basin = False
            if ok and control is not None and control is not current:
                basin = not self._better(trial, control)[0]
                if basin:
                    self.log(f"discover: {g}: its held-out gain is its basin's: the current "
                             f"model refitted from the trial's point predicts "
                             f"{control.heldout_rmse_Pa:.0f} Pa against the trial's "
                             f"{trial.heldout_rmse_Pa:.0f} Pa")
            ok = ok and not basin
            drop_Pa = current.heldout_rmse_Pa - trial.heldout_rmse_Pa
            least = min_gain_Pa(noise, gap_Pa, s)
            closed, short, under = gain_shortfall(drop_Pa, gap_Pa, min_gap_closed, least)
            small, tiny = ok and short, ok and under
            ok = ok and not small and not tiny
            names = model2.effect(g).parameter_names()
            ledger.append({
                "step": len(ledger), "action": "pass" if ok else "reject", "effect": g,
                "gap_closed": closed, "gain_under_floor": bool(tiny), "min_gain_Pa": least,
                "effect_options": model2.effect(g).options(), "forms": forms_info,
                "start": {k: start2[k] for k in names},
                "fitted": {k: trial.params[k] for k in names},
                "heldout_rmse_before_Pa": current.heldout_rmse_Pa,
                "heldout_rmse_after_Pa": trial.heldout_rmse_Pa,
                "score_gain": gain, "score_p_value": pval,
                "control_heldout_rmse_Pa": None if control is None else
                control.heldout_rmse_Pa,
                "not_better_than_control": basin,
                "windows_improved": int(np.sum(diff > 0)), "windows": int(diff.size),
                "evidence": sindy.evidence_[g], "wall_time_s": trial.wall_time_s})
            self.log(f"discover: {'passes' if ok else 'reject'} {g}: held-out RMSE "
                     f"{current.heldout_rmse_Pa:.0f} -> {trial.heldout_rmse_Pa:.0f} Pa, "
                     f"better in {int(np.sum(diff > 0))}/{diff.size} windows "
                     f"(p = {pval:.2g}), log predictive gain {gain:.1f}"
                     + (f"; it closes {100 * (closed or 0.0):.0f} % of the gap, under "
                        f"{100 * min_gap_closed:.0f} %" if small else "")
                     + (f"; it gains {drop_Pa:.1f} Pa, under {least:.1f} Pa (the larger of "
                        f"{s.min_gain_noise_share:g} x the noise floor and "
                        f"{s.min_gain_gap_share:g} x the gap)" if tiny else ""))
            if ok:
                passing.append((trial.heldout_rmse_Pa, g, trial, gain, pval))
        return current, passing

    def _better(self, new: StepFit, old: StepFit):
        return compare_heldout(new, old, self.settings.max_p_value)

    def _prune(self, current: StepFit, accepted: list, ledger: list, train_ws, held_ws,
               data_key, newest: int = 1) -> StepFit:
        """Backward step: drop an earlier effect the ``newest`` added ones have made
        unnecessary (an effect that only stood in for a newcomer)."""
        for a in list(accepted[:-newest]):
            name = a["name"]
            reduced = current.model.without(name)
            fit = self._fit(reduced, {k: current.params[k] for k in reduced.parameter_names},
                            train_ws, held_ws, data_key)
            needed, gain, pval, _ = self._better(current, fit)
            if needed:
                continue
            self.log(f"discover: REMOVE {name}: without it held-out RMSE "
                     f"{current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa "
                     f"(its gain is no longer significant, p = {pval:.2g})")
            ledger.append({"step": len(ledger), "action": "remove", "effect": name,
                           "heldout_rmse_before_Pa": current.heldout_rmse_Pa,
                           "heldout_rmse_after_Pa": fit.heldout_rmse_Pa,
                           "score_gain": -gain, "score_p_value": pval})
            accepted.remove(a)
            current = fit
        return current

    def _map(self, fit: StepFit, train_ws: WindowSet, train, data, noise: float) -> dict:
        s = self.settings
        theta = fit.model.vector(fit.params)[None]
        res = train_ws.simulate(fit.model, theta, s.fit.refine_solver)[0] - train_ws.measured
        per_rec, starts, one = [], [], []
        k = 0
        for b, d in zip(train_ws.blocks, data):
            w = b.starts.size
            per_rec.append(res[k:k + w])
            starts.append(b.starts)
            k += w
            p = np.asarray(d.recording.pressure_Pa, dtype=np.float64)
            one.append(p[1:] - d.predict(fit.model, theta, s.library_solver)[0])
        return disagreement_map(fit.model, fit.params, train, per_rec, starts,
                                train_ws.length, one, noise, s.regimes)

    def _posterior(self, fit: StepFit, train_ws: WindowSet):
        s = self.settings
        ref = TrajectoryRefiner(fit.model, s.fit.refine_solver, max_nfev=1)
        start = fit.params
        info = None
        try:  # the Laplace approximation at the refined point sizes the walker ball
            info = ref.fit(train_ws, start).information_
        except FloatingPointError:
            info = None
        if s.posterior_method == "laplace":
            if info is None:
                raise FloatingPointError("discover: the Laplace posterior needs the refined "
                                         "point's information, and it cannot be taken")
            self.log(f"discover: Laplace posterior of "
                     f"{list(fit.model.effect_names) or 'the base'} model")
            return LaplaceIdentification.from_sampler(
                fit.model, s.fit.sample_solver, s.fit.sampler, s.laplace_draws,
                s.laplace_check_draws, self.log).fit(train_ws, start, info)
        backend = None if self.out_dir is None else self.out_dir / "chain.h5"
        bi = BayesianIdentification(fit.model, s.fit.sample_solver, s.fit.sampler,
                                    backend_path=backend, progress=False, log=self.log)
        self.log(f"discover: emcee posterior of {list(fit.model.effect_names) or 'the base'}"
                 " model")
        if backend is not None:
            moved = set_aside_other_chain(backend, fit.model, train_ws)
            if moved is not None:
                self.log(f"discover: {backend.name} held the chain of another posterior (an "
                         f"earlier run's final model); kept as {moved.name}")
        bi.fit(train_ws, start, information=info)
        self.log(f"discover: emcee {bi.diagnostics_['steps']} steps, converged "
                 f"{bi.converged_}, {bi.wall_time_s_:.0f} s (solver rtol {bi.solver_.rtol:.0e}, "
                 f"log-density roughness {bi.diagnostics_['solver_jitter_nats']:.2f} nat)")
        return bi


def discover(recordings, settings: DiscoverySettings, checkpoint_dir=None,
             log=None) -> DiscoveryResult:
    """Run the discovery loop on ``recordings`` in memory; returns its
    :class:`DiscoveryResult` (``checkpoint_dir``: a folder for the step cache, so an
    interrupted run resumes; ``log``: progress lines, None for silent)."""
    return Discovery(settings, checkpoint_dir, log).fit(recordings).result_
