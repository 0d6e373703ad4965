"""Solver presets against scipy's Radau (rtol 1e-10) over chambers, motions and effects.

For each case (valve2 from Table II; dead volume 1e-7, 2.4e-6 and 2e-5 m^3; the piston
fixed or moving sinusoidally at 3 Hz over +-10 mm; a supply wandering +-15 kPa; a 1-s
random-step command (`pneubayes.bench.protocols.step_commands`: holds 30-300 ms, levels
-5..5 V); the paper's model and each
catalogue effect alone at its bench defaults) the largest absolute pressure error of
each preset, in Pa and in % of the 450-kPa working range. The claims of
``SolverConfig``'s docstrings are measured here.

    .venv/bin/python benchmarks/solver_accuracy.py --json results/solver_accuracy.json

The Radau references (5-60 s each, about 10 min in all) are kept in ``--cache`` as .npy
files: an interrupted run resumes from them, and a second run (another preset, another
code revision) reuses them. The JSON is written atomically; the seed is stored in it.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.protocols import step_commands
from pneubayes.effects import CATALOGUE
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.provenance import provenance
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate
from pneubayes.simulation.reference import reference_simulate

P_ATM_PA, P_SUPPLY_PA = 101325.0, 551325.0
RANGE_PA = P_SUPPLY_PA - P_ATM_PA
BORE_M = 0.009
VOLUMES_M3 = (1e-7, 2.4e-6, 2e-5)
PRESETS = {"standard": SolverConfig.standard, "sampling": SolverConfig.sampling}


def cases(seed: int, duration_s: float):
    """``(name, model, parameters, inputs)`` for every case, in a fixed order."""
    n = int(round(duration_s * 1000)) + 1
    t = np.arange(n) * 1e-3
    u = step_commands(t, np.random.default_rng(seed), 5.0)
    supply = P_SUPPLY_PA + 15_000.0 * (0.7 * np.sin(2 * np.pi * 1.3 * t)
                                       + 0.3 * np.sin(2 * np.pi * 7.1 * t))
    for effect in [None, *CATALOGUE]:
        model = Model([] if effect is None else [effect])
        for volume in VOLUMES_M3:
            for moving in (False, True):
                params = valve_preset("valve2").parameters()
                params["dead_volume_m3"] = volume
                for e in model.effects:
                    params.update(e.bench_defaults())
                x = 0.015 + 0.01 * np.sin(2 * np.pi * 3.0 * t) if moving else np.zeros(n)
                name = f"{effect or 'paper'}_{volume:g}_{'moving' if moving else 'fixed'}"
                yield name, model, params, Inputs(t, u, x, supply)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", required=True, help="where to write the errors (atomically)")
    ap.add_argument("--seed", type=int, default=0, help="the command's seed (default 0)")
    ap.add_argument("--duration", type=float, default=1.0, help="seconds a case (default 1)")
    ap.add_argument("--cache", default="results/solver_accuracy_cache",
                    help="folder of the Radau references (reused, resumed)")
    ap.add_argument("--presets", nargs="+", default=list(PRESETS), choices=list(PRESETS))
    args = ap.parse_args(argv)
    if not args.duration > 0:
        ap.error(f"--duration must be > 0, got {args.duration}")
    rig = Rig(BORE_M, P_ATM_PA, P_SUPPLY_PA)
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows = {}
    all_cases = list(cases(args.seed, args.duration))
    for i, (name, model, params, inputs) in enumerate(all_cases):
        key = hashlib.sha256(repr((name, sorted(params.items()), args.seed,
                                   args.duration)).encode()).hexdigest()[:16]
        path = cache / f"{name}_{key}.npy"
        if path.exists():
            ref = np.load(path)
        else:
            ref = np.asarray(reference_simulate(model, params, inputs, rig, 2e5,
                                                method="Radau", rtol=1e-10))
            tmp = path.with_suffix(".tmp.npy")
            np.save(tmp, ref)
            tmp.replace(path)
        row = {}
        for preset in args.presets:
            got = simulate(model, params, inputs, rig, 2e5, PRESETS[preset]()).pressure_Pa[0]
            row[preset] = float(np.max(np.abs(got - ref)))
        rows[name] = row
        print(f"[{i + 1:2d}/{len(all_cases)}] {name:38s} "
              + "  ".join(f"{p} {v:8.2f} Pa" for p, v in row.items()), flush=True)
    worst = {p: max(rows, key=lambda k: rows[k][p]) for p in args.presets}
    for p, k in worst.items():
        print(f"largest error, {p}: {rows[k][p]:.1f} Pa ({100 * rows[k][p] / RANGE_PA:.3f} % "
              f"of the range) in {k}")
    write_json_atomic(args.json, {
        "schema": "pneubayes-bench-solver-accuracy/1", "seed": args.seed,
        "duration_s": args.duration, "working_range_Pa": RANGE_PA,
        "errors_Pa": rows,
        "largest": {p: {"case": k, "error_Pa": rows[k][p],
                        "percent_of_range": 100 * rows[k][p] / RANGE_PA}
                    for p, k in worst.items()},
        "provenance": provenance(),
        "wall_s": time.perf_counter() - started})
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
