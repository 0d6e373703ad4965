"""The sensor's calibration, drift and curvature in the discovery loop: named where
planted, not named where another effect is (the stand-ins they risk).

    python experiments/calibration_study.py --out results/calibration_study [--seeds 0]
    python experiments/calibration_study.py --out results/calibration_study --collect

``sensor_calibration``'s library terms are off by default (its module says why: an
offset reads like a leak into a closed chamber, a gain like the supply's). This study
switches them on (``LibraryGrid``, its documented ``opt_in_strengths``) and runs the
loop from the plain model on the discovery study's six 20-s recordings per case
(:func:`discovery_study.six_recordings`):

- planted: the zero offset alone (5 kPa), the offset with a 3 % gain error, and the
  offset beside a laminar leak;
- controls, no calibration planted: no effect, a laminar leak (the offset's stand-in
  risk) and the supply fluctuation (the gain's);
- a drifting zero (``sensor_drift``, searched by default): a warm-up (the bench's 3 kPa
  over 5 s), a linear drift (100 Pa/s) and the warm-up beside a laminar leak; run them
  with ``--search off`` (the drift is in the default library either way) beside the
  controls;
- a curved reading (``sensor_nonlinearity``, searched by default): -300 Pa at 1 bar
  gauge (6 kPa at the AIR37 rig's full 4.5 bar), and a bow that vanishes at 0 and 6
  bar gauge (the same curvature with the gain error +1.8 % that makes it so).

With ``--search off`` the loop runs with its defaults (the calibration not searched):
what it names instead where a calibration is planted.

No pressure filter is declared (the bench's zero-phase 1-kHz DAQ filter rounds the
corners by tens of Pa; the same in every case). A case is correct when the named set is
the planted set. Every case is cached in
OUT/cases/NAME.json (an interrupted study resumes); OUT/summary.json holds the table
with the seeds, the revision and the versions.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from discovery_study import LEAK_OVERRIDE, cached_cases, six_recordings

from pneubayes.atomic import write_json_atomic
from pneubayes.discovery.library import LibraryGrid
from pneubayes.discovery.report import run_discover
from pneubayes.discovery.settings import DiscoverySettings, PosteriorSettings, SearchSettings
from pneubayes.effects import SensorCalibration, make_effect
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.provenance import provenance

#: case name -> (planted effects as (name, options), bench overrides)
CASES = {
    "offset": ((("sensor_calibration", {}),), {}),
    "offset_gain": ((("sensor_calibration", {"form": "offset_gain"}),), {}),
    "offset+leak": ((("sensor_calibration", {}), ("cylinder_leak", {"form": "laminar"})),
                    LEAK_OVERRIDE),
    "none": ((), {}),
    "leak": ((("cylinder_leak", {"form": "laminar"}),), LEAK_OVERRIDE),
    "supply": ((("supply_fluctuation", {}),), {}),
    "warm_up": ((("sensor_drift", {}),), {}),
    "linear": ((("sensor_drift", {"form": "linear"}),), {"reading_drift_Pa_per_s": 100.0}),
    "warm_up+leak": ((("sensor_drift", {}), ("cylinder_leak", {"form": "laminar"})),
                     LEAK_OVERRIDE),
    "curvature": ((("sensor_nonlinearity", {}),), {"reading_curvature_Pa": -300.0}),
    "bow": ((("sensor_nonlinearity", {"form": "curvature_gain"}),),
            {"reading_curvature_Pa": -300.0, "reading_curve_gain_error": 0.018}),
}


#: the revision the process imported its code from (a commit made while a study runs
#: does not change the code it runs)
STARTED_AT = provenance()


def run_case(name, rig, valve, seed, search, args, root):
    planted, overrides = CASES[name.split("@")[0]]  # (the rig, seed and search follow)
    effects = tuple(make_effect(n, **o) for n, o in planted)
    work = root / "work" / name
    paths, _ = six_recordings(rig, valve, seed, work, effects=effects, overrides=overrides,
                              duration_s=args.duration)
    recs = [read_recording(p) for p in paths]
    grid = LibraryGrid({"sensor_calibration": SensorCalibration.opt_in_strengths}
                       if search else {})
    settings = DiscoverySettings(
        posterior=PosteriorSettings(method="none"), seed=seed,
        search=SearchSettings(grid=grid),
        fit=FitSettings(sampler=SamplerSettings(n_walkers=32, max_steps=400, seed=seed)))
    t0 = time.perf_counter()
    doc = run_discover(recs, settings, work / "run", log=lambda m: None, figures=False)
    named = [e["name"] for e in doc["effects"]]
    hidden = [n for n, _ in planted]
    noise = doc["noise_floor_Pa"]
    gap0 = max(doc["rmse_base_Pa"] - noise, 0.0)
    gap1 = max(doc["rmse_final_Pa"] - noise, 0.0)
    return {"case": name, "rig": rig, "valve": valve, "seed": seed, "searched": search,
            "hidden": hidden,
            "named": named, "correct": sorted(named) == sorted(hidden),
            "rmse_base_Pa": doc["rmse_base_Pa"], "rmse_final_Pa": doc["rmse_final_Pa"],
            "noise_floor_Pa": noise, "gap_shrink": None if gap0 <= 0 else 1 - gap1 / gap0,
            "estimates": {e["name"]: e["parameters"] for e in doc["effects"]},
            "wall_time_s": time.perf_counter() - t0,
            "git_revision": STARTED_AT.get("git_revision"),
            "git_dirty": STARTED_AT.get("git_dirty")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--rigs", default="AIR37:valve1,SMC:valve2")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per recording")
    ap.add_argument("--search", choices=("on", "off"), default="on",
                    help="off: the loop's defaults, the calibration not searched (what it "
                         "names instead where one is planted); case names end in ~off")
    ap.add_argument("--collect", action="store_true",
                    help="run nothing: write OUT/summary.json from every case in OUT/cases "
                         "(cases run by several calls, e.g. other rigs or seeds)")
    args = ap.parse_args(argv)
    root = Path(args.out)
    if args.collect:
        paths = sorted((root / "cases").glob("*.json"))
        if not paths:
            ap.error(f"--collect: no cases in {root / 'cases'}")
        results = [json.loads(p.read_text()) for p in paths]
        _write_summary(root, results, args)
        return 0
    cases = []
    for seed in (int(s) for s in args.seeds.split(",")):
        for rv in args.rigs.split(","):
            rig, valve = rv.split(":")
            for c in args.cases.split(","):
                if c not in CASES:
                    ap.error(f"--cases: unknown case {c!r}; the cases are {list(CASES)}")
                suffix = "" if args.search == "on" else "~off"
                cases.append((f"{c}@{rig}-{valve}-s{seed}{suffix}",
                               (rig, valve, seed, args.search == "on")))

    def failed(name, case, why):
        return {"case": name, "failed": why}

    def describe(r):
        if "failed" in r:
            return f"FAILED {r['failed']}"
        return (f"named {r['named']} (planted {r['hidden']}), "
                f"{r['rmse_final_Pa']:.0f} Pa vs noise {r['noise_floor_Pa']:.0f}, "
                f"{r['wall_time_s']:.0f} s")

    results = cached_cases(cases, root, lambda n, c: run_case(n, *c, args, root), failed,
                           describe)
    _write_summary(root, results, args)
    return 0


def _write_summary(root: Path, results: list[dict], args) -> None:
    ok = [r for r in results if "failed" not in r]
    write_json_atomic(root / "summary.json", {
        "correct": sum(r["correct"] for r in ok), "cases": len(results),
        "results": results, "config": vars(args), "provenance": provenance()})
    print(f"{sum(r['correct'] for r in ok)} of {len(results)} cases named exactly")


if __name__ == "__main__":
    sys.exit(main())
