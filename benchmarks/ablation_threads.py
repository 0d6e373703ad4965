"""Ablation workers and their threads: do worker processes oversubscribe the cores?

Each :class:`pneubayes.ablation.executor.LocalExecutor` worker is a fresh process whose
BLAS (OpenBLAS) and numba thread pools would each default to every core, so ``workers``
processes run ``workers x cores`` threads. The proxy cell here does what a cell's fit
spends its time on: QR factorisations of a tall design (the paper's least squares,
:func:`pneubayes.inference.lsq._nonnegative_least_squares`) and batched simulations of
the paper's model (numba threads). Four cells on two workers, timed with each worker's
threads limited to its share of the cores (what the executor does) and with the pools
left at every core (``threads_per_worker`` = the core count), alternating, twice.

    python benchmarks/ablation_threads.py [--json results/ablation_threads.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np


def proxy_cell(seed: int) -> float:
    """One cell's kinds of work; returns its own wall time (s)."""
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.rig import Rig
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    design = rng.standard_normal((4000, 120))
    for _ in range(15):
        np.linalg.qr(design)
    n = 2001
    t = np.arange(n) / 1000.0
    rig = Rig(0.009, 101325.0, 551325.0)
    inputs = Inputs(t, 3.0 * np.sin(2 * np.pi * 2.0 * t), np.zeros(n), np.full(n, 551325.0))
    model = Model(["cylinder_leak"])
    p = dict(valve_preset("valve1").parameters(), dead_volume_m3=2.4e-6, leak_area_m2=3e-8)
    rows = np.tile(model.vector(p), (32, 1))
    for _ in range(3):
        simulate(model, rows, inputs, rig, 101325.0, SolverConfig.standard())
    return time.perf_counter() - start


def run(threads_per_worker: int, cells: int) -> dict:
    from pneubayes.ablation.executor import LocalExecutor

    start = time.perf_counter()
    with LocalExecutor(2, threads_per_worker=threads_per_worker) as ex:
        futures = [ex.submit(proxy_cell, seed) for seed in range(cells)]
        per_cell = [f.result() for f in ex.as_completed(futures)]
    return {"threads_per_worker": threads_per_worker, "wall_s": time.perf_counter() - start,
            "cell_s": sorted(per_cell)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--cells", type=int, default=4)
    args = ap.parse_args(argv)
    cores = os.cpu_count() or 1
    proxy_cell(0)  # compile (or load) the kernel once, outside the timings
    results = []
    for _ in range(2):
        for threads in (max(1, cores // 2), cores):
            r = run(threads, args.cells)
            results.append(r)
            print(f"threads per worker {threads}: {r['wall_s']:.1f} s "
                  f"(cells {', '.join(f'{s:.1f}' for s in r['cell_s'])})", file=sys.stderr)
    doc = {"cores": cores, "workers": 2, "cells": args.cells, "runs": results}
    if args.json:
        from pneubayes.atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
