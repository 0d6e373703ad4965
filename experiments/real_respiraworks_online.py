"""Real recordings: the RespiraWorks ventilator's lung tracked online (issue 67 items 1-2).

    python experiments/real_respiraworks_online.py --out results/real_respiraworks_online
        [--sets OXY,AIR] [--select] [--seeds 0,1,2] [--quick] [--smoke]
        [--population point|hierarchical] [--modes lookback,carried]
        [--data DIR] [--held-out RUN ...]

The shipped card (two compartments, the exhale valve on its own command), the split of
``real_respiraworks.py`` (runs 1-4 train, 5-6 held out; ``--held-out`` and ``--data`` as
there) and its 2-s windows. Per set:

1. *Shared fit*: every quantity refined on the training runs from the card's start
   (``real_respiraworks_forms.py``'s refinement, ``MAX_NFEV`` evaluations).
2. *Population*: the lung's quantities (``LUNG``) refitted on each whole training run,
   the card's others known at the shared fit; a log-normal over the four fits, its
   spread widened by ``FLOOR_LOG_SD`` (:meth:`LogNormalPrior.from_point_fits`); with
   ``--population hierarchical`` instead the posterior predictive of the hierarchical
   fit (``real_respiraworks_population.py``). The tracker's error scale ``noise_std_Pa``
   is the median of those fits' window RMSE (the model's error with the run's own lung),
   not the sensor noise.
3. *Online*: on each held-out run an :class:`~pneubayes.inference.online.OnlineTracker`
   over the lung's quantities takes the run as a stream, one tick every ``TICK_S``; at
   every tick from ``CAL_S`` on whose next 2 s lie in the run, it predicts them from the
   measured pressure (``forecast``: the lung's pressure brought to the start by a
   warm-up window) with 64 resampled particles; the 90 % band adds Gaussian errors of
   the band's scale to the particles' predictions. Beside it, the *online conformal*
   band (:class:`~pneubayes.inference.conformal.OnlineConformalBand`): the same band's
   shape rescaled by the run's own completed predictions (made every tick from
   ``BAND_FROM_S``; only outcomes measured before a prediction enter its band).

With ``--select`` the likelihood's power (``temper``) and the moves' floor are first
chosen on the training runs (``SELECT_GRID``; leave one run out: the population and
error scale from the other three, the tracker through the fourth; the valves' shared
fit has seen all four, so this is optimistic) and the held-out runs never choose
anything. ``--seeds`` repeats the tracker with several seeds (its result moves with
them: read the spread).

Compared on the same windows: the set-point baseline, the *frozen* shared fit, the
*calibrated* protocol (the lung refitted on the run's first ``CAL_S`` s, then fixed), and
(unless ``--quick``) *refit so far*: the lung refitted on the run up to each window's
start (the refitting the issue asks the online update to be compared with). Two window
sets: the protocol's (2-s windows every 2 s from ``CAL_S``: the samples of the forms
script's "after cal" numbers) and every tick's. The forms script's own numbers (windows
chained through the rest of the run) are recomputed for the shared and calibrated fits
as a check. ``--modes`` runs the tracker in each update mode (``lookback``: every tick
re-simulates ``lookback_s``; ``carried``: each particle carries its state, a tick
simulates its new samples) on the same baselines: ``online`` holds the first mode's,
``online_modes`` each one's. Tracker cost per tick is the wall time of ``update``
(this machine: 2 cores shared with other work). Seeds recorded. Writes
OUT/real_respiraworks_online.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from real_common import add_split_arguments
from real_respiraworks import DATA, HELD_OUT, HORIZON_S, setpoint_rmse_Pa, split_runs
from real_respiraworks_forms import CAL_S, LUNG, MAX_NFEV, form_card

from pneubayes.atomic import write_json_atomic
from pneubayes.inference.conformal import OnlineConformalBand
from pneubayes.inference.online import OnlineTracker, forecast
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.population import LogNormalPrior
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
           "drift_log_per_sqrt_s": 0.0, "adapt_noise_s": 0.0,
           "update_mode": "lookback", "pressure_gain": 1.0}
CMH2O_PA = 98.0665
#: The online conformal band (:class:`OnlineConformalBand`) is fed predictions at every
#: tick from this time on (before the scored ones, which start at ``CAL_S``): the run's
#: own completed predictions rescale the band.
BAND_FROM_S = 1.0
#: the knobs --select chooses among on the training runs (leave one out)
SELECT_GRID = {"temper": (0.03, 0.1, 0.3), "move_floor_log": (1e-3, 0.02, 0.1)}
#: warm-up windows (of the 2-s horizon) before every prediction, as many as the run holds
FORECAST_WARM = 3


def refit_lung(local: Model, recs, start: dict, solver, max_nfev: int):
    return TrajectoryRefiner(local, solver, max_nfev=max_nfev, uncertainty=False).fit(
        WindowSet(recs, HORIZON_S, HORIZON_S), start)


def shared_fit(kind, card, train, solver, cache: Path, max_nfev: int, log) -> dict:
    """The shared fit's parameters (read from ``cache`` when it holds this set's: the
    same card, budget and training runs)."""
    runs = [Path(r.source).name for r in train]
    if cache.exists():
        doc = json.loads(cache.read_text())
        if doc.get("card") == card.to_dict() and doc.get("max_nfev") == max_nfev \
                and doc.get("train") == runs:
            log(f"[{kind}] shared fit read from {cache}")
            return doc["params"]
    model = Model(rig_card=card)
    t0 = time.perf_counter()
    fit = TrajectoryRefiner(model, solver, max_nfev=max_nfev, uncertainty=False).fit(
        WindowSet(train, HORIZON_S, HORIZON_S), model.base_start_values())
    log(f"[{kind}] shared fit: train RMSE {fit.rmse_Pa_:.0f} Pa "
        f"({time.perf_counter() - t0:.0f} s)")
    write_json_atomic(cache, {"card": card.to_dict(), "params": fit.params_,
                              "train_rmse_Pa": fit.rmse_Pa_, "max_nfev": max_nfev,
                              "train": runs})
    return fit.params_


def rmse(e) -> float:
    return float(np.sqrt(np.mean(np.square(np.concatenate([np.ravel(x) for x in e])))))


def ticks_of(r, m: int, h: int) -> tuple[int, list[int], list[int]]:
    """(n_cal, the protocol's window starts, every tick's start): ticks end on samples
    0, m, 2m, ...; a start is a tick from ``CAL_S`` on whose next ``h`` samples lie in
    the run."""
    n = r.n_samples
    n_cal = int(np.searchsorted(r.time_s, r.time_s[0] + CAL_S))
    every = [k for k in range(0, n, m) if k >= n_cal and k + h < n]
    return n_cal, list(range(n_cal, n - h, h)), every


def track_online(model, shared, prior, sigma, band_sigma, knobs, r, seed, every_tick):
    """Stream the run ``r`` through a tracker; its predictions at the protocol's window
    starts (and with ``every_tick`` at every tick's) and their bands."""
    rng = np.random.default_rng(seed)
    std = SolverConfig.standard()
    p = np.asarray(r.pressure_Pa, dtype=np.float64)
    t = np.asarray(r.time_s, dtype=np.float64)
    dt = float(np.median(np.diff(t)))
    h, m = int(round(HORIZON_S / dt)), int(round(TICK_S / dt))
    _, protocol, every = ticks_of(r, m, h)
    wanted = set(every if every_tick else protocol)
    inputs, ue = Inputs.from_recording(r), r.exhaust_command()
    tracker = OnlineTracker(model, shared, prior, r.rig(), std, sigma,
                            n_particles=N_PARTICLES, **knobs).reset(rng)
    out = {"errors": {}, "inside": {}, "width": {}, "inside_conformal": {},
           "width_conformal": {}, "tick_ms": [], "trace": []}
    band = OnlineConformalBand(coverage=0.9)
    k_band = int(np.searchsorted(t, t[0] + BAND_FROM_S))
    for k0, k1 in zip([0, *range(1, p.size, m)], [*range(1, p.size, m), p.size]):
        c0 = time.perf_counter()
        tracker.update(t[k0:k1], r.command_V[k0:k1], p[k0:k1], ue[k0:k1])
        out["tick_ms"].append(1e3 * (time.perf_counter() - c0))
        k = k1 - 1
        if k % (5 * m) == 0:
            out["trace"].append({"time_s": float(t[k]), "ess": tracker.ess_,
                                 **tracker.quantiles()})
        band.observe(k, p[:k + 1])  # the predictions whose outcomes are measured by now
        if k not in wanted and not (k >= k_band and k % m == 0 and k + h < p.size):
            continue
        y = p[k + 1:k + h + 1]
        sims = forecast(model, tracker.draws(N_DRAWS, rng), inputs, r.rig(), k, h + 1, p,
                        std, FORECAST_WARM)[:, 1:]
        sims = sims[np.all(np.isfinite(sims), axis=1)]
        c_lo, c_hi = band.predict(k, *band.centre_and_scale(sims, band_sigma))
        if k not in wanted:
            continue
        noisy = sims + rng.normal(0.0, band_sigma, size=sims.shape)
        lo, hi = np.quantile(noisy, [0.05, 0.95], axis=0)
        out["errors"][k] = y - sims.mean(axis=0)
        out["inside"][k] = (y >= lo) & (y <= hi)
        out["width"][k] = hi - lo
        out["inside_conformal"][k] = (y >= c_lo) & (y <= c_hi)
        out["width_conformal"][k] = c_hi - c_lo
    out["final_quantiles"] = tracker.quantiles()
    out["n_resamples"] = tracker.n_resamples_
    return out, protocol, every


def select_knobs(model, shared, fits, fit_rmse, band_sigma, train, log, kind,
                 tracker_knobs=None) -> dict:
    """Leave one training run out: the population and error scale from the other three,
    the tracker through the left-out run; every setting of ``SELECT_GRID`` pooled over
    the four runs (the protocol's windows). The held-out runs are not read."""
    lung = LUNG["two_compartment"]
    table = []
    for temper in SELECT_GRID["temper"]:
        for floor in SELECT_GRID["move_floor_log"]:
            knobs = {**(tracker_knobs or TRACKER), "temper": temper,
                     "move_floor_log": floor}
            errs = []
            for j, r in enumerate(train):
                others = [f for i, f in enumerate(fits) if i != j]
                prior = LogNormalPrior.from_point_fits(model, lung, others, FLOOR_LOG_SD)
                sigma = float(np.median([x for i, x in enumerate(fit_rmse) if i != j]))
                res, protocol, _ = track_online(model, shared, prior, sigma, band_sigma,
                                                knobs, r, [SEED, 100 + j], False)
                errs += [res["errors"][k] for k in protocol]
            table.append({"temper": temper, "move_floor_log": floor, "rmse_Pa": rmse(errs)})
            log(f"[{kind}] select (training runs, leave one out): temper {temper:g}, "
                f"move floor {floor:g}: {table[-1]['rmse_Pa']:.0f} Pa")
    best = min(table, key=lambda row: row["rmse_Pa"])
    return {"grid": table, "chosen": {"temper": best["temper"],
                                      "move_floor_log": best["move_floor_log"]}}


def run_set(kind: str, out: Path, quick: bool, smoke: bool, select: bool, seeds,
            log, population: str = "point", modes=None, data: Path = DATA,
            held_out=HELD_OUT, tracker_knobs=None) -> dict:
    card = form_card(kind, "two_compartment", "separate", data)
    lung = LUNG["two_compartment"]
    recs = [read_recording(p, rig_card=card) for p in sorted((data / kind).glob("*.csv"))]
    train, held = split_runs(recs, held_out, data / kind)
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
    hierarchical = None
    if population == "hierarchical":  # the population script imports this one: import here
        from real_respiraworks_population import hierarchical_prior
        prior, hierarchical = hierarchical_prior(kind, card, shared, train, nfev, log)
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
    res = {"population": prior.describe(), "hierarchical_population": hierarchical,
           "per_run_lung_fits": fits,
           "per_run_lung_fit_rmse_Pa": fit_rmse, "noise_std_Pa": sigma,
           "band_std_Pa": band_sigma, "shared_parameters": shared, "runs": {}}
    knobs = dict(tracker_knobs or TRACKER)
    if select:
        res["selection"] = select_knobs(model, shared, fits, fit_rmse, band_sigma, train,
                                        log, kind, knobs)
        knobs.update(res["selection"]["chosen"])
    res["tracker"] = knobs
    # the baselines on the same windows (no random numbers)
    base = {k: [] for k in ("setpoint", "frozen", "calibrated", "refit")}
    base_all = {k: [] for k in ("setpoint", "frozen", "calibrated")}
    z90 = 1.6448536269514722 * band_sigma  # a point prediction's band with the same errors
    cover_point = {"frozen": [], "calibrated": []}
    forms_shared, forms_cal, rests = [], [], []
    for r in held:
        stem = Path(r.source).stem
        p = np.asarray(r.pressure_Pa, dtype=np.float64)
        dt = float(np.median(np.diff(r.time_s)))
        h, m = int(round(HORIZON_S / dt)), int(round(TICK_S / dt))
        n_cal, protocol, every = ticks_of(r, m, h)
        bound = read_recording(r.source, rig_card=local_card)
        cal = refit_lung(local, [bound.slice(0, n_cal + 1)], start_lung, solver, nfev)
        cal_theta = model.vector({**shared, **cal.params_})
        # the forms script's numbers: windows chained through the rest of the run
        rests.append(r.slice(n_cal, None))
        forms_shared.append(WindowSet([rests[-1]], HORIZON_S, HORIZON_S).residuals(
            model, shared, std))
        forms_cal.append(WindowSet([bound.slice(n_cal, None)], HORIZON_S, HORIZON_S)
                         .residuals(local, cal.params_, std))
        inputs = Inputs.from_recording(r)
        sp = r.extra_columns["pc_setpoint_cmH2O"].astype(float) * CMH2O_PA \
            + r.metadata.atmospheric_pressure_Pa
        refit_start = dict(cal.params_)
        for k in every:
            y = p[k + 1:k + h + 1]
            fro, cali = forecast(model, np.stack([model.vector(shared), cal_theta]), inputs,
                                 r.rig(), k, h + 1, p, std, FORECAST_WARM)[:, 1:]
            errs = {"setpoint": y - sp[k + 1:k + h + 1], "frozen": y - fro,
                    "calibrated": y - cali}
            for key, e in errs.items():
                base_all[key].append(e)
            if k in protocol:
                for key, e in errs.items():
                    base[key].append(e)
                cover_point["frozen"].append(np.abs(y - fro) <= z90)
                cover_point["calibrated"].append(np.abs(y - cali) <= z90)
                if not quick:
                    so_far = refit_lung(local, [bound.slice(0, k + 1)], refit_start, solver,
                                        nfev)
                    refit_start = dict(so_far.params_)
                    th = model.vector({**shared, **so_far.params_})
                    base["refit"].append(y - forecast(model, th[None], inputs, r.rig(), k,
                                                      h + 1, p, std, FORECAST_WARM)[0, 1:])
        res["runs"][stem] = {"calibrated_lung": {k: cal.params_[k] for k in lung}}
    res["protocol_windows"] = {k: rmse(v) for k, v in base.items() if v}
    res["every_tick_windows"] = {k: rmse(v) for k, v in base_all.items()}
    res["protocol_n_windows"] = len(base["frozen"])
    res["every_tick_n_windows"] = len(base_all["frozen"])
    res["point_coverage_90_same_error_band"] = {
        k: float(np.mean(np.concatenate(v))) for k, v in cover_point.items()}
    res["forms_script_after_cal_Pa"] = {"shared": rmse(forms_shared),
                                        "calibrated": rmse(forms_cal),
                                        "setpoint": setpoint_rmse_Pa(rests, HORIZON_S)}
    res["noise_floor_Pa"] = noise_floor_Pa(recs)
    # the tracker, per update mode and seed
    res["online_modes"] = {}
    modes = modes or [knobs["update_mode"]]
    for mode, seed in [(mode, seed) for mode in modes for seed in seeds]:
        res["online"] = res["online_modes"].setdefault(mode, {})
        knobs = {**res["tracker"], "update_mode": mode}
        errs_p, errs_a, in_p, in_a, width, ms = [], [], [], [], [], []
        cin_p, cin_a, cwidth = [], [], []
        for i, r in enumerate(held):
            o, protocol, every = track_online(model, shared, prior, sigma, band_sigma,
                                              knobs, r, [seed, i, ord(kind[0])], True)
            errs_p += [o["errors"][k] for k in protocol]
            in_p += [o["inside"][k] for k in protocol]
            width += [o["width"][k] for k in protocol]
            cin_p += [o["inside_conformal"][k] for k in protocol]
            cin_a += [o["inside_conformal"][k] for k in every]
            cwidth += [o["width_conformal"][k] for k in protocol]
            errs_a += [o["errors"][k] for k in every]
            in_a += [o["inside"][k] for k in every]
            ms += o["tick_ms"]
            if seed == seeds[0] and mode == modes[0]:
                stem = Path(r.source).stem
                res["runs"][stem].update({"trace": o["trace"], "n_resamples": o["n_resamples"],
                                          "final_quantiles": o["final_quantiles"]})
                log(f"[{kind}] {stem}: lung calibrated {res['runs'][stem]['calibrated_lung']}"
                    f", tracked at the end {o['final_quantiles']}")
        ms = np.array(ms)
        res["online"][str(seed)] = {
            "protocol_rmse_Pa": rmse(errs_p), "every_tick_rmse_Pa": rmse(errs_a),
            "coverage_90_protocol": float(np.mean(np.concatenate(in_p))),
            "coverage_90_every_tick": float(np.mean(np.concatenate(in_a))),
            "band_90_median_width_Pa": float(np.median(np.concatenate(width))),
            "conformal_coverage_90_protocol": float(np.mean(np.concatenate(cin_p))),
            "conformal_coverage_90_every_tick": float(np.mean(np.concatenate(cin_a))),
            "conformal_band_90_median_width_Pa": float(np.median(np.concatenate(cwidth))),
            "tick_ms": {"median": float(np.median(ms)), "mean": float(ms.mean()),
                        "p95": float(np.percentile(ms, 95)), "max": float(ms.max()),
                        "ticks": int(ms.size)}}
        o = res["online"][str(seed)]
        log(f"[{kind}] {mode}, seed {seed}: online {o['protocol_rmse_Pa']:.0f} Pa on the "
            f"protocol's windows, {o['every_tick_rmse_Pa']:.0f} Pa every tick; 90 % coverage "
            f"{o['coverage_90_protocol']:.2f} (band {o['band_90_median_width_Pa']:.0f} Pa), "
            f"online conformal {o['conformal_coverage_90_protocol']:.2f} (band "
            f"{o['conformal_band_90_median_width_Pa']:.0f} Pa); "
            f"tick {o['tick_ms']['median']:.1f} ms median")
    res["online"] = res["online_modes"][modes[0]]
    pw = res["protocol_windows"]
    log(f"[{kind}] protocol windows ({res['protocol_n_windows']}): set-point "
        f"{pw['setpoint']:.0f}, frozen {pw['frozen']:.0f}, calibrated {pw['calibrated']:.0f}"
        + (f", refit so far {pw['refit']:.0f}" if "refit" in pw else "") + " Pa; online "
        + ", ".join(f"{v['protocol_rmse_Pa']:.0f}" for v in res["online"].values())
        + f" Pa (seeds {list(seeds)})")
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--sets", default="OXY,AIR")
    ap.add_argument("--quick", action="store_true",
                    help="skip the refit-so-far comparison (the slow part)")
    ap.add_argument("--smoke", action="store_true",
                    help="one held-out run, 10-evaluation refinements (a check it runs)")
    ap.add_argument("--select", action="store_true",
                    help="choose temper and the move floor on the training runs (leave one "
                         "out, SELECT_GRID) before the held-out runs")
    ap.add_argument("--seeds", default=str(SEED),
                    help="comma-separated tracker seeds (the first one's traces are kept)")
    ap.add_argument("--population", choices=("point", "hierarchical"), default="point",
                    help="the tracker's prior: the point fits' log-normal, or the posterior "
                         "predictive of real_respiraworks_population.py's hierarchical fit")
    ap.add_argument("--set", action="append", default=[], metavar="KNOB=VALUE",
                    help="override a tracker knob of TRACKER for this run (recorded in "
                         "the result)")
    ap.add_argument("--modes", default=None,
                    help="comma-separated update modes to run the tracker in (lookback, "
                         "carried; default: TRACKER's update_mode)")
    add_split_arguments(ap, DATA, HELD_OUT, "run")
    args = ap.parse_args(argv)
    held_out = tuple(args.held_out or HELD_OUT)
    modes = [m.strip() for m in args.modes.split(",") if m.strip()] if args.modes else None
    if modes and any(m not in ("lookback", "carried") for m in modes):
        ap.error(f"--modes {args.modes}: lookback and/or carried")
    tracker = dict(TRACKER)  # (this run's knobs; the module's defaults stay as they are)
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in tracker:
            ap.error(f"--set {item}: not a knob of {sorted(tracker)}")
        kind = type(tracker[key])
        try:
            tracker[key] = value if kind is str else kind(
                float(value) if kind is float else int(value))
        except ValueError:
            ap.error(f"--set {item}: {key} takes a {kind.__name__}, got {value!r}")
    seeds = [int(v) for v in args.seeds.split(",") if v.strip()]
    out = Path(args.out)
    path = out / "real_respiraworks_online.json"
    result = {"horizon_s": HORIZON_S, "held_out": list(held_out), "calibration_s": CAL_S,
              "tick_s": TICK_S, "n_particles": N_PARTICLES, "n_draws": N_DRAWS,
              "floor_log_sd": FLOOR_LOG_SD, "tracker": tracker,
              "forecast_warm_up_windows": FORECAST_WARM, "seed": SEED,
              "max_nfev": MAX_NFEV, "quick": args.quick, "smoke": args.smoke,
              "select": args.select, "population": args.population,
              "select_grid": SELECT_GRID if args.select else None,
              "seeds": seeds, "modes": modes, "sets": {},
              "provenance": provenance()}
    for kind in [k.strip() for k in args.sets.split(",") if k.strip()]:
        result["sets"][kind] = run_set(kind, out, args.quick, args.smoke, args.select, seeds,
                                       lambda msg: print(msg, file=sys.stderr),
                                       args.population, modes, Path(args.data), held_out,
                                       tracker)
        write_json_atomic(path, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
