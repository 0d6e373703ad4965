"""``pneubayes fit`` and ``pneubayes predict``: the identification pipeline end to end.

fit: the paper's least squares on the fixed-volume recordings (when they span two or
more positions) -> trajectory refinement on every recording -> emcee posterior ->
RUNDIR/model.json (posterior median card), posterior.nc (arviz), summary.json,
chain.h5 (resumable), figures/.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic, write_text_atomic
from pneubayes.errors import ModelCardError

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
    write_fit,
)
from pneubayes.inference.predictive import PosteriorPredictive
from pneubayes.inference.sampler import arviz
from pneubayes.io.plausibility import recorded_findings
from pneubayes.io.preprocess import prepare_recording
from pneubayes.model import Model
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.simulation import SolverConfig


def run_fit(recordings, model: Model, settings: FitSettings, out_dir,
            progress: bool = True, log=print, figures: bool = True,
            method: str = "mcmc") -> dict:
    """Fit ``model`` to ``recordings``; write the run folder; return the summary.

    ``method``: ``"lsq"`` stops after the paper's least squares (section VI-B),
    ``"refine"`` after multiple shooting, ``"mcmc"`` (default) samples the posterior.
    The fit itself is :func:`pneubayes.inference.fit.identify` (in memory), with the run
    folder as its checkpoint (the chain and the refined start), so a killed fit resumes;
    :func:`pneubayes.inference.fit.write_fit` writes what it found.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fit = identify(recordings, model, settings, method=method, checkpoint_dir=out,
                   progress=progress, log=log)
    write_fit(fit, out, figures=figures)
    return fit.summary


def load_posterior(run_dir, n_draws: int, rng: np.random.Generator):
    """(model, model draws (N, P), noise draws (N, 2)) from a run folder."""
    run = Path(run_dir)
    model, params = Model.load_card(run / "model.json")
    try:
        idata = arviz().from_netcdf(str(run / "posterior.nc"))
        post = idata.posterior
    except (OSError, ValueError, AttributeError, KeyError) as exc:
        raise ValueError(f"{run / 'posterior.nc'}: not a readable posterior ({exc})") from None
    recorded = (getattr(idata, "attrs", None) or {}).get("model_card",
                                                         post.attrs.get("model_card"))
    if recorded is not None:  # the card the posterior was sampled for: never mix runs
        try:
            card = json.loads(recorded)
        except ValueError:
            card = None
        if not isinstance(card, dict) or card.get("effects") != list(model.effect_names) \
                or card.get("parameters") != {k: float(v) for k, v in params.items()}:
            raise ValueError(f"{run}: posterior.nc was sampled for another model card than "
                             "model.json (files of different runs); fit again into an empty "
                             "folder")
    draws, noise = posterior_draws(model, idata, n_draws, rng, str(run / "posterior.nc"))
    return model, draws, noise


def run_preparation(run_dir) -> dict:
    """How a run prepared its recordings (its model card): the input low-passes, Hz (None
    or absent, as in a card written before the supply's: raw), and the declared pressure
    filter (None or absent: none)."""
    path = Path(run_dir) / "model.json"
    try:
        card = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ModelCardError(f"{path}: cannot read the model card ({exc})") from None
    fit = card.get("fit") if isinstance(card, dict) else None
    if fit is None:
        fit = {}
    if not isinstance(fit, dict):
        raise ModelCardError(f"{path}: key 'fit' must be an object, got {fit!r}")
    out = {k: fit.get(k) for k in ("position_cutoff_Hz", "supply_cutoff_Hz",
                                    "pressure_filter")}
    for key in ("position_cutoff_Hz", "supply_cutoff_Hz"):
        v = out[key]
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                              or not math.isfinite(v) or v < 0):
            raise ModelCardError(f"{path}: key 'fit' -> {key!r} must be a number >= 0 (Hz) "
                                 f"or null, got {v!r}")
    if out["pressure_filter"] is not None:
        try:
            PressureFilter.from_dict(out["pressure_filter"],
                                     source=f"{path} key 'fit' -> 'pressure_filter'")
        except ValueError as exc:
            raise ModelCardError(str(exc)) from None
    return out


def run_predict(run_dir, recording, horizon_s: float, out_csv, n_draws: int, seed: int,
                solver: SolverConfig, stride_s: float | None = None,
                figure_path=None) -> dict:
    """Rolling windows with posterior-predictive bands -> CSV + ``.metrics.json``.

    With ``figure_path``, the same bands are also drawn there (Figs. 7-10 style).
    """
    rng = np.random.default_rng(seed)
    model, draws, noise = load_posterior(run_dir, n_draws, rng)
    if model.rig_card != recording.rig_card:
        def rig(c):
            return "the paper's cylinders" if c is None else f"the rig card {c.name!r}"
        raise ValueError(f"{recording.source} describes {rig(recording.rig_card)}, the run "
                         f"{run_dir} {rig(model.rig_card)}: predict on the rig it was "
                         "fitted to (give --rig CARD if the sidecar names none)")
    recording = prepare_recording(recording, run_preparation(run_dir))
    pp = PosteriorPredictive(model, draws, noise, solver)
    bands = pp.bands(recording, horizon_s, stride_s or horizon_s, rng)
    w, n = bands.mean.shape
    cols = [np.repeat(np.arange(w), n), bands.time_s.ravel(),
            (bands.time_s - bands.time_s[:, :1]).ravel(), bands.measured.ravel(),
            bands.mean.ravel(), bands.q05.ravel(), bands.q50.ravel(), bands.q95.ravel()]
    header = "window,time_s,horizon_s,measured_Pa,mean_Pa,q05_Pa,q50_Pa,q95_Pa"
    lines = [header] + [",".join(f"{v:.10g}" for v in row) for row in zip(*cols)]
    out = Path(out_csv)
    write_text_atomic(out, "\n".join(lines) + "\n")
    metrics = bands.metrics()
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
