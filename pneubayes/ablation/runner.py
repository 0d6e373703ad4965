"""Run a study: every cell through an executor, each result cached on disk.

``OUT/cells/<cell id>.json`` holds one cell's result, written atomically as soon as the
cell finishes, so an interrupted study (Ctrl-C, a killed job) loses only the cells that
were running. Running the study again into the same ``OUT`` skips the cells already
cached with status ``"ok"`` and *retries* the failed ones (status ``"error"``, with
their error and traceback). A changed setting changes the cell ids (their hash), so
stale results are never reused; they stay in ``OUT/cells`` but are not reported.

When every cell has been visited, ``OUT/results.json`` (format ``pneubayes-ablation/1``:
the study with its TOML text, settings and seeds, provenance, and every cell's result
in grid order) and ``OUT/results.csv`` (one row per cell, flat columns) are written.
Each cell's own working files (bench recordings, fit run folder) are in
``OUT/work/<cell id>``, removed after a successful cell unless ``keep_work``.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from pneubayes import interrupt
from pneubayes.ablation.cell import run_cell
from pneubayes.ablation.executor import Executor, LocalExecutor
from pneubayes.ablation.study import Cell, Study
from pneubayes.atomic import json_safe, write_json_atomic, write_text_atomic
from pneubayes.provenance import provenance

FORMAT = "pneubayes-ablation/1"


def execute_cell(cell_fn: Callable, cell: Cell, workdir, keep_work: bool = False) -> dict:
    """Run ``cell_fn(cell, workdir)`` where the executor put it; never raises ``Exception``.

    A failure becomes ``{"status": "error", "error": ..., "traceback": ...}``. The
    result gets the cell's id, axes, settings, wall time (s) and provenance.
    """
    t0 = time.perf_counter()
    work = Path(workdir)
    try:
        res = dict(cell_fn(cell, work))
        res.setdefault("status", "ok")
        json.dumps(json_safe(res), allow_nan=False)
    except Exception as exc:  # a failed cell is recorded and the study goes on
        res = {"status": "error", "error": f"{type(exc).__name__}: {exc}",
               "traceback": traceback.format_exc()}
    else:
        if not keep_work:
            shutil.rmtree(work, ignore_errors=True)
    out = {"id": cell.id, "status": res.pop("status"), "cell": cell.axes(), **res}
    out["id"] = cell.id
    out.setdefault("wall_time_s", time.perf_counter() - t0)
    out["settings"] = cell.settings.to_dict()
    out["provenance"] = provenance()
    return json_safe(out)


def _error_result(cell: Cell, exc: BaseException) -> dict:
    """The result of a cell whose task failed outside ``execute_cell`` (a lost worker)."""
    return json_safe({"id": cell.id, "status": "error", "cell": cell.axes(),
                      "error": f"{type(exc).__name__}: {exc}",
                      "traceback": "".join(traceback.format_exception(exc)),
                      "settings": cell.settings.to_dict()})


def _cached(path: Path, log) -> dict | None:
    if not path.exists():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        log(f"{path}: unreadable cached result ({exc}); running the cell again")
        return None
    return doc if isinstance(doc, dict) else None


def _save_finished(pending, results: dict, record) -> None:
    """On an interrupt, keep the cells that finished but were not yet collected."""
    for f, c in pending:
        if c.id in results or not f.done():
            continue
        try:
            if f.cancelled():
                continue
            res = f.result()
        except Exception:  # nothing to keep from a failed or lost task
            continue
        if isinstance(res, dict) and res.get("status") == "ok":
            record(c, res)


def _describe(res: dict) -> str:
    if res.get("status") != "ok":
        return f"ERROR {res.get('error', '')}".strip()
    m = res.get("metrics") or {}
    text = "ok"
    if m.get("rmse_Pa") is not None:
        text += f", held-out RMSE {m['rmse_Pa']:.0f} Pa"
        if m.get("rmse_percent_of_range") is not None:
            text += f" ({m['rmse_percent_of_range']:.2f} % of range)"
        if m.get("noise_floor_Pa") is not None:
            text += f", noise {m['noise_floor_Pa']:.0f} Pa"
    if res.get("wall_time_s") is not None:
        text += f", {res['wall_time_s']:.0f} s"
    return text


def run_study(study: Study, out_dir, executor: Executor | None = None, progress: bool = True,
              log: Callable[[str], None] = print, cell_fn: Callable = run_cell,
              keep_work: bool = False) -> dict:
    """Run (or resume) ``study`` into ``out_dir``; return the ``results.json`` document.

    ``executor`` defaults to ``LocalExecutor(1)`` (in-process) and is then shut down
    here; one passed in is left to its owner. ``cell_fn(cell, workdir) -> dict`` is the
    work of one cell (:func:`~pneubayes.ablation.cell.run_cell`); with a process or Dask
    executor it must be a picklable module-level function. A ``KeyboardInterrupt``
    propagates after the finished cells are on disk.
    """
    out = Path(out_dir)
    cells_dir, work_dir = out / "cells", out / "work"
    t0 = time.perf_counter()
    cells_dir.mkdir(parents=True, exist_ok=True)
    cells = study.cells()
    results: dict[str, dict] = {}
    todo = []
    for c in cells:
        doc = _cached(cells_dir / f"{c.id}.json", log)
        if doc is not None and doc.get("status") == "ok":
            results[c.id] = doc
        else:
            todo.append(c)
    retried = sum((cells_dir / f"{c.id}.json").exists() for c in todo)
    log(f"study {study.name!r}: {len(cells)} cell(s); {len(results)} cached, "
        f"{len(todo)} to run" + (f" ({retried} failed before, retried)" if retried else ""))
    own = executor is None
    if own:
        executor = LocalExecutor(1)
    from tqdm import tqdm

    bar = tqdm(total=len(cells), initial=len(results), unit="cell", disable=not progress,
               desc=study.name, dynamic_ncols=True)

    def say(message: str) -> None:
        if progress:
            with tqdm.external_write_mode():
                log(message)
        else:
            log(message)

    ran = 0
    pending: list = []

    def record(c: Cell, res: dict) -> None:
        nonlocal ran
        write_json_atomic(cells_dir / f"{c.id}.json", res)
        results[c.id] = res
        ran += 1
        bar.update(1)
        say(f"{c.id}: {_describe(res)}")

    failed_exc: BaseException | None = None
    try:
        pending = [(executor.submit(execute_cell, cell_fn, c, str(work_dir / c.id),
                                    keep_work), c) for c in todo]
        by_future = {id(f): c for f, c in pending}
        for f in executor.as_completed([f for f, _ in pending]):
            c = by_future[id(f)]
            try:
                res = f.result()
            except Exception as exc:  # the executor lost the task (e.g. a worker died)
                res = _error_result(c, exc)
            record(c, res)
            interrupt.check()  # between cells (the in-process executor runs them here)
    except BaseException as exc:
        failed_exc = exc
        if isinstance(exc, KeyboardInterrupt):
            _save_finished(pending, results, record)
            say(f"interrupted: {len(results)} of {len(cells)} cell(s) are cached in "
                f"{cells_dir}; run the study again to resume")
        raise
    finally:
        bar.close()
        if own:
            executor.shutdown(cancel=failed_exc is not None)
    if work_dir.is_dir() and not any(work_dir.iterdir()):
        work_dir.rmdir()
    ordered = [results[c.id] for c in cells]
    n_ok = sum(r.get("status") == "ok" for r in ordered)
    doc = {"format": FORMAT, "study": study.to_dict(),
           "seeds": list(study.grid.seeds), "settings": study.settings.to_dict(),
           "counts": {"cells": len(cells), "ok": n_ok, "error": len(cells) - n_ok,
                      "run_now": ran, "cached": len(cells) - ran},
           "cells": ordered, "provenance": provenance(),
           "wall_time_s": time.perf_counter() - t0}
    write_json_atomic(out / "results.json", doc)
    write_text_atomic(out / "results.csv", results_csv(ordered))
    log(f"{out / 'results.json'}: {n_ok} ok, {len(cells) - n_ok} failed"
        + (" (run again to retry the failed cells)" if n_ok < len(cells) else ""))
    return doc


def _scalar(v):
    if v is None:
        return ""
    if isinstance(v, (list, tuple)):
        return "+".join(str(x) for x in v)
    if isinstance(v, dict):
        return json.dumps(v, sort_keys=True)
    return v


def flat_row(result: dict) -> dict:
    """One CSV row of a cell result: id, status, axes, metrics, fit, ``param.NAME``."""
    row = {"id": result.get("id"), "status": result.get("status")}
    for k, v in (result.get("cell") or {}).items():
        if k not in ("model_effects", "discover"):  # "model" names them
            row[k] = _scalar(v)
    for k, v in (result.get("metrics") or {}).items():
        row[k] = _scalar(v)
    model = result.get("model") or {}
    if "effects" in model:
        row["fitted_effects"] = _scalar(model["effects"])
    fit = result.get("fit") or {}
    for k in ("estimate", "discovered", "train_rmse_Pa", "converged", "steps"):
        if k in fit:
            row[f"fit_{k}"] = _scalar(fit[k])
    for k, v in (model.get("parameters") or {}).items():
        row[f"param.{k}"] = _scalar(v)
    row["wall_time_s"] = _scalar(result.get("wall_time_s"))
    row["error"] = result.get("error", "")
    return row


def results_csv(results) -> str:
    """The CSV text of ``results`` (columns: the union of :func:`flat_row` keys)."""
    rows = [flat_row(r) for r in results]
    columns: list[str] = []
    for r in rows:
        columns += [k for k in r if k not in columns]
    tail = ["wall_time_s", "error"]
    columns = [k for k in columns if k not in tail] + tail
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, restval="", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()
