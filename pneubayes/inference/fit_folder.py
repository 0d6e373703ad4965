"""The fit's run folder: :func:`write_fit` writes a :class:`~pneubayes.inference.fit.Fit`
there and :func:`read_fit` reads one back, for ``pneubayes predict`` and for a user who
comes back to yesterday's fit. (A fit never reads back its own folder: it resumes from
the checkpoints :func:`~pneubayes.inference.fit.identify` keeps.)

``model.json`` (the point estimate's model card, with how the recordings were
prepared), ``posterior.nc`` (arviz, "mcmc" and "laplace" fits), ``summary.json``
(diagnostics) and ``figures/``; every file is written atomically.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.errors import ModelCardError
from pneubayes.inference.fit import Fit, posterior_draws
from pneubayes.inference.sampler import arviz
from pneubayes.io.preprocess import prepare_recording
from pneubayes.model import Model
from pneubayes.physics.sensor_filter import PressureFilter


def write_posterior(idata, path) -> None:
    """Write arviz InferenceData to ``path`` (netCDF) atomically: a temporary file
    beside it, then a rename."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    idata.to_netcdf(str(tmp))
    os.replace(tmp, path)


def _non_finite_rmse(doc, where: str = "") -> list:
    """``[(key path, value)]`` of every RMSE in ``doc`` that is not a finite number."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            path = f"{where}.{k}" if where else str(k)
            if "rmse" in str(k).lower() and isinstance(v, (int, float, np.floating)) \
                    and not isinstance(v, bool) and not np.isfinite(v):
                out.append((path, v))
            else:
                out += _non_finite_rmse(v, path)
    return out


def write_fit(fit: Fit, out_dir, figures: bool = True) -> None:
    """Write ``fit`` as a run folder, every file atomically.

    Parameters
    ----------
    fit : Fit
        What :func:`~pneubayes.inference.fit.identify` returned.
    out_dir : path
        The run folder (created if missing): ``model.json`` (the point estimate's card),
        ``posterior.nc`` (arviz; "mcmc", "laplace") and ``summary.json``.
    figures : bool
        Also draw the posterior's figures into ``figures/`` (needs matplotlib).

    Raises
    ------
    FloatingPointError
        A non-finite RMSE in the summary (the model's simulation failed); nothing written.
    """
    bad = _non_finite_rmse(fit.summary)
    if bad:
        raise FloatingPointError(f"the fit's {bad[0][0]} is {bad[0][1]}: not a result (the "
                                 "model's simulation failed on the data); nothing written")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fit.model.save_card(fit.params, out / "model.json", extra=fit.card_extra())
    if fit.posterior is not None:
        write_posterior(fit.posterior, out / "posterior.nc")
    write_json_atomic(out / "summary.json", fit.summary)
    if figures and fit.posterior is not None:
        from pneubayes.plotting import plot_fit_figures

        post = fit.posterior.posterior
        samples = np.column_stack([np.asarray(post[n]).T.reshape(-1)  # step-major
                                   for n in fit.model.parameter_names])
        plot_fit_figures(fit.model, samples, list(fit.recordings), out / "figures",
                         idata=fit.posterior)


def read_fit(run_dir) -> Fit:
    """The :class:`~pneubayes.inference.fit.Fit` a run folder holds.

    Parameters
    ----------
    run_dir : path
        A run folder of :func:`write_fit` or ``pneubayes fit``.

    Returns
    -------
    Fit
        Its model card's point estimate and preparation, its posterior (when it has
        ``posterior.nc``, checked to belong to the card) and its ``summary.json`` (``{}``
        without one). A run folder keeps no recordings: ``recordings`` is empty.
    """
    run = Path(run_dir)
    card = Model.read_card(run / "model.json")  # read once: the model and its preparation
    model, params = Model.from_card(card, str(run / "model.json"))
    idata = _read_posterior(run, model, params) if (run / "posterior.nc").exists() else None
    summary = {}
    if (run / "summary.json").exists():
        try:
            summary = json.loads((run / "summary.json").read_text())
        except (OSError, ValueError) as exc:
            raise ValueError(f"{run / 'summary.json'}: not readable ({exc})") from None
    method = summary.get("method") if isinstance(summary, dict) else None
    if method is None:
        method = "mcmc" if idata is not None else "refine"
    return Fit(model, method, params, summary,
               card_preparation(card, run / "model.json"), idata)


def _read_posterior(run: Path, model: Model, params: dict):
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
    return idata


def load_posterior(run_dir, n_draws: int, rng: np.random.Generator):
    """(model, model draws (N, P), noise draws (N, 2)) from a run folder."""
    return folder_draws(read_fit(run_dir), run_dir, n_draws, rng)


def folder_draws(fit: Fit, run_dir, n_draws: int, rng: np.random.Generator):
    """:func:`load_posterior` of a fit already read from ``run_dir``."""
    path = Path(run_dir) / "posterior.nc"
    if fit.posterior is None:
        raise ValueError(f"{path}: not a readable posterior (the run has none: fit with "
                         "method 'mcmc')")
    draws, noise = posterior_draws(fit.model, fit.posterior, n_draws, rng, str(path))
    return fit.model, draws, noise


def prepare_as_fitted(recording, preparation: Mapping, card_path):
    """:func:`~pneubayes.io.prepare_recording` with a run's recorded ``preparation``; a
    preparation that cannot apply to ``recording`` (a cutoff above its Nyquist
    frequency) is refused naming the model card that holds it."""
    try:
        return prepare_recording(recording, preparation)
    except ValueError as exc:
        raise ValueError(f"{exc}. The run's model card {card_path} prepared its recordings "
                         "so: refit with a cutoff this recording allows to use the model "
                         "on it") from None


def run_preparation(run_dir) -> dict:
    """How a run prepared its recordings (its model card): the input low-passes, Hz (None
    or absent, as in a card written before the supply's: raw), whether the pressure was
    despiked (absent: not), and the declared pressure filter (None or absent: none)."""
    path = Path(run_dir) / "model.json"
    return card_preparation(Model.read_card(path), path)


def card_preparation(card, path) -> dict:
    """:func:`run_preparation` from a model card already read from ``path``."""
    fit = card.get("fit") if isinstance(card, dict) else None
    if fit is None:
        fit = {}
    if not isinstance(fit, dict):
        raise ModelCardError(f"{path}: key 'fit' must be an object, got {fit!r}")
    out = {k: fit.get(k) for k in ("position_cutoff_Hz", "supply_cutoff_Hz",
                                    "pressure_filter")}
    out["despike_pressure"] = fit.get("despike_pressure", False)  # (absent: older cards)
    if not isinstance(out["despike_pressure"], bool):
        raise ModelCardError(f"{path}: key 'fit' -> 'despike_pressure' must be true or "
                             f"false, got {out['despike_pressure']!r}")
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
