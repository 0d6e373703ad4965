"""Fig. 11 reproduced: the effect of chamber volume and of cylinder leakage on the 2-s
prediction error (the Table III cells, ``experiments/studies/table3.toml``).

    python experiments/fig11_volume.py [--out results/paper] [--smoke]

(a) the four cylinders' error (% of range) against their swept volume, the paper's
Table III beside ours with the paper's model and after discovery; the Airpels carry
the realistic clearance leak at full strength, SMC and PRN at 5 % (Table I: "high" and
"low leak"). (b) SMC against PRN (large against small volume, both low leak). Writes
OUT/fig11_volume.json and OUT/figures/fig11_volume.png.
"""

from __future__ import annotations

import sys

import numpy as np
from paper_common import (
    PAPER_NAME,
    PAPER_TABLE3,
    parser,
    pyplot,
    run_named_study,
    save,
    save_figure,
)
from table3 import rows

from pneubayes.physics.cylinder import cylinder_preset

LEAK = {"AIR37": "high", "AIR200": "high", "SMC": "low", "PRN": "low"}


def main(argv=None) -> int:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    doc = run_named_study("table3", args)
    table = rows(doc)
    for r in table:
        r["swept_volume_m3"] = cylinder_preset(r["cylinder"]).swept_volume_m3
        r["leak"] = LEAK[r["cylinder"]]
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    for key, label, marker in (("paper_percent", "paper (Table III)", "s"),
                               ("ours_paper_model_percent", "ours, paper's model", "o"),
                               ("ours_discovery_percent", "ours, after discovery", "^")):
        pts = [(r["swept_volume_m3"], r.get(key), r) for r in table if r.get(key) is not None]
        if not pts:
            continue
        ax.scatter([p[0] * 1e6 for p in pts], [p[1] for p in pts], marker=marker, label=label)
        if key == "paper_percent":
            for v, y, r in pts:
                ax.annotate(PAPER_NAME[r["cylinder"]], (v * 1e6, y), fontsize=8,
                            xytext=(4, 2), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_xlabel("swept volume (cm$^3$)")
    ax.set_ylabel("2-s RMSE (% of working range)")
    ax.set_title("(a) four cylinders (Airpels: high leak)")
    ax.legend(fontsize=8)
    sub = [r for r in table if r["cylinder"] in ("SMC", "PRN")]
    x = np.arange(len(sub))
    w = 0.27
    for i, (key, label) in enumerate((("paper_percent", "paper"),
                                      ("ours_paper_model_percent", "ours, paper's model"),
                                      ("ours_discovery_percent", "ours, after discovery"))):
        bx.bar(x + (i - 1) * w, [r.get(key) or 0.0 for r in sub], w, label=label)
    bx.set_xticks(x, [f"{PAPER_NAME[r['cylinder']]}\n{r['swept_volume_m3'] * 1e6:.1f} cm$^3$"
                      for r in sub])
    bx.set_ylabel("2-s RMSE (% of working range)")
    bx.set_title("(b) SMC against PRN")
    bx.legend(fontsize=8)
    path = save_figure(args, fig, "fig11_volume")
    numbers = {"rows": [{k: r.get(k) for k in (
        "cylinder", "seed", "swept_volume_m3", "leak", "paper_percent",
        "ours_paper_model_percent", "ours_discovery_percent", "noise_floor_Pa")}
        for r in table], "paper_table3": PAPER_TABLE3}
    save(args, "fig11_volume", numbers, {"table3": doc}, [path])
    for r in numbers["rows"]:
        print(r)
    return 0 if doc["counts"]["error"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
