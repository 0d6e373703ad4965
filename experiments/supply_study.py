"""Measured against nominal supply pressure (paper section IV-F; studies
``experiments/studies/supply_measured.toml`` and ``supply_nominal.toml``).

    python experiments/supply_study.py [--out results/paper] [--smoke]

Data from a regulator that droops under flow; the paper's model with the supply term,
fitted and scored once with the measured supply column and once with the nominal
supply only. Writes OUT/supply_study.json and OUT/figures/supply_study.png.
"""

from __future__ import annotations

import sys

from paper_common import bars_against_noise, find, ok_cells, parser, run_named_study, save


def main(argv=None) -> int:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    docs = {f"supply_{k}": run_named_study(f"supply_{k}", args)
            for k in ("measured", "nominal")}
    table = []
    for c in ok_cells(docs["supply_measured"]):
        ax_ = c["cell"]
        other = find(ok_cells(docs["supply_nominal"]), cylinder=ax_["cylinder"],
                     seed=ax_["seed"])
        if other is None:
            continue
        table.append({"cylinder": ax_["cylinder"], "seed": ax_["seed"],
                      "measured_rmse_Pa": c["metrics"]["rmse_Pa"],
                      "nominal_rmse_Pa": other["metrics"]["rmse_Pa"],
                      "measured_percent": c["metrics"]["rmse_percent_of_range"],
                      "nominal_percent": other["metrics"]["rmse_percent_of_range"],
                      "noise_floor_Pa": c["metrics"]["noise_floor_Pa"],
                      "supply_gain_measured": c["model"]["parameters"].get("supply_gain"),
                      "cells": [c["id"], other["id"]]})
    path = bars_against_noise(args, "supply_study", table,
                              (("nominal_rmse_Pa", "nominal supply"),
                               ("measured_rmse_Pa", "measured supply")),
                              "Measured against nominal supply pressure")
    save(args, "supply_study", {"rows": table}, docs, [path])
    for r in table:
        print(r)
    return 0 if all(d["counts"]["error"] == 0 for d in docs.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
