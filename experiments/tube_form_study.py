"""The loop's outside-tube forms on near-continuous tubes, unlike the bench's own.

    python experiments/tube_form_study.py --out /tmp/tfs [--lengths 2.5] [--cells 32]
                                          [--forms line,wave] [--duration 16] [--seed 31]

The bench's realistic tube (:class:`~pneubayes.bench.forms.AcousticTube`) is a lumped
line of 8-24 cells, and the model's lumped line can match it cell for cell; a real tube
is continuous. Here each case plants one tube of ``--cells`` cells (32 by default: the
plant's 64-cell tube costs about 15 s per simulated second, too slow for six
recordings in a session) on AIR37 / valve 1, six recordings as ``blind_study.py`` (its
``run_case``; 16 s is the shortest that leaves the signed-rank test 7 held-out
windows), and runs
``pneubayes discover`` once per outside-tube form the loop may try
(``FormSettings.tube_line_form``: the lumped line with cells following the tube,
or the transmission-line tube). The bore is drawn (1.5-4 mm, log-uniform) from
``--seed``, recorded with every case's bench seed.

Reported per case and form: the named set, held-out 2-s RMSE before and after (Pa), the
noise floor, final / noise and the wall time. Cases are cached in
OUT/cases/NAME.json (rerun to resume); OUT/summary.json holds them with the seed,
revision and versions. Nothing is asserted here.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from blind_study import run_case
from discovery_study import cached_cases

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.forms import AcousticTube
from pneubayes.provenance import provenance


def cases(lengths_m, cells: int, seed: int) -> list[dict]:
    """One case per tube length: AIR37 / valve 1, the bore and the bench seed drawn."""
    rng = np.random.default_rng(seed)
    out = []
    for i, length in enumerate(lengths_m):
        dia = float(math.exp(rng.uniform(math.log(0.0015), math.log(0.004))))
        tube = AcousticTube(length_m=length, diameter_m=dia, segments=cells)
        out.append({"name": f"t{i:02d}_{length:g}m_{1e3 * dia:.2f}mm_{cells}cells",
                    "cylinder": "AIR37", "valve": "valve1", "hidden": ["tube_delay"],
                    "bench_seed": int(rng.integers(1000, 100000)),
                    "forms": {"tube_delay": tube.to_dict()},
                    "_objects": {"tube_delay": tube}})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="results folder (cases cached there)")
    ap.add_argument("--lengths", default="2.5", help="tube lengths, m (comma list)")
    ap.add_argument("--forms", default="line,wave", help="outside-tube forms to run")
    ap.add_argument("--cells", type=int, default=32, help="the planted tube's cells")
    ap.add_argument("--seed", type=int, default=31, help="draws the bores and bench seeds")
    ap.add_argument("--duration", type=float, default=16.0, help="seconds per recording")
    args = ap.parse_args(argv)
    forms = [f for f in args.forms.split(",") if f]
    bad = [f for f in forms if f not in ("line", "wave")]
    if bad:
        ap.error(f"--forms: unknown form(s) {bad}; line or wave")
    try:
        lengths = [float(v) for v in args.lengths.split(",") if v]
    except ValueError:
        ap.error(f"--lengths: not a comma list of numbers: {args.lengths!r}")
    if not lengths or any(not (0.05 <= v <= 20.0) for v in lengths):
        ap.error(f"--lengths: each length must be in [0.05, 20] m, got {args.lengths!r}")
    root = Path(args.out)
    todo = []
    for case in cases(lengths, args.cells, args.seed):
        for form in forms:
            todo.append((f"{case['name']}_{form}", (case, form)))

    def run(name, item):
        case, form = item
        ns = argparse.Namespace(duration=args.duration, tube_line_form=form)
        t0 = time.perf_counter()
        res = run_case(dict(case, name=name), ns, root)
        return res | {"tube_line_form": form, "wall_s": time.perf_counter() - t0}

    def failed(name, item, error):
        case, form = item
        return {k: v for k, v in case.items() if not k.startswith("_")} | {
            "name": name, "tube_line_form": form, "error": error, "named": []}

    def describe(r):
        if r.get("error"):
            return f"failed: {r['error']}"
        return (f"{r['tube_line_form']}: named {r['named']}, {r['rmse_base_Pa']:.0f} -> "
                f"{r['rmse_final_Pa']:.0f} Pa ({r['final_over_noise']:.2f} x noise), "
                f"{r['wall_time_s'] / 60:.1f} min")

    results = cached_cases(todo, root, run, failed, describe)
    write_json_atomic(root / "summary.json", {
        "seed": args.seed, "cells": args.cells, "lengths_m": lengths, "forms": forms,
        "duration_s": args.duration, "cases": results, "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
