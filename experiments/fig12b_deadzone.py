"""Figs. 12b and 13 reproduced: the error for commands within +-0.1 V against +-3 V
(study ``experiments/studies/deadzone.toml``).

    python experiments/fig12b_deadzone.py [--out results/paper] [--smoke]

Data with a rounded valve dead zone; the paper's model (Gompertz maps only) against
the model with the catalogue's ``valve_deadzone``; each fitted once (fixed volume,
+-5 and +-0.5 V) and scored on held-out fixed-volume recordings driven at +-0.1 V and at
+-3 V. Writes OUT/fig12b_deadzone.json and OUT/figures/fig12b_deadzone.png.
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

MODELS = {"cylinder_leak": "paper's model", "cylinder_leak+valve_deadzone": "+ valve_deadzone"}


def main(argv=None) -> int:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    doc = run_named_study("deadzone", args)
    cells = ok_cells(doc)
    table = []
    for c in cells:
        ax_ = c["cell"]
        table.append({"cylinder": ax_["cylinder"], "seed": ax_["seed"], "model": ax_["model"],
                      "command_range_V": ax_["command_range_V"],
                      "rmse_Pa": c["metrics"]["rmse_Pa"],
                      "rmse_percent": c["metrics"]["rmse_percent_of_range"],
                      "noise_floor_Pa": c["metrics"]["noise_floor_Pa"],
                      "deadzone_halfwidth_V": c["model"]["parameters"].get(
                          "deadzone_halfwidth_V"), "cell": c["id"]})
    plt = pyplot()
    rigs = sorted({(r["cylinder"], r["seed"]) for r in table})
    fig, axes = plt.subplots(1, max(1, len(rigs)), figsize=(5 * max(1, len(rigs)), 4),
                             squeeze=False)
    for ax, (cyl, seed) in zip(axes[0], rigs):
        x = np.arange(len(MODELS))
        for j, (rng, color) in enumerate(((0.1, "tab:red"), (3.0, "tab:blue"))):
            vals = []
            for m in MODELS:
                hit = find(cells, cylinder=cyl, seed=seed, model=m, command_range_V=rng)
                vals.append(np.nan if hit is None else hit["metrics"]["rmse_percent_of_range"])
            ax.bar(x + (j - 0.5) * 0.38, vals, 0.38, color=color, label=f"commands +-{rng:g} V")
        ax.set_xticks(x, list(MODELS.values()))
        ax.set_ylabel("2-s RMSE (% of working range)")
        ax.set_title(f"{PAPER_NAME[cyl]}, seed {seed}")
        ax.legend(fontsize=8)
    fig.suptitle("Figs. 12b/13: error near the valve dead zone")
    path = save_figure(args, fig, "fig12b_deadzone")
    save(args, "fig12b_deadzone", {"rows": table}, {"deadzone": doc}, [path])
    for r in table:
        print(r)
    return 0 if doc["counts"]["error"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
