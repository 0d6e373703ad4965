"""The name-add-refit loop: fit, map the disagreement, search, name, add, verify, repeat.

Starting from the plain thin-port model (eqs. 1-5 with Gompertz maps):

1. **Fit** on the training part of every recording (the first ``1 - holdout_fraction``
   of its samples, or all but the last ``data.holdout_recordings``): the paper's least
   squares where possible, then 2-s multiple shooting (:mod:`pneubayes.inference`).
2. **Map** the disagreement (:mod:`~pneubayes.discovery.disagreement`).
3. **Search**: grouped SINDy on the one-step residual (:mod:`~pneubayes.discovery.library`,
   :mod:`~pneubayes.discovery.sindy`); while the held-out error is ``rounds.gap_fallback_ratio``
   x the noise floor or more, weakly supported groups are tried too.
4. **Trials**: the ``max_trials_per_round`` best-supported effects are each added in
   the forms they propose, refitted, and verified on the held-out windows against the
   current fit and their control (:mod:`~pneubayes.discovery.trials`).
5. **Stages**: the pipeline's stages, in order (:mod:`~pneubayes.discovery.stages`:
   the other supported groups, the last resort, the catalogue sweep, runner-ups, pairs,
   other forms).
6. **Add** the passing trial with the lowest held-out RMSE and **prune** each earlier
   effect the newcomer made unnecessary; **repeat** until nothing passes.

The final model gets a posterior on the training data. A ledger records every step
(:class:`~pneubayes.discovery.state.Ledger`); finished fits are cached in
``RUNDIR/steps`` so an interrupted run resumes. The held-out score is a plug-in log
predictive density (:func:`~pneubayes.discovery.verification.crossfit_window_lpd`).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

import pneubayes
from pneubayes.discovery.disagreement import disagreement_map, flagged_bins
from pneubayes.discovery.library import build_library
from pneubayes.discovery.one_step import one_step_data
from pneubayes.discovery.result import DiscoveryResult
from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.discovery.sindy import GroupedSINDy
from pneubayes.discovery.stages import Stage, default_stages
from pneubayes.discovery.state import Ledger, LoopData, RoundState
from pneubayes.discovery.trials import TrialRunner, fingerprint
from pneubayes.discovery.verification import StepFit, split_recordings
from pneubayes.errors import SimulationError
from pneubayes.inference.chain_store import set_aside_other_chain
from pneubayes.inference.laplace import LaplaceIdentification
from pneubayes.inference.pipeline import starting_point
from pneubayes.inference.predictive import noise_floor_Pa
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.sampler import BayesianIdentification
from pneubayes.inference.windows import WindowSet
from pneubayes.io.preprocess import prepare_recording
from pneubayes.model import Model


def _silent(message: str) -> None:
    """A log that drops its messages."""


class Discovery:
    """The loop (scikit-learn-style: configure, then :meth:`fit`, which returns the
    estimator with its answer in ``result_``, a :class:`DiscoveryResult`).

    Parameters
    ----------
    settings : DiscoverySettings
        Every setting of the search, the fits and the verification.
    out_dir : path or None
        Run folder for the step cache (resume); None keeps everything in memory.
    log : callable or None
        Progress messages (None: silent).
    stages : list of Stage or None
        The pipeline run after each round's trials (:mod:`pneubayes.discovery.stages`);
        None: the one ``settings`` describe (:func:`default_stages`); ``[]``: the plain
        search, name, add, refit, verify loop.
    """

    def __init__(self, settings: DiscoverySettings, out_dir=None, log=print,
                 stages: list[Stage] | None = None):
        self.settings = settings
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.log = log if log is not None else _silent
        self.stages = stages

    # ------------------------------------------------------------------ search
    def _search(self, fit: StepFit, train):
        s = self.settings
        data = [one_step_data(r, s.search.block) for r in train]
        lib = build_library(fit.model, fit.params, data, s.search.grid, s.search.solver)
        sindy = GroupedSINDy(threshold_t=s.search.threshold_t, n_models=s.search.n_bags,
                             chunk_rows=s.search.chunk_rows, seed=s.seed).fit(lib)
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
        if s.data.holdout_recordings:
            n_held = s.data.holdout_recordings
            if n_held >= len(recs):
                raise ValueError(f"discover: {n_held} recording(s) held out whole leave none "
                                 f"of the {len(recs)} to fit on")
            train, held = recs[:-n_held], recs[-n_held:]
            held_ws = WindowSet(held, s.fit.horizon_s, s.fit.stride_s)
            more = "more held-out recordings, or shorter windows (--horizon)"
            split = ("recordings", n_held)
        else:
            train, held = split_recordings(recs, s.data.holdout_fraction, s.fit.horizon_s)
            # the held-out windows are scored on the held-out stretch only; the recording
            # before it is history (warm-up windows carry a heat model's temperature in)
            held_ws = WindowSet(recs, s.fit.horizon_s, s.fit.stride_s,
                                score_from_s=[h.time_s[0] for h in held])
            more = "longer recordings or a larger holdout fraction"
            split = s.data.holdout_fraction
        train_ws = WindowSet(train, s.fit.horizon_s, s.fit.stride_s)
        if 0.5 ** held_ws.n_windows > s.verify.max_p_value:
            raise ValueError(
                f"discover: only {held_ws.n_windows} held-out {s.fit.horizon_s:g}-s windows; "
                f"the signed-rank test cannot reach p <= {s.verify.max_p_value:g} with fewer than "
                f"{math.ceil(math.log(s.verify.max_p_value) / math.log(0.5))}: give {more}")
        data_key = fingerprint([r.pressure_Pa.tobytes().hex()[:64] + str(r.n_samples)
                                for r in recs], split)
        return recs, train, held, train_ws, held_ws, data_key

    def fit(self, recordings) -> "Discovery":
        s = self.settings
        t_start = time.perf_counter()
        self._deadline = (t_start + s.rounds.max_seconds if s.rounds.max_seconds > 0
                          else math.inf)
        self._stopped_for_time = False
        recs, train, held, train_ws, held_ws, data_key = self._data(recordings)
        noise = noise_floor_Pa(recs)
        lo, hi = np.percentile(np.concatenate([r.pressure_Pa for r in recs]), [1, 99])
        span = float(hi - lo)  # measured, not the nominal supply's range
        card = recs[0].rig_card
        if any(r.rig_card != card for r in recs):
            raise ValueError("discover: the recordings describe different rigs (rig cards); "
                             "discover on one rig at a time")
        stages = default_stages(s) if self.stages is None else list(self.stages)
        ledger = Ledger()
        runner = TrialRunner(s, LoopData(tuple(train), tuple(held), train_ws, held_ws,
                                         data_key, noise), ledger, self.out_dir, self.log,
                             deadline_s=self._deadline)
        model = Model(rig_card=card)
        start, notes, how = starting_point(model, train, s.fit, noise)
        self.log("discover: base model ("
                 + ("eqs. 1-5, Gompertz maps" if card is None else f"rig card {card.name!r}")
                 + f") from {how}")
        current = runner.fit(model, start)
        self.log(f"discover: base held-out {s.fit.horizon_s:g}-s RMSE "
                 f"{current.heldout_rmse_Pa:.0f} Pa "
                 f"(noise floor {noise:.0f} Pa)")
        base = current
        ledger.record("fit base", model=list(model.effect_names), start=how,
                      train_rmse_Pa=current.train_rmse_Pa,
                      heldout_rmse_Pa=current.heldout_rmse_Pa,
                      heldout_lpd=current.heldout_lpd)
        accepted: list[dict] = []
        maps, searches, counts = [], [], {}
        round_, adds = 0, 0
        while adds < s.rounds.max_effects:
            if self._out_of_time(ledger, f"before round {round_ + 1}"):
                break
            round_ += 1
            try:
                state = self._round_search(current, round_, runner, maps, searches, counts)
            except SimulationError as exc:
                # the search's trial terms or sensitivities cannot be simulated beside
                # the current model: nothing more can be searched for
                self.log(f"discover: round {round_}: the search cannot simulate its "
                         f"candidates beside the current model ({str(exc).splitlines()[0]});"
                         " stop")
                ledger.record("search failed", round=round_,
                              error=str(exc).splitlines()[0])
                break
            current = self._run_round(state, stages, runner)
            if state.replacement is not None:
                continue  # a stage reshaped the model: search again beside it
            if not state.passing:
                self.log("discover: no effect is supported; stop" if state.exhausted else
                         "discover: no supported effect passed verification; stop")
                break
            adds += 1
            current = self._add(state, accepted, runner)
        params, estimate, post = self._estimate(current, train_ws, ledger)
        self.result_ = DiscoveryResult(
            settings=s, base=base, final=current, accepted=tuple(accepted),
            ledger=ledger.events(), maps=tuple(maps), searches=tuple(searches),
            params=params, estimate=estimate, noise_floor_Pa=noise,
            range_Pa=float(recs[0].rig().working_range_Pa), span_Pa=span,
            train=tuple(train), held=tuple(held),
            wall_time_s=time.perf_counter() - t_start,
            stages=tuple({"stage": st.name, **st.options()} for st in stages), **post)
        return self

    def _out_of_time(self, ledger: Ledger, where: str) -> bool:
        """Whether ``rounds.max_seconds`` is spent; the first time, logged and recorded
        (where the loop stopped)."""
        if time.perf_counter() <= self._deadline:
            return False
        if not self._stopped_for_time:
            self._stopped_for_time = True
            budget = self.settings.rounds.max_seconds
            self.log(f"discover: the time budget ({budget:g} s, rounds.max_seconds) is "
                     f"spent {where}: no further stage or round starts")
            ledger.record("time budget", max_seconds=budget, where=where)
        return True

    def _run_round(self, state: RoundState, stages: list[Stage], runner: TrialRunner
                   ) -> StepFit:
        """The round's first trials, then its stages in order (until one reshapes the
        model). A round whose search supported nothing goes on only if a stage opens it
        (the last resort far above the noise floor, the catalogue sweep near it); otherwise
        only the stages that reshape the model run. Returns the round's current fit, or
        the replacement."""
        candidates = state.supported[: self.settings.rounds.max_trials_per_round] + state.tentative
        state.candidates = list(candidates)
        empty = not candidates and not any(st.opens_empty_round(state) for st in stages)
        state.exhausted = empty
        if not empty:
            # a tentative group (tried on weak evidence, far above the noise) must close
            # the share of the gap an effect the last resort tries must: weak evidence
            # and a small gain is how a stand-in enters
            state.passing = runner.trials(
                candidates, state,
                {g: self.settings.stages.last_resort_min_gap_closed for g in state.tentative})
        for stage in stages:
            if empty and not stage.reshapes:
                continue
            if self._out_of_time(runner.ledger, f"round {state.number}, before stage "
                                 f"{stage.name}"):
                break
            stage.run(state, runner)
            if state.replacement is not None:
                return state.replacement
        return state.current

    def _round_search(self, current: StepFit, round_: int, runner: TrialRunner,
                      maps: list, searches: list, counts: dict) -> RoundState:
        """A round's search: the disagreement map and the sparse regression on the
        current model's residual (appended to ``maps``, ``searches`` and the ledger),
        and what it supports: the round's state (tentative: the groups below the
        inclusion threshold tried when the held-out error is ``rounds.gap_fallback_ratio`` x
        the noise floor or more)."""
        s, d = self.settings, runner.data
        noise = d.noise_Pa
        lib, sindy, data = self._search(current, d.train)
        dmap = self._map(current, d.train_ws, d.train, data, noise)
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
        supported = sindy.supported(s.search.min_inclusion)
        tentative = []
        far = (s.rounds.gap_fallback_ratio > 0
               and current.heldout_rmse_Pa > s.rounds.gap_fallback_ratio * noise)
        if far:
            tentative = [g for g in sindy.supported(s.search.fallback_min_inclusion)
                         if g not in supported][: s.rounds.max_trials_per_round]
            if tentative:
                self.log(f"discover: the held-out error is "
                         f"{current.heldout_rmse_Pa / noise:.1f} x the noise floor: also "
                         f"trying {', '.join(tentative)} (inclusion below "
                         f"{s.search.min_inclusion:g})")
        apart = lib.meta["not_steppable"]
        if apart:
            self.log(f"discover: not searched: {', '.join(apart)} (the simulator cannot "
                     "step them beside this model)")
        search_step = len(runner.ledger)
        runner.ledger.record("search", round=round_, supported=supported, tentative=tentative,
                             not_steppable=apart,
                             inclusion={g: sindy.evidence_[g]["inclusion_probability"]
                                        for g in sindy.ranking_})
        return RoundState(number=round_, current=current, search=sindy, supported=supported,
                          tentative=tentative, started_far=far,
                          gap_ratio=s.rounds.gap_fallback_ratio, noise_Pa=noise,
                          search_step=search_step, counts=counts)

    def _add(self, state: RoundState, accepted: list, runner: TrialRunner) -> StepFit:
        """Add the passing trial with the lowest held-out RMSE (an effect, or a pair),
        record it in the ledger and ``accepted``, and prune what it made redundant."""
        current = state.current
        _, g, trial, gain, pval = min(state.passing, key=lambda t: t[0])
        names = g if isinstance(g, tuple) else (g,)
        self.log(f"discover: ADD {' and '.join(names)} (the largest held-out "
                 "improvement)")
        for name in names:
            runner.ledger.record("add", effect=name,
                                 heldout_rmse_before_Pa=current.heldout_rmse_Pa,
                                 heldout_rmse_after_Pa=trial.heldout_rmse_Pa,
                                 score_gain=gain, score_p_value=pval,
                                 **({"pair": list(names)} if len(names) > 1 else {}))
            accepted.append({"name": name, "evidence": state.evidence_of(name),
                             "score_gain": gain, "score_p_value": pval,
                             "rmse_before_Pa": current.heldout_rmse_Pa,
                             "rmse_after_Pa": trial.heldout_rmse_Pa})
        return runner.prune(trial, accepted, newest=len(names))

    def _estimate(self, current: StepFit, train_ws: WindowSet, ledger: Ledger):
        """The final model's parameters: ``(params, how they were estimated, the posterior
        fields of the result)``: the refined point, or with ``posterior`` the posterior
        median and the posterior itself. A Laplace posterior that cannot be taken (no
        finite density near the mode) leaves the refined point, said in the log, the
        ledger and the estimate: the discovery stands without its posterior."""
        s = self.settings
        if not s.posterior.sampled:
            return dict(current.params), "refined (multiple shooting)", {}
        try:
            bi = self._posterior(current, train_ws)
        except FloatingPointError as exc:
            if s.posterior.method != "laplace":
                raise
            why = str(exc).splitlines()[0]
            self.log(f"discover: the Laplace posterior failed ({why}); the result is the "
                     "refined point, without a posterior (posterior.method 'emcee' samples "
                     "it)")
            ledger.record("posterior failed", method="laplace", error=why)
            return (dict(current.params),
                    "refined (multiple shooting; the Laplace posterior failed)", {})
        params = bi.median_params()
        post = {"posterior": bi.inference_data({
                    "seed": s.seed, "pneubayes_version": pneubayes.__version__,
                    "model_card": json.dumps(current.model.to_card(params))}),
                "posterior_summary": bi.summary(),
                "posterior_info": {"method": s.posterior.method,
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
            one.append(p[1:] - d.predict(fit.model, theta, s.search.solver)[0])
        return disagreement_map(fit.model, fit.params, train, per_rec, starts,
                                train_ws.length, one, noise, s.search.regimes)

    def _posterior(self, fit: StepFit, train_ws: WindowSet):
        s = self.settings
        ref = TrajectoryRefiner(fit.model, s.fit.refine_solver, max_nfev=1)
        start = fit.params
        info = None
        try:  # the Laplace approximation at the refined point sizes the walker ball
            info = ref.fit(train_ws, start).information_
        except FloatingPointError:
            info = None
        if s.posterior.method == "laplace":
            if info is None:
                raise FloatingPointError("discover: the Laplace posterior needs the refined "
                                         "point's information, and it cannot be taken")
            self.log(f"discover: Laplace posterior of "
                     f"{list(fit.model.effect_names) or 'the base'} model")
            return LaplaceIdentification.from_sampler(
                fit.model, s.fit.sample_solver, s.fit.sampler, s.posterior.laplace_draws,
                s.posterior.laplace_check_draws, self.log).fit(train_ws, start, info)
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
    """Run the discovery loop on ``recordings`` in memory.

    Parameters
    ----------
    recordings : sequence of Recording
        Every recording; the settings say which parts are held out.
    settings : DiscoverySettings
        Every setting of the loop.
    checkpoint_dir : path or None
        A folder for the step cache, so an interrupted run resumes.
    log : callable or None
        Receives progress lines (None: silent).

    Returns
    -------
    DiscoveryResult
    """
    return Discovery(settings, checkpoint_dir, log).fit(recordings).result_
