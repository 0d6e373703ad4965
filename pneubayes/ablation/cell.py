"""One cell of an ablation study: bench data, a fit, held-out 2-s predictions.

:func:`run_cell` makes the cell's bench recordings (:func:`make_data`), fits the cell's
model on the fitting recordings (:func:`fit_model`: ``pneubayes fit`` with the study's
method, the discovery loop from the plain model, or the Tassa peer baseline) and scores
open-loop predictions of ``horizon_s`` started from the measured pressure on the held-out recordings
(:func:`evaluate`, the paper's section-VIII metric, with ``SolverConfig.standard()``).

Data design (seeds are the cell's ``seed`` plus fixed offsets, so every cell of a seed
sees the same recordings):

- fitting: fixed-volume recordings at ``fit_positions`` x ``fit_command_ranges_V``
  (seed), plus ``fit_moving_count`` moving-piston recordings at ``fit_moving_range_V``
  (seed + 500), as in ``experiments/discovery_study.py``;
- held out: the cell's protocol at the cell's command range: ``fixed`` recordings at
  ``eval_positions``, or ``eval_moving_count`` ``moving`` ones (seed +
  ``heldout_seed_offset``).

Catalogue data plant the effect objects in the bench's model (a leak in
``data_leak_form``); realistic data plant :func:`~pneubayes.bench.forms.forms_from_names`
for the cell's cylinder, simulated by the independent plant. The result is a JSON-safe
dict; ``truth`` holds the bench's true card, scored too (``rmse_truth_Pa``) when the
data are catalogue forms (the card is then the whole truth).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pneubayes.ablation.settings import Settings
from pneubayes.ablation.study import TASSA, Cell
from pneubayes.atomic import json_safe
from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.bench.forms import forms_from_names
from pneubayes.effects import effects_from_names
from pneubayes.evaluation import predict_windows
from pneubayes.inference.fit import FitSettings, identify
from pneubayes.inference.fit_folder import write_fit
from pneubayes.inference.predictive import estimate_noise_std
from pneubayes.io import read_recording, smooth_position
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

#: Seed offset of the fitting recordings' moving-piston part (as discovery_study.py).
FIT_MOVING_SEED_OFFSET = 500


@dataclass(frozen=True)
class CellData:
    """Paths of a cell's recordings and the bench's truth card."""

    fit: tuple[Path, ...]
    held_out: tuple[Path, ...]
    truth: dict


def make_data(cell: Cell, out_dir) -> CellData:
    """Write the cell's fitting and held-out bench recordings under ``out_dir``."""
    s, out = cell.settings, Path(out_dir)
    if cell.data_form == "realistic":
        common = {"effects": (), "forms": forms_from_names(cell.data_effects, cell.cylinder)}
    else:
        common = {"effects": effects_from_names(cell.data_effects, s.data_leak_form),
                  "forms": ()}
    common.update(duration_s=s.duration_s)
    rig = (cell.cylinder, cell.valve)
    fixed = run_bench(BenchConfig(*rig, protocol="fixed", seed=cell.seed,
                                  positions=s.fit_positions, ranges_V=s.fit_command_ranges_V,
                                  **common), out / "fit_fixed", overwrite=True)
    fit = list(fixed.recordings)
    if s.fit_moving_count:
        moving = run_bench(BenchConfig(*rig, protocol="moving",
                                       seed=cell.seed + FIT_MOVING_SEED_OFFSET,
                                       count=s.fit_moving_count,
                                       moving_range_V=s.fit_moving_range_V, **common),
                           out / "fit_moving", overwrite=True)
        fit += list(moving.recordings)
    held_seed = cell.seed + s.heldout_seed_offset
    if cell.protocol == "fixed":
        cfg = BenchConfig(*rig, protocol="fixed", seed=held_seed, positions=s.eval_positions,
                          ranges_V=(cell.command_range_V,), **common)
    else:
        cfg = BenchConfig(*rig, protocol="moving", seed=held_seed, count=s.eval_moving_count,
                          moving_range_V=cell.command_range_V, **common)
    held = run_bench(cfg, out / "held_out", overwrite=True)
    return CellData(tuple(fit), tuple(held.recordings), fixed.truth)


def with_supply(recording, supply: str):
    """The recording as the fitted model sees it: ``"nominal"`` drops the supply column
    (the model then gets the JSON's nominal supply), ``"measured"`` keeps it."""
    if supply == "nominal":
        return replace(recording, supply_pressure_Pa=None)
    return recording


def _fit_settings(cell: Cell) -> FitSettings:
    """The study's fit settings with the study's windows and the cell's seed."""
    s = cell.settings
    return replace(s.fit, horizon_s=s.horizon_s, stride_s=s.horizon_s,
                   sampler=replace(s.fit.sampler, seed=cell.seed))


def fit_model(cell: Cell, recordings, out_dir, log=lambda message: None):
    """Fit the cell's model; return ``(model, parameters, fit information)``.

    ``"discover"`` cells run the discovery loop from the plain model (its refined point
    estimates, or the posterior median with ``method = "mcmc"``); other cells run
    ``pneubayes fit`` with the study's method. The parameters are those of the run
    folder's ``model.json``.
    """
    s, out = cell.settings, Path(out_dir)
    if cell.kind == TASSA:
        from pneubayes.baselines.tassa import PARAMETER_NAMES, TassaModel

        est = TassaModel(horizon_s=s.horizon_s, stride_s=s.effective_stride_s,
                         seed=cell.seed).fit([smooth_position(r, s.fit.position_cutoff_Hz)
                                              for r in recordings])
        info = {"method": "tassa", "estimate": "least squares (one-step, then 2-s windows)",
                "train_rmse_Pa": est.rmse_Pa_, "train_start_rmse_Pa": est.start_rmse_Pa_,
                "frozen": list(est.frozen_), "success": bool(est.success_)}
        return est, dict(zip(PARAMETER_NAMES, map(float, est.params_))), info
    if cell.discover:
        from pneubayes.discovery.loop import Discovery
        from pneubayes.discovery.report import write_discovery

        ds = replace(s.discovery, seed=cell.seed,
                     posterior=replace(s.discovery.posterior,
                                       method="emcee" if s.method == "mcmc" else "none"),
                     fit=_fit_settings(cell))
        result = Discovery(ds, out, log).fit(recordings).result_
        doc = write_discovery(result, recordings, out, figures=False)
        model, params = result.model, result.params
        info = {"method": "discover",
                "estimate": "posterior median" if ds.posterior.sampled else "refined",
                "discovered": [e["name"] for e in doc["effects"]],
                "discovery_rmse_base_Pa": doc["rmse_base_Pa"],
                "discovery_rmse_final_Pa": doc["rmse_final_Pa"],
                "discovery_effects": doc["effects"],
                # every trial, its forms, verdict and held-out numbers: why an effect
                # was or was not named (the work folder is removed after the cell)
                "discovery_ledger": doc["ledger"]}
        return model, params, info
    model = Model(effects_from_names(cell.model_effects, s.leak_form))
    fit = identify(recordings, model, _fit_settings(cell), method=s.method,
                   checkpoint_dir=out, log=log)
    write_fit(fit, out, figures=False)
    summary, params = fit.summary, fit.params
    info = {"method": s.method, "start": summary["start"]["method"],
            "notes": summary["start"]["notes"],
            "train_noise_floor_Pa": summary["noise_floor_Pa"]}
    if summary.get("refined"):
        info["train_rmse_Pa"] = summary["refined"]["rmse_Pa"]
        info["train_start_rmse_Pa"] = summary["refined"]["start_rmse_Pa"]
    if s.method == "mcmc":
        info.update(estimate="posterior median", converged=summary["converged"],
                    steps=summary["steps"], posterior=summary["parameters"])
    else:
        info["estimate"] = s.method
    return model, params, info


def band_key(band_V: float) -> str:
    """Suffix of the per-band metrics, e.g. ``within_0.1V``."""
    return f"within_{band_V:g}V"


def _predictor(model, params, settings: Settings, solver: SolverConfig):
    """``recording -> WindowPrediction`` for a thin-port model or a fitted baseline."""
    if isinstance(model, Model):
        return lambda rec: predict_windows(model, params, rec, settings.horizon_s,
                                           settings.effective_stride_s, solver)
    return model.predict_windows  # a fitted estimator (the Tassa baseline)


def evaluate(model, params, recordings, settings: Settings,
             solver: SolverConfig) -> tuple[dict, list[dict]]:
    """Held-out ``horizon_s`` predictions from the measured pressure every ``stride_s``.

    ``model`` is a :class:`Model` with ``params``, or a fitted baseline estimator
    (``params`` unused) whose ``predict_windows(recording)`` gives the same windows.

    Returns ``(metrics, per-recording rows)``. The RMSE pools every predicted sample of
    every window (the measured start excluded), Pa and % of the working range; the
    noise floor is the median white-noise std of the held-out pressures
    (:func:`estimate_noise_std`), Pa. For each ``eval_command_bands_V`` band the RMSE
    is over the samples whose command, held over the interval ending there, has
    ``|u| <= band`` (None when no sample qualifies).
    """
    bands = settings.eval_command_bands_V
    sq, n = 0.0, 0
    band_sq, band_n = np.zeros(len(bands)), np.zeros(len(bands), dtype=np.int64)
    rows, noise, windows = [], [], 0
    predict = _predictor(model, params, settings, solver)
    for rec in recordings:
        # scored with the position low-passed as in fitting (pneubayes predict does too)
        wp = predict(smooth_position(rec, settings.fit.position_cutoff_Hz))
        r = wp.residual_Pa[0, :, 1:]
        idx = wp.starts[:, None] + np.arange(1, wp.length)[None, :]
        u = np.abs(np.asarray(rec.command_V)[idx - 1])
        for i, b in enumerate(bands):
            sel = u <= b + 1e-9
            band_sq[i] += float(np.sum(r[sel] ** 2))
            band_n[i] += int(sel.sum())
        sq += float(np.sum(r * r))
        n += r.size
        windows += r.shape[0]
        nf = estimate_noise_std(rec.pressure_Pa)
        noise.append(nf)
        rows.append({"recording": Path(str(rec.source)).name, "windows": int(r.shape[0]),
                     "rmse_Pa": float(np.sqrt(np.mean(r * r))), "noise_floor_Pa": nf})
    span = recordings[0].working_range_Pa
    rmse = float(np.sqrt(sq / n))
    floor = float(np.median(noise))
    metrics = {"rmse_Pa": rmse, "rmse_percent_of_range": 100.0 * rmse / span,
               "noise_floor_Pa": floor, "rmse_over_noise": rmse / floor if floor > 0 else None,
               "working_range_Pa": span, "windows": windows, "samples": n}
    for i, b in enumerate(bands):
        rb = float(np.sqrt(band_sq[i] / band_n[i])) if band_n[i] else None
        metrics[f"rmse_Pa_{band_key(b)}"] = rb
        metrics[f"rmse_percent_of_range_{band_key(b)}"] = (None if rb is None
                                                           else 100.0 * rb / span)
        metrics[f"samples_{band_key(b)}"] = int(band_n[i])
    return metrics, rows


def run_cell(cell: Cell, workdir) -> dict:
    """Run one cell in ``workdir`` (bench data, fit run folder); return its result.

    The result (JSON-safe) holds ``metrics`` (held-out RMSE in Pa and % of range, noise
    floor, per-band RMSE), the fitted ``model`` (effects and parameters), ``fit``
    details, the bench ``truth``, per-recording rows and wall times in s.
    """
    t0 = time.perf_counter()
    s, work = cell.settings, Path(workdir)
    data = make_data(cell, work / "data")
    t_data = time.perf_counter()
    fit_recs = [with_supply(read_recording(p), s.supply) for p in data.fit]
    held_raw = [read_recording(p) for p in data.held_out]
    held = [with_supply(r, s.supply) for r in held_raw]
    model, params, fit_info = fit_model(cell, fit_recs, work / "fit")
    t_fit = time.perf_counter()
    solver = SolverConfig.standard()
    metrics, rows = evaluate(model, params, held, s, solver)
    bench = data.truth["bench"]
    truth = {"planted_effects": bench["planted_effects"],
             "planted_forms": bench["planted_forms"],
             "parameters": data.truth["parameters"]}
    if cell.data_form == "catalogue":
        true_model, true_params = Model.from_card(data.truth, "truth.json")
        truth_metrics, _ = evaluate(true_model, true_params, held_raw, s, solver)
        metrics["rmse_truth_Pa"] = truth_metrics["rmse_Pa"]
    t_end = time.perf_counter()
    return json_safe({
        "id": cell.id, "status": "ok", "cell": cell.axes(), "metrics": metrics,
        "model": {"effects": list(model.effect_names) if isinstance(model, Model)
                  else [cell.kind], "parameters": params},
        "fit": fit_info, "truth": truth,
        "recordings": {"fit": [p.name for p in data.fit], "held_out": rows},
        "solver": solver.to_dict(),
        "timing_s": {"data": t_data - t0, "fit": t_fit - t_data, "evaluate": t_end - t_fit},
        "wall_time_s": t_end - t0})
