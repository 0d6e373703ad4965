"""The tube's model forms against a finely lumped tube: accuracy and cost per form.

    python benchmarks/tube_forms.py [--json OUT.json] [--cells 64] [--seed 1] [--no-pareto]

For three tubes (0.34 m x 2.5 mm, 1 m x 2 mm, 2.9 m x 1.83 mm) into a 1.5e-7 m^3 dead
volume at half stroke (fixed, and a piston moving at 3 Hz), random 5-V steps held 30-300
ms on a 1-ms clock, 1 s at 10 kHz: the plant's acoustic tube in ``--cells`` cells
(:mod:`pneubayes.bench.plant`, LSODA, written apart from the model) is the reference, a
near-continuous line. Each model form (the wave tube with 4, 8 and 16 elements, the
lumped line with 8 cells, the 8-element wave tube on a 0.25-ms grid, and the bare
chamber with the tube's volume) is simulated with
the standard preset on one thread; reported: RMSE and largest error against the
reference (Pa), and milliseconds per simulated second (the median of 3 calls after a
compiling one). At 10 kHz every model steps at least every 0.1 ms, so the costs there
are a simulator's on fine inputs; the second table is the cost on what recordings are,
1-kHz inputs (5 s, the same kind of command, fixed volume): the plain chamber takes a
step per sample there, the wave tube one per grid step (0.1 ms at most by default), also
with its unsteady shear at weight 1 (the quasi-steady tube's cost beside it). The third
table puts accuracy and cost on the same 1-kHz inputs (2 s; the reference driven by
them too): the wave tube by element count K and grid step, RMSE against the reference
(Pa and % of its range) and the cost as a share of the bare chamber's speed (the
issue-68 floor is 0.1 % and 0.25 x). Seeded; nothing is asserted here
(``tests/test_wave.py`` holds the floors).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numba
import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.forms import AcousticTube
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.effects import make_effect
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.provenance import provenance
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate

P_ATM, P_SUP, BORE, STROKE = 101_325.0, 551_325.0, 0.009, 0.0375
TUBES = ((0.34, 0.0025), (1.0, 0.002), (2.9, 0.00183))  # length, bore (m)
#: The wave tube on a coarser grid (0.25 ms, or an element's transit if shorter).
_COARSE = {"form": "wave", "segments": 8, "grid_s": 2.5e-4}
COST_FORMS = (("line, 3 cells", {"form": "line", "segments": 3}),) + (
    ("line, 8 cells", {"form": "line", "segments": 8}),
    ("wave, 4 elements", {"form": "wave", "segments": 4}),
    ("wave, 8 elements", {"form": "wave", "segments": 8}),
    ("wave, 8 elements, 0.25-ms grid", _COARSE),
    ("wave, 8 elements, unsteady shear", {"form": "wave", "segments": 8,
                                          "unsteady_friction": True}))
FORMS = (("wave, 4 elements", {"form": "wave", "segments": 4}),
         ("wave, 8 elements", {"form": "wave", "segments": 8}),
         ("wave, 8 elements, 0.25-ms grid", _COARSE),
         ("wave, 16 elements", {"form": "wave", "segments": 16}),
         ("line, 8 cells", {"form": "line", "segments": 8}))
DT_S = 1e-4
#: The third table's wave tubes: (elements K, grid step in s; an element's transit if
#: shorter).
PARETO = ((8, 1e-4), (8, 2.5e-4), (4, 2.5e-4), (4, 5e-4), (4, 1e-3), (2, 1e-4),
          (2, 1e-3), (1, 1e-3))


def _inputs(seed: int, moving: bool, dt_s: float = DT_S, duration_s: float = 1.0) -> Inputs:
    t = np.arange(int(round(duration_s / dt_s)) + 1) * dt_s
    rng = np.random.default_rng(seed)
    u, i = np.empty(t.size), 0
    while i < t.size:
        hold = int(round(1e-3 / dt_s)) * int(rng.integers(30, 301))
        u[i:i + hold] = rng.uniform(-5.0, 5.0)
        i += hold
    x = (0.5 * STROKE + 0.4 * STROKE * np.sin(2 * np.pi * 3.0 * t)) if moving \
        else np.full(t.size, 0.5 * STROKE)
    return Inputs(t, u, x, np.full(t.size, P_SUP))


def _timed(fn):
    fn()  # compiles
    times = []
    for _ in range(3):
        a = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - a)
    return out, float(np.median(times))


def _tube_params(rig: Rig, base: dict, length: float, dia: float) -> tuple[dict, dict]:
    """The model's parameters for a tube of ``length`` x ``dia`` (m): its transit time and
    bore, its volume added to the dead volume; and the bare chamber's (the tube's volume
    kept, the tube's parameters dropped)."""
    tube = AcousticTube(length, dia)
    params = dict(base, tube_delay_s=tube.transit_time_s(rig.gas), tube_diameter_m=dia,
                  dead_volume_m3=base["dead_volume_m3"] + tube.volume_m3)
    return params, {k: v for k, v in params.items() if not k.startswith("tube_")}


def _pareto(rig: Rig, base: dict, cells: int, seed: int) -> list[dict]:
    """The third table: accuracy and cost of the wave tube by K and grid, 1-kHz inputs."""
    rows = []
    for length, dia in TUBES:
        inputs = _inputs(seed, False, dt_s=1e-3, duration_s=2.0)
        ref = simulate_plant(base, (AcousticTube(length, dia, segments=cells),), inputs, rig,
                             P_ATM, PlantConfig.reference()).pressure_Pa
        params, plain = _tube_params(rig, base, length, dia)
        _, bare_s = _timed(lambda plain=plain, inputs=inputs: simulate(
            Model(), plain, inputs, rig, P_ATM, SolverConfig.standard()))
        for k, grid in PARETO:
            model = Model([make_effect("tube_delay", form="wave", segments=k, grid_s=grid)])
            y, sec = _timed(lambda model=model, params=params, inputs=inputs: simulate(
                model, params, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0])
            rmse = float(np.sqrt(np.mean((y - ref) ** 2)))
            row = {"length_m": length, "diameter_m": dia, "segments": k, "grid_s": grid,
                   "rmse_Pa": rmse, "rmse_percent_of_range": 100.0 * rmse / float(np.ptp(ref)),
                   "ms_per_simulated_s": 1e3 * sec / float(inputs.time_s[-1]),
                   "speed_vs_bare_chamber": bare_s / sec}
            rows.append(row)
            print(f"1-kHz accuracy and cost: {length:4.2f} m K={k} grid {grid * 1e3:4.2f} ms "
                  f"RMSE {rmse:6.0f} Pa ({row['rmse_percent_of_range']:.3f} % of range), "
                  f"{row['ms_per_simulated_s']:5.2f} ms per simulated s, "
                  f"{row['speed_vs_bare_chamber']:.3f} x the bare chamber's speed", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None, help="results (JSON, written atomically)")
    ap.add_argument("--cells", type=int, default=64, help="the reference tube's cells")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-pareto", action="store_true",
                    help="skip the third table (accuracy and cost on 1-kHz inputs)")
    args = ap.parse_args(argv)
    numba.set_num_threads(1)
    rig = Rig(BORE, P_ATM, P_SUP)
    base = dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)
    rows = []
    for length, dia in TUBES:
        for moving in (False, True):
            inputs = _inputs(args.seed, moving)
            ref = simulate_plant(base, (AcousticTube(length, dia, segments=args.cells),),
                                 inputs, rig, P_ATM, PlantConfig.reference()).pressure_Pa
            params, plain = _tube_params(rig, base, length, dia)
            models = [(label, Model([make_effect("tube_delay", **opts)]), params)
                      for label, opts in FORMS]
            models.append(("bare chamber (the tube's volume)", Model(), plain))
            for label, model, theta in models:
                y, sec = _timed(lambda model=model, theta=theta, inputs=inputs: simulate(
                    model, theta, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0])
                err = y - ref
                row = {"length_m": length, "diameter_m": dia, "moving": moving,
                       "form": label, "rmse_Pa": float(np.sqrt(np.mean(err ** 2))),
                       "max_error_Pa": float(np.max(np.abs(err))),
                       "ms_per_simulated_s": 1e3 * sec / float(inputs.time_s[-1])}
                rows.append(row)
                print(f"{length:4.2f} m x {dia * 1e3:4.2f} mm {'moving' if moving else 'fixed '}"
                      f" {label:34s} RMSE {row['rmse_Pa']:6.0f} Pa, max {row['max_error_Pa']:6.0f}"
                      f" Pa, {row['ms_per_simulated_s']:7.1f} ms per simulated s", flush=True)
    costs = []
    slow = _inputs(args.seed, False, dt_s=1e-3, duration_s=5.0)
    for length, dia in TUBES:
        params, plain = _tube_params(rig, base, length, dia)
        shear = dict(params, tube_unsteady_friction=1.0)  # (weight 1: Zielke's)
        for label, model, theta in ([("bare chamber", Model(), plain)]
                                    + [(lab, Model([make_effect("tube_delay", **o)]),
                                        shear if o.get("unsteady_friction") else params)
                                       for lab, o in COST_FORMS]):
            _, sec = _timed(lambda model=model, theta=theta: simulate(
                model, theta, slow, rig, P_ATM, SolverConfig.standard()))
            row = {"length_m": length, "diameter_m": dia, "form": label,
                   "ms_per_simulated_s_1kHz": 1e3 * sec / float(slow.time_s[-1])}
            costs.append(row)
            print(f"1-kHz inputs: {length:4.2f} m x {dia * 1e3:4.2f} mm {label:18s} "
                  f"{row['ms_per_simulated_s_1kHz']:7.2f} ms per simulated s", flush=True)
    pareto = [] if args.no_pareto else _pareto(rig, base, args.cells, args.seed)
    if args.json:
        write_json_atomic(Path(args.json), {"reference_cells": args.cells, "seed": args.seed,
                                            "rows": rows, "costs_1kHz": costs,
                                            "pareto_1kHz": pareto,
                                            "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
