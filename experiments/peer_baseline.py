"""The peer baseline: the Tassa et al. (2013) 10-parameter first-order model fitted on
the same data as ours (the Table III cells, ``experiments/studies/table3.toml``).

    python experiments/peer_baseline.py [--out results/paper] [--smoke]

Both are fitted on the same recordings (fixed volume +-5 and +-0.5 V, two moving-piston
recordings) by least squares on the 2-s window error, and scored on the same held-out
moving-piston recordings. Writes OUT/peer_baseline.json and
OUT/figures/peer_baseline.png.
"""

from __future__ import annotations

import sys

import numpy as np
from paper_common import (
    PAPER_NAME,
    find,
    ok_cells,
    parser,
    pyplot,
    run_named_study,
    save,
    save_figure,
)

COLUMNS = (("tassa", "Tassa et al. 2013"), ("cylinder_leak+supply_fluctuation",
                                             "paper's model"), ("discover", "after discovery"))


def main(argv=None) -> int:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    doc = run_named_study("table3", args)
    cells = ok_cells(doc)
    table = []
    for cyl in ("SMC", "PRN", "AIR37", "AIR200"):
        for seed in doc["seeds"]:
            row = {"cylinder": cyl, "seed": seed}
            for model, _ in COLUMNS:
                c = find(cells, cylinder=cyl, model=model, seed=seed)
                row[f"{model}_rmse_Pa"] = None if c is None else c["metrics"]["rmse_Pa"]
                row[f"{model}_percent"] = (None if c is None
                                           else c["metrics"]["rmse_percent_of_range"])
                if c is not None:
                    row["noise_floor_Pa"] = c["metrics"]["noise_floor_Pa"]
                    if model == "tassa":
                        row["tassa_parameters"] = c["model"]["parameters"]
                        row["tassa_frozen"] = c["fit"].get("frozen")
            if any(row[f"{m}_rmse_Pa"] is not None for m, _ in COLUMNS):
                table.append(row)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(table))
    for i, (model, label) in enumerate(COLUMNS):
        ax.bar(x + (i - 1) * 0.27, [r[f"{model}_percent"] or np.nan for r in table], 0.27,
               label=label)
    ax.set_xticks(x, [f"{PAPER_NAME[r['cylinder']]} s{r['seed']}" for r in table])
    ax.set_yscale("log")
    ax.set_ylabel("2-s RMSE (% of working range)")
    ax.set_title("Peer baseline against the thin-port model")
    ax.legend(fontsize=8)
    path = save_figure(args, fig, "peer_baseline")
    save(args, "peer_baseline", {"rows": table}, {"table3": doc}, [path])
    for r in table:
        print({k: v for k, v in r.items() if k != "tassa_parameters"})
    return 0 if doc["counts"]["error"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
