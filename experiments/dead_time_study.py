"""A valve whose dead time depends on the supply, hidden on the bench at three supplies:
does discovery name ``valve_dead_time``, and not where there is none?

    python experiments/dead_time_study.py --out results/dead_time_study [--smoke]
        [--cases armature_AIR37 none_AIR37 ...]

Each case records a rig at three regulated supplies (3, 4.5 and 6 bar gauge), two
fixed-piston recordings each (command ranges +-5 and +-3 V, the piston at half stroke),
through the high-fidelity plant. ``armature`` plants
:class:`~pneubayes.bench.forms.ArmatureDeadTime` (a coil delay of 2 ms and an
armature's travel of 8 ms at 5 bar gauge, scaled as the inverse square root of the
supply at each command change: not the catalogue's power law of the nominal supply);
``held`` plants :class:`~pneubayes.bench.forms.HeldArmatureDeadTime` (the same at 5 bar,
a poppet the supply holds back, which cannot open at 10 bar: its dead time rises with
the supply); ``none`` plants nothing (a null control: the stage may run, and must name nothing).
The first recording of each supply trains, the second is held out. Discovery runs with
its default stages; the result records what it named, the held-out error before and
after against the noise floor, and the fitted dead times at the three supplies beside
the planted ones. Each case's result is cached (an interrupted study resumes). Seeds:
the bench's, from ``--seed`` (recorded).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from discovery_study import cached_cases

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.bench import ATMOSPHERE_PA, BenchConfig, run_bench
from pneubayes.bench.forms import ArmatureDeadTime, HeldArmatureDeadTime
from pneubayes.discovery.report import run_discover
from pneubayes.discovery.settings import DataSettings, DiscoverySettings, PosteriorSettings
from pneubayes.effects import ValveDeadTime
from pneubayes.io import read_recording
from pneubayes.provenance import provenance
from pneubayes.rig import Rig

#: The regulated supplies, gauge Pa.
SUPPLIES_GAUGE_PA = (3e5, 4.5e5, 6e5)
#: The planted armatures: one the supply drives (a pilot stage), one it holds back (a
#: direct-acting poppet that cannot open at 10 bar gauge).
ARMATURES = {"armature": ArmatureDeadTime(travel_s=8e-3, coil_s=2e-3, reference_gauge_Pa=5e5),
             "held": HeldArmatureDeadTime(travel_s=8e-3, coil_s=2e-3,
                                          reference_gauge_Pa=5e5, limit_gauge_Pa=1e6)}
CASES = {"armature_AIR37": ("AIR37", "valve1", "armature"),
         "none_AIR37": ("AIR37", "valve1", None),
         "armature_SMC": ("SMC", "valve2", "armature"), "none_SMC": ("SMC", "valve2", None),
         "held_AIR37": ("AIR37", "valve1", "held"), "held_SMC": ("SMC", "valve2", "held")}


def recordings(cylinder, valve, planted, seed, duration_s, work: Path):
    """``(train, held)``: one recording per supply each."""
    train, held = [], []
    for i, gauge in enumerate(SUPPLIES_GAUGE_PA):
        res = run_bench(BenchConfig(cylinder, valve, protocol="fixed", seed=seed + i,
                                    positions=(0.5,), ranges_V=(5.0, 3.0),
                                    duration_s=duration_s,
                                    forms=(ARMATURES[planted],) if planted else (),
                                    supply_Pa=ATMOSPHERE_PA + gauge),
                        work / f"supply{gauge / 1e5:g}bar", overwrite=True)
        first, second = [read_recording(p) for p in res.recordings]
        train.append(first)
        held.append(second)
    return train, held


def planted_dead_times_s(planted: str | None) -> list[float]:
    """The planted armature's dead time at each supply (its supply is constant), s."""
    if planted is None:
        return [0.0] * len(SUPPLIES_GAUGE_PA)
    a = ARMATURES[planted]
    return [a.coil_s + a.travel_s * a.travel_factor(g) for g in SUPPLIES_GAUGE_PA]


def fitted_dead_times_s(doc: dict) -> list[float] | None:
    """The named ``valve_dead_time``'s dead time at each supply (posterior medians or
    the point estimate), or None where it was not named."""
    eff = next((e for e in doc["effects"] if e["name"] == "valve_dead_time"), None)
    if eff is None:
        return None
    p = {k: v.get("median", v.get("estimate")) for k, v in eff["parameters"].items()}
    law = ValveDeadTime()
    return [float(law.dead_time_s({k: np.array([v]) for k, v in p.items()},
                                  Rig(0.01, ATMOSPHERE_PA, ATMOSPHERE_PA + g))[0])
            for g in SUPPLIES_GAUGE_PA]


def run_case(name, case, args, root: Path) -> dict:
    cylinder, valve, planted = case
    train, held = recordings(cylinder, valve, planted, args.seed, args.duration,
                             root / "work" / name)
    settings = DiscoverySettings(
        data=DataSettings(holdout_recordings=len(held)), seed=args.seed,
        posterior=PosteriorSettings(method="laplace" if args.smoke else "emcee"))
    t0 = time.perf_counter()
    doc = run_discover(train + held, settings, root / "work" / name / "discovery",
                       log=lambda m: print(m, file=sys.stderr, flush=True), figures=False)
    named = [e["name"] for e in doc["effects"]]
    noise = doc["noise_floor_Pa"]
    return {"case": name, "cylinder": cylinder, "valve": valve, "planted": planted,
            "named": named, "correct": named == (["valve_dead_time"] if planted else []),
            "rmse_base_Pa": doc["rmse_base_Pa"], "rmse_final_Pa": doc["rmse_final_Pa"],
            "noise_floor_Pa": noise, "final_over_noise": doc["rmse_final_Pa"] / noise,
            "planted_dead_times_s": planted_dead_times_s(planted),
            "fitted_dead_times_s": fitted_dead_times_s(doc),
            "supplies_gauge_Pa": list(SUPPLIES_GAUGE_PA),
            "wall_time_s": time.perf_counter() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES),
                    default=["armature_AIR37", "none_AIR37"])
    ap.add_argument("--seed", type=int, default=951)
    ap.add_argument("--duration", type=float, default=8.0, help="each recording's s")
    ap.add_argument("--smoke", action="store_true", help="a Laplace posterior, not emcee")
    args = ap.parse_args(argv)
    root = Path(args.out)

    def failed(name, case, error):
        return {"case": name, "error": error}

    def describe(r):
        if "error" in r:
            return r["error"]
        fitted = r["fitted_dead_times_s"]
        return (f"named {r['named'] or 'nothing'}; held out {r['rmse_base_Pa']:.0f} -> "
                f"{r['rmse_final_Pa']:.0f} Pa ({r['final_over_noise']:.2f} x the noise); "
                f"dead times planted {[round(1e3 * d, 2) for d in r['planted_dead_times_s']]}"
                f" ms, fitted {fitted and [round(1e3 * d, 2) for d in fitted]} ms")

    results = cached_cases([(n, CASES[n]) for n in args.cases], root,
                           lambda n, c: run_case(n, c, args, root), failed, describe)
    write_json_atomic(root / "dead_time_study.json",
                      {"results": results, "seed": args.seed, "duration_s": args.duration,
                       "smoke": args.smoke, "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
