"""Real recordings: the RespiraWorks ventilator's lung tracked online (issue 67 items 1-2).

    python experiments/real_respiraworks_online.py --out results/real_respiraworks_online
        [--sets OXY,AIR] [--quick] [--smoke]

The shipped card (two compartments, the exhale valve on its own command), the split of
``real_respiraworks.py`` (runs 1-4 train, 5-6 held out) and its 2-s windows. Per set:

1. *Shared fit*: every quantity refined on the training runs from the card's start
   (``real_respiraworks_forms.py``'s refinement, ``MAX_NFEV`` evaluations).
2. *Population*: the lung's quantities (``LUNG``) refitted on each whole training run,
   the card's others known at the shared fit; a log-normal over the four fits, its
   spread widened by ``FLOOR_LOG_SD`` (:meth:`LogNormalPrior.from_point_fits`). The
   tracker's error scale ``noise_std_Pa`` is the median of those fits' window RMSE (the
   model's error with the run's own lung), not the sensor noise.
3. *Online*: on each held-out run an :class:`~pneubayes.inference.online.OnlineTracker`
   over the lung's quantities takes the run as a stream, one tick every ``TICK_S``; at
   every tick from ``CAL_S`` on whose next 2 s lie in the run, it predicts them from the
   measured pressure (``forecast``: the lung's pressure brought to the start by a
   warm-up window) with 64 resampled particles; the 90 % band adds Gaussian errors of
   ``noise_std_Pa`` to the particles' predictions.

Compared on the same windows: the set-point baseline, the *frozen* shared fit, the
*calibrated* protocol (the lung refitted on the run's first ``CAL_S`` s, then fixed), and
(unless ``--quick``) *refit so far*: the lung refitted on the run up to each window's
start (the refitting the issue asks the online update to be compared with). Two window
sets: the protocol's (2-s windows every 2 s from ``CAL_S``: the samples of the forms
script's "after cal" numbers) and every tick's. The forms script's own numbers (windows
chained through the rest of the run) are recomputed for the shared and calibrated fits
as a check. Tracker cost per tick is the wall time of ``update`` (this machine: 2 cores
shared with other work). Seeds recorded. Writes OUT/real_respiraworks_online.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from real_respiraworks import DATA, HELD_OUT, HORIZON_S, setpoint_rmse_Pa
from real_respiraworks_forms import CAL_S, LUNG, MAX_NFEV, form_card

from pneubayes.atomic import write_json_atomic
from pneubayes.inference.online import LogNormalPrior, OnlineTracker, forecast
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.predictive import noise_floor_Pa
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance
from pneubayes.simulation import Inputs, SolverConfig

SEED = 0
TICK_S = 0.1
N_PARTICLES = 64
N_DRAWS = 64
FLOOR_LOG_SD = 0.25
#: the tracker's knobs (OnlineTracker's arguments), recorded with the result
#: lookback = memory = the 2-s horizon: the likelihood scores 2-s-ahead predictions, the
#: error the protocol measures (1 s, tried first on OXY: 233 -> 206 Pa with 2 warm-ups)
TRACKER = {"lookback_s": 2.0, "warm_up_windows": 1, "temper": 0.1, "ess_threshold": 0.5,
           "n_moves": 2, "move_scale": 0.5, "move_floor_log": 1e-3, "memory_s": 2.0,
           "drift_log_per_sqrt_s": 0.0}
CMH2O_PA = 98.0665
#: warm-up windows (of the 2-s horizon) before every prediction, as many as the run holds
FORECAST_WARM = 3


def refit_lung(local: Model, recs, start: dict, solver, max_nfev: int):
    return TrajectoryRefiner(local, solver, max_nfev=max_nfev, uncertainty=False).fit(
        WindowSet(recs, HORIZON_S, HORIZON_S), start)


def shared_fit(kind, card, train, solver, cache: Path, max_nfev: int, log) -> dict:
    """The shared fit's parameters (read from ``cache`` when it holds this set's)."""
    if cache.exists():
        doc = json.loads(cache.read_text())
        if doc.get("card") == card.to_dict() and doc.get("max_nfev") == max_nfev:
            log(f"[{kind}] shared fit read from {cache}")
            return doc["params"]
    model = Model(rig_card=card)
    t0 = time.perf_counter()
    fit = TrajectoryRefiner(model, solver, max_nfev=max_nfev, uncertainty=False).fit(
        WindowSet(train, HORIZON_S, HORIZON_S), model.base_start_values())
    log(f"[{kind}] shared fit: train RMSE {fit.rmse_Pa_:.0f} Pa "
        f"({time.perf_counter() - t0:.0f} s)")
    write_json_atomic(cache, {"card": card.to_dict(), "params": fit.params_,
                              "train_rmse_Pa": fit.rmse_Pa_, "max_nfev": max_nfev})
    return fit.params_


def rmse(e) -> float:
    return float(np.sqrt(np.mean(np.square(np.concatenate([np.ravel(x) for x in e])))))


def run_set(kind: str, out: Path, quick: bool, smoke: bool, log) -> dict:
    card = form_card(kind, "two_compartment", "separate")
    lung = LUNG["two_compartment"]
    recs = [read_recording(p, rig_card=card) for p in sorted((DATA / kind).glob("*.csv"))]
    train = [r for r in recs if Path(r.source).stem not in HELD_OUT]
    held = [r for r in recs if Path(r.source).stem in HELD_OUT]
    if smoke:
        held = held[:1]
    model = Model(rig_card=card)
    solver = FitSettings().refine_solver
    std = SolverConfig.standard()
    nfev = 10 if smoke else MAX_NFEV
    shared = shared_fit(kind, card, train, solver, out / f"shared_{kind}.json", nfev, log)
    local_card = card.known_at(shared, keep_unknown=lung)
    local = Model(rig_card=local_card)
    start_lung = {k: shared[k] for k in lung}
    # population: the lung of every whole training run
    fits, fit_rmse = [], []
    for r in train:
        f = refit_lung(local, [read_recording(r.source, rig_card=local_card)], start_lung,
                       solver, nfev)
        fits.append({k: f.params_[k] for k in lung})
        fit_rmse.append(f.rmse_Pa_)
    prior = LogNormalPrior.from_point_fits(model, lung, fits, FLOOR_LOG_SD)
    sigma = float(np.median(fit_rmse))
    # the band's error scale: the calibrated protocol's error on the training runs
    band_err = []
    for r in train:
        n_cal = int(np.searchsorted(r.time_s, r.time_s[0] + CAL_S))
        bound = read_recording(r.source, rig_card=local_card)
        cal = refit_lung(local, [bound.slice(0, n_cal + 1)], start_lung, solver, nfev)
        th = model.vector({**shared, **cal.params_})[None]
        p = np.asarray(r.pressure_Pa, dtype=np.float64)
        h = int(round(HORIZON_S / float(np.median(np.diff(r.time_s)))))
        for k in range(n_cal, p.size - h, h):
            band_err.append(p[k + 1:k + h + 1] - forecast(
                model, th, Inputs.from_recording(r), r.rig(), k, h + 1, p, std,
                FORECAST_WARM)[0, 1:])
    band_sigma = rmse(band_err)
    log(f"[{kind}] population {prior.describe()}; per-run lung fits' RMSE "
        f"{[round(x) for x in fit_rmse]} Pa -> noise_std_Pa {sigma:.0f}; the calibrated "
        f"protocol's error on the training runs (the band's scale) {band_sigma:.0f} Pa")
    res = {"population": prior.describe(), "per_run_lung_fits": fits,
           "per_run_lung_fit_rmse_Pa": fit_rmse, "noise_std_Pa": sigma,
           "band_std_Pa": band_sigma,
           "shared_parameters": shared, "runs": {}}
    pooled = {k: [] for k in ("setpoint", "frozen", "calibrated", "online", "refit")}
    pooled_all = {k: [] for k in ("setpoint", "frozen", "calibrated", "online")}
    cover, width, cover_all, cover_frozen, cover_cal = [], [], [], [], []
    forms_shared, forms_cal, tick_ms, rests = [], [], [], []
    for i, r in enumerate(held):
        stem = Path(r.source).stem
        rng = np.random.default_rng([SEED, i, ord(kind[0])])
        p = np.asarray(r.pressure_Pa, dtype=np.float64)
        t = np.asarray(r.time_s, dtype=np.float64)
        dt = float(np.median(np.diff(t)))
        h = int(round(HORIZON_S / dt))  # samples after a window's start
        n_cal = int(np.searchsorted(t, t[0] + CAL_S))
        bound = read_recording(r.source, rig_card=local_card)
        cal = refit_lung(local, [bound.slice(0, n_cal + 1)], start_lung, solver, nfev)
        cal_theta = model.vector({**shared, **{k: cal.params_[k] for k in lung}})
        # the forms script's numbers: windows chained through the rest of the run
        rest = r.slice(n_cal, None)
        rests.append(rest)
        forms_shared.append(WindowSet([rest], HORIZON_S, HORIZON_S).residuals(
            model, shared, std))
        forms_cal.append(WindowSet([bound.slice(n_cal, None)], HORIZON_S, HORIZON_S)
                         .residuals(local, cal.params_, std))
        inputs = Inputs.from_recording(r)
        ue = r.exhaust_command()
        sp = r.extra_columns["pc_setpoint_cmH2O"].astype(float) * CMH2O_PA \
            + r.metadata.atmospheric_pressure_Pa
        tracker = OnlineTracker(model, shared, prior, r.rig(), std, sigma,
                                n_particles=N_PARTICLES, **TRACKER).reset(rng)
        m = int(round(TICK_S / dt))
        protocol = set(range(n_cal, p.size - h, h))
        refit_start = dict(cal.params_)
        trace = []
        # ticks end on samples 0, m, 2m, ...: the protocol's window starts among them
        for k0, k1 in zip([0, *range(1, p.size, m)], [*range(1, p.size, m), p.size]):
            c0 = time.perf_counter()
            tracker.update(t[k0:k1], r.command_V[k0:k1], p[k0:k1], ue[k0:k1])
            tick_ms.append(1e3 * (time.perf_counter() - c0))
            k = k1 - 1  # the last sample seen
            q = tracker.quantiles()
            trace.append({"time_s": float(t[k]), "ess": tracker.ess_, **{
                n: q[n] for n in lung}})
            if k < n_cal or k + h >= p.size:
                continue
            y = p[k + 1:k + h + 1]
            draws = tracker.draws(N_DRAWS, rng)
            sims = forecast(model, draws, inputs, r.rig(), k, h + 1, p, std,
                            FORECAST_WARM)[:, 1:]
            ok = np.all(np.isfinite(sims), axis=1)
            sims = sims[ok]
            pred = sims.mean(axis=0)
            fro, cali = forecast(model, np.stack([model.vector(shared), cal_theta]), inputs,
                                 r.rig(), k, h + 1, p, std, FORECAST_WARM)[:, 1:]
            noisy = sims + rng.normal(0.0, band_sigma, size=sims.shape)
            lo, hi = np.quantile(noisy, [0.05, 0.95], axis=0)
            inside = (y >= lo) & (y <= hi)
            z = 1.6448536269514722 * band_sigma  # a point prediction's band with the same errors
            errs = {"setpoint": y - sp[k + 1:k + h + 1], "frozen": y - fro,
                    "calibrated": y - cali, "online": y - pred}
            for key, e in errs.items():
                pooled_all[key].append(e)
            cover_all.append(inside)
            if k in protocol:
                for key, e in errs.items():
                    pooled[key].append(e)
                cover.append(inside)
                width.append(hi - lo)
                cover_frozen.append(np.abs(y - fro) <= z)
                cover_cal.append(np.abs(y - cali) <= z)
                if not quick:
                    so_far = refit_lung(local, [bound.slice(0, k + 1)], refit_start, solver,
                                        nfev)
                    refit_start = dict(so_far.params_)
                    th = model.vector({**shared, **so_far.params_})
                    pooled["refit"].append(y - forecast(model, th[None], inputs, r.rig(), k,
                                                        h + 1, p, std, FORECAST_WARM)[0, 1:])
        res["runs"][stem] = {"calibrated_lung": {k: cal.params_[k] for k in lung},
                             "trace": trace[::5], "final_quantiles": tracker.quantiles(),
                             "n_resamples": tracker.n_resamples_}
        log(f"[{kind}] {stem}: {len(trace)} ticks, {tracker.n_resamples_} resamples; lung "
            f"calibrated {res['runs'][stem]['calibrated_lung']}, tracked at the end "
            f"{tracker.quantiles()}")
    ms = np.array(tick_ms)
    res.update({
        "protocol_windows": {k: rmse(v) for k, v in pooled.items() if v},
        "protocol_n_windows": len(pooled["online"]),
        "every_tick_windows": {k: rmse(v) for k, v in pooled_all.items()},
        "every_tick_n_windows": len(pooled_all["online"]),
        "online_coverage_90_protocol": float(np.mean(np.concatenate(cover))),
        "online_coverage_90_every_tick": float(np.mean(np.concatenate(cover_all))),
        "online_band_90_median_width_Pa": float(np.median(np.concatenate(width))),
        "frozen_coverage_90_same_error_band": float(np.mean(np.concatenate(cover_frozen))),
        "calibrated_coverage_90_same_error_band": float(np.mean(np.concatenate(cover_cal))),
        "forms_script_after_cal_shared_Pa": rmse([e[:, :, :] for e in forms_shared]),
        "forms_script_after_cal_calibrated_Pa": rmse(forms_cal),
        "forms_script_setpoint_after_cal_Pa": setpoint_rmse_Pa(rests, HORIZON_S),
        "noise_floor_Pa": noise_floor_Pa(recs),
        "tick_ms": {"median": float(np.median(ms)), "mean": float(ms.mean()),
                    "p95": float(np.percentile(ms, 95)), "max": float(ms.max()),
                    "ticks": int(ms.size)},
    })
    pw = res["protocol_windows"]
    log(f"[{kind}] protocol windows ({res['protocol_n_windows']}): set-point "
        f"{pw['setpoint']:.0f}, frozen {pw['frozen']:.0f}, calibrated {pw['calibrated']:.0f}, "
        f"online {pw['online']:.0f}" + (f", refit so far {pw['refit']:.0f}" if 'refit' in pw
                                        else "")
        + f" Pa; 90 % coverage {res['online_coverage_90_protocol']:.2f} (band "
        f"{res['online_band_90_median_width_Pa']:.0f} Pa); every tick: "
        + ", ".join(f"{k} {v:.0f}" for k, v in res["every_tick_windows"].items())
        + f" Pa; tick {res['tick_ms']['median']:.1f} ms median")
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--sets", default="OXY,AIR")
    ap.add_argument("--quick", action="store_true",
                    help="skip the refit-so-far comparison (the slow part)")
    ap.add_argument("--smoke", action="store_true",
                    help="one held-out run, 10-evaluation refinements (a check it runs)")
    ap.add_argument("--set", action="append", default=[], metavar="KNOB=VALUE",
                    help="override a tracker knob of TRACKER (recorded in the result)")
    args = ap.parse_args(argv)
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in TRACKER:
            ap.error(f"--set {item}: not a knob of {sorted(TRACKER)}")
        TRACKER[key] = type(TRACKER[key])(float(value) if isinstance(TRACKER[key], float)
                                          else int(value))
    out = Path(args.out)
    path = out / "real_respiraworks_online.json"
    result = {"horizon_s": HORIZON_S, "held_out": list(HELD_OUT), "calibration_s": CAL_S,
              "tick_s": TICK_S, "n_particles": N_PARTICLES, "n_draws": N_DRAWS,
              "floor_log_sd": FLOOR_LOG_SD, "tracker": TRACKER,
              "forecast_warm_up_windows": FORECAST_WARM, "seed": SEED,
              "max_nfev": MAX_NFEV, "quick": args.quick, "smoke": args.smoke, "sets": {},
              "provenance": provenance()}
    for kind in [k.strip() for k in args.sets.split(",") if k.strip()]:
        result["sets"][kind] = run_set(kind, out, args.quick, args.smoke,
                                       lambda msg: print(msg, file=sys.stderr))
        write_json_atomic(path, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
