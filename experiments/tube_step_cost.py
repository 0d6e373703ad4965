"""Where a tube form's simulation time goes: steps against cost per step (issue 68, item 1).

    python experiments/tube_step_cost.py --out results/tube_step_cost.json [--seed 0]

The case is ``benchmarks/simulate.py``'s effect-form section: the paper's model on the
fixed 2.4e-6 m^3 chamber, a seeded 2-s random-step command at 1 kHz (holds 30-300 ms,
+-5 V), each tube form at its bench defaults (1-ms transit time, 2.5-mm bore), batch 1,
one thread. For each form it reports the simulated seconds per wall second and their
ratio to the paper's model in the same run, the accepted-plus-rejected steps of the
window (the kernel does not return them: found by bisecting ``max_steps_per_s`` for the
smallest budget the window completes in) and so the wall time per step; and the same
at tolerances 10x and 100x looser, which
shows how many of the steps the accuracy asks for (one step per sample is the floor:
the line's steps stop on every sample).

Measured 2026-12-02 (seed 0, a shared 2-core machine, load 4.9; ratios from one run):

| form | sim-s/s | x paper | steps (10x, 100x looser) | us/step |
|---|---|---|---|---|
| paper's model | 6365 | 1 | 2170 (2043, 2039) | 0.14 |
| line, 3 cells | 93 | 0.015 | 3516 (2340, 2053) | 6.1 |
| line, 8 cells | 20.5 | 0.0032 | 4201 (2473, 2075) | 23 |
| wave, 8 elements | 88 | 0.014 | 20013 (20013, 20013) | 1.1 |

(a quieter run the same day: 0.023 x, 0.0045 x, 0.020 x at 4.0, 16.9, 0.79 us/step).
The line is not limited by stability (its step is exponential in the full Jacobian:
one step per sample through the holds) but by the accuracy its transients ask for
(59 % of the 3-cell line's steps fall within 50 ms of the 12 valve switches, 30 % of
the samples, counted with a replica of the kernel's line loop; at looser tolerance the
extra steps go) and above all by the cost of a step: the phi-functions of the
augmented Jacobian by scaling and squaring, O(n^3) with n = 2 N + 3, 30-170 x the
paper model's scalar step. The wave tube is limited by its 0.1-ms grid (20000 steps
whatever the tolerance). The floor of 0.25 x needs about 0.6 us a step at one step a
sample: no dense O(n^3) work per step, and fewer steps through the transients.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import simulate as bench  # noqa: E402  (benchmarks/simulate.py: the same case)

from pneubayes.atomic import write_json_atomic  # noqa: E402
from pneubayes.effects import make_effect  # noqa: E402
from pneubayes.errors import SimulationError  # noqa: E402
from pneubayes.model import Model  # noqa: E402
from pneubayes.physics.valve import valve_preset  # noqa: E402
from pneubayes.rig import Rig  # noqa: E402
from pneubayes.simulation import Inputs, SolverConfig, simulate  # noqa: E402

FORMS = (
    ("paper's model", None),
    ("tube line, 3 cells", {"form": "line", "segments": 3}),
    ("tube line, 8 cells", {"form": "line", "segments": 8}),
    ("tube wave, 8 elements", {"form": "wave"}),
)


def steps_taken(run, solver, sim_s, samples):
    """Steps (accepted and rejected) the window takes: the smallest step budget it
    completes in, by bisection on ``max_steps_per_s`` (the budget is ``samples - 1``
    plus ``max_steps_per_s`` per simulated second)."""
    lo, hi = 0.0, solver.max_steps_per_s
    while hi - lo >= 0.5 / sim_s:
        mid = 0.5 * (lo + hi)
        try:
            run(replace(solver, max_steps_per_s=mid))
            hi = mid
        except SimulationError:
            lo = mid
    return int(round(samples - 1 + hi * sim_s))


def looser(solver, factor):
    """``solver`` with its tolerances ``factor`` times looser."""
    return replace(solver, rtol=solver.rtol * factor, atol_Pa=solver.atol_Pa * factor,
                   atol_K=solver.atol_K * factor)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    import numba

    numba.set_num_threads(1)
    rng_cmd = np.random.default_rng(np.random.SeedSequence(args.seed).spawn(3)[0])
    n = round(bench.DURATION_S * bench.SAMPLE_RATE_HZ) + 1
    t = np.arange(n) / bench.SAMPLE_RATE_HZ
    sim_s = float(t[-1])
    inputs = Inputs(t, bench.make_command(rng_cmd, n), np.zeros(n), np.full(n, bench.P_SUPPLY))
    rig = Rig(bench.BORE_M, bench.P_ATM, bench.P_SUPPLY)
    base = Model(["cylinder_leak"])
    params = valve_preset("valve1").parameters()
    params.update(dead_volume_m3=2.4e-6, leak_area_m2=bench.LEAK_AREA_M2)
    standard = SolverConfig.standard()
    rows = []
    for label, options in FORMS:
        model = base if options is None else Model(
            [*base.effects, make_effect("tube_delay", **options)])
        theta = dict(params, **({} if options is None else model.effects[-1].bench_defaults()))

        def run(solver, model=model, theta=theta):
            return simulate(model, theta, inputs, rig, bench.P_ATM, solver)

        run(standard)  # compiles
        timing = bench.time_calls(lambda: run(standard), 0.5, 3)
        row = {"form": label, "options": options,
               "sim_seconds_per_second": sim_s / timing["median_s"],
               "wall_per_trajectory_s": timing["median_s"]}
        for name, solver in (("standard", standard), ("looser_10x", looser(standard, 10.0)),
                             ("looser_100x", looser(standard, 100.0))):
            row[f"steps_{name}"] = steps_taken(run, solver, sim_s, n)
        row["wall_per_step_us"] = 1e6 * timing["median_s"] / row["steps_standard"]
        rows.append(row)
        print(f"{label:24s} {row['sim_seconds_per_second']:9.1f} sim-s/s  "
              f"steps {row['steps_standard']:6d} (10x looser {row['steps_looser_10x']:6d}, "
              f"100x {row['steps_looser_100x']:6d})  {row['wall_per_step_us']:6.2f} us/step",
              flush=True)
    for row in rows:
        row["relative_to_paper_model"] = (row["sim_seconds_per_second"]
                                          / rows[0]["sim_seconds_per_second"])
    write_json_atomic(Path(args.out), {"seed": args.seed, "load_average": bench._loadavg(),
                                       "samples": n, "rows": rows})
    for row in rows:
        print(f"{row['form']:24s} x the paper's model: {row['relative_to_paper_model']:.4f}")


if __name__ == "__main__":
    main()
