"""Benchmark of the controller API: posterior draws x candidate command sequences.

    .venv/bin/python benchmarks/controller.py --json OUT.json [--seed 0] [--quick]

64 parameter draws (valve1 and the AIR37 leak, each parameter scaled by a seeded uniform
factor in 0.95-1.05: a stand-in for a posterior; the cost does not depend on where the
draws come from), 2-s horizons of random step commands (holds 50-300 ms, levels -5..5 V)
from 3e5 Pa, fixed dead volumes 1e-7, 2.4e-7 and 2.4e-6 m^3. For 1 and 8 candidates, on
the controller's 200-Hz grid and on a 1-kHz grid, with ``SolverConfig.standard()``
stopping at every sample ("standard") and with dense output ("dense": steps cross the
samples where the command holds; ``SolverConfig.sampling()``), it times
``PressurePredictor.predict`` (quantiles out; median of repeated calls after a warm-up,
on 1 and 2 numba threads, the two variants alternating) and measures the largest error
of the draws' trajectories against ``SolverConfig.reference()``. Issue 23's floor: 64
draws x 2 s in <= 5 ms on 2 cores, reported for both. Times are reported, never
asserted.
"""

from __future__ import annotations

import argparse
import sys
import time

import numba
import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.inference.predictive import PressurePredictor
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import SolverConfig

P_ATM, P_SUPPLY, BORE_M = 101325.0, 551325.0, 0.009
VOLUMES_M3 = (1e-7, 2.4e-7, 2.4e-6)
HORIZON_S = 2.0
N_DRAWS = 64
FLOOR_MS = 5.0


def random_steps(rng, n, dt):
    """n held commands at period dt: holds of 50-300 ms, levels uniform in -5..5 V."""
    out = np.empty(n)
    i = 0
    while i < n:
        hold = max(1, round(rng.uniform(0.05, 0.3) / dt))
        out[i:i + hold] = rng.uniform(-5.0, 5.0)
        i += hold
    return out


def time_medians(fns, reps):
    """Median wall time of each callable (s), after one warm-up call each, the callables
    alternating so that a change in the machine's load reaches them alike."""
    ts = {name: [] for name in fns}
    for fn in fns.values():
        fn()
    for _ in range(reps):
        for name, fn in fns.items():
            a = time.perf_counter()
            fn()
            ts[name].append(time.perf_counter() - a)
    return {name: float(np.median(v)) for name, v in ts.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = ap.parse_args(argv)
    reps = 5 if args.quick else 30
    rng = np.random.default_rng(args.seed)
    model = Model(["cylinder_leak"])
    rig = Rig(BORE_M, P_ATM, P_SUPPLY)
    variants = {"standard": False, "dense": True}  # dense_output
    rows = []
    for vol in VOLUMES_M3:
        p = valve_preset("valve1").parameters()
        p.update(dead_volume_m3=vol, leak_area_m2=3.04e-8)
        draws = model.vector(p) * rng.uniform(0.95, 1.05, (N_DRAWS, model.n_parameters))
        for rate_hz in (200.0, 1000.0):
            dt = 1.0 / rate_hz
            n_l = round(HORIZON_S * rate_hz)
            cands = np.stack([random_steps(rng, n_l, dt) for _ in range(8)])
            ref = PressurePredictor(model, draws, rig, SolverConfig.reference())
            truth = ref.predict_draws(3e5, cands, 0.0, dt)
            apis = {name: PressurePredictor(model, draws, rig,
                                            SolverConfig.standard().with_dense_output(dense))
                    for name, dense in variants.items()}
            errs = {name: float(np.abs(api.predict_draws(3e5, cands, 0.0, dt)
                                       - truth).max()) for name, api in apis.items()}
            for n_c in (1, 8):
                for threads in (1, 2):
                    if threads > numba.config.NUMBA_NUM_THREADS:
                        continue
                    numba.set_num_threads(threads)
                    calls = {name: (lambda api=api, c=cands[:n_c], dt=dt:
                                    api.predict(3e5, c, 0.0, dt))
                             for name, api in apis.items()}
                    times = time_medians(calls, reps)
                    for name, sec in times.items():
                        ms, err = 1e3 * sec, errs[name]
                        row = {"dead_volume_m3": vol, "rate_Hz": rate_hz, "solver": "standard",
                               "variant": name, "dense_output": variants[name],
                               "candidates": n_c, "threads": threads, "draws": N_DRAWS,
                               "median_ms": ms, "max_error_Pa": err,
                               "max_error_percent_of_range": 100 * err / (P_SUPPLY - P_ATM)}
                        rows.append(row)
                        print(f"V {vol:.1e}  {rate_hz:>6.0f} Hz  {name:<8} {n_c} cand  "
                              f"{threads} thr  {ms:7.2f} ms  err {err:7.1f} Pa",
                              file=sys.stderr, flush=True)
    floors = {}
    for name in variants:
        key = [r for r in rows if r["rate_Hz"] == 200.0 and r["candidates"] == 1
               and r["threads"] == 2 and r["variant"] == name]
        worst = max(r["median_ms"] for r in key) if key else None
        floors[name] = {"what": "64 draws x 2 s at 200 Hz, standard preset"
                                + (", dense output" if variants[name] else "")
                                + ", 2 threads, worst over volumes",
                        "ceiling_ms": FLOOR_MS, "value_ms": worst,
                        "met": None if worst is None else bool(worst <= FLOOR_MS),
                        "max_error_Pa_200Hz": max(r["max_error_Pa"] for r in rows
                                                  if r["rate_Hz"] == 200.0
                                                  and r["variant"] == name),
                        "max_error_Pa_1kHz": max(r["max_error_Pa"] for r in rows
                                                 if r["rate_Hz"] == 1000.0
                                                 and r["variant"] == name)}
    report = {"format": "pneubayes-bench-controller/2", "seed": args.seed,
              "quick": args.quick, "rows": rows, "floor": floors}
    write_json_atomic(args.json, report)
    for f in floors.values():
        worst = f["value_ms"]
        print(f"{f['what']}: {'n/a' if worst is None else f'{worst:.2f} ms'} (ceiling "
              f"{FLOOR_MS:g} ms) {'MET' if f['met'] else 'NOT MET'}; largest error against "
              f"the reference preset {f['max_error_Pa_200Hz']:.0f} Pa at 200 Hz, "
              f"{f['max_error_Pa_1kHz']:.0f} Pa at 1 kHz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
