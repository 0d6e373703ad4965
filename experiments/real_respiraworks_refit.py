"""Real recordings: the ventilator's whole card refitted online, anchored (issue 67).

    python experiments/real_respiraworks_refit.py --out results/real_respiraworks_refit
        [--sets OXY,AIR] [--smoke] [--spread-anchors] [--data DIR] [--held-out RUN ...]

The shipped card (two compartments, the exhale valve on its own command), the split of
``real_respiraworks.py`` (runs 1-4 train, 5-6 held out; ``--held-out`` and ``--data`` as
there) and the protocol of
``real_respiraworks_online.py``: on each held-out run, at every 2-s window start from
the run's first ``CAL_S`` s, the next 2 s are predicted from the measured pressure, the
model brought there by warm-up windows. Per set:

1. *Shared fit*: every quantity refined on the training runs (``shared_fit``).
2. *Choice of the anchor, on the training runs only*: for each training run, a shared
   fit of the other three, then :class:`~pneubayes.inference.online_refit.OnlineRefit`
   through the run (every quantity of the card, refitted at each window start on the
   run so far, anchored to that shared fit); the anchor's relative SD and error scale
   and the refit's evaluations per window (``GRID``) with the lowest error over the four
   runs are kept, and those runs' prediction errors give the band's scale. The held-out
   runs choose nothing. With ``--spread-anchors`` the choice is also among anchors of
   each quantity's own width: how far it moves from run to run, the spread of fits of
   each other training run alone about the shared fit
   (:func:`~pneubayes.inference.refine.relative_spread`), times ``SPREAD_FACTORS``.
3. *Held out*: the same through runs 5-6 from the shared fit of runs 1-4, with the
   chosen anchor; the 90 % band is ``N_DRAWS`` Laplace draws' predictions plus Gaussian
   errors of the band's scale (seeded). Beside it on the same windows: the set-point,
   the frozen shared fit, and the same refit without the anchor.
4. *The exhale valve's form*: on its own command (the shipped card) or as the inhale
   command's exhaust port (``EXHAUSTS``); 2-3 run for each, and the form whose chosen
   anchor scores lower on runs 1-4 is the one reported (the other beside it).
5. *The measured flows*: the venturis' differential pressures (``dp_inhale``,
   ``dp_exhale``; uncalibrated, ``FlowChannel`` law ``square``) beside the pressure in
   the refit, their weight (``FLOW_WEIGHTS``) chosen on runs 1-4 at the chosen anchor
   as in 2, then runs 5-6 scored with it.

Beside the Gaussian band, the online conformal band
(:class:`~pneubayes.inference.conformal.OnlineConformalBand`): the draws' band rescaled
by the run's own completed predictions, fed one every ``BAND_EVERY_S`` from
``BAND_FROM_S`` (with the latest posterior; only outcomes measured before a prediction
enter its band); and the mode's conformal band: the same rescaling around the online
refit's own prediction (the posterior mode), its scale per step ahead the RMS error of
the chosen anchor's predictions on runs 1-4 (the Laplace draws of a 13-quantity
posterior under a wide anchor spread far wider than the mode's errors), fed only the
refit's predictions (from the run's first refit on: the shared fit's errors before it,
several times larger, would widen it for the rest of the run). That band's adaptive
conformal step and memory (``BAND_GRID``) are chosen on runs 1-4 at the chosen anchor
by the mean interval score of its 90 % band over the protocol's windows (each run
through from the others' fit); runs 5-6 are scored once with the choice, and with the
class's defaults beside it.

Writes OUT/real_respiraworks_refit.json (atomically, when a set is done; a set already
in it is not rerun); each anchor's training score is kept in OUT/choice_SET.json as it
finishes, so a stopped run resumes there.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from real_common import add_split_arguments
from real_respiraworks import DATA, HELD_OUT, HORIZON_S, split_runs
from real_respiraworks_forms import MAX_NFEV, form_card
from real_respiraworks_online import CMH2O_PA, FORECAST_WARM, TICK_S, rmse, shared_fit, ticks_of

from pneubayes.atomic import write_json_atomic
from pneubayes.inference.conformal import OnlineConformalBand
from pneubayes.inference.flow_channels import FlowChannel
from pneubayes.inference.online import forecast
from pneubayes.inference.online_refit import OnlineRefit
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.predictive import noise_floor_Pa
from pneubayes.inference.refine import TrajectoryRefiner, relative_spread
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance
from pneubayes.simulation import Inputs, SolverConfig

SEED = 67
N_DRAWS = 64
#: the anchor's relative SD and error scale (Pa), and the online refit's evaluations per
#: window (MAX_NFEV, or fewer: a refit that moves less from its last estimate), chosen
#: among on the training runs
GRID = {"relative_sd": (0.1, 0.3, 1.0), "error_Pa": (30.0, 100.0, 300.0),
        "refit_nfev": (MAX_NFEV, 30, 10)}
#: with --spread-anchors, anchors of each quantity's own width beside them: its spread
#: over fits of each other training run alone (relative_spread) times a factor among
SPREAD_FACTORS = (0.5, 1.0, 2.0)
#: the spread anchors' floor (a fraction of each quantity's scale): a quantity the
#: per-run fits agree on is still free to move this much
SPREAD_FLOOR = 0.01
#: then, at the chosen anchor, the venturi channels' weight (Pa per unit of the
#: uncalibrated differential pressure; flow_channels.FlowChannel) chosen among
FLOW_WEIGHTS = (10.0, 30.0, 100.0)
#: the exhale valve's forms (real_respiraworks_forms.form_card), chosen among on runs 1-4
EXHAUSTS = ("separate", "port")
#: the online conformal band is fed a prediction every BAND_EVERY_S from BAND_FROM_S
BAND_FROM_S = 1.0
BAND_EVERY_S = 0.5
#: the mode's conformal band: adaptive conformal inference's step and the completed
#: predictions kept (None: all), chosen among on runs 1-4 by the interval score
BAND_GRID = {"step": (0.0, 0.01, 0.03, 0.1), "memory": (None, 60, 20)}
BAND_ALPHA = 0.1


def mode_band(p, preds, profile, step, memory) -> dict:
    """Replay the mode's online conformal band (``step``, ``memory``) over a run's mode
    predictions ``preds`` ((start sample, prediction, protocol window?), in time order;
    the measured pressure ``p``, Pa): per protocol window whether each sample lies in
    the 90 % band, its width and the interval score (Gneiting and Raftery 2007: width
    plus 2 / alpha times the miss, Pa), each prediction's band from the outcomes
    measured before it."""
    band = OnlineConformalBand(coverage=1.0 - BAND_ALPHA, step=step, memory=memory)
    out = {"inside": [], "width": [], "score": []}
    for k, pred, protocol in preds:
        band.observe(k, p[:k + 1])
        lo, hi = band.predict(k, pred, profile)
        if protocol:
            y = p[k + 1:k + 1 + len(pred)]
            miss = np.maximum(lo - y, 0.0) + np.maximum(y - hi, 0.0)
            out["inside"].append((y >= lo) & (y <= hi))
            out["width"].append(hi - lo)
            out["score"].append(hi - lo + 2.0 / BAND_ALPHA * miss)
    return out


def pooled_band(runs) -> dict:
    """Coverage, median width and mean interval score (Pa) of :func:`mode_band`'s
    output over runs."""
    cat = {key: np.concatenate([x for run in runs for x in run[key]])
           for key in ("inside", "width", "score")}
    return {"coverage_90": float(np.mean(cat["inside"])),
            "median_width_Pa": float(np.median(cat["width"])),
            "interval_score_Pa": float(np.mean(cat["score"]))}


def channels_of(weight):
    """The ventilator's two venturi channels at ``weight`` Pa per unit (none: None)."""
    if weight is None:
        return ()
    return (FlowChannel("dp_inhale", "inlet", weight), FlowChannel("dp_exhale", "exhaust",
                                                                   weight))


def run_fits(kind, model, runs, centre, solver, out: Path, tag: str, nfev: int, log) -> list:
    """Every quantity of ``model`` (the card's) refitted on each of ``runs`` alone from
    ``centre`` (each read from OUT when it holds this run's from this centre)."""
    # (as JSON stores it: a cached key compares equal)
    key = json.loads(json.dumps({"card": model.rig_card.to_dict(), "max_nfev": nfev,
                                 "centre": centre}))
    fits = []
    for r in runs:
        cache = out / f"run_{tag}_{Path(r.source).stem}.json"
        doc = json.loads(cache.read_text()) if cache.exists() else {}
        hit = [f for f in doc.get("fits", []) if f["key"] == key]
        if hit:
            fits.append(hit[0]["params"])
            continue
        t0 = time.perf_counter()
        fit = TrajectoryRefiner(model, solver, max_nfev=nfev, uncertainty=False).fit(
            WindowSet([r], HORIZON_S, HORIZON_S), centre)
        log(f"[{kind}] {Path(r.source).stem} alone: RMSE {fit.rmse_Pa_:.0f} Pa "
            f"({time.perf_counter() - t0:.0f} s)")
        doc.setdefault("fits", []).append({"key": key, "params": fit.params_})
        write_json_atomic(cache, doc)
        fits.append(fit.params_)
    return fits


def anchor_widths(knobs, names, spread) -> float | dict:
    """The anchor's relative SD of ``knobs``: one for all (``relative_sd``) or each
    quantity's spread over per-run fits (``spread``, :func:`relative_spread`) times
    ``spread_factor``."""
    if "spread_factor" in knobs:
        return {n: knobs["spread_factor"] * spread[n] for n in names}
    return knobs["relative_sd"]


def through_run(model, shared, r, knobs, solver, std, nfev, anchored=True, draws=0,
                band_sd=0.0, rng=None, profile=None, mode_ticks=False, spread=None):
    """Refit through run ``r`` at its protocol windows; per window the errors of the
    mode's prediction, the set-point's and the frozen fit's, and (with ``draws``) whether
    each sample lies in the 90 % band and the band's width, and the same for two online
    conformal bands fed a prediction every ``BAND_EVERY_S`` from ``BAND_FROM_S``, each
    with the latest posterior: the draws' (their mean, their spread with ``band_sd`` in
    quadrature) and the mode's (its prediction, with ``profile``, the training runs' RMS
    error per step ahead, as the scale; fed from the first refit on, not the shared
    fit's predictions before it). The mode's predictions that band is fed are kept in
    ``mode_preds`` as (start sample, prediction, protocol window or not), for
    :func:`mode_band` to replay at any of its settings; ``mode_ticks`` feeds them (the mode
    alone forecast at the band's ticks) without ``draws``."""
    p = np.asarray(r.pressure_Pa, dtype=np.float64)
    dt = float(np.median(np.diff(r.time_s)))
    h, m = int(round(HORIZON_S / dt)), int(round(TICK_S / dt))
    _, protocol, _ = ticks_of(r, m, h)
    every = int(round(BAND_EVERY_S / dt))
    first = int(np.searchsorted(r.time_s, r.time_s[0] + BAND_FROM_S))
    band_ticks = set(range(first, p.size - h, every)) if draws or mode_ticks else set()
    inputs = Inputs.from_recording(r)
    sp = r.extra_columns["pc_setpoint_cmH2O"].astype(float) * CMH2O_PA \
        + r.metadata.atmospheric_pressure_Pa
    names = list(model.parameter_names)
    on = OnlineRefit(model, shared, names, anchor_widths(knobs, names, spread),
                     knobs["error_Pa"],
                     solver, HORIZON_S, memory_s=knobs.get("memory_s"),
                     refit_every_s=HORIZON_S, max_nfev=knobs.get("refit_nfev", nfev),
                     channels=channels_of(knobs.get("flow_weight_Pa"))).reset()
    band = OnlineConformalBand(coverage=0.9)
    out = {"refit": [], "setpoint": [], "frozen": [], "inside": [], "width": [],
           "refit_s": [], "inside_conformal": [], "width_conformal": [], "mode_preds": []}
    start = dict(shared)
    params = dict(shared)
    for k in sorted(set(protocol) | band_ticks):
        band.observe(k, p[:k + 1])
        y = p[k + 1:k + h + 1]
        if k not in protocol:  # a band tick: the latest posterior's draws, no refit
            thetas = model.vector(params)[None]
            if draws:
                thetas = np.concatenate([thetas, on.draws(draws, rng)])
            sims = forecast(model, thetas, inputs, r.rig(), k, h + 1, p, std,
                            FORECAST_WARM)[:, 1:]
            if k > protocol[0] and profile is not None:  # the online refit's predictions
                out["mode_preds"].append((k, sims[0], False))
            if draws:
                sims = sims[1:][np.all(np.isfinite(sims[1:]), axis=1)]
                band.predict(k, *band.centre_and_scale(sims, band_sd))
            continue
        so_far = r.slice(0, k + 1)
        if anchored:
            on.update(so_far)
            params = on.params_
            out["refit_s"].append(on.refit_seconds_[-1])
        else:
            params = TrajectoryRefiner(model, solver, max_nfev=nfev, uncertainty=False).fit(
                WindowSet([so_far], HORIZON_S, HORIZON_S), start).params_
            start = dict(params)
        thetas = [model.vector(shared), model.vector(params)]
        if draws:
            thetas += list(on.draws(draws, rng))
        pred = forecast(model, np.stack(thetas), inputs, r.rig(), k, h + 1, p, std,
                        FORECAST_WARM)[:, 1:]
        out["frozen"].append(y - pred[0])
        out["refit"].append(y - pred[1])
        out["setpoint"].append(y - sp[k + 1:k + h + 1])
        if profile is not None:
            out["mode_preds"].append((k, pred[1], True))
        if draws:
            sims = pred[2:][np.all(np.isfinite(pred[2:]), axis=1)]
            c_lo, c_hi = band.predict(k, *band.centre_and_scale(sims, band_sd))
            out["inside_conformal"].append((y >= c_lo) & (y <= c_hi))
            out["width_conformal"].append(c_hi - c_lo)
            sims = sims + rng.normal(0.0, band_sd, sims.shape)
            lo, hi = np.quantile(sims, [0.05, 0.95], axis=0)
            out["inside"].append((y >= lo) & (y <= hi))
            out["width"].append(hi - lo)
    return out


def run_set(kind: str, out: Path, smoke: bool, log, exhaust: str = "separate",
            with_flows: bool = True, data: Path = DATA, held_out=HELD_OUT,
            spread_anchors: bool = False) -> dict:
    card = form_card(kind, "two_compartment", exhaust, data)
    tag = kind if exhaust == "separate" else f"{kind}_{exhaust}"  # the caches' names
    recs = [read_recording(p, rig_card=card) for p in sorted((data / kind).glob("*.csv"))]
    train, held = split_runs(recs, held_out, data / kind)
    model = Model(rig_card=card)
    solver = FitSettings().refine_solver
    std = SolverConfig.standard()
    nfev = 10 if smoke else MAX_NFEV
    # (the refit's evaluations are a knob only below the default, so that the anchors'
    # cached scores at the default are read again)
    grid = [{"relative_sd": a, "error_Pa": e, **({} if n == MAX_NFEV else {"refit_nfev": n})}
            for n in GRID["refit_nfev"] for a in GRID["relative_sd"]
            for e in GRID["error_Pa"]]
    if spread_anchors:
        grid += [{"spread_factor": k, "error_Pa": e} for k in SPREAD_FACTORS
                 for e in GRID["error_Pa"]]
    if smoke:
        grid, train = grid[:1] + (grid[-1:] if spread_anchors else []), train[:2]
    # the choice: each training run through from the shared fit of the other three
    loo = {}
    for i, r in enumerate(train):
        others = [x for j, x in enumerate(train) if j != i]
        loo[i] = shared_fit(kind, card, others, solver,
                            out / f"shared_{tag}_without_{Path(r.source).stem}.json", nfev,
                            log)
    # how far each quantity moves from run to run: each other run fitted alone
    names = list(model.parameter_names)
    loo_spread = {i: relative_spread(model, loo[i], run_fits(
        kind, model, [x for j, x in enumerate(train) if j != i], loo[i], solver, out, tag,
        nfev, log), names, SPREAD_FLOOR) if spread_anchors else None for i in loo}
    # each anchor's score is kept as it finishes (a rerun or a resumed run reads it)
    cache = out / f"choice_{tag}.json"
    key = json.dumps({"card": card.to_dict(), "max_nfev": nfev, "smoke": smoke,
                      "train": [Path(r.source).name for r in train]}, sort_keys=True)
    done = json.loads(cache.read_text()) if cache.exists() else {}
    if done.get("key") != key:
        done = {"key": key, "scores": {}}
    done.setdefault("profiles", {})

    def training_score(knobs) -> float:
        """The pooled error of ``knobs`` through runs 1-4 (each from the others' fit);
        its RMS per step ahead is kept beside it (``profile``)."""
        name = json.dumps(knobs, sort_keys=True)
        if name not in done["scores"] or name not in done["profiles"]:
            t0 = time.perf_counter()
            errs = [through_run(model, loo[i], r, knobs, solver, std, nfev,
                                spread=loo_spread[i])["refit"]
                    for i, r in enumerate(train)]
            done["scores"][name] = rmse([e for run in errs for e in run])
            done["profiles"][name] = np.sqrt(np.mean(np.square(
                [e for run in errs for e in run]), axis=0)).tolist()
            write_json_atomic(cache, done)
            log(f"[{kind}] training runs, anchor {knobs}: {done['scores'][name]:.0f} Pa "
                f"({time.perf_counter() - t0:.0f} s)")
        return done["scores"][name]

    def profile(knobs) -> np.ndarray:
        """The training runs' RMS error of ``knobs`` per step ahead (Pa, >= 1 Pa)."""
        training_score(knobs)
        return np.maximum(done["profiles"][json.dumps(knobs, sort_keys=True)], 1.0)

    def band_choice(knobs) -> tuple[dict, list]:
        """The mode band's (step, memory) with the lowest interval score on runs 1-4 at
        ``knobs`` (each run through from the others' fit, the mode forecast at the
        band's ticks too), and every setting's pooled result there."""
        name = json.dumps(knobs, sort_keys=True)
        rec = done.setdefault("band_records", {})
        if name not in rec:
            rec[name] = [[(int(k), np.asarray(m).tolist(), bool(pr)) for k, m, pr in
                          through_run(model, loo[i], r, knobs, solver, std, nfev,
                                      profile=profile(knobs), mode_ticks=True,
                                      spread=loo_spread[i])["mode_preds"]]
                         for i, r in enumerate(train)]
            write_json_atomic(cache, done)
        scale = profile(knobs)
        series = [(np.asarray(r.pressure_Pa, dtype=np.float64),
                   [(k, np.asarray(m), pr) for k, m, pr in preds])
                  for r, preds in zip(train, rec[name])]
        tried = []
        for step in BAND_GRID["step"]:
            for memory in BAND_GRID["memory"]:
                runs = [mode_band(p, preds, scale, step, memory) for p, preds in series]
                tried.append({"step": step, "memory": memory, **pooled_band(runs)})
        best = min(tried, key=lambda x: x["interval_score_Pa"])
        log(f"[{kind}] the mode band on runs 1-4: step {best['step']:g}, memory "
            f"{best['memory']} (interval score {best['interval_score_Pa']:.0f} Pa, coverage "
            f"{best['coverage_90']:.2f})")
        return {"step": best["step"], "memory": best["memory"]}, tried

    def held_band(source, knobs, band) -> dict:
        """The mode band at ``band``'s settings over the held-out runs ``source``."""
        return pooled_band([mode_band(np.asarray(r.pressure_Pa, dtype=np.float64),
                                      run["mode_preds"], profile(knobs), band["step"],
                                      band["memory"]) for r, run in zip(held, source)])

    scores = [training_score(knobs) for knobs in grid]
    chosen = grid[int(np.argmin(scores))]
    band_sd = float(min(scores))
    # then the measured flows beside the pressure, at the chosen anchor (same runs)
    if with_flows:
        flow_scores = [(training_score(k), k) for k in (
            {**chosen, "flow_weight_Pa": w}
            for w in (FLOW_WEIGHTS[:1] if smoke else FLOW_WEIGHTS))]
        flow_sd, flow_chosen = min(flow_scores, key=lambda x: x[0])
    shared = shared_fit(kind, card, train, solver, out / f"shared_{tag}.json", nfev, log)
    spread = relative_spread(model, shared, run_fits(
        kind, model, train, shared, solver, out, tag, nfev, log), names,
        SPREAD_FLOOR) if spread_anchors else None
    rng = np.random.default_rng([SEED, ord(kind[0])])
    res = {"chosen": chosen, "band_sd_Pa": band_sd,
           "training_runs_rmse_Pa": [{"anchor": k, "rmse_Pa": s} for k, s in zip(grid, scores)],
           "noise_floor_Pa": noise_floor_Pa(recs)}
    if spread_anchors:
        res["spread"] = spread
    runs = [through_run(model, shared, r, chosen, solver, std, nfev, draws=N_DRAWS,
                        band_sd=band_sd, rng=rng, profile=profile(chosen), spread=spread)
            for r in held]
    free = [through_run(model, shared, r, chosen, solver, std, nfev, anchored=False,
                        spread=spread) for r in held]
    flows = [through_run(model, shared, r, flow_chosen, solver, std, nfev, draws=N_DRAWS,
                         band_sd=flow_sd, rng=rng, profile=profile(flow_chosen),
                         spread=spread)
             for r in held] if with_flows else []

    band, band_tried = band_choice(chosen)
    res["mode_band"] = {"chosen": band, "training_runs": band_tried,
                        "held_out": held_band(runs, chosen, band),
                        "held_out_default": held_band(runs, chosen,
                                                      {"step": 0.02, "memory": None})}
    if with_flows:
        flow_band, _ = band_choice(flow_chosen)
        flow_mode = held_band(flows, flow_chosen, flow_band)

    def pooled(key, source=runs):
        return rmse([e for run in source for e in run[key]])

    res["protocol_rmse_Pa"] = {"setpoint": pooled("setpoint"), "frozen": pooled("frozen"),
                               "online_refit": pooled("refit"),
                               "refit_without_anchor": pooled("refit", free)}
    if with_flows:
        res["flows"] = {
            "chosen": flow_chosen, "band_sd_Pa": flow_sd,
            "training_runs_rmse_Pa": [{"anchor": k, "rmse_Pa": v} for v, k in flow_scores],
            "protocol_rmse_Pa": pooled("refit", flows),
            "online_over_setpoint": pooled("refit", flows) / pooled("setpoint"),
            "per_window_rmse_Pa": [rmse([e]) for run in flows for e in run["refit"]],
            "coverage_90": float(np.mean(np.concatenate([x for run in flows
                                                         for x in run["inside"]]))),
            "band_90_median_width_Pa": float(np.median(np.concatenate(
                [x for run in flows for x in run["width"]]))),
            "refit_seconds_median": float(np.median([x for run in flows for x in run["refit_s"]])),
            "conformal_coverage_90": float(np.mean(np.concatenate(
                [x for run in flows for x in run["inside_conformal"]]))),
            "conformal_band_90_median_width_Pa": float(np.median(np.concatenate(
                [x for run in flows for x in run["width_conformal"]]))),
            "mode_band_chosen": flow_band,
            "mode_conformal_coverage_90": flow_mode["coverage_90"],
            "mode_conformal_band_90_median_width_Pa": flow_mode["median_width_Pa"]}
    res["online_over_setpoint"] = res["protocol_rmse_Pa"]["online_refit"] / pooled("setpoint")
    res["per_window_online_rmse_Pa"] = [rmse([e]) for run in runs for e in run["refit"]]
    res["per_window_without_anchor_rmse_Pa"] = [rmse([e]) for run in free for e in run["refit"]]
    res["coverage_90"] = float(np.mean(np.concatenate([x for run in runs
                                                        for x in run["inside"]])))
    res["conformal_coverage_90"] = float(np.mean(np.concatenate(
        [x for run in runs for x in run["inside_conformal"]])))
    res["conformal_band_90_median_width_Pa"] = float(np.median(np.concatenate(
        [x for run in runs for x in run["width_conformal"]])))
    res["band_90_median_width_Pa"] = float(np.median(np.concatenate(
        [x for run in runs for x in run["width"]])))
    res["mode_conformal_coverage_90"] = res["mode_band"]["held_out"]["coverage_90"]
    res["mode_conformal_band_90_median_width_Pa"] = res["mode_band"]["held_out"][
        "median_width_Pa"]
    secs = np.array([s for run in runs for s in run["refit_s"]])
    res["refit_seconds"] = {"median": float(np.median(secs)), "max": float(secs.max()),
                            "n": int(secs.size)}
    res["n_windows"] = len(res["per_window_online_rmse_Pa"])
    pr = res["protocol_rmse_Pa"]
    log(f"[{kind}] held out ({res['n_windows']} windows): set-point {pr['setpoint']:.0f}, "
        f"frozen {pr['frozen']:.0f}, online refit {pr['online_refit']:.0f} "
        f"({res['online_over_setpoint']:.2f} x the set-point), without the anchor "
        f"{pr['refit_without_anchor']:.0f} Pa; 90 % band covers {res['coverage_90']:.2f} at "
        f"{res['band_90_median_width_Pa']:.0f} Pa, the online conformal band "
        f"{res['conformal_coverage_90']:.2f} at {res['conformal_band_90_median_width_Pa']:.0f}"
        f" Pa, the mode's conformal band {res['mode_conformal_coverage_90']:.2f} at "
        f"{res['mode_conformal_band_90_median_width_Pa']:.0f} Pa; refit "
        f"{res['refit_seconds']['median']:.2f} s median")
    if with_flows:
        fl = res["flows"]
        log(f"[{kind}] with the measured flows (weight {flow_chosen['flow_weight_Pa']:g} Pa per "
            f"unit, chosen on runs 1-4): {fl['protocol_rmse_Pa']:.0f} Pa "
            f"({fl['online_over_setpoint']:.2f} x the set-point); 90 % band covers "
            f"{fl['coverage_90']:.2f} at {fl['band_90_median_width_Pa']:.0f} Pa")
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--sets", default="OXY,AIR")
    ap.add_argument("--smoke", action="store_true", help="one anchor, two runs, 10 "
                    "evaluations (a check that it runs)")
    ap.add_argument("--exhausts", default=",".join(EXHAUSTS),
                    help="the exhale valve's forms to choose among on runs 1-4 (one: "
                         "taken as given, e.g. the form a full run chose there)")
    ap.add_argument("--spread-anchors", action="store_true",
                    help="anchors of each quantity's own width (its spread over fits of "
                         "each other training run alone) beside the grid's")
    ap.add_argument("--no-flows", action="store_true",
                    help="leave out the measured flows' variant (its three weights)")
    add_split_arguments(ap, DATA, HELD_OUT, "run")
    args = ap.parse_args(argv)
    held_out = tuple(args.held_out or HELD_OUT)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "real_respiraworks_refit.json"
    doc = json.loads(path.read_text()) if path.exists() else {"sets": {}}
    if doc.get("smoke", args.smoke) != args.smoke:
        raise SystemExit(f"{path}: written with --smoke={doc['smoke']}; use another --out")
    if doc.get("held_out", list(held_out)) != list(held_out):
        raise SystemExit(f"{path}: written with --held-out {' '.join(doc['held_out'])}; "
                         "use another --out")

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    for kind in args.sets.split(","):
        if kind in doc["sets"]:
            log(f"[{kind}] done already in {path}")
            continue
        # the card's exhale valve on its own command, or as the inhale command's exhaust
        # port: the form is chosen on runs 1-4 (the chosen anchor's score there)
        forms = args.exhausts.split(",")
        if not set(forms) <= set(EXHAUSTS):
            ap.error(f"--exhausts: the forms are {list(EXHAUSTS)}, got {forms}")
        by_form = {ex: run_set(kind, out, args.smoke, log, ex, not args.no_flows,
                               Path(args.data), held_out, args.spread_anchors)
                   for ex in forms}
        chosen = min(by_form, key=lambda ex: by_form[ex]["band_sd_Pa"])
        log(f"[{kind}] exhale valve form chosen on runs 1-4: {chosen} ("
            + ", ".join(f"{ex} {r['band_sd_Pa']:.0f} Pa" for ex, r in by_form.items()) + ")")
        doc["sets"][kind] = {**by_form[chosen], "exhaust": chosen, "exhausts_tried": forms,
                             "other_forms": {ex: r for ex, r in by_form.items()
                                             if ex != chosen}}
        grid = {**GRID, **({"spread_factor": SPREAD_FACTORS} if args.spread_anchors else {})}
        doc.update(seed=SEED, smoke=args.smoke, held_out=list(held_out), grid=grid,
                   flow_weights=FLOW_WEIGHTS,
                   band_every_s=BAND_EVERY_S, band_from_s=BAND_FROM_S, band_grid=BAND_GRID,
                   n_draws=N_DRAWS,
                   provenance=provenance())
        write_json_atomic(path, doc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
