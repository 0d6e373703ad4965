"""Benchmark of emcee's start: from the posterior's Laplace approximation
(``SamplerSettings.laplace_start``, the default) against the walker ball and
differential evolution first, in the same run, on ``benchmarks/mcmc.py``'s data.

    python benchmarks/emcee_start.py --json OUT.json [--seed 0] [--repeats 1]

Both runs start from the same refined point and information, with the same solver and
seed, and stop on the same convergence rule; reported: wall time (the Laplace start
included), steps, seconds per step, acceptance, R-hat and ESS. Times are reported, never
asserted.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.bench import identification_sets
from pneubayes.effects import effects_from_names
from pneubayes.inference.fit import FitSettings
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.sampler import BayesianIdentification
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="pneubayes-emcee-start-"))
    train, _ = identification_sets("AIR37", "valve1", args.seed, 20.0, work)
    _, truth = Model.load_card(train.truth_path)
    recs = [read_recording(p) for p in train.recordings]
    model = Model(effects_from_names(["cylinder_leak"]))
    fs = FitSettings()
    data = WindowSet(recs, fs.horizon_s, fs.stride_s)
    ref = TrajectoryRefiner(model, fs.refine_solver).fit(data, truth)
    runs = []
    for rep in range(args.repeats):
        for laplace_start in (False, True):
            s = SamplerSettings(n_walkers=32, max_steps=12000, seed=args.seed,
                                laplace_start=laplace_start)
            t0 = time.perf_counter()
            bi = BayesianIdentification(model, fs.sample_solver, s, progress=False).fit(
                data, ref.params_, ref.information_)
            wall = time.perf_counter() - t0
            d = bi.diagnostics_
            run = {"laplace_start": laplace_start, "repeat": rep, "wall_time_s": wall,
                   "steps": int(d["steps"]), "burn": int(bi.burn_),
                   "s_per_step": bi.wall_time_s_ / d["steps"],
                   "acceptance": bi.acceptance_fraction_, "converged": bi.converged_,
                   "max_rhat": max(d["rhat"].values()), "min_ess": min(d["ess"].values())}
            runs.append(run)
            print(f"laplace_start={laplace_start}: {wall:.0f} s, {run['steps']} steps "
                  f"(production from {run['burn']}), {run['s_per_step']:.2f} s/step, "
                  f"acceptance {run['acceptance']:.2f}, converged {run['converged']}, "
                  f"R-hat {run['max_rhat']:.3f}, ESS {run['min_ess']:.0f}", flush=True)
    write_json_atomic(args.json, {"format": "pneubayes-bench-emcee-start/1",
                                  "seed": args.seed, "runs": runs,
                                  "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
