"""Small and large batches on one thread and on several: what the threads cost per call.

    .venv/bin/python benchmarks/batch_threads.py [--threads 2] [--seconds 1]
        [--json results/batch_threads.json]

A batch (parameter sets x windows) runs as chunks on numba's thread count of threads
(the calling one and helpers started once per process,
:mod:`pneubayes.simulation.task_threads`). Handing chunks to threads costs a little per
call, which a short batch may not earn back. This times ``simulate`` of the paper's
model (valve 1, the fixed 2.4e-6 m^3 chamber, a seeded square-wave command) over a grid
of trajectory lengths and batch sizes, each on one thread and on ``--threads``, in the
same process and run, and prints each one's median call and the ratio (threads / one
thread; < 1 is the threads' gain). Nothing here fails on a slow time.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
from timing import time_calls

#: (samples at 1 kHz, parameter sets) per case
GRID = ((21, 2), (21, 8), (21, 64), (201, 2), (201, 8), (201, 64), (2001, 2), (2001, 8),
        (2001, 64))


def _median_call(fn, seconds: float) -> float:
    fn()  # (compiled, or loaded from the cache, before timing)
    return time_calls(fn, seconds, min_calls=5)["median_s"]


def main(argv=None) -> int:
    import numba

    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.rig import Rig
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2, help="threads to compare with one")
    ap.add_argument("--seconds", type=float, default=1.0, help="least time per case")
    ap.add_argument("--json", type=Path, default=None, help="results (written atomically)")
    args = ap.parse_args(argv)
    if not 2 <= args.threads <= numba.config.NUMBA_NUM_THREADS:
        ap.error(f"--threads must be in 2..{numba.config.NUMBA_NUM_THREADS} "
                 "(numba.config.NUMBA_NUM_THREADS)")
    p_atm, p_sup = 101325.0, 551325.0
    rig = Rig(0.009, p_atm, p_sup, stroke_m=0.03)
    model = Model([])
    values = dict(valve_preset("valve1").parameters(), dead_volume_m3=2.4e-6)
    row = np.array([values[k] for k in model.parameter_names])
    rng = np.random.default_rng(0)  # the batch's perturbations
    solver = SolverConfig.standard()
    rows = []
    for n, sets in GRID:
        t = np.arange(n) * 1e-3
        u = np.where((t * 10.0) % 2.0 < 1.0, 3.0, -3.0)
        inputs = Inputs(t, u, np.zeros(n), np.full(n, p_sup))
        lo, hi = model.bounds
        theta = np.clip(row * rng.uniform(0.95, 1.05, (sets, row.size)), lo, hi)
        medians = {}
        for threads in (1, args.threads):
            numba.set_num_threads(threads)
            medians[threads] = _median_call(
                lambda th=theta, inp=inputs: simulate(model, th, inp, rig, 2e5, solver),
                args.seconds)
        ratio = medians[args.threads] / medians[1]
        rows.append({"samples": n, "sets": sets, "one_thread_s": medians[1],
                     "threads_s": medians[args.threads], "ratio": ratio})
        print(f"{n:5d} samples x {sets:3d} sets  1 thread {1e3 * medians[1]:8.3f} ms  "
              f"{args.threads} threads {1e3 * medians[args.threads]:8.3f} ms  "
              f"ratio {ratio:.2f}", flush=True)
    numba.set_num_threads(1)
    if args.json:
        from pneubayes.atomic import write_json_atomic
        from pneubayes.provenance import provenance
        write_json_atomic(args.json, {"rows": rows, "threads": args.threads,
                                      "seconds": args.seconds, "cpu_count": os.cpu_count(),
                                      "load_average": list(os.getloadavg()),
                                      "provenance": provenance()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
