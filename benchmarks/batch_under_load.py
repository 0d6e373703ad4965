"""The batched simulator on a shared machine: batch 64 against batch 1, per trajectory.

    .venv/bin/python benchmarks/batch_under_load.py [--busy 0,1] [--seconds 2]
        [--json results/batch_under_load.json]

MCMC and the controller simulate many parameter sets in one call; a lab's workstation
or a cluster node is shared. This times, per trajectory, a batch of 64 perturbed
parameter sets against a batch of one (``benchmarks/simulate.py``'s seeded 2-s, 1-kHz
trajectory on the fixed 2.4e-6 m^3 chamber, forms of its section 4), on one and on two
numba threads, while ``--busy`` other processes (started here: each a pure-Python busy
loop) keep cores occupied. Per case: the median and the fastest call of each batch
size over at least ``--seconds``, and the ratio of the medians (batch 64 per
trajectory over batch 1; issue 68's floor: <= 1.2 with one busy process). Load
averages are recorded. Nothing here fails on a slow time.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np
from timing import time_calls

HERE = Path(__file__).resolve().parent
#: forms of simulate.py's section 4 timed here (label, effect, options)
FORMS = (("paper's model", None, {}), ("heat_transfer", "heat_transfer", {}),
         ("sensor_lag", "sensor_lag", {}), ("tube wave, 8 elements", "tube_delay",
                                            {"form": "wave"}))


def _burn(stop) -> None:
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def _cases():
    sys.path.insert(0, str(HERE))
    import simulate as bench

    from pneubayes.effects import make_effect
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.rig import Rig
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    rng_cmd, rng_params = np.random.default_rng([0, 0]), np.random.default_rng([0, 2])
    n = round(bench.DURATION_S * bench.SAMPLE_RATE_HZ) + 1
    t = np.arange(n) / bench.SAMPLE_RATE_HZ
    fixed = Inputs(t, bench.make_command(rng_cmd, n), np.zeros(n), np.full(n, bench.P_SUPPLY))
    rig = Rig(bench.BORE_M, bench.P_ATM, bench.P_SUPPLY)
    base = valve_preset("valve1").parameters()
    base.update(dead_volume_m3=2.4e-6, leak_area_m2=bench.LEAK_AREA_M2)
    solver = SolverConfig.standard()
    out = {}
    for label, name, options in FORMS:
        m = Model(["cylinder_leak"] + ([] if name is None else [make_effect(name, **options)]))
        theta = m.vector(dict(base, **({} if name is None else m.effects[-1].bench_defaults())))
        lo, hi = m.bounds
        batch = np.clip(theta[None, :] * rng_params.uniform(0.95, 1.05, (64, theta.size)),
                        lo, hi)
        out[label] = {
            1: lambda m=m, th=theta[None, :]: simulate(m, th, fixed, rig, bench.P_ATM, solver),
            64: lambda m=m, th=batch: simulate(m, th, fixed, rig, bench.P_ATM, solver)}
    return out


def main(argv=None) -> int:
    import numba

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--busy", default="0,1", help="busy processes per run (default 0,1)")
    ap.add_argument("--seconds", type=float, default=2.0,
                    help="least time timing each batch size (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="results (written atomically)")
    args = ap.parse_args(argv)
    busy_counts = [int(b) for b in args.busy.split(",")]
    cases = _cases()
    for fns in cases.values():  # compile (not timed)
        fns[1]()
        fns[64]()
    rows = []
    for busy in busy_counts:
        stop = mp.Event()
        procs = [mp.Process(target=_burn, args=(stop,), daemon=True) for _ in range(busy)]
        for p in procs:
            p.start()
        time.sleep(1.0 if busy else 0.0)
        try:
            for threads in (1, 2):
                numba.set_num_threads(threads)
                for label, fns in cases.items():
                    one = time_calls(fns[1], args.seconds)
                    many = time_calls(fns[64], args.seconds, per=64)
                    rows.append({"case": label, "busy_processes": busy, "threads": threads,
                                 "batch1": one, "batch64": many,
                                 "ratio_median": many["median_s"] / one["median_s"],
                                 "load_average": list(os.getloadavg())})
                    r = rows[-1]
                    print(f"busy {busy} threads {threads} {label:24s} batch 1 "
                          f"{1e3 * one['median_s']:8.3f} ms  batch 64 "
                          f"{1e3 * many['median_s']:8.3f} ms/trajectory  ratio "
                          f"{r['ratio_median']:.2f}  (load {r['load_average'][0]:.1f})",
                          flush=True)
        finally:
            stop.set()
            for p in procs:
                p.join()
    if args.json:
        from pneubayes.atomic import write_json_atomic
        from pneubayes.provenance import provenance
        write_json_atomic(args.json, {"rows": rows, "seconds": args.seconds,
                                      "cpu_count": os.cpu_count(),
                                      "provenance": provenance()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
