"""Table III reproduced: 2-s prediction RMSE on SMC, PRN, AR37 and AR200 bench rigs that
carry realistic unmodelled effects (study ``experiments/studies/table3.toml``).

    python experiments/table3.py [--out results/paper] [--smoke] [--workers 2]

Columns: the paper's numbers; ours with the paper's model (thin port + orifice leak +
measured supply, fitted by the paper's least squares and 2-s multiple shooting); ours
after the discovery loop (which effects it named); the noise floor. A second table
summarises discovery per rig over the seeds (issue 22): which planted effects it named
and which it named that were not planted, the gap it closed between the plain thin-port
model and the noise floor, and its final error against the noise floor (median and
range over seeds), all on the held-out evaluation recordings. Writes OUT/table3.json
and OUT/table3.md.
"""

from __future__ import annotations

import sys

import numpy as np
from paper_common import (
    PAPER_NAME,
    PAPER_TABLE3,
    find,
    ok_cells,
    parser,
    run_named_study,
    save,
)

from pneubayes.atomic import write_text_atomic

PAPER_MODEL = "cylinder_leak+supply_fluctuation"


def rows(doc: dict) -> list[dict]:
    cells = ok_cells(doc)
    out = []
    for cyl in ("SMC", "PRN", "AIR37", "AIR200"):
        for seed in doc["seeds"]:
            paper = find(cells, cylinder=cyl, model=PAPER_MODEL, seed=seed)
            disc = find(cells, cylinder=cyl, model="discover", seed=seed)
            plain = find(cells, cylinder=cyl, model="plain", seed=seed)
            if paper is None and disc is None:
                continue
            ref = paper or disc
            row = {"cylinder": cyl, "paper_name": PAPER_NAME[cyl], "seed": seed,
                   "valve": ref["cell"]["valve"],
                   "paper_rmse_Pa": PAPER_TABLE3[cyl][0],
                   "paper_percent": PAPER_TABLE3[cyl][1],
                   "noise_floor_Pa": ref["metrics"]["noise_floor_Pa"],
                   "working_range_Pa": ref["metrics"]["working_range_Pa"]}
            if paper:
                row.update(ours_paper_model_rmse_Pa=paper["metrics"]["rmse_Pa"],
                           ours_paper_model_percent=paper["metrics"]["rmse_percent_of_range"],
                           paper_model_cell=paper["id"])
            if plain:
                row["ours_plain_rmse_Pa"] = plain["metrics"]["rmse_Pa"]
            if disc:
                row["planted"] = list(disc["cell"]["data_effects"])
                row.update(ours_discovery_rmse_Pa=disc["metrics"]["rmse_Pa"],
                           ours_discovery_percent=disc["metrics"]["rmse_percent_of_range"],
                           discovered=disc["fit"].get("discovered", []),
                           discovery_cell=disc["id"],
                           discovery_revision=str((disc.get("provenance") or {})
                                                  .get("git_revision") or "")[:7],
                           discovery_rekeyed=disc.get("rekeyed"))
            out.append(row)
    return out


def discovery_summary(table: list[dict]) -> list[dict]:
    """Per rig over its seeds: planted effects named (count and which), effects named
    that were not planted, gap shrink ``(plain - discovered) / (plain - noise)`` and
    ``discovered / noise`` on the evaluation recordings (median, min, max)."""
    out = []
    for cyl in dict.fromkeys(r["cylinder"] for r in table):
        rs = [r for r in table if r["cylinder"] == cyl
              and r.get("ours_discovery_rmse_Pa") is not None]
        if not rs:
            continue
        named = [len(set(r["discovered"]) & set(r["planted"])) for r in rs]
        extra = sorted({e for r in rs for e in r["discovered"] if e not in r["planted"]})
        shrink = [(r["ours_plain_rmse_Pa"] - r["ours_discovery_rmse_Pa"])
                  / (r["ours_plain_rmse_Pa"] - r["noise_floor_Pa"]) for r in rs
                  if r.get("ours_plain_rmse_Pa", 0.0) > r["noise_floor_Pa"]]
        ratio = [r["ours_discovery_rmse_Pa"] / r["noise_floor_Pa"] for r in rs]

        def spread(v):
            return ({"median": float(np.median(v)), "min": float(min(v)),
                     "max": float(max(v))} if v else None)

        out.append({"cylinder": cyl, "paper_name": rs[0]["paper_name"],
                    "seeds": [r["seed"] for r in rs], "planted": rs[0]["planted"],
                    "planted_named_mean": float(np.mean(named)), "planted_named": named,
                    "named_per_seed": [r["discovered"] for r in rs],
                    "not_planted_named": extra, "gap_shrink": spread(shrink),
                    "final_over_noise": spread(ratio)})
    return out


def summary_markdown(summary: list[dict]) -> str:
    def sp(d, scale, fmt):
        if d is None:
            return "n/a"
        return (f"{fmt.format(scale * d['median'])} [{fmt.format(scale * d['min'])}, "
                f"{fmt.format(scale * d['max'])}]")

    lines = ["| cylinder | seeds | planted effects named (mean of 4) | named per seed | "
             "named, not planted | gap shrink, median [range] | final / noise floor, "
             "median [range] |", "|---|---|---|---|---|---|---|"]
    for r in summary:
        per = "; ".join(", ".join(n) or "none" for n in r["named_per_seed"])
        lines.append(
            f"| {r['paper_name']} | {len(r['seeds'])} | {r['planted_named_mean']:.2f} | "
            f"{per} | {', '.join(r['not_planted_named']) or 'none'} | "
            f"{sp(r['gap_shrink'], 100, '{:.0f}')} % | "
            f"{sp(r['final_over_noise'], 1, '{:.2f}')} |")
    return "\n".join(lines) + "\n"


def revision_markdown(table: list[dict]) -> str:
    """Which revision computed each discovery cell, and the cells carried over from an
    earlier cell id (``rekeyed``: computed before a settings change that provably does
    not alter them), with the reason each gives."""
    by_rev: dict[str, list[str]] = {}
    for r in table:
        if r.get("ours_discovery_rmse_Pa") is None:
            continue
        by_rev.setdefault(r.get("discovery_revision") or "unknown", []).append(
            f"{r['paper_name']} seed {r['seed']}")
    if not by_rev:
        return ""
    text = "Discovery cells by the git revision that computed them: " + "; ".join(
        f"`{rev}`: {', '.join(cells)}" for rev, cells in by_rev.items()) + "."
    moved = [r for r in table if r.get("discovery_rekeyed")]
    if moved:
        text += " Carried over from an earlier cell id: " + "; ".join(
            f"{r['paper_name']} seed {r['seed']} ({r['discovery_rekeyed']['why']})"
            for r in moved) + "."
    return text + "\n"


def markdown(table: list[dict]) -> str:
    def f(row, key, fmt):
        v = row.get(key)
        return "n/a" if v is None else fmt.format(v)

    lines = ["| cylinder | paper RMSE (Pa) | paper % | ours, paper's model (Pa) | % | "
             "ours, after discovery (Pa) | % | effects named | noise floor (Pa) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in table:
        lines.append(
            f"| {r['paper_name']} ({r['valve']}, seed {r['seed']}) | {r['paper_rmse_Pa']:.4g} | "
            f"{r['paper_percent']:.3g} | {f(r, 'ours_paper_model_rmse_Pa', '{:.0f}')} | "
            f"{f(r, 'ours_paper_model_percent', '{:.2f}')} | "
            f"{f(r, 'ours_discovery_rmse_Pa', '{:.0f}')} | "
            f"{f(r, 'ours_discovery_percent', '{:.2f}')} | "
            f"{', '.join(r.get('discovered', [])) or 'none'} | {r['noise_floor_Pa']:.0f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    args = parser(__doc__.splitlines()[0]).parse_args(argv)
    doc = run_named_study("table3", args)
    table = rows(doc)
    summary = discovery_summary(table)
    md = markdown(table)
    md_summary = summary_markdown(summary)
    revisions = revision_markdown(table)
    if revisions:
        md_summary += "\n" + revisions
    save(args, "table3", {"rows": table, "markdown": md, "discovery_summary": summary,
                          "discovery_markdown": md_summary}, {"table3": doc})
    from pathlib import Path

    write_text_atomic(Path(args.out) / ("table3" + ("-smoke" if args.smoke else "") + ".md"),
                      md + "\n" + md_summary)
    print(md + "\n" + md_summary)
    return 0 if doc["counts"]["error"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
