"""Is the window likelihood calibrated? Its MAP and Laplace intervals over many seeds.

The identification study (issue 3) runs a full emcee fit per case, so it affords a few
seeds, and within one seed every rig shares commands and noise: its coverage rests on
few independent tries. This check is cheaper and counts many: for each bench seed it
draws the identification design's four fixed-volume recordings, maximises the same
posterior the sampler explores (:class:`WindowLikelihood`, sampling coordinates,
nuisance coordinates held at the truth since the posterior is flat in them), and takes
a Laplace approximation there (finite-difference Hessian). Over seeds, a calibrated
likelihood gives ``z = (truth - MAP) / sd`` with mean 0 and SD 1 per coordinate, 90 %
intervals covering the truth 90 % of the time, and ``m2 = z^T C^-1 z ~ chi^2_k``.

    python experiments/likelihood_calibration.py --rig AIR200:valve2 --seeds 100:140 \\
        --out results/likelihood_calibration/AIR200

Each seed's result is written atomically to OUT/cases/ (an interrupted run resumes);
OUT/summary.json and OUT/summary.md hold the tables. Seeds are the bench seeds
(commands and noise); they are recorded with every case.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats
from scipy.optimize import minimize

from pneubayes.atomic import write_json_atomic, write_text_atomic
from pneubayes.bench.bench import identification_sets
from pneubayes.inference.likelihood import WindowLikelihood
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance
from pneubayes.simulation import SolverConfig

#: the refinement solver (pneubayes fit's refine_solver): smooth enough in the
#: parameters for finite differences, unlike the sampler's looser preset
SOLVER = SolverConfig.refinement()
#: Hessian step, in (diagonal-curvature) standard deviations
HESSIAN_STEP_SD = 0.05
Z90 = stats.norm.ppf(0.95)


def run_seed(cylinder: str, valve: str, seed: int, duration_s: float,
             effects: tuple[str, ...] = ("cylinder_leak",)) -> dict:
    """MAP, Laplace covariance and the truth's z for one bench seed."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        train, _ = identification_sets(cylinder, valve, seed, duration_s, d, effects=effects)
        model, truth = Model.load_card(train.truth_path)
        recs = [read_recording(p) for p in train.recordings]
    like = WindowLikelihood(model, WindowSet(recs, 2.0, 2.0), SOLVER)
    zt = like.to_sampling(model.vector(truth)[None])[0]
    nuisance = set(like.nuisance())
    cols = [j for j in range(zt.size) if j not in nuisance]
    base = like.log_prob_sampling(zt[None])[0]
    # unit scales: the diagonal curvature at the truth
    scale = np.empty(len(cols))
    for i, j in enumerate(cols):
        h = 1e-4 * abs(zt[j]) if zt[j] != 0 else 1e-12
        pm = np.stack([zt, zt])
        pm[0, j] += h
        pm[1, j] -= h
        lp = like.log_prob_sampling(pm)
        curv = -(lp[0] + lp[1] - 2.0 * base) / h**2
        if not curv > 0:
            raise RuntimeError(f"seed {seed}: no curvature in {like.names[j]} at the truth")
        scale[i] = 1.0 / np.sqrt(curv)

    def neg_lp(v):
        z = zt.copy()
        z[cols] = zt[cols] + v * scale
        return -like.log_prob_sampling(z[None])[0]

    opt = minimize(neg_lp, np.zeros(len(cols)), method="BFGS",
                   options={"gtol": 1e-4, "eps": 1e-3, "maxiter": 200})
    v = opt.x
    k = len(cols)
    e = HESSIAN_STEP_SD
    f0 = neg_lp(v)
    hess = np.empty((k, k))
    for a in range(k):
        ea = np.zeros(k)
        ea[a] = e
        hess[a, a] = (neg_lp(v + ea) - 2.0 * f0 + neg_lp(v - ea)) / e**2
        for b in range(a + 1, k):
            eb = np.zeros(k)
            eb[b] = e
            hess[a, b] = hess[b, a] = (neg_lp(v + ea + eb) - neg_lp(v + ea - eb)
                                       - neg_lp(v - ea + eb) + neg_lp(v - ea - eb)) / (4 * e * e)
    cov = np.linalg.inv(hess)
    z = -v / np.sqrt(np.diag(cov))  # (truth - MAP) / sd
    return {"cylinder": cylinder, "valve": valve, "seed": seed, "effects": list(effects),
            "coordinates": [like.names[j] for j in cols],
            "z": z.tolist(), "m2": float(v @ hess @ v), "k": k,
            "optimizer_iterations": int(opt.nit), "optimizer_message": str(opt.message),
            "wall_time_s": time.perf_counter() - t0}


def _label(name: str) -> str:
    """What a sampling coordinate is (see WindowLikelihood.to_sampling)."""
    if name in ("inlet_b", "exhaust_b"):
        port = name.split("_")[0]
        return f"ln {name} - c d ({port})"
    if name == "leak_area_m2":
        return "exhaust_offset_m2 + leak_area_m2"
    return name


def summarise(cases: list[dict]) -> dict:
    names = [_label(c) for c in cases[0]["coordinates"]]
    z = np.array([c["z"] for c in cases])
    m2 = np.array([c["m2"] for c in cases])
    k = cases[0]["k"]
    n = len(cases)
    return {"cases": n, "coordinates": names,
            "mean_z": dict(zip(names, z.mean(axis=0).tolist())),
            "se_mean_z": dict(zip(names, (z.std(axis=0, ddof=1) / np.sqrt(n)).tolist())),
            "sd_z": dict(zip(names, z.std(axis=0, ddof=1).tolist())),
            "coverage_90": dict(zip(names, (np.abs(z) <= Z90).mean(axis=0).tolist())),
            "sum_m2": float(m2.sum()), "sum_k": int(k * n),
            "chi2_p_value": float(stats.chi2.sf(m2.sum(), k * n))}


def markdown(s: dict, rig: str) -> str:
    lines = [f"Likelihood calibration on {rig}: {s['cases']} bench seeds (MAP + Laplace).", "",
             "| coordinate | mean z (se) | SD of z | 90 % interval covers truth |",
             "|---|---|---|---|"]
    for c in s["coordinates"]:
        lines.append(f"| {c} | {s['mean_z'][c]:+.2f} ({s['se_mean_z'][c]:.2f}) | "
                     f"{s['sd_z'][c]:.2f} | {100 * s['coverage_90'][c]:.0f} % |")
    lines += ["", f"Joint: sum of m2 {s['sum_m2']:.1f} on {s['sum_k']} degrees of freedom "
              f"({s['sum_m2'] / s['sum_k']:.2f} x k), chi2 p = {s['chi2_p_value']:.2g}."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--rig", default="AIR200:valve2", help="CYLINDER:VALVE")
    ap.add_argument("--seeds", default="100:140", help="FIRST:STOP (Python range)")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per recording")
    ap.add_argument("--effects", default="cylinder_leak",
                    help="comma-separated effects planted and fitted (the paper's model: "
                         "cylinder_leak)")
    args = ap.parse_args(argv)
    effects = tuple(e for e in args.effects.split(",") if e)
    try:
        cylinder, valve = args.rig.split(":")
        first, stop = (int(v) for v in args.seeds.split(":"))
    except ValueError:
        ap.error(f"--rig must be CYLINDER:VALVE and --seeds FIRST:STOP, got {args.rig!r}, "
                 f"{args.seeds!r}")
    out = Path(args.out)
    (out / "cases").mkdir(parents=True, exist_ok=True)
    cases = []
    for i, seed in enumerate(range(first, stop)):
        extra = "" if effects == ("cylinder_leak",) else "_" + "+".join(effects)
        path = out / "cases" / f"{cylinder}_{valve}{extra}_s{seed}.json"
        if path.exists():
            cases.append(json.loads(path.read_text()))
            continue
        case = run_seed(cylinder, valve, seed, args.duration, effects)
        write_json_atomic(path, case)
        cases.append(case)
        print(f"[{i + 1}/{stop - first}] seed {seed}: m2 {case['m2']:.1f}, z "
              + " ".join(f"{v:+.2f}" for v in case["z"])
              + f" ({case['wall_time_s']:.0f} s)", flush=True)
    if not cases:
        print("no seeds", file=sys.stderr)
        return 1
    s = summarise(cases)
    s["config"] = vars(args)
    s["provenance"] = provenance()
    write_json_atomic(out / "summary.json", s)
    md = markdown(s, args.rig)
    write_text_atomic(out / "summary.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
