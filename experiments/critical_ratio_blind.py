"""A blind check of ``critical_ratio``: valves rated by ISO 6358 on rigs and at values
the effect was not developed on, run once and reported once.

    python experiments/critical_ratio_blind.py --list --seed S
    python experiments/critical_ratio_blind.py --out results/cr_blind --seed S

The effect was written beside two development cases (AIR37 / valve 1 and SMC / valve 2,
b = 0.3, m = 0.45; ``discovery_study.py --conditions critical_ratio --forms realistic``).
This set draws from ``--seed`` (record it; draw it from the clock before looking): four
single cases on the other rigs, the ISO 6358 ports' ``b`` in 0.15-0.45 and ``m`` in
0.35-0.75 (:func:`blind_study.draw_form`); two pairs beside effects that also shape a
fill's end (a regulator's droop, a tube); one null control. Each runs the bench's six
20-s recordings and ``pneubayes discover`` from the plain model (``blind_study.run_case``);
cases are cached in OUT/cases/NAME.json (a stopped run resumes), the table written to
OUT/summary.md with the seed and git revision.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from blind_study import _public, check_case, check_summary, draw_form, fitted_effect, run_check
from discovery_study import results_root

#: The rigs of the singles: not the development cases' AIR37 / valve 1, SMC / valve 2.
SINGLE_RIGS = ("AIR37:valve2", "SMC:valve1", "PRN:valve1", "AIR200:valve2")
PAIRS = (("critical_ratio", "supply_fluctuation"), ("critical_ratio", "tube_delay"))
PAIR_RIGS = ("PRN:valve2", "AIR200:valve1")


def draw_cases(seed: int) -> list[dict]:
    """The set's cases (each a rig, the planted effects' drawn forms and a bench seed)."""
    rng = np.random.default_rng(seed)
    plan = ([(r, ("critical_ratio",)) for r in SINGLE_RIGS]
            + list(zip(PAIR_RIGS, PAIRS)) + [("AIR37:valve2", ())])
    cases = []
    for i, (rig, hidden) in enumerate(plan):
        cylinder, valve = rig.split(":")
        forms = {h: draw_form(h, cylinder, rng) for h in hidden}
        cases.append(check_case(f"c{i:02d}_{cylinder}_{valve}_{'+'.join(hidden) or 'none'}",
                                rig, hidden, forms, rng))
    return cases


def _fitted(root: Path, name: str) -> str:
    """The named effect's fitted ratios and index from the case's discovery.json."""
    got = fitted_effect(root, name, "critical_ratio")
    if got is None:
        return "-"
    p = got[1]
    b_in = p.get("inlet_critical_ratio", p.get("critical_ratio"))
    b_ex = p.get("exhaust_critical_ratio", p.get("critical_ratio"))
    return f"{b_in:.3f}, {b_ex:.3f}, {p.get('subsonic_index', 0.5):.3f}"


def _planted(r: dict) -> str:
    iso = r["forms"].get("critical_ratio")
    return f"{iso['critical_pressure_ratio']:.3f}, {iso['subsonic_index']:.3f}" if iso else "-"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out")
    ap.add_argument("--seed", type=int, required=True, help="the draw's seed (record it)")
    ap.add_argument("--list", action="store_true", help="print the cases and stop")
    args = ap.parse_args(argv)
    cases = draw_cases(args.seed)
    root = results_root(ap, args, cases, _public)
    if root is None:
        return 0
    results = run_check(cases, root)
    print(check_summary(root, f"critical_ratio blind check, seed {args.seed}",
                        ("planted (b, m)", "fitted (b in, b out, m)"), results, _planted,
                        _fitted))
    return 0


if __name__ == "__main__":
    sys.exit(main())
