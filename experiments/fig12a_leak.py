"""Fig. 12a reproduced: modelling the cylinder leak reduces the error (the Table III
cells, ``experiments/studies/table3.toml``).

    python experiments/fig12a_leak.py [--out results/paper] [--smoke]

The paper's model with and without its orifice leak (both with the measured supply),
fitted to the same data, on every rig. The data's leak is a clearance gap
(pneubayes.bench.forms.ClearanceLeak), a different law from the model's orifice.
Writes OUT/fig12a_leak.json and OUT/figures/fig12a_leak.png.
"""

from __future__ import annotations

import sys

from paper_common import bars_against_noise, find, ok_cells, parser, run_named_study, save

WITH, WITHOUT = "cylinder_leak+supply_fluctuation", "supply_fluctuation"


def main(argv=None) -> int:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    doc = run_named_study("table3", args)
    cells = ok_cells(doc)
    table = []
    for cyl in ("AIR37", "AIR200", "SMC", "PRN"):
        for seed in doc["seeds"]:
            a, b = (find(cells, cylinder=cyl, model=m, seed=seed) for m in (WITHOUT, WITH))
            if a is None or b is None:
                continue
            table.append({"cylinder": cyl, "seed": seed,
                          "without_leak_rmse_Pa": a["metrics"]["rmse_Pa"],
                          "with_leak_rmse_Pa": b["metrics"]["rmse_Pa"],
                          "without_leak_percent": a["metrics"]["rmse_percent_of_range"],
                          "with_leak_percent": b["metrics"]["rmse_percent_of_range"],
                          "reduction_percent": 100 * (1 - b["metrics"]["rmse_Pa"]
                                                      / a["metrics"]["rmse_Pa"]),
                          "noise_floor_Pa": b["metrics"]["noise_floor_Pa"],
                          "cells": [a["id"], b["id"]]})
    path = bars_against_noise(args, "fig12a_leak", table,
                              (("without_leak_rmse_Pa", "without leak"),
                               ("with_leak_rmse_Pa", "with the orifice leak")),
                              "Fig. 12a: modelling the leak")
    save(args, "fig12a_leak", {"rows": table}, {"table3": doc}, [path])
    for r in table:
        print(r)
    return 0 if doc["counts"]["error"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
