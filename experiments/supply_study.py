"""Measured against nominal supply pressure (paper section IV-F; studies
``experiments/studies/supply_measured.toml`` and ``supply_nominal.toml``).

    python experiments/supply_study.py [--out results/paper] [--smoke]

Data from a regulator that droops under flow; the paper's model with the supply term,
fitted and scored once with the measured supply column and once with the nominal
supply only. Writes OUT/supply_study.json and OUT/figures/supply_study.png.
"""

from __future__ import annotations

import sys

import numpy as np
from paper_common import PAPER_NAME, figure_path, find, ok_cells, parser, run_named_study, save


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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.arange(len(table))
    ax.bar(x - 0.2, [r["nominal_rmse_Pa"] / 1e3 for r in table], 0.4, label="nominal supply")
    ax.bar(x + 0.2, [r["measured_rmse_Pa"] / 1e3 for r in table], 0.4,
           label="measured supply")
    ax.plot(x, [r["noise_floor_Pa"] / 1e3 for r in table], "k_", markersize=30,
            label="noise floor")
    ax.set_xticks(x, [f"{PAPER_NAME[r['cylinder']]} s{r['seed']}" for r in table])
    ax.set_ylabel("2-s RMSE (kPa)")
    ax.set_title("Measured against nominal supply pressure")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = figure_path(args, "supply_study")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    save(args, "supply_study", {"rows": table}, docs, [path])
    for r in table:
        print(r)
    return 0 if all(d["counts"]["error"] == 0 for d in docs.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
