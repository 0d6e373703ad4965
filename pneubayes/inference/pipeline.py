"""``pneubayes fit`` and ``pneubayes predict``: the identification pipeline end to end.

fit: the paper's least squares on the fixed-volume recordings (when they span two or
more positions) -> trajectory refinement on every recording -> emcee posterior ->
RUNDIR/model.json (posterior median card), posterior.nc (arviz), summary.json,
chain.h5 (resumable), figures/.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

import pneubayes
from pneubayes.atomic import json_safe, write_json_atomic, write_text_atomic
from pneubayes.errors import ModelCardError
from pneubayes.inference.derivative import SavitzkyGolay
from pneubayes.inference.identifiability import identifiability_report
from pneubayes.inference.lsq import PaperLeastSquares
from pneubayes.inference.predictive import PosteriorPredictive, estimate_noise_std
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.sampler import BayesianIdentification, SamplerSettings, arviz
from pneubayes.inference.windows import WindowSet
from pneubayes.io.plausibility import recorded_findings
from pneubayes.io.preprocess import prepare_recording
from pneubayes.model import Model
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import SolverConfig


def _tight() -> SolverConfig:
    """The refinement solver: tight tolerances for smooth least-squares Jacobians, and a
    step budget of 1e5 per simulated second, about ten times what the costliest
    legitimate window measured needs (a 0.3-ms acoustic line: 9,000 steps per second),
    so a degenerate trial of a fit fails in about a second instead of a minute."""
    return SolverConfig(rtol=1e-6, atol_Pa=1.0, atol_K=0.01, max_step_s=0.02,
                        min_step_s=1e-12, max_steps_per_s=1e5)


@dataclass(frozen=True)
class FitSettings:
    """Every setting of ``pneubayes fit`` (saved in summary.json)."""

    horizon_s: float = 2.0
    stride_s: float = 2.0
    sg_window_s: float = 0.011
    sg_polyorder: int = 3
    refine_max_nfev: int = 60
    refine_solver: SolverConfig = field(default_factory=_tight)
    sample_solver: SolverConfig = field(default_factory=SolverConfig.standard)
    sampler: SamplerSettings = field(default_factory=SamplerSettings)
    #: zero-phase low-pass of the measured position before it drives the model, Hz
    #: (None: raw); see :func:`pneubayes.io.smooth_position`. Saved in the model card,
    #: and ``pneubayes predict`` applies the same.
    position_cutoff_Hz: float | None = 50.0
    #: zero-phase low-pass of the measured supply before it drives a model (with
    #: supply_fluctuation), Hz (None: raw); see :func:`pneubayes.io.smooth_supply`.
    #: Saved in the model card like the position's.
    supply_cutoff_Hz: float | None = 100.0
    #: the pressure channel's zero-phase anti-alias filter (None: the reading is the
    #: chamber pressure). The recording format does not carry it; declare the DAQ's
    #: (the bench's: order 2 at 1 kHz). Saved in the model card like the cutoffs.
    pressure_filter: PressureFilter | None = None

    def __post_init__(self):
        if self.pressure_filter is not None and not isinstance(self.pressure_filter,
                                                               PressureFilter):
            raise TypeError("FitSettings.pressure_filter must be a PressureFilter or None, "
                            f"got {type(self.pressure_filter).__name__}")

    def to_dict(self) -> dict:
        return asdict(self)

    def preparation(self) -> dict:
        """How the recordings are prepared (:func:`pneubayes.io.prepare_recording`): the
        input low-passes and the declared pressure filter, as the model card records them."""
        return {"position_cutoff_Hz": self.position_cutoff_Hz,
                "supply_cutoff_Hz": self.supply_cutoff_Hz,
                "pressure_filter": (None if self.pressure_filter is None
                                    else self.pressure_filter.to_dict())}


def _fixed(rec) -> bool:
    return rec.position_m is None or np.ptp(rec.position_m) < 0.02 * rec.metadata.stroke_m


def starting_point(model: Model, recordings, settings: FitSettings, noise_Pa: float):
    """The paper's least squares where the data allow it, else a generic start (a rig
    card's model: the card's starts, or its priors' centres)."""
    notes = []
    card_start = model.base_start_values()
    if card_start is not None:
        start = {**model.neutral_values(), **card_start}
        notes.append(f"started from the rig card {model.rig_card.name!r}: its start "
                     "values, else its priors' centres (the paper's least squares needs "
                     "the Gompertz ports of the thin-port core)")
        return start, notes, "rig card"
    fixed = [r for r in recordings if _fixed(r)]
    if fixed:
        try:
            lsq = PaperLeastSquares(model, SavitzkyGolay(settings.sg_window_s,
                                                         settings.sg_polyorder),
                                    noise_std_Pa=noise_Pa).fit(fixed)
            return lsq.params_, lsq.notes_, "paper least squares (eq. 10)"
        except ValueError as exc:
            notes.append(f"paper least squares skipped: {exc}")
    start = dict(model.neutral_values())
    start.update(valve_preset("valve1").parameters())
    start["dead_volume_m3"] = 1e-6
    if model.has("cylinder_leak"):
        e = model.effect("cylinder_leak")
        start.update({k: 0.2 * v for k, v in e.bench_defaults().items()})
    notes.append("started from the Table II valve1 maps and a 1e-6 m^3 dead volume")
    return start, notes, "generic"


METHODS = ("lsq", "refine", "mcmc")

#: A fit or held-out error above this x the noise floor is reported as misfit, never as
#: explained (fit, predict, the discovery report); an AR(1) noise coefficient above the
#: other limit means the noise model stands in for the misfit.
MISFIT_RATIO = 1.5
ABSORBING_AR1 = 0.9


#: A 90 % interval within this fraction of the bounds' width from a bound "sits" there.
BOUND_FRACTION = 0.01


def at_bounds(model: Model, summary: dict) -> list[dict]:
    """Parameters whose posterior 90 % interval reaches within ``BOUND_FRACTION`` of the
    bounds' width of a bound: the data push them there (an effect the data do not show
    sits at its zero; a bound sized for another rig cuts the posterior off)."""
    out = []
    lo, hi = model.bounds
    for name, a, b in zip(model.parameter_names, lo, hi):
        s = summary.get(name)
        if s is None or not (np.isfinite(a) and np.isfinite(b)) or b <= a:
            continue
        # bounds over decades (a dead volume, 1e-8..1e-4 m^3) are judged in log space
        f = np.log10 if a > 0 and b / a > 100 else (lambda v: v)
        tol = BOUND_FRACTION * (f(b) - f(a))
        q05, q95 = max(s["q05"], a), min(s["q95"], b)
        if f(q95) - f(q05) > 0.5 * (f(b) - f(a)):
            continue  # spread over its range: the prior's, not pushed by the data
        for side, bound, reached in (("lower", a, f(q05) <= f(a) + tol),
                                     ("upper", b, f(q95) >= f(b) - tol)):
            if reached:
                out.append({"parameter": name, "bound": side, "value": float(bound),
                            "q05": s["q05"], "q95": s["q95"]})
    return out


def misfit_report(rmse_Pa: float, noise_floor_Pa: float, noise_ar1: float) -> dict:
    """Misfit stated apart from noise: the refined window RMSE against the sensor's noise
    floor, and whether the AR(1) noise model absorbs what the model misses."""
    ratio = rmse_Pa / noise_floor_Pa
    note = None
    if ratio > MISFIT_RATIO:
        note = (f"the model misses by {ratio:.1f} x the noise floor ({rmse_Pa:.0f} Pa "
                f"against {noise_floor_Pa:.0f} Pa)")
        if noise_ar1 > ABSORBING_AR1:
            note += (f"; the noise model absorbs it (AR(1) coefficient {noise_ar1:.3f}), so "
                     "its bands are wide because the model misses, not because the sensor "
                     "is noisy")
    return {"rmse_Pa": rmse_Pa, "rmse_over_noise_floor": ratio, "noise_ar1_median": noise_ar1,
            "note": note}


@dataclass(frozen=True)
class _SavedRefinement:
    """The refiner's results a posterior needs, as :class:`_StageCache` keeps them."""

    params_: dict
    information_: np.ndarray | None
    rmse_Pa_: float
    start_rmse_Pa_: float


class _StageCache:
    """The start and the refined point of a posterior fit, saved beside its chain so a
    resumed fit skips least squares and refinement. Used only when it was saved for the
    same model, recordings (paths and digests of their samples) and fit settings."""

    def __init__(self, path: Path, model: Model, recs, settings: FitSettings):
        self.path = path
        digest = hashlib.sha256()
        for r in recs:
            for a in (r.time_s, r.command_V, r.pressure_Pa):
                digest.update(np.ascontiguousarray(a).tobytes())
        settings_doc = settings.to_dict()
        settings_doc.pop("sampler", None)  # a longer chain resumes from the same start
        self.key = json_safe({"effects": list(model.effect_names),
                              "options": {e.name: e.options() for e in model.effects},
                              "recordings": [str(r.source) for r in recs],
                              "samples_sha256": digest.hexdigest(),
                              "settings": settings_doc})

    def load(self) -> dict | None:
        try:
            doc = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None
        if not isinstance(doc, dict) or doc.get("key") != self.key:
            return None
        r = doc["refined"]
        info = None if r["information"] is None else np.asarray(r["information"], float)
        return {"start": doc["start"], "notes": doc["notes"], "how": doc["how"],
                "refined": _SavedRefinement(r["params"], info, r["rmse_Pa"],
                                            r["start_rmse_Pa"])}

    def save(self, start, notes, how, ref) -> None:
        info = getattr(ref, "information_", None)
        write_json_atomic(self.path, {
            "key": self.key, "start": start, "notes": notes, "how": how,
            "refined": {"params": ref.params_, "rmse_Pa": ref.rmse_Pa_,
                        "start_rmse_Pa": ref.start_rmse_Pa_,
                        "information": None if info is None else np.asarray(info).tolist()}})


def _point_summary(method, recs, start, notes, how, noise, settings, t0, refined=None):
    return {"format": "pneubayes-fit-summary/1", "method": method,
            "recordings": [str(r.source) for r in recs],
            "input_findings": recorded_findings(recs),
            "start": {"method": how, "notes": notes, "parameters": start},
            "refined": refined, "noise_floor_Pa": noise, "settings": settings.to_dict(),
            "wall_time_s": time.perf_counter() - t0,
            "pneubayes_version": pneubayes.__version__}


def run_fit(recordings, model: Model, settings: FitSettings, out_dir,
            progress: bool = True, log=print, figures: bool = True,
            method: str = "mcmc") -> dict:
    """Fit ``model`` to ``recordings``; write the run folder; return the summary.

    ``method``: ``"lsq"`` stops after the paper's least squares (section VI-B),
    ``"refine"`` after multiple shooting, ``"mcmc"`` (default) samples the posterior.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    inputs_card = settings.preparation()
    recs = [prepare_recording(r, inputs_card) for r in recordings]
    t0 = time.perf_counter()
    noise = float(np.median([estimate_noise_std(r.pressure_Pa) for r in recs]))
    stages = _StageCache(out / "refined.json", model, recs, settings)
    saved = stages.load() if method == "mcmc" else None
    if saved is not None:
        start, notes, how = saved["start"], saved["notes"], saved["how"]
        log("fit: least squares and refinement skipped: their result is saved in "
            f"{stages.path}")
    else:
        start, notes, how = starting_point(model, recs, settings, noise)
        log(f"fit: start from {how}")
    if method == "lsq":
        if how != "paper least squares (eq. 10)":
            raise ValueError("--method lsq needs fixed-volume recordings at two or more "
                             "positions: " + "; ".join(notes))
        model.save_card(start, out / "model.json",
                        extra={"fit": {"estimate": "lsq", **inputs_card}})
        summary = _point_summary(method, recs, start, notes, how, noise, settings, t0)
        write_json_atomic(out / "summary.json", summary)
        return summary
    data = WindowSet(recs, settings.horizon_s, settings.stride_s)
    if saved is not None:
        ref = saved["refined"]
    else:
        ref = TrajectoryRefiner(model, settings.refine_solver,
                                max_nfev=settings.refine_max_nfev).fit(data, start)
        log(f"fit: refined {settings.horizon_s:g}-s RMSE {ref.start_rmse_Pa_:.0f} -> "
            f"{ref.rmse_Pa_:.0f} Pa "
            f"({ref.n_evaluations_} evaluations)")
        if method == "mcmc":
            stages.save(start, notes, how, ref)
    if method == "refine":
        model.save_card(ref.params_, out / "model.json",
                        extra={"fit": {"estimate": "refine", **inputs_card}})
        summary = _point_summary(method, recs, start, notes, how, noise, settings, t0,
                                 {"parameters": ref.params_, "rmse_Pa": ref.rmse_Pa_,
                                  "start_rmse_Pa": ref.start_rmse_Pa_})
        write_json_atomic(out / "summary.json", summary)
        return summary
    bi = BayesianIdentification(model, settings.sample_solver, settings.sampler,
                                backend_path=out / "chain.h5", progress=progress,
                                log=log)
    bi.fit(data, ref.params_, information=ref.information_)
    log(f"fit: emcee {bi.diagnostics_['steps']} steps x {bi.chain_.shape[1]} walkers, "
        f"converged={bi.converged_}, {bi.wall_time_s_:.0f} s (solver rtol "
        f"{bi.solver_.rtol:.0e}, log-density roughness "
        f"{bi.diagnostics_['solver_jitter_nats']:.2f} nat)")
    median = bi.median_params()
    card_extra = {"fit": {"estimate": "posterior median", "posterior": "posterior.nc",
                          "summary": "summary.json", **inputs_card}}
    model.save_card(median, out / "model.json", extra=card_extra)
    idata = bi.inference_data({"seed": settings.sampler.seed,
                               "pneubayes_version": pneubayes.__version__,
                               "model_card": json.dumps(model.to_card(median))})
    tmp = out / ".posterior.nc.tmp"
    idata.to_netcdf(str(tmp))
    os.replace(tmp, out / "posterior.nc")
    ident = identifiability_report(model, bi.names_, bi.samples())
    posterior = bi.summary()
    summary = {
        "format": "pneubayes-fit-summary/1", "method": method,
        "recordings": [str(r.source) for r in recs],
        "input_findings": recorded_findings(recs),
        "parameters": posterior,
        "converged": bi.converged_,
        "steps": bi.diagnostics_["steps"], "burn": bi.burn_,
        "n_walkers": int(bi.chain_.shape[1]), "tau_max": bi.diagnostics_["tau_max"],
        "acceptance_fraction": bi.acceptance_fraction_,
        "resumed": bi.resumed_,
        "sampling_solver": bi.diagnostics_["solver"],
        "solver_roughness_nats": bi.diagnostics_["solver_jitter_nats"],
        "start": {"method": how, "notes": notes, "parameters": start},
        "refined": {"parameters": ref.params_, "rmse_Pa": ref.rmse_Pa_,
                    "start_rmse_Pa": ref.start_rmse_Pa_},
        "noise_floor_Pa": noise,
        "misfit": misfit_report(ref.rmse_Pa_, noise, posterior["noise_ar1"]["median"]),
        "at_bounds": at_bounds(model, posterior),
        "identifiability": ident,
        "settings": settings.to_dict(), "seed": settings.sampler.seed,
        "wall_time_s": time.perf_counter() - t0,
        "pneubayes_version": pneubayes.__version__,
    }
    write_json_atomic(out / "summary.json", summary)
    if figures:
        from pneubayes.plotting import plot_fit_figures

        plot_fit_figures(model, bi.model_samples(), recs, out / "figures", idata=idata)
    return summary


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
    names = list(model.parameter_names) + ["noise_scale_Pa", "noise_ar1"]
    missing = [n for n in names if n not in post]
    if missing:
        raise ValueError(f"{run / 'posterior.nc'}: missing variables {missing}")
    flat = np.column_stack([np.asarray(post[n]).reshape(-1) for n in names])
    pick = rng.choice(flat.shape[0], size=min(n_draws, flat.shape[0]), replace=False)
    draws = flat[pick]
    return model, draws[:, : model.n_parameters], draws[:, model.n_parameters:]


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
