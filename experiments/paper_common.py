"""Shared plumbing of the paper's study scripts (issue 5): run a study TOML from
``experiments/studies`` through the ablation runner, and save a script's numbers with
their provenance.

Every script takes ``--out`` (default ``results/paper``), ``--smoke`` (one short cell per
study), ``--workers`` (local processes), ``--scheduler`` (a Dask cluster), ``--seeds``
(override the study's seeds) and ``--rigs`` (only some of its rigs). Studies run into
``OUT/studies/NAME`` and are cached per cell, so scripts sharing a study (Table III,
Figs. 11 and 12a, the peer baseline) fit each cell once, and an interrupted run
resumes. Each script writes ``OUT/NAME.json`` (numbers, study configs, seeds, git
revision and package versions) and its figures in ``OUT/figures``;
``experiments/make_paper.py`` assembles ``paper/`` from those files.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from pneubayes.ablation import DaskExecutor, LocalExecutor, load_study, run_study
from pneubayes.atomic import write_json_atomic
from pneubayes.provenance import provenance

STUDIES = Path(__file__).resolve().parent / "studies"

#: Table III of the paper: RMSE (Pa) and percent of the working pressure range.
PAPER_TABLE3 = {"SMC": (1.476e4, 3.2), "PRN": (1.369e4, 3.042), "AIR200": (5.161e4, 11.4),
                "AIR37": (1.370e4, 3.04)}
#: The paper's names of the Airpel cylinders.
PAPER_NAME = {"SMC": "SMC", "PRN": "PRN", "AIR37": "AR37", "AIR200": "AR200"}


def parser(description: str) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--out", default="results/paper", help="results folder (default "
                    "results/paper)")
    ap.add_argument("--smoke", action="store_true", help="one short cell per study")
    ap.add_argument("--workers", type=int, default=2, help="local worker processes")
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address")
    ap.add_argument("--seeds", default=None, help="comma-separated seeds (default: the "
                    "study file's)")
    ap.add_argument("--rigs", default=None, help="comma-separated cylinders or "
                    "CYLINDER:VALVE pairs: run only the study's cells of these rigs (a "
                    "long study split into parts; the cells are cached alike)")
    ap.add_argument("-q", "--quiet", action="store_true")
    return ap


def select_rigs(study, rigs: str):
    """``study`` with only the rigs named in ``rigs`` (comma-separated cylinders, e.g.
    ``AIR37``, or ``CYLINDER:VALVE`` pairs); a name that matches none of the study's rigs
    is an error naming the rigs it has."""
    names = [r.strip() for r in rigs.split(",") if r.strip()]
    have = study.grid.rigs
    keep = []
    for name in names:
        hits = [r for r in have if name in (r[0], f"{r[0]}:{r[1]}")]
        if not hits:
            raise SystemExit(f"--rigs {rigs}: {name!r} is not a rig of study "
                             f"{study.name!r} (it has "
                             f"{', '.join(f'{c}:{v}' for c, v in have)})")
        keep += [r for r in hits if r not in keep]
    return replace(study, grid=replace(study.grid, rigs=tuple(keep)))


def run_named_study(name: str, args) -> dict:
    """Run (or resume) ``studies/NAME.toml``; return its ``results.json`` document."""
    study = load_study(STUDIES / f"{name}.toml")
    if args.seeds:
        seeds = tuple(int(s) for s in args.seeds.split(","))
        study = replace(study, grid=replace(study.grid, seeds=seeds))
    if args.rigs:
        study = select_rigs(study, args.rigs)
    if args.smoke:
        study = study.smoke()
    out = Path(args.out) / "studies" / (name + ("-smoke" if args.smoke else ""))
    executor = (DaskExecutor(args.scheduler) if args.scheduler
                else LocalExecutor(max(1, args.workers)))
    log = (lambda m: None) if args.quiet else print
    with executor:
        return run_study(study, out, executor, progress=not args.quiet, log=log)


def ok_cells(doc: dict) -> list[dict]:
    return [c for c in doc["cells"] if c.get("status") == "ok"]


def find(cells, **axes) -> dict | None:
    """The one cell whose ``cell`` axes match ``axes`` (None if absent)."""
    hits = [c for c in cells if all(c["cell"].get(k) == v for k, v in axes.items())]
    return hits[0] if hits else None


def save(args, name: str, numbers: dict, studies: dict[str, dict], figures=()) -> Path:
    """Write ``OUT/NAME.json``: the numbers with the studies' configs and provenance."""
    out = Path(args.out) / (name + ("-smoke" if args.smoke else "") + ".json")
    doc = {"format": "pneubayes-paper-result/1", "name": name, "smoke": bool(args.smoke),
           "numbers": numbers, "figures": [str(f) for f in figures],
           "studies": {k: {"study": d["study"], "seeds": d["seeds"],
                           "counts": d["counts"], "cell_provenance": d["provenance"]}
                       for k, d in studies.items()},
           "provenance": provenance()}
    write_json_atomic(out, doc)
    return out


def figure_path(args, name: str) -> Path:
    p = Path(args.out) / "figures" / (name + ("-smoke" if args.smoke else "") + ".png")
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def pyplot():
    """matplotlib.pyplot on the file-only Agg backend (scripts run headless)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(args, fig, name: str) -> Path:
    """Write ``fig`` to ``OUT/figures/NAME.png`` and close it; return the path."""
    path = figure_path(args, name)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    pyplot().close(fig)
    return path


def bars_against_noise(args, name: str, table: list[dict], bars: tuple, title: str) -> Path:
    """Two bars per rig (``bars``: ``((key, label), (key, label))``, RMSE in Pa) and the
    noise floor, in kPa; the figure of Fig. 12a and of the supply study."""
    import numpy as np

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.arange(len(table))
    for (key, label), dx in zip(bars, (-0.2, 0.2)):
        ax.bar(x + dx, [r[key] / 1e3 for r in table], 0.4, label=label)
    ax.plot(x, [r["noise_floor_Pa"] / 1e3 for r in table], "k_", markersize=30,
            label="noise floor")
    ax.set_xticks(x, [f"{PAPER_NAME[r['cylinder']]} s{r['seed']}" for r in table])
    ax.set_ylabel("2-s RMSE (kPa)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return save_figure(args, fig, name)
