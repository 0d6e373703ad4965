"""Benchmark of Bayesian identification and of the controller API (issue 3 floors).

    python benchmarks/mcmc.py --json OUT.json [--seed 0] [--cylinder AIR37] [--quick]
                              [--no-dense-output]

1. ``pneubayes fit`` (least squares -> refinement -> emcee) on 4 x 20-s fixed-volume
   bench recordings of the paper's model (two positions x command ranges +-5 and
   +-0.5 V); reports wall time, steps, the worst R-hat and ESS, and whether each
   parameter's 90 % interval covers the truth. Floors: R-hat <= 1.01 and ESS >= 400
   for every parameter within 15 minutes on 2 cores. The sampler's likelihood (and the
   Laplace posterior's) uses the default ``SolverConfig.sampling()`` (dense output: steps
   cross the samples where the command holds); ``--no-dense-output`` uses
   ``SolverConfig.standard()``, which stops at every sample (the default before).
2. ``predict`` on a held-out moving recording: RMSE against the noise floor (<= 1.5x)
   and 90 % band coverage (0.85-0.95).
3. The controller API: 64 posterior draws over a 2-s horizon on the controller's 200-Hz
   grid (issue 23's floor 5 ms) and on a 1-kHz grid, median of repeated calls on all
   cores, stopping at every sample and with dense output (the two alternating).
4. The Laplace posterior (``pneubayes fit --method laplace``) from the same refined
   point, against the emcee posterior of the same run: its wall time, each parameter's
   median and 90 % interval beside emcee's (the median's shift in emcee SDs, the
   interval's width as a ratio), its coverage of the truth and its held-out bands.
Times are reported, never asserted.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.bench import identification_sets
from pneubayes.effects import effects_from_names
from pneubayes.inference.fit import FitSettings, identify
from pneubayes.inference.fit_folder import write_fit
from pneubayes.inference.pipeline import run_predict
from pneubayes.inference.predictive import PressurePredictor
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cylinder", default="AIR37")
    ap.add_argument("--valve", default="valve1")
    ap.add_argument("--max-steps", type=int, default=12000)
    ap.add_argument("--quick", action="store_true", help="short chains: exercises the path")
    ap.add_argument("--dense-output", action=argparse.BooleanOptionalAction, default=True,
                    help="the sampler's solver with dense output (default; "
                         "--no-dense-output: SolverConfig.standard())")
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="pneubayes-mcmc-"))
    leak = effects_from_names(["cylinder_leak"])
    dur = 5.0 if args.quick else 20.0
    train, held = identification_sets(args.cylinder, args.valve, args.seed, dur, work)
    _, truth = Model.load_card(train.truth_path)
    recs = [read_recording(p) for p in train.recordings]
    sample_solver = SolverConfig.sampling() if args.dense_output else SolverConfig.standard()
    settings = FitSettings(sample_solver=sample_solver, sampler=SamplerSettings(
        n_walkers=32, max_steps=300 if args.quick else args.max_steps, seed=args.seed))
    t0 = time.perf_counter()
    c0 = time.process_time()
    fit = identify(recs, Model(leak), settings, checkpoint_dir=work / "run",
                   log=lambda m: print(m, file=sys.stderr))
    write_fit(fit, work / "run", figures=False)  # `pneubayes predict` reads it below
    wall = time.perf_counter() - t0
    fit_cpu = time.process_time() - c0
    summary = fit.summary
    params = summary["parameters"]
    rhat = max(p["rhat"] for p in params.values())
    ess = min(p["ess"] for p in params.values())
    cover = {n: bool(p["q05"] <= truth[n] <= p["q95"]) for n, p in params.items()
             if n in truth}
    pred = run_predict(work / "run", read_recording(held.recordings[0]), 2.0,
                       work / "pred.csv", 200, args.seed, SolverConfig.standard())
    # controller API
    rng = np.random.default_rng(args.seed)
    model, (draws, _) = fit.model, fit.draws(64, rng)
    rig = recs[0].rig()
    apis = [PressurePredictor(model, draws, rig, SolverConfig.standard().with_dense_output(d))
            for d in (False, True)]
    levels = rng.uniform(-5, 5, 20)  # 2 s of 100-ms holds

    def controller_ms(rate_hz):
        """Median ms per call, stopping at every sample and with dense output."""
        cmd = np.repeat(levels, round(0.1 * rate_hz))[None]
        times = [[], []]
        for api in apis:
            api.predict(3e5, cmd, 0.01, 1.0 / rate_hz)
        for _ in range(30):  # alternating, so that a change in load reaches both alike
            for api, ts in zip(apis, times):
                a = time.perf_counter()
                api.predict(3e5, cmd, 0.01, 1.0 / rate_hz)
                ts.append(time.perf_counter() - a)
        return [1e3 * float(np.median(ts)) for ts in times]

    # the controller's own grid (the paper's 200-Hz loop) and 1 kHz
    ctrl_ms, ctrl_dense_ms = controller_ms(200.0)
    ctrl_ms_1khz, ctrl_dense_ms_1khz = controller_ms(1000.0)
    # the Laplace posterior from the same refined point (the stage cache is copied)
    lap_dir = work / "run_laplace"
    lap_dir.mkdir()
    shutil.copy(work / "run" / "refined.json", lap_dir / "refined.json")
    t0 = time.perf_counter()
    lap = identify(recs, Model(leak), settings, method="laplace", checkpoint_dir=lap_dir,
                   log=lambda m: print(m, file=sys.stderr))
    lap_wall = time.perf_counter() - t0
    write_fit(lap, lap_dir, figures=False)
    lp = lap.summary["parameters"]
    lap_cmp = {}
    for n, e in params.items():
        if n not in lp:
            continue
        sd = (e["q95"] - e["q05"]) / 3.29  # a 90 % interval's width over a normal's SD
        lap_cmp[n] = {"emcee": [e["q05"], e["median"], e["q95"]],
                      "laplace": [lp[n]["q05"], lp[n]["median"], lp[n]["q95"]],
                      "median_shift_emcee_sd": (lp[n]["median"] - e["median"]) / sd
                      if sd > 0 else None,
                      "width_ratio": (lp[n]["q95"] - lp[n]["q05"]) / (e["q95"] - e["q05"])
                      if e["q95"] > e["q05"] else None,
                      "covers_truth": (bool(lp[n]["q05"] <= truth[n] <= lp[n]["q95"])
                                       if n in truth else None)}
    lap_pred = run_predict(lap_dir, read_recording(held.recordings[0]), 2.0,
                           work / "pred_laplace.csv", 200, args.seed, SolverConfig.standard())
    report = {
        "format": "pneubayes-bench-mcmc/1", "seed": args.seed, "quick": args.quick,
        "rig": [args.cylinder, args.valve], "recordings": f"4 x {dur:g} s fixed",
        "sample_solver": sample_solver.to_dict(),
        "fit_wall_time_s": wall, "fit_cpu_time_s": fit_cpu, "emcee_steps": summary["steps"],
        "n_walkers": summary["n_walkers"], "converged": summary["converged"],
        "tau_max": summary["tau_max"], "max_rhat": rhat, "min_ess": ess,
        "coverage_90_by_parameter": cover,
        "coverage_90_fraction": float(np.mean(list(cover.values()))),
        "heldout": pred, "controller_ms_64_draws_2s_200Hz": ctrl_ms,
        "controller_ms_64_draws_2s_1kHz": ctrl_ms_1khz,
        "controller_dense_ms_64_draws_2s_200Hz": ctrl_dense_ms,
        "controller_dense_ms_64_draws_2s_1kHz": ctrl_dense_ms_1khz,
        "laplace": {"wall_time_s": lap_wall, "reliable": lap.summary["converged"],
                    "importance_check": lap.summary["importance_check"],
                    "hessian_eigenvalues": lap.summary["hessian_eigenvalues"],
                    "by_parameter": lap_cmp, "heldout": lap_pred},
        "floors": {"rhat_le_1.01": rhat <= 1.01, "ess_ge_400": ess >= 400,
                   "wall_le_900s": wall <= 900,
                   "heldout_rmse_le_1.5x_noise": pred["rmse_over_noise_floor"] <= 1.5,
                   "coverage_90_in_0.85_0.95": 0.85 <= pred["coverage_90"] <= 0.95,
                   "controller_le_20ms": ctrl_ms <= 20.0,
                   "controller_le_5ms_issue23": ctrl_ms <= 5.0,
                   "controller_dense_le_5ms_issue23": ctrl_dense_ms <= 5.0},
    }
    write_json_atomic(args.json, report)
    print(f"fit {wall:.0f} s ({fit_cpu:.0f} CPU s), {summary['steps']} steps x 32 walkers, "
          f"dense output {args.dense_output}, converged "
          f"{summary['converged']}, max R-hat {rhat:.3f}, min ESS {ess:.0f}, tau_max "
          f"{summary['tau_max']:.0f}")
    print(f"90 % intervals covering the truth: {sum(cover.values())}/{len(cover)} "
          f"{[n for n, c in cover.items() if not c]}")
    print(f"held-out: RMSE {pred['rmse_Pa']:.0f} Pa = {pred['rmse_over_noise_floor']:.2f} x "
          f"noise floor; coverage 90 % {pred['coverage_90']:.3f}, 50 % {pred['coverage_50']:.3f}")
    print(f"controller API: 64 draws x 2 s in {ctrl_ms:.1f} ms at 200 Hz, {ctrl_ms_1khz:.1f} ms "
          f"at 1 kHz (median); with dense output {ctrl_dense_ms:.1f} and "
          f"{ctrl_dense_ms_1khz:.1f} ms")
    model_names = [n for n in lap_cmp if n in truth]
    print(f"Laplace from the same refined point: {lap_wall:.1f} s (emcee {wall:.0f} s with "
          f"the refinement); 90 % intervals covering the truth: "
          f"{sum(lap_cmp[n]['covers_truth'] for n in model_names)}/{len(model_names)}; "
          f"held-out coverage 90 % {lap_pred['coverage_90']:.3f}; importance check Pareto "
          f"k {lap.summary['importance_check']['pareto_k']} (reliable <= "
          f"{lap.summary['importance_check']['khat_threshold']:.2f})")
    for n, c in lap_cmp.items():
        shift, ratio = c["median_shift_emcee_sd"], c["width_ratio"]
        print(f"  {n:28s} median shift {shift if shift is None else round(shift, 2)} "
              f"emcee SD, width ratio {ratio if ratio is None else round(ratio, 2)}")
    for k, v in report["floors"].items():
        print(f"  {k:32s} {'MET' if v else 'NOT MET'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
