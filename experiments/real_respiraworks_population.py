"""Real recordings: the population of the RespiraWorks test lung across runs (issue 67,
item 1), a hierarchical fit with R-hat and ESS.

    python experiments/real_respiraworks_population.py --out DIR [--sets OXY,AIR]
        [--quick] [--shared-from DIR] [--at-bound drop|keep] [--data DIR] [--held-out RUN ...]

The shipped card (two compartments, the exhale valve on its own command) and the split of
``real_respiraworks_online.py`` (runs 1-4 train, 5-6 held out, not read; ``--held-out``
and ``--data`` as there). Per set:

1. *Shared fit*: every quantity refined on the training runs (``shared_fit`` of
   ``real_respiraworks_online.py``; read from ``--shared-from DIR/shared_SET.json`` or
   ``OUT/shared_SET.json`` when it holds this card's).
2. *Stage 1, per run*: the lung's quantities (``LUNG``) refined on the whole run, the
   others known at the shared fit; the run's likelihood as a Gaussian in the log values:
   the Gauss-Newton information of the refinement (``TrajectoryRefiner.information_``,
   error scale the fit's RMSE) in log coordinates, divided by the AR(1) factor
   ``(1 + rho) / (1 - rho)`` of the residuals' lag-1 correlation within windows (the
   samples are far from independent). A quantity whose fit sits on a bound (within
   ``BOUND_TOL`` in log) has no Gaussian there; ``POLICIES`` (function ``bounded``):
   ``condition`` (default) the run says nothing of it and its other quantities keep
   their Gaussian given it at the bound; ``marginal`` the others' Gaussian marginalised
   over it (near-degenerate pairs, the lung's volume and compliance, lose most of their
   information); ``keep`` the Gaussian at the bound as it is. Stage 2 runs for each
   (``--at-bound`` picks the one reported first).
3. *Stage 2*: :class:`~pneubayes.inference.hierarchical.HierarchicalPopulation`:
   priors ``mu ~ Normal(centre of the card's log bounds, a quarter of their width)``,
   ``tau ~ HalfNormal(TAU_SCALE)``; ``N_CHAINS`` ensembles of ``N_WALKERS`` for
   ``N_STEPS`` steps; R-hat, ESS; the population median, mean and log SD with 90 %
   intervals (SI units), a new run's predictive, each run's shrunk value; beside it the
   point-fit population (``LogNormalPrior.from_point_fits``, ``FLOOR_LOG_SD``) the online
   experiment uses; and tau's interval under ``TAU_SCALES`` (what the prior sets).

Seed ``SEED`` (recorded). Writes OUT/real_respiraworks_population.json and prints the table.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from real_common import add_split_arguments
from real_respiraworks import DATA, HELD_OUT, HORIZON_S, split_runs
from real_respiraworks_forms import LUNG, MAX_NFEV, form_card
from real_respiraworks_online import FLOOR_LOG_SD, shared_fit

from pneubayes.atomic import write_json_atomic
from pneubayes.inference.hierarchical import HierarchicalPopulation
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.population import LogNormalPrior, log_bounds
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance

SEED = 67
N_CHAINS, N_WALKERS, N_STEPS = 4, 32, 4000
TAU_SCALE = 1.0
#: the half-normal scales of the sensitivity run (the reported policy)
TAU_SCALES = (0.5, 1.0, 2.0)
BOUND_TOL = 0.01
#: how a run's fit on a bound enters stage 2 (``bounded``); the first is the default
POLICIES = ("condition", "marginal", "keep")


def lag1(res: np.ndarray) -> float:
    """Lag-1 correlation of residuals ``(windows, samples)`` within windows, pooled."""
    r = res - res.mean(axis=1, keepdims=True)
    return float(np.sum(r[:, 1:] * r[:, :-1]) / np.sum(r * r))


def bounded(prec: np.ndarray, on_bound: np.ndarray, policy: str) -> np.ndarray:
    """A run's log precision with its fits on a bound treated by ``policy``: ``condition``
    (the run says nothing of them; the others keep their Gaussian given them at the
    bound: their rows and columns 0), ``marginal`` (the others' Gaussian marginalised
    over them) or ``keep`` (the Gaussian at the bound as it is)."""
    if policy == "keep" or not on_bound.any():
        return prec.copy()
    keep = ~on_bound
    out = np.zeros_like(prec)
    pkk = prec[np.ix_(keep, keep)]
    if policy == "marginal":
        pkd, pdd = prec[np.ix_(keep, on_bound)], prec[np.ix_(on_bound, on_bound)]
        pkk = pkk - pkd @ np.linalg.pinv(pdd) @ pkd.T
    out[np.ix_(keep, keep)] = 0.5 * (pkk + pkk.T)
    return out


def stage1(kind, card, shared, train, nfev, log) -> dict:
    lung = LUNG["two_compartment"]
    local_card = card.known_at(shared, keep_unknown=lung)
    local = Model(rig_card=local_card)
    lo, hi = log_bounds(local, lung)
    solver = FitSettings().refine_solver
    runs = []
    for r in train:
        t0 = time.perf_counter()
        data = WindowSet([read_recording(r.source, rig_card=local_card)], HORIZON_S,
                         HORIZON_S)
        f = TrajectoryRefiner(local, solver, max_nfev=nfev).fit(
            data, {k: shared[k] for k in lung})
        theta = np.array([f.params_[k] for k in lung])
        idx = [list(f.free_).index(k) for k in lung]
        info = f.information_[np.ix_(idx, idx)] * np.outer(theta, theta)  # log coords
        res = data.residuals(local, f.params_, solver)
        rho = lag1(np.atleast_2d(res.reshape(-1, res.shape[-1])))
        factor = (1 + rho) / max(1 - rho, 1e-6)
        z = np.log(theta)
        on_bound = (z - lo < BOUND_TOL) | (hi - z < BOUND_TOL)
        runs.append({"run": Path(r.source).stem, "params": dict(zip(lung, theta.tolist())),
                     "rmse_Pa": f.rmse_Pa_, "lag1": rho, "ar1_factor": factor,
                     "log_mean": z, "log_precision": info / factor, "on_bound": on_bound,
                     "n_evaluations": f.n_evaluations_, "wall_s": time.perf_counter() - t0})
        sd = 1 / np.sqrt(np.maximum(np.diag(info / factor), 1e-300))
        log(f"[{kind}] stage 1 {runs[-1]['run']}: "
            + ", ".join(f"{k} {v:.3g}" + (" (bound)" if b else "") + f" x/÷ {np.exp(s):.3g}"
                        for k, v, b, s in zip(lung, theta, on_bound, sd))
            + f"; RMSE {f.rmse_Pa_:.0f} Pa, lag-1 {rho:.3f} (x{factor:.0f}); "
              f"{runs[-1]['wall_s']:.0f} s")
    return {"runs": runs, "log_lower": lo, "log_upper": hi, "names": lung, "local": local}


def stage2(s1: dict, policy: str, n_steps: int, tau_scale: float = None
           ) -> HierarchicalPopulation:
    """The hierarchical fit of stage 1's runs, fits on a bound treated by ``policy``."""
    m = np.array([r["log_mean"] for r in s1["runs"]])
    prec = np.array([bounded(r["log_precision"], r["on_bound"], policy) for r in s1["runs"]])
    lo, hi = s1["log_lower"], s1["log_upper"]
    return HierarchicalPopulation(
        s1["names"], mu_prior_mean=0.5 * (lo + hi), mu_prior_sd=0.25 * (hi - lo),
        tau_prior_scale=TAU_SCALE if tau_scale is None else tau_scale, n_walkers=N_WALKERS,
        n_steps=n_steps, n_chains=N_CHAINS, seed=SEED).fit(m, log_precision=prec)


def hierarchical_prior(kind, card, shared, train, nfev, log, policy: str = POLICIES[0]):
    """The tracker's prior from the hierarchical population (``N_STEPS``), and the fit's
    summary (for ``real_respiraworks_online.py --population hierarchical``)."""
    s1 = stage1(kind, card, shared, train, nfev, log)
    hp = stage2(s1, policy, N_STEPS)
    log(f"[{kind}] hierarchical population ({policy}): converged {hp.converged_}, "
        f"max R-hat {max(hp.rhat_.values()):.3f}, min ESS {min(hp.ess_.values()):.0f}")
    return hp.prior(Model(rig_card=card)), {"policy": policy, "converged": hp.converged_,
                                            "population": hp.summary()}


def run_set(kind, out, shared_from, quick, at_bound, log, data: Path = DATA,
            held_out=HELD_OUT) -> dict:
    card = form_card(kind, "two_compartment", "separate", data)
    recs = [read_recording(p, rig_card=card) for p in sorted((data / kind).glob("*.csv"))]
    train, _ = split_runs(recs, held_out, data / kind)
    model = Model(rig_card=card)
    solver = FitSettings().refine_solver
    cache = (Path(shared_from) / f"shared_{kind}.json"
             if shared_from and (Path(shared_from) / f"shared_{kind}.json").exists()
             else out / f"shared_{kind}.json")
    t0 = time.perf_counter()
    shared = shared_fit(kind, card, train, solver, cache, MAX_NFEV, log)
    nfev = 20 if quick else MAX_NFEV
    s1 = stage1(kind, card, shared, train, nfev, log)
    t1 = time.perf_counter()
    names = s1["names"]
    n_steps = 1000 if quick else N_STEPS
    fits = {}
    for policy in POLICIES:  # stage 2 is cheap: every policy for a fit on a bound
        hp = stage2(s1, policy, n_steps)
        fits[policy] = {
            "runs_informing": {n: int(sum(bounded(r["log_precision"], r["on_bound"],
                                                  policy)[i, i] > 0 for r in s1["runs"]))
                               for i, n in enumerate(names)},
            "population": hp.summary(), "converged": hp.converged_,
            "acceptance": hp.acceptance_, "stage2_wall_s": hp.wall_s_,
            "predictive_prior": hp.prior(model).describe()}
        log(f"[{kind}] stage 2 ({policy}): converged {hp.converged_}, {hp.wall_s_:.1f} s")
    # how much of the spread the runs set: tau's interval under other priors' scales
    sensitivity = {}
    for scale in TAU_SCALES:
        hp = stage2(s1, at_bound, n_steps, scale)
        sensitivity[str(scale)] = {n: {**hp.summary()[n]["log_sd"],
                                       "prior_q05": float(scale * 0.0627),
                                       "prior_q95": float(scale * 1.960)}
                                   for n in names}
        sensitivity[str(scale)]["converged"] = hp.converged_
    point = LogNormalPrior.from_point_fits(model, names, [r["params"] for r in s1["runs"]],
                                           FLOOR_LOG_SD)
    return {"names": list(names), "train": [r["run"] for r in s1["runs"]],
            "shared_parameters": shared, "shared_cache": str(cache),
            "stage1": [{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                        for k, v in r.items()} for r in s1["runs"]],
            "stage1_wall_s": t1 - t0, "at_bound": at_bound, **fits[at_bound],
            "policies": fits, "tau_prior_sensitivity": sensitivity,
            "point_fit_prior": point.describe(),
            "sampler": {"n_chains": N_CHAINS, "n_walkers": N_WALKERS, "n_steps": n_steps,
                        "burn": n_steps // 2, "seed": SEED,
                        "tau_half_normal_scale": TAU_SCALE}}


def table(kind: str, res: dict) -> str:
    """The population per policy (the reported one first) and the point fits' prior."""
    order = [res["at_bound"]] + [p for p in res["policies"] if p != res["at_bound"]]
    pf = res["point_fit_prior"]
    rows = [f"{kind}: the lung's population over runs {', '.join(res['train'])} "
            f"(stage 1 {res['stage1_wall_s']:.0f} s); point fits' prior: "
            + ", ".join(f"{n} {md:.3g} (log SD {sd:.2f})" for n, md, sd in
                        zip(pf["names"], pf["median"], pf["log_sd"]))]
    for policy in order:
        fit = res["policies"][policy]
        rows += [f"  fits on a bound: {policy}; converged {fit['converged']}; stage 2 "
                 f"{fit['stage2_wall_s']:.1f} s",
                 f"    {'quantity':26s} {'runs':>4s} {'median [5 %, 95 %]':>33s} "
                 f"{'log SD [5 %, 95 %]':>22s} {'R-hat mu/tau':>13s} {'ESS mu/tau':>11s}"]
        for n in res["names"]:
            p = fit["population"][n]
            md, ls = p["median"], p["log_sd"]
            rows.append(f"    {n:26s} {fit['runs_informing'][n]:4d} "
                        f"{md['q50']:10.3g} [{md['q05']:9.3g}, {md['q95']:9.3g}] "
                        f"{ls['q50']:7.2f} [{ls['q05']:5.2f}, {ls['q95']:5.2f}] "
                        f"{p['rhat']['mu']:6.3f}/{p['rhat']['tau']:5.3f} "
                        f"{p['ess']['mu']:5.0f}/{p['ess']['tau']:5.0f}")
    rows.append(f"  log SD (median [5 %, 95 %]) under tau ~ HalfNormal(scale), "
                f"{res['at_bound']}:")
    for scale, sens in res["tau_prior_sensitivity"].items():
        rows.append(f"    scale {scale:>4s} (prior 90 %: [{0.0627 * float(scale):.2f}, "
                    f"{1.960 * float(scale):.2f}]): " + ", ".join(
                        f"{n} {sens[n]['q50']:.2f} [{sens[n]['q05']:.2f}, "
                        f"{sens[n]['q95']:.2f}]" for n in res["names"]))
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--sets", default="OXY,AIR")
    ap.add_argument("--quick", action="store_true",
                    help="20-evaluation lung refits and 1000 steps (a check it runs)")
    ap.add_argument("--shared-from", default=None,
                    help="a folder holding shared_SET.json from real_respiraworks_online.py")
    ap.add_argument("--at-bound", choices=POLICIES, default=POLICIES[0],
                    help="the policy reported first (all are computed and written)")
    add_split_arguments(ap, DATA, HELD_OUT, "run")
    args = ap.parse_args(argv)
    held_out = tuple(args.held_out or HELD_OUT)
    out = Path(args.out)
    path = out / "real_respiraworks_population.json"
    result = {"horizon_s": HORIZON_S, "held_out": list(held_out), "max_nfev": MAX_NFEV,
              "quick": args.quick, "seed": SEED, "bound_tol_log": BOUND_TOL, "sets": {},
              "provenance": provenance()}

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    tables = []
    for kind in [k.strip() for k in args.sets.split(",") if k.strip()]:
        result["sets"][kind] = res = run_set(kind, out, args.shared_from, args.quick,
                                             args.at_bound, log, Path(args.data), held_out)
        write_json_atomic(path, result)
        tables.append(table(kind, res))
        log(tables[-1])
    print("\n\n".join(tables))
    return 0


if __name__ == "__main__":
    sys.exit(main())
