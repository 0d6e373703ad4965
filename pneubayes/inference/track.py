"""Replay a recording as a stream (``pneubayes track``) through an
:class:`~pneubayes.inference.online.OnlineTracker` (particles) or an
:class:`~pneubayes.inference.online_refit.OnlineRefit` (the run so far refitted,
anchored): per tick the varying quantities' quantiles and the error of the prediction
``horizon_s`` ahead from the measured pressure, next to the frozen fit's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.inference.conformal import OnlineConformalBand
from pneubayes.inference.fit_folder import card_preparation, prepare_as_fitted
from pneubayes.inference.online import OnlineTracker, forecast
from pneubayes.inference.online_refit import OnlineRefit
from pneubayes.inference.population import LogNormalPrior, LogUniformPrior
from pneubayes.io.plausibility import recorded_findings
from pneubayes.model import Model
from pneubayes.run_folder import recorded_number
from pneubayes.simulation import Inputs, SolverConfig

#: ``pneubayes track``'s methods: the particle filter, or the anchored refit
METHODS = ("particles", "refit")


def replay(tracker: OnlineTracker | OnlineRefit, recording, horizon_s: float, tick_s: float,
           n_draws: int, rng: np.random.Generator, predict_every: int = 1,
           frozen=None) -> list[dict]:
    """Feed ``recording`` to ``tracker`` one tick of ``tick_s`` at a time.

    Parameters
    ----------
    tracker : OnlineTracker or OnlineRefit
        Already reset. An :class:`OnlineRefit` is given the run up to each tick's last
        sample (it refits every ``refit_every_s``); its errors' scale is ``error_Pa``.
    recording : Recording
    horizon_s : float
        Length of the predictions, s.
    tick_s : float
        Seconds of samples per update; ticks end on samples 0, m, 2m, ...
    n_draws : int
        Resampled particles per prediction.
    rng : numpy.random.Generator
        For the draws and the band's errors.
    predict_every : int
        Predict every this many ticks (while ``horizon_s`` more samples follow).
    frozen : (P,) ndarray or None
        A parameter vector whose prediction error on the same samples is recorded.

    Returns
    -------
    list of dict
        One record per tick: ``time_s``, ``update_ms`` (the update's wall time),
        ``ess``, ``quantiles`` (each varying quantity's 5/50/95 %) and, where predicted,
        ``prediction_rmse_Pa`` (of the mean of the draws' predictions, or for an
        :class:`OnlineRefit` of its posterior mode's prediction, from the measured
        pressure, :func:`~pneubayes.inference.online.forecast`), ``coverage_90`` and
        ``band_90_width_Pa`` (the draws' predictions plus the tracker's Gaussian
        errors), ``conformal_coverage_90`` and ``conformal_band_90_width_Pa`` (that band
        rescaled by the run's completed predictions,
        :class:`~pneubayes.inference.conformal.OnlineConformalBand`) and
        ``frozen_rmse_Pa``.
    """
    import time

    t = np.asarray(recording.time_s, dtype=np.float64)
    p = np.asarray(recording.pressure_Pa, dtype=np.float64)
    dt = float(np.median(np.diff(t)))
    h = int(round(horizon_s / dt))
    m = max(1, int(round(tick_s / dt)))
    inputs = Inputs.from_recording(recording)
    ue = recording.exhaust_command()
    x, ps = recording.position_or_fixed(), recording.supply_or_nominal()
    rig = recording.rig()
    refit = isinstance(tracker, OnlineRefit)
    sigma = float(tracker.error_Pa if refit else tracker.noise_std_Pa)
    band = OnlineConformalBand(coverage=0.9)
    out = []
    # ticks end on samples 0, m, 2m, ... (the first tick: the first sample alone)
    bounds = [0, *range(1, t.size, m), t.size]
    for j, (k0, k1) in enumerate(zip(bounds[:-1], bounds[1:])):
        c0 = time.perf_counter()
        if refit:
            tracker.update(recording, stop=k1)
        else:
            tracker.update(t[k0:k1], recording.command_V[k0:k1], p[k0:k1],
                           None if ue is None else ue[k0:k1], x[k0:k1], ps[k0:k1])
        rec = {"time_s": float(t[k1 - 1]), "update_ms": 1e3 * (time.perf_counter() - c0),
               "ess": None if refit else tracker.ess_, "quantiles": tracker.quantiles()}
        k = k1 - 1
        band.observe(k, p[:k + 1])
        if j % predict_every == 0 and k + h < t.size and k >= 1:
            y = p[k + 1:k + h + 1]
            sims = forecast(tracker.model, tracker.draws(n_draws, rng), inputs, rig, k,
                            h + 1, p, tracker.solver)[:, 1:]
            sims = sims[np.all(np.isfinite(sims), axis=1)]
            if sims.shape[0]:
                noisy = sims + rng.normal(0.0, sigma, size=sims.shape)
                lo, hi = np.quantile(noisy, [0.05, 0.95], axis=0)
                point = sims.mean(0)
                if refit:  # the refit's estimate is its posterior mode
                    point = forecast(tracker.model, tracker.model.vector(tracker.params_)[None],
                                     inputs, rig, k, h + 1, p, tracker.solver)[0, 1:]
                rec["prediction_rmse_Pa"] = float(np.sqrt(np.mean((point - y) ** 2)))
                rec["coverage_90"] = float(np.mean((y >= lo) & (y <= hi)))
                rec["band_90_width_Pa"] = float(np.median(hi - lo))
                c_lo, c_hi = band.predict(k, *band.centre_and_scale(sims, sigma))
                rec["conformal_coverage_90"] = float(np.mean((y >= c_lo) & (y <= c_hi)))
                rec["conformal_band_90_width_Pa"] = float(np.median(c_hi - c_lo))
            if frozen is not None:
                f = forecast(tracker.model, frozen[None], inputs, rig, k, h + 1, p,
                             tracker.solver)[0, 1:]
                rec["frozen_rmse_Pa"] = float(np.sqrt(np.mean((f - y) ** 2)))
        out.append(rec)
    return out


def _summary(ticks: list[dict]) -> dict:
    def pooled(key):
        v = [r[key] for r in ticks if key in r]
        return float(np.sqrt(np.mean(np.square(v)))) if v else None
    cov = [r["coverage_90"] for r in ticks if "coverage_90" in r]
    ccov = [r["conformal_coverage_90"] for r in ticks if "conformal_coverage_90" in r]
    ms = np.array([r["update_ms"] for r in ticks])
    return {"ticks": len(ticks), "predicted_ticks": len(cov),
            "online_rmse_Pa": pooled("prediction_rmse_Pa"),
            "frozen_rmse_Pa": pooled("frozen_rmse_Pa"),
            "coverage_90": float(np.mean(cov)) if cov else None,
            "conformal_coverage_90": float(np.mean(ccov)) if ccov else None,
            "update_ms_median": float(np.median(ms)) if ms.size else None,
            "update_ms_p95": float(np.percentile(ms, 95)) if ms.size else None}


def run_track(run_dir, recording, vary, out_json, *, tick_s: float, horizon_s: float,
              n_particles: int, n_draws: int, seed: int, noise_std_Pa: float | None,
              prior: str, prior_log_sd: float, solver: SolverConfig,
              predict_every: int = 1, tracker_options=None, method: str = "particles",
              refit_options=None) -> dict:
    """Replay ``recording`` against the model of ``run_dir`` (its ``model.json``) with
    the quantities ``vary`` tracked, the others at the run's values; write the ticks and
    a summary to ``out_json`` (atomically) and return the summary.

    ``method``: ``"particles"`` (:class:`OnlineTracker`, its options
    ``tracker_options``) or ``"refit"`` (:class:`OnlineRefit` anchored at the run's
    values, its options ``refit_options``: ``relative_sd``, ``refit_every_s``,
    ``max_nfev``). ``prior`` (particles): ``"fit"`` (log-normal at the run's values,
    log-spread ``prior_log_sd``) or ``"bounds"`` (log-uniform over the model's bounds).
    ``noise_std_Pa`` None: the run's refined RMSE (its ``summary.json`` or
    ``discovery.json``), the errors' scale of either method."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    run = Path(run_dir)
    card = Model.read_card(run / "model.json")
    model, params = Model.from_card(card, str(run / "model.json"))
    if model.rig_card != recording.rig_card:
        raise ValueError(f"{recording.source}: describes another rig than the run {run} "
                         "(give --rig CARD if the sidecar names none)")
    names = list(vary)
    unknown = [n for n in names if n not in model.parameter_names]
    if unknown:
        raise ValueError(f"--vary: {', '.join(unknown)} not a parameter of {run}/model.json; "
                         f"it has {', '.join(model.parameter_names)}")
    if noise_std_Pa is None:
        noise_std_Pa = run_rmse_Pa(run)
    recording = prepare_as_fitted(recording, card_preparation(card, run / "model.json"),
                                  run / "model.json")
    rng = np.random.default_rng(seed)
    settings = {"method": method, "vary": names, "tick_s": tick_s, "horizon_s": horizon_s,
                "n_draws": n_draws, "seed": seed, "noise_std_Pa": noise_std_Pa,
                "predict_every": predict_every}
    if method == "refit":
        opts = {"refit_every_s": horizon_s, **(refit_options or {})}
        tracker = OnlineRefit(model, params, names, solver=solver, error_Pa=noise_std_Pa,
                              horizon_s=horizon_s, **opts).reset()
        settings["refit"] = {k: getattr(tracker, k) for k in (
            "relative_sd", "error_Pa", "memory_s", "refit_every_s", "max_nfev", "min_windows")}
    else:
        if prior == "fit":
            pr = LogNormalPrior(model, names, {n: params[n] for n in names},
                                {n: prior_log_sd for n in names})
        else:
            pr = LogUniformPrior(model, names)
        tracker = OnlineTracker(model, params, pr, recording.rig(), solver, noise_std_Pa,
                                n_particles=n_particles, **(tracker_options or {})).reset(rng)
        settings.update(n_particles=n_particles, prior=pr.describe(), tracker={
            k: getattr(tracker, k) for k in (
                "lookback_s", "warm_up_windows", "temper", "ess_threshold", "n_moves",
                "move_scale", "move_floor_log", "memory_s", "history_s", "update_mode",
                "pressure_gain")})
    ticks = replay(tracker, recording, horizon_s, tick_s, n_draws, rng, predict_every,
                   frozen=model.vector(params))
    summary = _summary(ticks)
    write_json_atomic(out_json, {"run": str(run), "recording": str(recording.source),
                                 "input_findings": recorded_findings([recording]),
                                 "settings": settings, "summary": summary,
                                 "final_quantiles": tracker.quantiles(), "ticks": ticks})
    return summary


def run_rmse_Pa(run: Path) -> float:
    """A run folder's refined window RMSE, Pa (``summary.json``'s or the discovery's final
    one); ValueError when it records none."""
    rmse = recorded_number(run, (("summary.json", ("refined", "rmse_Pa")),
                                 ("discovery.json", ("rmse_final_Pa",))))
    if rmse is not None:
        return rmse
    raise ValueError(f"{run}: records no refined RMSE (summary.json or discovery.json); "
                     "give --noise-std, the model's prediction error in Pa")
