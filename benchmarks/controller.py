"""Benchmark of the controller API: posterior draws x candidate command sequences.

    .venv/bin/python benchmarks/controller.py --json OUT.json [--seed 0] [--quick]

64 parameter draws (valve1 and the AIR37 leak, each parameter scaled by a seeded uniform
factor in 0.95-1.05: a stand-in for a posterior; the cost does not depend on where the
draws come from), 2-s horizons of random step commands (holds 50-300 ms, levels -5..5 V)
from 3e5 Pa, fixed dead volumes 1e-7, 2.4e-7 and 2.4e-6 m^3. For 1 and 8 candidates, on
the controller's 200-Hz grid and on a 1-kHz grid, with ``SolverConfig.standard()``, it
times ``PressurePredictor.predict`` (quantiles out; median of repeated
calls after a warm-up, on 1 and 2 numba threads) and measures the largest error of the
draws' trajectories against ``SolverConfig.reference()``. Issue 23's floor: 64 draws x 2 s
in <= 5 ms on 2 cores. Times are reported, never asserted.
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


def time_median(fn, reps):
    fn()
    ts = []
    for _ in range(reps):
        a = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - a)
    return float(np.median(ts))


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
    presets = {"standard": SolverConfig.standard()}
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
            for name, solver in presets.items():
                api = PressurePredictor(model, draws, rig, solver)
                err = float(np.abs(api.predict_draws(3e5, cands, 0.0, dt) - truth).max())
                for n_c in (1, 8):
                    for threads in (1, 2):
                        if threads > numba.config.NUMBA_NUM_THREADS:
                            continue
                        numba.set_num_threads(threads)
                        def call(api=api, c=cands[:n_c], dt=dt):
                            return api.predict(3e5, c, 0.0, dt)

                        ms = 1e3 * time_median(call, reps)
                        row = {"dead_volume_m3": vol, "rate_Hz": rate_hz, "solver": name,
                               "candidates": n_c, "threads": threads, "draws": N_DRAWS,
                               "median_ms": ms, "max_error_Pa": err,
                               "max_error_percent_of_range": 100 * err / (P_SUPPLY - P_ATM)}
                        rows.append(row)
                        print(f"V {vol:.1e}  {rate_hz:>6.0f} Hz  {name:<8} {n_c} cand  "
                              f"{threads} thr  {ms:7.2f} ms  err {err:7.1f} Pa",
                              file=sys.stderr, flush=True)
    key = [r for r in rows if r["rate_Hz"] == 200.0 and r["candidates"] == 1
           and r["threads"] == 2]
    worst = max(r["median_ms"] for r in key) if key else None
    report = {"format": "pneubayes-bench-controller/1", "seed": args.seed,
              "quick": args.quick, "rows": rows,
              "floor": {"what": "64 draws x 2 s at 200 Hz, standard preset, 2 threads, "
                                "worst over volumes", "ceiling_ms": FLOOR_MS,
                        "value_ms": worst,
                        "met": None if worst is None else bool(worst <= FLOOR_MS)},
              "max_error_Pa_200Hz": max(r["max_error_Pa"] for r in rows
                                        if r["rate_Hz"] == 200.0),
              "max_error_Pa_1kHz": max(r["max_error_Pa"] for r in rows
                                       if r["rate_Hz"] == 1000.0)}
    write_json_atomic(args.json, report)
    print(f"64 draws x 2 s at 200 Hz, standard preset, 2 threads: worst {worst:.2f} ms "
          f"(ceiling {FLOOR_MS:g} ms) {'MET' if report['floor']['met'] else 'NOT MET'}; "
          f"largest error against the reference preset {report['max_error_Pa_200Hz']:.0f} Pa "
          f"at 200 Hz, {report['max_error_Pa_1kHz']:.0f} Pa at 1 kHz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
