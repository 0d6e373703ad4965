"""Write the paper's rigs (Table I cylinders x Table II valves) as rig cards in
``data/rigs/`` (``<cylinder>-<valve>.rig.json``; the valve's maps as priors, fitted).

    python experiments/make_paper_rig_cards.py
"""

from __future__ import annotations

import sys
from pathlib import Path

from pneubayes.atomic import write_json_atomic
from pneubayes.physics.cylinder import CYLINDERS
from pneubayes.physics.valve import VALVES
from pneubayes.rigcard.paper import paper_rig_card

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    out = ROOT / "data" / "rigs"
    for cyl in sorted(CYLINDERS):
        for valve in sorted(VALVES):
            path = out / f"{cyl}-{valve}.rig.json"
            write_json_atomic(path, paper_rig_card(cyl, valve).to_dict())
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
