"""Identification on the virtual bench: the figures of the paper's Figs. 5a, 5b and
7-10 with posterior bands, plus a corner plot, from one re-runnable script.

    python experiments/identification.py --out results/identification [--seed 0]
    python experiments/identification.py --smoke --out /tmp/ident   # a fast check

Writes OUT/run/ (the ``pneubayes fit`` run folder: model card, posterior, summary,
figures/areas.png, figures/volume.png, figures/corner.png), OUT/pred_*.csv and
OUT/pred_*.png (prediction bands on held-out moving recordings), and OUT/report.json
with the config, seed, git revision and package versions.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.bench import identification_sets
from pneubayes.effects import effects_from_names
from pneubayes.inference.pipeline import FitSettings, run_fit, run_predict
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance
from pneubayes.simulation import SolverConfig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cylinder", default="AIR37")
    ap.add_argument("--valve", default="valve1")
    ap.add_argument("--max-steps", type=int, default=12000)
    ap.add_argument("--duration", type=float, default=20.0, help="recording length, s")
    ap.add_argument("--smoke", action="store_true", help="tiny data and chains (seconds)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    dur = 4.0 if args.smoke else args.duration
    leak = effects_from_names(["cylinder_leak"])
    config = {"cylinder": args.cylinder, "valve": args.valve, "seed": args.seed,
              "duration_s": dur, "train": "fixed, positions 0.5/0.9, ranges +-5/+-0.5 V",
              "held_out": "2 moving recordings", "smoke": args.smoke}
    train, held = identification_sets(args.cylinder, args.valve, args.seed, dur,
                                      out / "bench", held_count=2, overwrite=True)
    steps = 100 if args.smoke else args.max_steps
    settings = FitSettings(sampler=SamplerSettings(n_walkers=32, max_steps=steps,
                                                   check_every=min(250, steps), seed=args.seed))
    summary = run_fit([read_recording(p) for p in train.recordings], Model(leak), settings,
                      out / "run", progress=not args.smoke)
    _, truth = Model.load_card(train.truth_path)
    preds = []
    for p in held.recordings:
        preds.append(run_predict(out / "run", read_recording(p), 2.0,
                                 out / f"pred_{p.stem}.csv", 200, args.seed,
                                 SolverConfig.standard(),
                                 figure_path=out / f"pred_{p.stem}.png"))
    cover = {n: bool(s["q05"] <= truth[n] <= s["q95"])
             for n, s in summary["parameters"].items() if n in truth}
    write_json_atomic(out / "report.json", {
        "config": config, "provenance": provenance(), "converged": summary["converged"],
        "steps": summary["steps"], "coverage_90_by_parameter": cover,
        "predictions": preds, "figures": ["run/figures/areas.png", "run/figures/volume.png",
                                          "run/figures/corner.png"]
        + [f"pred_{p.stem}.png" for p in held.recordings]})
    print(f"{out / 'report.json'}: converged {summary['converged']} after "
          f"{summary['steps']} steps; 90 % intervals cover {sum(cover.values())}/{len(cover)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
