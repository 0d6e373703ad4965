"""Before and after, in one run: the simulator's speed from two source trees, alternated.

    .venv/bin/python benchmarks/kernel_ab.py --before /path/to/old/checkout \
        [--after .] [--rounds 3] [--json results/kernel_ab.json]

A refactor of the compiled kernel must not cost speed. This runs the same workload
(``benchmarks/simulate.py``'s seeded 2-s, 1-kHz trajectory on the fixed 2.4e-6 m^3
chamber: the paper's model and every form of its section 4, batch 1 on one thread;
the moving piston with dense output, the chord and q steps' path; and a batch of 64
perturbed parameter sets) in worker processes whose ``PYTHONPATH`` is each tree in
turn, alternating ``before, after, before, after, ...`` so that a machine's drift
falls on both. Each worker compiles first (not timed), then times each case for at
least ``--seconds`` and reports its fastest call and its median. The table gives, per
case, the fastest over the rounds for each tree and their ratio (after / before: > 1
is slower). A worktree of the old commit is the usual ``--before``::

    git worktree add /tmp/before HEAD~1

Nothing here fails on a slow time; it prints and writes what it measured.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _worker(seconds: float) -> dict:
    """Time every case with the ``pneubayes`` on ``sys.path``; returns {case: times}."""
    import numpy as np

    sys.path.insert(0, str(HERE))
    import simulate as bench  # the workload's definitions (this tree's benchmark)
    from timing import time_calls

    from pneubayes.effects import make_effect
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.rig import Rig
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    rng_cmd, rng_motion, rng_params = (np.random.default_rng([0, k]) for k in range(3))
    n = round(bench.DURATION_S * bench.SAMPLE_RATE_HZ) + 1
    t = np.arange(n) / bench.SAMPLE_RATE_HZ
    command = bench.make_command(rng_cmd, n)
    motion = bench.make_motion(rng_motion, t)
    supply = np.full(n, bench.P_SUPPLY)
    rig = Rig(bench.BORE_M, bench.P_ATM, bench.P_SUPPLY)
    base = valve_preset("valve1").parameters()
    base.update(dead_volume_m3=2.4e-6, leak_area_m2=bench.LEAK_AREA_M2)
    fixed = Inputs(t, command, np.zeros(n), supply)
    moving = Inputs(t, command, motion, supply)
    solver = SolverConfig.standard()
    cases = {}
    for label, name, options in bench.EFFECT_FORMS:
        m = Model(["cylinder_leak"] + ([] if name is None else [make_effect(name, **options)]))
        theta = dict(base, **({} if name is None else m.effects[-1].bench_defaults()))
        cases[label] = (lambda m=m, theta=theta: simulate(m, theta, fixed, rig, bench.P_ATM,
                                                          solver))
    plain = Model(["cylinder_leak"])
    moving_theta = dict(base, dead_volume_m3=2e-7)
    dense = solver.with_dense_output(True)
    cases["moving piston, dense output"] = lambda: simulate(plain, moving_theta, moving, rig,
                                                            bench.P_ATM, dense)
    lo, hi = plain.bounds
    batch = np.clip(plain.vector(base)[None, :]
                    * rng_params.uniform(0.9, 1.1, size=(64, plain.n_parameters)), lo, hi)
    cases["paper's model, batch 64 (per trajectory)"] = lambda: simulate(
        plain, batch, fixed, rig, bench.P_ATM, solver)
    import numba
    numba.set_num_threads(1)
    out = {}
    for label, fn in cases.items():
        fn()  # compile (not timed)
        out[label] = time_calls(fn, seconds, per=64 if "batch 64" in label else 1)
    return out


def _run_worker(tree: Path, seconds: float) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    proc = subprocess.run([sys.executable, __file__, "--worker", "--seconds", str(seconds)],
                          env=env, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"worker for {tree} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="the old source tree (a git worktree)")
    ap.add_argument("--after", type=Path, default=HERE.parent, help="the new one (default: "
                    "this checkout)")
    ap.add_argument("--rounds", type=int, default=3, help="alternations (default 3)")
    ap.add_argument("--seconds", type=float, default=1.0,
                    help="least time spent timing each case per worker (default 1)")
    ap.add_argument("--json", type=Path, default=None, help="results (written atomically)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(_worker(args.seconds)))
        return 0
    if args.before is None:
        ap.error("--before is required")
    for tree in (args.before, args.after):
        if not (tree / "pneubayes" / "__init__.py").is_file():
            ap.error(f"{tree}: not a pneubayes source tree (no pneubayes/__init__.py)")
    runs = {"before": [], "after": []}
    for r in range(args.rounds):
        for which in ("before", "after"):
            tree = getattr(args, which)
            print(f"round {r + 1}/{args.rounds}: {which} ({tree}) ...", file=sys.stderr,
                  flush=True)
            runs[which].append(_run_worker(tree.resolve(), args.seconds))
    rows = []
    for case in runs["after"][0]:
        best = {w: min(run[case]["min_s"] for run in runs[w]) for w in runs}
        rows.append({"case": case, "before_min_s": best["before"],
                     "after_min_s": best["after"], "after_over_before":
                     best["after"] / best["before"]})
    print(f"{'case':44s} {'before ms':>10s} {'after ms':>10s} {'after/before':>13s}")
    for row in rows:
        print(f"{row['case']:44s} {1e3 * row['before_min_s']:10.3f} "
              f"{1e3 * row['after_min_s']:10.3f} {row['after_over_before']:13.3f}")
    if args.json:
        from pneubayes.atomic import write_json_atomic
        write_json_atomic(args.json, {"before": str(args.before), "after": str(args.after),
                                      "rounds": args.rounds, "rows": rows, "runs": runs,
                                      "loadavg": os.getloadavg()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
