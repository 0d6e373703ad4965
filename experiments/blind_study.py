"""The blind discovery study (issue 22, item 5): realistic cases drawn at random, run
once and reported once, never looked at while the loop is tuned.

    python experiments/blind_study.py --list                 # the cases, no runs
    python experiments/blind_study.py --out results/blind    # run (resumes) and report
    python experiments/blind_study.py --out /tmp/b --smoke   # a short check on tuning data
    python experiments/blind_study.py --out results/blind --case b16   # one case only

``--case NAME`` (repeatable; a case's full name or its ``bNN`` prefix) runs only those
cases into the same cache and writes no summary: start a second process on the last
cases to use a second core, then rerun without ``--case`` to report (finished cases
are read from the cache).

Each case is drawn from ``--seed`` (default 22022, recorded): a rig (cylinder and
valve) and, for each planted effect, a realistic plant form
(:mod:`pneubayes.bench.forms`) whose parameters are drawn from wide physical ranges
instead of the bench defaults the loop was tuned on -- a tube of 0.4-3 m and 1.5-4 mm
bore (in 8-24 cells as the bench's, or ``--min-tube-cells 32`` for a near-continuous
tube unlike the bench's; ``--tube-unsteady-friction 1`` gives it a line's unsteady
wall shear too), a rounded dead zone of 0.1-0.5 V, a regulator drooping
15-70 kPa per g/s with a 15-120 ms time constant, a clearance leak 0.5-3 x the
bench's, a 2nd-order spool at 70-220 Hz, wall convection of 10-80 W/(m^2 K) and an
undeclared causal Butterworth anti-alias filter at 120-600 Hz for a sensor lag. The
set: no-effect controls, every single effect, pairs and four-effect rigs. Every case
runs the bench (six 20-s recordings, as ``discovery_study.py``) and ``pneubayes
discover`` from the plain model.

Reported: per case the named set against the planted one, the held-out RMSE before and
after (Pa), the noise floor, the gap shrink and final / noise; and the issue's floors
(single effects and pairs: planted named in >= 90 %, median shrink >= 80 %, median
final <= 1.5 x noise; controls: nothing named in >= 90 %; four-effect rigs: >= 3 of 4
named, shrink >= 70 %). Cases are cached in OUT/cases/NAME.json; OUT/summary.json and
OUT/summary.md hold the report with the seed, git revision and versions.

``--smoke`` runs one short case drawn from a different seed (a tuning draw, not the
blind set) to check the plumbing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from discovery_study import cached_cases, results_root, six_recordings

from pneubayes.atomic import write_json_atomic, write_text_atomic
from pneubayes.bench.forms import (
    AcousticTube,
    ClearanceLeak,
    Iso6358Ports,
    RegulatorDroop,
    RoundedDeadzone,
    SecondOrderSpool,
    WallHeatTransfer,
    check_forms,
    forms_from_names,
)
from pneubayes.bench.sensors import SensorChain
from pneubayes.discovery.report import run_discover
from pneubayes.discovery.settings import (
    DiscoverySettings,
    FormSettings,
    PosteriorSettings,
    SearchSettings,
)
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.provenance import provenance

BLIND_SEED = 22022
SMOKE_SEED = 7
RIGS = ("AIR37:valve1", "AIR37:valve2", "SMC:valve1", "SMC:valve2", "PRN:valve1",
        "PRN:valve2", "AIR200:valve1", "AIR200:valve2")
SINGLES = ("tube_delay", "valve_deadzone", "supply_fluctuation", "cylinder_leak",
           "spool_lag", "heat_transfer", "sensor_lag")
#: The four-effect rigs carry Table III's four effects.
FOUR = ("tube_delay", "valve_deadzone", "supply_fluctuation", "cylinder_leak")
N_CONTROLS, N_PAIRS, N_FOUR = 3, 5, 2


def _log_uniform(rng, lo, hi) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_form(name: str, cylinder: str, rng, min_tube_cells: int = 8,
              tube_unsteady_friction: float = 0.0):
    """A realistic plant form of catalogue effect ``name`` with drawn parameters (the
    sensor lag is a SensorChain, not a plant form). A tube has 8 cells per metre,
    8-24 of them (the bench's rule), or ``min_tube_cells`` if that is more, and
    ``tube_unsteady_friction`` times Zielke's unsteady wall shear (not drawn)."""
    if name == "tube_delay":
        length = _log_uniform(rng, 0.4, 3.0)
        cells = max(int(min_tube_cells), int(min(24, max(8, math.ceil(8 * length)))))
        return AcousticTube(length_m=length, diameter_m=_log_uniform(rng, 0.0015, 0.004),
                            segments=cells, unsteady_friction=float(tube_unsteady_friction))
    if name == "valve_deadzone":
        w = rng.uniform(0.1, 0.5)
        return RoundedDeadzone(halfwidth_V=w, rounding_V=w * rng.uniform(0.1, 0.6))
    if name == "supply_fluctuation":
        return RegulatorDroop(droop_Pa_per_g_per_s=_log_uniform(rng, 15e3, 70e3),
                              time_constant_s=_log_uniform(rng, 0.015, 0.12))
    if name == "cylinder_leak":
        (base,) = forms_from_names(["cylinder_leak"], cylinder)
        # the conductance scales as gap^3: 0.5-3 x the bench's leak
        scale = _log_uniform(rng, 0.5, 3.0)
        return ClearanceLeak(gap_m=base.gap_m * scale ** (1 / 3),
                             seal_length_m=base.seal_length_m,
                             seal_length_slope=base.seal_length_slope * rng.uniform(0, 2))
    if name == "spool_lag":
        return SecondOrderSpool(natural_frequency_Hz=_log_uniform(rng, 70.0, 220.0),
                                damping=rng.uniform(0.5, 0.9))
    if name == "heat_transfer":
        return WallHeatTransfer(h_W_per_m2_K=_log_uniform(rng, 10.0, 80.0))
    if name == "sensor_lag":
        return SensorChain(phase="causal", cutoff_Hz=_log_uniform(rng, 120.0, 600.0))
    if name == "critical_ratio":  # (not among SINGLES: the recorded seeds' draws stay)
        return Iso6358Ports(critical_pressure_ratio=rng.uniform(0.15, 0.45),
                            subsonic_index=rng.uniform(0.35, 0.75))
    raise ValueError(f"draw_form: unknown effect {name!r}")


def draw_cases(seed: int, min_tube_cells: int = 8,
               tube_unsteady_friction: float = 0.0) -> list[dict]:
    """The blind set: controls, every single effect, pairs and four-effect rigs, each
    with a drawn rig, forms and bench seed (a JSON-ready list). ``min_tube_cells`` and
    ``tube_unsteady_friction`` set the plant tube's fewest cells and unsteady shear
    (:func:`draw_form`); the draws do not depend on them."""
    rng = np.random.default_rng(seed)
    sets: list[tuple[str, ...]] = [()] * N_CONTROLS + [(s,) for s in SINGLES]
    pairs = [(a, b) for i, a in enumerate(SINGLES) for b in SINGLES[i + 1:]]
    for k in rng.choice(len(pairs), size=N_PAIRS, replace=False):
        sets.append(pairs[int(k)])
    sets += [FOUR] * N_FOUR
    cases = []
    for i, hidden in enumerate(sets):
        rig = RIGS[int(rng.integers(len(RIGS)))]
        cylinder, valve = rig.split(":")
        forms = {h: draw_form(h, cylinder, rng, min_tube_cells, tube_unsteady_friction)
                 for h in hidden}
        cases.append({"name": f"b{i:02d}_{cylinder}_{valve}_{'+'.join(hidden) or 'none'}",
                      "cylinder": cylinder, "valve": valve, "hidden": list(hidden),
                      "bench_seed": int(rng.integers(1000, 100000)),
                      "forms": {h: (f.to_dict() if h != "sensor_lag" else
                                    {"phase": f.phase, "cutoff_Hz": f.cutoff_Hz})
                                for h, f in forms.items()},
                      "_objects": forms})
    return cases


def _public(case: dict) -> dict:
    """The case's JSON-ready record (without its form objects)."""
    return {k: v for k, v in case.items() if not k.startswith("_")}


def run_case(case: dict, args, root: Path) -> dict:
    work = root / "work" / case["name"]
    objs = case["_objects"]
    sensor = objs.get("sensor_lag", SensorChain())
    plant = check_forms([f for h, f in objs.items() if h != "sensor_lag"])
    seed = case["bench_seed"]
    paths, _ = six_recordings(case["cylinder"], case["valve"], seed, work, effects=(),
                              forms=plant, duration_s=args.duration, sensor=sensor)
    recs = [read_recording(p) for p in paths]
    settings = DiscoverySettings(
        posterior=PosteriorSettings(method="none" if args.posterior == "off"
                                    else args.posterior),
        seed=seed, search=SearchSettings(n_bags=40),
        forms=FormSettings(tube_line_form=args.tube_line_form,
                           tube_wave_unsteady=args.wave_unsteady),
        fit=FitSettings(sampler=SamplerSettings(n_walkers=32, max_steps=400, seed=seed),
                        pressure_filter=sensor.declared_filter()))
    t0 = time.perf_counter()
    doc = run_discover(recs, settings, work / "run", log=lambda m: None, figures=False)
    named = [e["name"] for e in doc["effects"]]
    kept = [e["name"] for e in doc.get("stand_ins", [])]  # in the model, not named
    noise = doc["noise_floor_Pa"]
    gap0 = max(doc["rmse_base_Pa"] - noise, 0.0)
    gap1 = max(doc["rmse_final_Pa"] - noise, 0.0)
    return _public(case) | {
        "named": named, "kept_at_bound": kept,
        "correct": sorted(named) == sorted(case["hidden"]),
        "planted_named": len(set(named) & set(case["hidden"])),
        "rmse_base_Pa": doc["rmse_base_Pa"], "rmse_final_Pa": doc["rmse_final_Pa"],
        "noise_floor_Pa": noise, "gap_shrink": None if gap0 <= 0 else 1.0 - gap1 / gap0,
        "final_over_noise": doc["rmse_final_Pa"] / noise,
        "wall_time_s": time.perf_counter() - t0, "ledger": doc["ledger"],
        "posterior": ({k: v for k, v in doc["posterior"].items() if k != "summary"}
                      if "posterior" in doc else None)}


def case_kind(case: dict) -> str:
    """The floor a case counts towards: ``"control"`` (nothing planted),
    ``"single/pair"`` or ``"four-effect"``."""
    n = len(case["hidden"])
    return "control" if n == 0 else ("single/pair" if n <= 2 else "four-effect")


def summarise(results: list[dict]) -> tuple[dict, str]:
    """The issue's floors over the blind set, and a per-case table."""
    kind = case_kind
    out = {}
    for k in ("control", "single/pair", "four-effect"):
        rs = [r for r in results if kind(r) == k and "error" not in r]
        if not rs:
            continue
        shrink = [r["gap_shrink"] for r in rs if r["gap_shrink"] is not None]
        d = {"cases": len(rs), "errors": sum(kind(r) == k and "error" in r for r in results)}
        if k == "control":
            d["nothing_named_fraction"] = float(np.mean(  # (a stand-in kept counts)
                [not r["named"] and not r.get("kept_at_bound") for r in rs]))
        else:
            d["all_planted_named_fraction"] = float(np.mean(
                [r["planted_named"] == len(r["hidden"]) for r in rs]))
            d["planted_named_mean"] = float(np.mean([r["planted_named"] for r in rs]))
            d["exactly_planted_fraction"] = float(np.mean([r["correct"] for r in rs]))
            d["gap_shrink_median"] = float(np.median(shrink)) if shrink else None
            d["gap_shrink_min"] = float(min(shrink)) if shrink else None
        d["final_over_noise_median"] = float(np.median([r["final_over_noise"] for r in rs]))
        out[k] = d
    lines = ["| case | rig | planted | named | held-out RMSE base -> final (Pa) | noise (Pa) "
             "| gap shrink | final / noise |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        if "error" in r:
            lines.append(f"| {r['name']} | {r['cylinder']}/{r['valve']} | "
                         f"{', '.join(r['hidden']) or '-'} | error: {r['error']} | | | | |")
            continue
        sh = "-" if r["gap_shrink"] is None else f"{100 * r['gap_shrink']:.0f} %"
        kept = r.get("kept_at_bound") or []
        kept_note = f" (kept at a bound, not named: {', '.join(kept)})" if kept else ""
        lines.append(f"| {r['name']} | {r['cylinder']}/{r['valve']} | "
                     f"{', '.join(r['hidden']) or '-'} | {', '.join(r['named']) or '-'}"
                     f"{kept_note} | "
                     f"{r['rmse_base_Pa']:.0f} -> {r['rmse_final_Pa']:.0f} | "
                     f"{r['noise_floor_Pa']:.0f} | {sh} | {r['final_over_noise']:.2f} |")
    lines += ["", "| kind | cases | floor check |", "|---|---|---|"]
    for k, d in out.items():
        if k == "control":
            check = f"nothing named in {100 * d['nothing_named_fraction']:.0f} % (floor 90 %)"
        else:
            med, low = d["gap_shrink_median"], d["gap_shrink_min"]
            pair = k == "single/pair"
            check = (f"all planted named in {100 * d['all_planted_named_fraction']:.0f} %"
                     + (" (floor 90 %)" if pair else "") + ", "
                     f"{d['planted_named_mean']:.2f} planted named on average"
                     + ("" if pair else " (floor 3 of 4)") + ", exactly the "
                     f"planted set in {100 * d['exactly_planted_fraction']:.0f} %, median "
                     f"gap shrink {'n/a' if med is None else f'{100 * med:.0f} %'}"
                     + (" (floor 80 %)" if pair else
                        f", least {'n/a' if low is None else f'{100 * low:.0f} %'} "
                        "(floor 70 % on every rig)"))
        check += (f"; median final / noise {d['final_over_noise_median']:.2f}"
                  + (" (floor 1.5)" if k == "single/pair" else ""))
        lines.append(f"| {k} | {d['cases']} | {check} |")
    return out, "\n".join(lines) + "\n"


def addition_gains(result: dict, noise_share: float, gap_share: float) -> list[dict]:
    """Each effect the loop added in ``result`` (a case's record with its ledger), with
    its held-out gain (Pa) and the least gain the loop's gain floor asks
    (``VerifySettings.min_gain_noise_share`` x the noise floor or ``min_gain_gap_share``
    x the gap above it, whichever is larger; :func:`pneubayes.discovery.rounds.min_gain_Pa`):
    a check for sets run before that floor existed."""
    noise = result["noise_floor_Pa"]
    out = []
    for e in result.get("ledger", []):
        if e.get("action") != "add":
            continue
        before, after = e["heldout_rmse_before_Pa"], e["heldout_rmse_after_Pa"]
        least = max(noise_share * noise, gap_share * max(before - noise, 0.0))
        out.append({"case": result["name"], "effect": e["effect"],
                    "heldout_before_Pa": before, "gain_Pa": before - after,
                    "least_gain_Pa": least, "meets": before - after >= least})
    return out


def _is_case(case: dict, key: str) -> bool:
    """Whether ``key`` names ``case``: its full name or its ``bNN`` prefix."""
    return case["name"] == key or case["name"].split("_")[0] == key


def check_case(name: str, rig: str, hidden, forms: dict, rng) -> dict:
    """A one-effect blind check's case ``name`` on ``rig`` (``"CYL:valveN"``), its planted
    forms by catalogue name and a bench seed drawn from ``rng``."""
    cylinder, valve = rig.split(":")
    return {"name": name, "cylinder": cylinder, "valve": valve, "hidden": list(hidden),
            "bench_seed": int(rng.integers(1000, 100000)),
            "forms": {h: f.to_dict() for h, f in forms.items()}, "_objects": forms}


def fitted_effect(root: Path, name: str, effect: str) -> tuple[dict, dict] | None:
    """A case's named ``effect``: its options and fitted values from the case's
    discovery.json (None: not named, or the case not run)."""
    path = root / "work" / name / "run" / "discovery.json"
    if not path.exists():
        return None
    for e in json.loads(path.read_text())["effects"]:
        if e["name"] == effect:
            return (e.get("options", {}),
                    {k: v["estimate"] for k, v in e["parameters"].items()})
    return None


def check_summary(root: Path, title: str, columns: tuple[str, str], results, planted,
                  fitted) -> str:
    """A one-effect blind check's table (``planted(result)`` and ``fitted(root, name)``
    give its two columns, headed ``columns``), written to ROOT/summary.md with the
    provenance; returns the table."""
    lines = [title, "", f"| case | {columns[0]} | {columns[1]} | named | held-out RMSE (Pa) "
             "| x noise | shrink |", "|---|---|---|---|---|---|---|"]
    for r in results:
        if "error" in r:
            lines.append(f"| {r['name']} | {planted(r)} | - | failed: {r['error']} | - | - "
                         "| - |")
            continue
        shrink = "-" if r["gap_shrink"] is None else f"{100 * r['gap_shrink']:.0f} %"
        lines.append(f"| {r['name']} | {planted(r)} | {fitted(root, r['name'])} | "
                     f"{', '.join(r['named']) or '-'} | "
                     f"{r['rmse_base_Pa']:.0f} -> {r['rmse_final_Pa']:.0f} | "
                     f"{r['final_over_noise']:.2f} | {shrink} |")
    table = "\n".join(lines)
    write_text_atomic(root / "summary.md",
                      table + f"\n\nprovenance: {json.dumps(provenance())}\n")
    return table


def run_check(cases, root: Path) -> list[dict]:
    """A one-effect blind check's cases (``critical_ratio_blind``, ``heat_wall_blind``):
    each run as the blind study runs it (20-s recordings, no posterior, the wave tube)
    into ROOT/cases, or read from there, one line per case as it finishes."""
    opts = argparse.Namespace(duration=20.0, posterior="off", tube_line_form="wave",
                              wave_unsteady=False)

    def describe(r):
        if "error" in r:
            return f"FAILED {r['error']}"
        return (f"named {r['named']} ({'correct' if r['correct'] else 'WRONG'}), "
                f"{r['rmse_base_Pa']:.0f} -> {r['rmse_final_Pa']:.0f} Pa, "
                f"{r['final_over_noise']:.2f} x the noise, {r['wall_time_s']:.0f} s")

    return cached_cases([(c["name"], c) for c in cases], root,
                        lambda name, c: run_case(c, opts, root),
                        lambda name, c, err: _public(c) | {"error": err}, describe)


def _run_cached(cases, args, root: Path) -> list[dict]:
    """Each case's result from ROOT/cases (run and cached when missing), one word per
    case: the blind results are read once, in the summary."""
    return cached_cases(
        [(c["name"], c) for c in cases], root, lambda name, c: run_case(c, args, root),
        lambda name, c, error: _public(c) | {"error": error, "named": []},
        lambda res: "done")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="results folder (cases cached there)")
    ap.add_argument("--seed", type=int, default=BLIND_SEED, help="the draw's seed")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per recording")
    ap.add_argument("--list", action="store_true", help="print the cases and stop")
    ap.add_argument("--case", action="append", default=[], metavar="NAME",
                    help="run only this case (full name or bNN prefix; repeatable) into "
                         "the cache, without a summary")
    ap.add_argument("--tube-line-form", choices=("line", "wave"), default="wave",
                    help="the outside tube's form the loop tries (FormSettings."
                         "tube_line_form; wave)")
    ap.add_argument("--min-tube-cells", type=int, default=8, metavar="N",
                    help="the plant tube's fewest cells (default 8: the bench's rule of 8 "
                         "per metre, 8-24; 32 makes a near-continuous tube, unlike the "
                         "bench's; the plant costs about 4x more)")
    ap.add_argument("--tube-unsteady-friction", type=float, default=0.0, metavar="W",
                    help="the plant tubes' share of Zielke's unsteady wall shear (default 0: "
                         "quasi-steady, as the model's tube; 1: a line's own)")
    ap.add_argument("--wave-unsteady", action="store_true",
                    help="the loop's wave tube fits the unsteady shear's weight too "
                         "(FormSettings.tube_wave_unsteady)")
    ap.add_argument("--posterior", choices=("off", "emcee", "laplace"), default="off",
                    help="the final model's posterior (off: the loop alone, as the blind "
                         "sets ran; its time is part of the issue's loop floor)")
    ap.add_argument("--smoke", action="store_true",
                    help="one short case from a tuning draw (not the blind set)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.seed, args.duration = SMOKE_SEED, 16.0
    if args.min_tube_cells < 1:
        ap.error(f"--min-tube-cells: must be at least 1, got {args.min_tube_cells}")
    if not args.tube_unsteady_friction >= 0:
        ap.error(f"--tube-unsteady-friction: must be >= 0, got {args.tube_unsteady_friction}")
    cases = draw_cases(args.seed, args.min_tube_cells, args.tube_unsteady_friction)
    if args.smoke:
        cases = [c for c in cases if c["hidden"] == ["tube_delay"]]
    root = results_root(ap, args, cases, _public)
    if root is None:
        return 0
    if args.case:
        missing = [k for k in args.case if not any(_is_case(c, k) for c in cases)]
        if missing:
            ap.error(f"--case: no case {missing} in the draw of seed {args.seed} "
                     f"(--list shows them)")
        _run_cached([c for c in cases if any(_is_case(c, k) for k in args.case)], args, root)
        return 0
    t_all = time.perf_counter()
    results = _run_cached(cases, args, root)
    table, md = summarise(results)
    write_json_atomic(root / "summary.json", {
        "seed": args.seed, "duration_s": args.duration, "smoke": args.smoke,
        "tube_line_form": args.tube_line_form, "min_tube_cells": args.min_tube_cells,
        "floors": table, "cases": results, "wall_time_s": time.perf_counter() - t_all,
        "provenance": provenance()})
    write_text_atomic(root / "summary.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
