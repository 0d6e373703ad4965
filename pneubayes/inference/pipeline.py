"""``pneubayes fit`` and ``pneubayes predict``: the identification pipeline end to end.

fit: the paper's least squares on the fixed-volume recordings (when they span two or
more positions) -> trajectory refinement on every recording -> emcee posterior ->
RUNDIR/model.json (posterior median card), posterior.nc (arviz), summary.json,
chain.h5 (resumable), figures/.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic, write_text_atomic

# settings, start and reports live with the in-memory fit; these names stay importable
from pneubayes.inference.fit import (  # noqa: E402,F401
    ABSORBING_AR1,
    BOUND_FRACTION,
    METHODS,
    MISFIT_RATIO,
    Fit,
    FitSettings,
    _tight,
    at_bounds,
    identify,
    misfit_report,
    posterior_draws,
    starting_point,
)
from pneubayes.inference.fit_folder import (  # noqa: F401
    folder_draws,
    load_posterior,
    prepare_as_fitted,
    read_fit,
    run_preparation,
    write_fit,
    write_posterior,
)
from pneubayes.inference.predictive import PosteriorPredictive
from pneubayes.io.plausibility import recorded_findings
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


def run_fit(recordings, model: Model, settings: FitSettings, out_dir,
            progress: bool = True, log=print, figures: bool = True,
            method: str = "mcmc") -> dict:
    """Fit ``model`` to ``recordings``; write the run folder; return the summary.

    ``method``: ``"lsq"`` stops after the paper's least squares (section VI-B),
    ``"refine"`` after multiple shooting, ``"mcmc"`` (default) samples the posterior,
    ``"laplace"`` approximates it (:mod:`pneubayes.inference.laplace`).
    The fit itself is :func:`pneubayes.inference.fit.identify` (in memory), with the run
    folder as its checkpoint (the chain and the refined start), so a killed fit resumes;
    :func:`pneubayes.inference.fit_folder.write_fit` writes what it found.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fit = identify(recordings, model, settings, method=method, checkpoint_dir=out,
                   progress=progress, log=log)
    write_fit(fit, out, figures=figures)
    return fit.summary


def run_predict(run_dir, recording, horizon_s: float, out_csv, n_draws: int, seed: int,
                solver: SolverConfig, stride_s: float | None = None,
                figure_path=None) -> dict:
    """Rolling windows with posterior-predictive bands -> CSV + ``.metrics.json``.

    With ``figure_path``, the same bands are also drawn there (Figs. 7-10 style).
    """
    rng = np.random.default_rng(seed)
    fit = read_fit(run_dir)  # the run folder read once: card, posterior, preparation
    model, draws, noise = folder_draws(fit, run_dir, n_draws, rng)
    if model.rig_card != recording.rig_card:
        def rig(c):
            return "the paper's cylinders" if c is None else f"the rig card {c.name!r}"
        raise ValueError(f"{recording.source} describes {rig(recording.rig_card)}, the run "
                         f"{run_dir} {rig(model.rig_card)}: predict on the rig it was "
                         "fitted to (give --rig CARD if the sidecar names none)")
    recording = prepare_as_fitted(recording, fit.preparation, Path(run_dir) / "model.json")
    pp = PosteriorPredictive(model, draws, noise, solver)
    bands = pp.bands(recording, horizon_s, stride_s or horizon_s, rng)
    metrics = bands.metrics()
    if not np.isfinite(metrics["rmse_Pa"]):
        raise FloatingPointError(f"{recording.source}: the prediction's RMSE is "
                                 f"{metrics['rmse_Pa']} (the model's simulation failed on "
                                 "it); no prediction written")
    w, n = bands.mean.shape
    cols = [np.repeat(np.arange(w), n), bands.time_s.ravel(),
            (bands.time_s - bands.time_s[:, :1]).ravel(), bands.measured.ravel(),
            bands.mean.ravel(), bands.q05.ravel(), bands.q50.ravel(), bands.q95.ravel()]
    header = "window,time_s,horizon_s,measured_Pa,mean_Pa,q05_Pa,q50_Pa,q95_Pa"
    lines = [header] + [",".join(f"{v:.10g}" for v in row) for row in zip(*cols)]
    out = Path(out_csv)
    write_text_atomic(out, "\n".join(lines) + "\n")
    metrics.update({"recording": str(recording.source), "run": str(run_dir),
                    "input_findings": recorded_findings([recording]),
                    "horizon_s": horizon_s, "n_draws": int(draws.shape[0]), "seed": seed})
    write_json_atomic(out.with_suffix(".metrics.json"), metrics)
    if figure_path is not None:
        from pneubayes.plotting import plot_prediction_bands

        effects = " + ".join(model.effect_names) or "thin-port model"
        name = Path(recording.source).name if recording.source else "recording"
        plot_prediction_bands(bands, figure_path,
                              title=f"{name}: {effects} ({run_dir}), {horizon_s:g}-s windows")
    return metrics
