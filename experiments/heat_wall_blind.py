"""A blind check of ``heat_transfer``'s wall offset: chambers whose wall is warmer or
colder than the supply's air, on rigs and at values the option was not developed on,
run once and reported once.

    python experiments/heat_wall_blind.py --list --seed S
    python experiments/heat_wall_blind.py --out results/heat_wall_blind --seed S

The option was written beside two development cases (AIR200 / valve 1, a wall 20 K
above the supply, h = 30 W/(m^2 K); SMC / valve 2, 10 K below, h = 50; seed 5). This
set draws from ``--seed`` (record it; draw it from the clock before looking): four
single cases on other rigs, the bench's ``WallHeatTransfer`` with h in 10-120 W/(m^2 K)
and the wall 5-25 K (log-uniform) above or below the supply; a pair beside a spool lag;
a control with the wall at the supply's temperature (heat named, the offset expected
near 0 or not chosen); a null control. Each runs the bench's six 20-s recordings and
``pneubayes discover`` from the plain model (``blind_study.run_case``); cases are cached
in OUT/cases/NAME.json (a stopped run resumes), the table written to OUT/summary.md
with the seed and git revision.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from blind_study import _public, check_case, check_summary, draw_form, fitted_effect, run_check
from discovery_study import results_root

from pneubayes.bench.forms import WallHeatTransfer
from pneubayes.physics.gas import GasConstants

#: The rigs of the singles: not the development cases' AIR200 / valve 1, SMC / valve 2.
SINGLE_RIGS = ("AIR37:valve2", "SMC:valve1", "PRN:valve1", "AIR200:valve2")
PAIR_RIG = "PRN:valve2"
CONTROL_RIGS = ("AIR37:valve1", "SMC:valve2")


def _wall(rng, offset: bool) -> WallHeatTransfer:
    h = math.exp(rng.uniform(math.log(10.0), math.log(120.0)))
    t_s = GasConstants().temperature_K
    if not offset:
        return WallHeatTransfer(h_W_per_m2_K=h)
    size = math.exp(rng.uniform(math.log(5.0), math.log(25.0)))
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    return WallHeatTransfer(h_W_per_m2_K=h, wall_temperature_K=t_s + sign * size)


def draw_cases(seed: int) -> list[dict]:
    """The set's cases (each a rig, the planted forms and a bench seed)."""
    rng = np.random.default_rng(seed)
    plan = ([(r, ("heat_transfer",), True) for r in SINGLE_RIGS]
            + [(PAIR_RIG, ("heat_transfer", "spool_lag"), True),
               (CONTROL_RIGS[0], ("heat_transfer",), False), (CONTROL_RIGS[1], (), False)])
    cases = []
    for i, (rig, hidden, offset) in enumerate(plan):
        cylinder, valve = rig.split(":")
        forms = {h: (_wall(rng, offset) if h == "heat_transfer" else draw_form(h, cylinder, rng))
                 for h in hidden}
        tag = ("+".join(hidden) or "none") + ("-nowall" if hidden and not offset else "")
        cases.append(check_case(f"h{i:02d}_{cylinder}_{valve}_{tag}", rig, hidden, forms, rng))
    return cases


def _fitted(root: Path, name: str) -> str:
    """The named heat exchange's form, coefficient and wall offset."""
    got = fitted_effect(root, name, "heat_transfer")
    if got is None:
        return "-"
    options, p = got
    strength = p.get("heat_transfer_coefficient_W_per_m2_K", p.get("heat_transfer_rate_per_s"))
    off = p.get("heat_transfer_wall_offset_K")
    return (f"{options.get('form', '-')}, {strength:.1f}, "
            f"{'-' if off is None else f'{off:+.2f} K'}")


def _planted(r: dict) -> str:
    f = r["forms"].get("heat_transfer")
    if not f:
        return "-"
    t_w = f.get("wall_temperature_K")
    off = 0.0 if t_w is None else t_w - GasConstants().temperature_K
    return f"h {f['h_W_per_m2_K']:.1f}, {off:+.2f} K"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out")
    ap.add_argument("--seed", type=int, required=True, help="the draw's seed (record it)")
    ap.add_argument("--list", action="store_true", help="print the cases and stop")
    ap.add_argument("--case", action="append", default=[],
                    help="run only this case (name prefix; repeatable)")
    args = ap.parse_args(argv)
    cases = draw_cases(args.seed)
    root = results_root(ap, args, cases, _public)
    if root is None:
        return 0
    if args.case:
        cases = [c for c in cases if any(c["name"].startswith(k) for k in args.case)]
    results = run_check(cases, root)
    print(check_summary(root, f"heat_transfer wall-offset blind check, seed {args.seed}",
                        ("planted (h W/(m^2 K), wall - supply)", "fitted (form, h, offset)"),
                        results, _planted, _fitted))
    return 0


if __name__ == "__main__":
    sys.exit(main())
