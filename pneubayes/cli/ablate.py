"""``pneubayes ablate``: an ablation study's cells, cached and resumable."""

from __future__ import annotations

import sys

from pneubayes.errors import PneubayesError
from pneubayes.run_folder import open_run_folder


def cmd_ablate(args) -> int:
    from pneubayes.ablation.executor import DaskExecutor, LocalExecutor
    from pneubayes.ablation.runner import run_study
    from pneubayes.ablation.study import load_study

    study = load_study(args.study)
    if args.smoke:
        study = study.smoke()
    if args.scheduler and args.workers is not None:
        raise PneubayesError("--workers: not with --scheduler (the Dask cluster has its own "
                             "workers)")
    if args.dry_run:
        for cell in study.cells():
            print(cell.id)
        print(f"{args.study}: valid; {study.n_cells} cell(s) (nothing run)")
        return 0
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    folder = open_run_folder(args.out, "ablate", {"study": study.to_dict()},
                             overwrite=args.overwrite, resume=args.resume,
                             outputs=("results.json", "results.csv", "cells", "work"),
                             argv=args.argv)
    if folder.resumed:
        log(f"ablate: resuming the study in {args.out}")
    try:
        executor = (DaskExecutor(args.scheduler) if args.scheduler
                    else LocalExecutor(args.workers or 1))
    except (ImportError, OSError) as exc:
        raise PneubayesError(f"--scheduler {args.scheduler}: {exc}") from None
    except (MemoryError, ValueError, RuntimeError) as exc:  # a scheduler that does not answer
        raise PneubayesError(f"--scheduler {args.scheduler}: no Dask scheduler answers "
                             f"there ({type(exc).__name__}: {exc})") from None
    # SIGINT or SIGTERM (a batch system's stop) ends the study between cells: running
    # cells are cancelled (local worker processes ended), finished ones are on disk
    with executor:
        doc = run_study(study, args.out, executor, progress=not args.quiet, log=log,
                        keep_work=args.keep_work)
    folder.record("results.json", "results.csv")
    c = doc["counts"]
    print(f"{args.out}/results.json  ({c['cells']} cells: {c['ok']} ok, {c['error']} failed; "
          f"{c['run_now']} run now, {c['cached']} cached)")
    print(f"{args.out}/results.csv")
    return 1 if c["error"] else 0
