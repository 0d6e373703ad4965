"""Real recordings: the RespiraWorks ventilator's test lung (OXY and AIR), plain model ->
discovery, whole runs held out, against the set-point as a baseline.

    python experiments/real_respiraworks.py --out results/real_respiraworks [--smoke]
        [--sets OXY,AIR] [--data DIR] [--held-out RUN ...]

Data: ``data/real/respiraworks/`` (``pneubayes import respiraworks`` of the twelve
shared runs, 100 Hz, kPa gauge; licence file beside them). Each gas path has its rig
card: a compliant chamber (the test lung and circuit: volume and compliance as priors),
a Gompertz inhale map and exhale map of the inhale command (the exhale pinch valve is
commanded in closed loop from it), a constant supply (OXY: 400 kPa absolute assumed;
AIR: the blower's 5 kPa gauge).

Per set: train on runs 1-4, hold out runs 5 and 6 whole (``--held-out`` names others,
e.g. ``covent_pc_7``, repeatable: every run not held out trains); 2-s windows (11 per run,
22 held out), each started from the measured pressure. The result records the held-out
RMSE of the plain model and after discovery, in Pa and against the noise floor and the
measured span, next to the set-point baseline (predicting the controller's set-point,
which a closed loop tracks), the named effects with intervals, and the parameters whose
90 % interval sits on a bound. Seed 0 (recorded). Writes OUT/real_respiraworks.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from real_common import (
    add_split_arguments,
    added_names,
    plain_fit,
    prediction_figure,
    split_held_out,
)

from pneubayes.atomic import write_json_atomic
from pneubayes.discovery.report import run_discover
from pneubayes.discovery.settings import DataSettings, DiscoverySettings, RoundSettings
from pneubayes.inference.pipeline import FitSettings, at_bounds
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "real" / "respiraworks"
CMH2O_PA = 98.0665
HORIZON_S = 2.0
HELD_OUT = ("covent_pc_5", "covent_pc_6")
SEED = 0
#: emcee's step budget per set; the result records convergence
MAX_STEPS = 1500


def setpoint_rmse_Pa(recs, horizon_s: float) -> float:
    """RMSE of predicting the set-point over the same windows (after each window's first
    sample, as the model's predictions)."""
    errs = []
    for r in recs:
        dt = float(np.median(np.diff(r.time_s)))
        n = int(round(horizon_s / dt))
        gauge = r.pressure_Pa - r.metadata.atmospheric_pressure_Pa
        sp = r.extra_columns["pc_setpoint_cmH2O"].astype(float) * CMH2O_PA
        for s in range(0, r.n_samples - n, n):
            errs.append(gauge[s + 1:s + n + 1] - sp[s + 1:s + n + 1])
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e ** 2)))


def split_runs(recs, held_out, where) -> tuple:
    """``(train, held)``: the runs whose file stems are in ``held_out`` held out
    (:func:`real_common.split_held_out`; ``where`` names the folder in its errors)."""
    return split_held_out(recs, held_out, lambda r: Path(r.source).stem, str(where))


def run_set(kind: str, data: Path, out: Path, smoke: bool, held_out=HELD_OUT) -> dict:
    paths = sorted((data / kind).glob("*.csv"))
    if not paths:
        raise SystemExit(f"{data / kind}: no recordings (run 'pneubayes import respiraworks')")
    recs = [read_recording(p) for p in paths]
    train, held = split_runs(recs, held_out, data / kind)
    sampler = (SamplerSettings(n_walkers=32, max_steps=200, seed=SEED) if smoke
               else SamplerSettings(seed=SEED, max_steps=MAX_STEPS))
    settings = DiscoverySettings(
        data=DataSettings(holdout_recordings=len(held)), seed=SEED,
        rounds=RoundSettings(max_effects=2 if smoke else 4),
        fit=FitSettings(horizon_s=HORIZON_S, stride_s=HORIZON_S, sampler=sampler,
                        supply_cutoff_Hz=None, position_cutoff_Hz=None))
    doc = run_discover(train + held, settings, out / kind,
                       log=lambda m: print(f"[{kind}] {m}", file=sys.stderr))
    noise = doc["noise_floor_Pa"]
    post = (doc.get("posterior") or {}).get("summary", {})
    plain = plain_fit(train, HORIZON_S, FitSettings().refine_solver)
    fig, predictive = prediction_figure(
        held, plain, out / kind, HORIZON_S, out / "figures" / f"respiraworks_{kind}.png",
        f"RespiraWorks {kind}, held-out runs: plain rig-card model (orange) and after "
        f"discovery ({', '.join(added_names(doc)) or 'nothing added'}; "
        "blue)", SEED)
    return {
        "train": [str(r.source) for r in train], "held_out": [str(r.source) for r in held],
        "noise_floor_Pa": noise, "span_Pa": doc["span_Pa"],
        "held_out_rmse_plain_Pa": doc["rmse_base_Pa"],
        "held_out_rmse_final_Pa": doc["rmse_final_Pa"],
        "final_over_noise": doc["rmse_final_Pa"] / noise,
        "setpoint_baseline_rmse_Pa": setpoint_rmse_Pa(held, HORIZON_S),
        "effects": [e["name"] for e in doc["effects"]],
        "stand_ins": [e["name"] for e in doc.get("stand_ins", [])],
        "posterior": post,
        "converged": (doc.get("posterior") or {}).get("converged"),
        "at_bounds": [b["parameter"] for b in at_bounds(Model(rig_card=recs[0].rig_card),
                                                         post)],
        "plain_parameters": plain, "figure": str(fig),
        "posterior_predictive": predictive,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    add_split_arguments(ap, DATA, HELD_OUT, "run")
    ap.add_argument("--sets", default="OXY,AIR")
    ap.add_argument("--smoke", action="store_true", help="short sampler (a check it runs)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    held_out = tuple(args.held_out or HELD_OUT)
    result = {"horizon_s": HORIZON_S, "seed": SEED, "smoke": args.smoke,
              "held_out": list(held_out), "sets": {}, "provenance": provenance()}
    for kind in [k.strip() for k in args.sets.split(",") if k.strip()]:
        result["sets"][kind] = res = run_set(kind, Path(args.data), out, args.smoke, held_out)
        write_json_atomic(out / "real_respiraworks.json", result)
        print(f"{kind}: held-out {HORIZON_S:g}-s RMSE plain {res['held_out_rmse_plain_Pa']:.0f}"
              f" Pa -> {res['held_out_rmse_final_Pa']:.0f} Pa ({res['final_over_noise']:.1f} x "
              f"the noise floor {res['noise_floor_Pa']:.0f} Pa; measured span "
              f"{res['span_Pa']:.0f} Pa); set-point baseline "
              f"{res['setpoint_baseline_rmse_Pa']:.0f} Pa; effects {res['effects']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
