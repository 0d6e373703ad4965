"""What the open-form stage adds to a discovery (issue 69 floor: at most 5 minutes on a
6 x 20-s case on 2 cores).

    python benchmarks/openform_cost.py --json OUT.json [--seed 0]

The bench hides a relief valve (an out-of-catalogue plant form, cracking at 3.2 bar
gauge, 3e-11 kg/(s Pa^1.5)) in AIR37/valve1 data: the recordings of
``benchmarks/discovery.py`` (fixed at 50 % and 90 % of the stroke, ranges +-5 and
+-0.5 V, two moving-piston recordings), 20 s each. The same discovery (no posterior)
runs twice in this process: with the default stages (the baseline: the catalogue's
stages only, ``open_form_min_noise_ratio=0``), and with the open-form stage. Reports
each wall time, the difference, what each named or found and its held-out error;
times are reported, never asserted.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.bench import ATMOSPHERE_PA, BenchConfig, run_bench
from pneubayes.bench.forms import ReliefValve
from pneubayes.bench.sensors import SensorChain
from pneubayes.discovery.report import run_discover
from pneubayes.discovery.settings import DiscoverySettings, PosteriorSettings, StageSettings
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.provenance import provenance

#: The hidden form's parameters (fixed: a timing case, not a study).
CRACK_GAUGE_PA = 3.2e5
FLOW_COEFFICIENT = 3e-11  # kg/(s Pa^1.5)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    form = ReliefValve(crack_pressure_Pa=ATMOSPHERE_PA + CRACK_GAUGE_PA,
                       flow_coefficient_kg_per_s_Pa1p5=FLOW_COEFFICIENT)
    work = Path(tempfile.mkdtemp(prefix="pneubayes-openform-cost-"))
    fixed = run_bench(BenchConfig("AIR37", "valve1", (), forms=(form,), protocol="fixed",
                                  duration_s=20.0, seed=args.seed, positions=(0.5, 0.9),
                                  ranges_V=(5.0, 0.5)), work / "fixed")
    moving = run_bench(BenchConfig("AIR37", "valve1", (), forms=(form,), protocol="moving",
                                   duration_s=20.0, seed=args.seed + 500, count=2),
                       work / "moving")
    recs = [read_recording(p) for p in list(fixed.recordings) + list(moving.recordings)]
    out = {}
    default_ratio = DiscoverySettings().stages.open_form_min_noise_ratio
    for label, ratio in (("catalogue stages only (baseline)", 0.0),
                         ("with the open-form stage", default_ratio)):
        settings = DiscoverySettings(posterior=PosteriorSettings(method="none"),
                                     seed=args.seed,
                                     stages=StageSettings(open_form_min_noise_ratio=ratio),
                                     fit=FitSettings(sampler=SamplerSettings(
                                         n_walkers=32, seed=args.seed),
                                         pressure_filter=SensorChain().declared_filter()))
        t0 = time.perf_counter()
        doc = run_discover(recs, settings, work / ("open" if ratio else "plain"),
                           log=lambda m: print("  " + m, file=sys.stderr), figures=False)
        wall = time.perf_counter() - t0
        out[label] = {"wall_time_s": wall, "named": [e["name"] for e in doc["effects"]],
                      "found_terms": [t["term"] for t in doc.get("found_terms", [])],
                      "rmse_base_Pa": doc["rmse_base_Pa"],
                      "rmse_final_Pa": doc["rmse_final_Pa"],
                      "noise_floor_Pa": doc["noise_floor_Pa"]}
        print(f"{label}: {wall:.0f} s, named {out[label]['named']}, found "
              f"{out[label]['found_terms']}, held-out {doc['rmse_base_Pa']:.0f} -> "
              f"{doc['rmse_final_Pa']:.0f} Pa (noise {doc['noise_floor_Pa']:.0f} Pa)")
    added = (out["with the open-form stage"]["wall_time_s"]
             - out["catalogue stages only (baseline)"]["wall_time_s"])
    print(f"the open-form stage added {added:.0f} s")
    write_json_atomic(args.json, {
        "format": "pneubayes-bench-openform-cost/1", "seed": args.seed,
        "hidden": {"form": "ReliefValve", "crack_gauge_Pa": CRACK_GAUGE_PA,
                   "flow_coefficient_kg_per_s_Pa1p5": FLOW_COEFFICIENT},
        "rig": ["AIR37", "valve1"], "recordings": "6 x 20 s", "runs": out,
        "added_wall_time_s": added, "floor_le_300s": added <= 300.0,
        "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
