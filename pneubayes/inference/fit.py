"""Identification in memory: ``identify(recordings, model, settings) -> Fit``.

The paper's least squares on the fixed-volume recordings (when they span two or more
positions) -> trajectory refinement on every recording -> emcee posterior. The result
is a :class:`Fit` value object (point estimate, posterior as arviz InferenceData, noise
floor, diagnostics); :func:`write_fit` writes it as a run folder (``pneubayes fit``,
:func:`pneubayes.inference.pipeline.run_fit`). With ``checkpoint_dir`` the chain and
the refined start are kept there as they are made, so a killed fit resumes.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

import pneubayes
from pneubayes.atomic import json_safe, write_json_atomic
from pneubayes.evaluation import PAPER_HORIZON_S
from pneubayes.inference.derivative import SavitzkyGolay
from pneubayes.inference.identifiability import identifiability_report
from pneubayes.inference.importance import IMPORTANCE_CHECK_DRAWS
from pneubayes.inference.laplace import LAPLACE_DRAWS, LaplaceIdentification
from pneubayes.inference.lsq import PaperLeastSquares
from pneubayes.inference.predictive import PressurePredictor, noise_floor_Pa
from pneubayes.inference.refine import Stall, TrajectoryRefiner
from pneubayes.inference.sampler import BayesianIdentification
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.inference.windows import WindowSet
from pneubayes.io.plausibility import recorded_findings
from pneubayes.io.preprocess import prepare_recording
from pneubayes.model import Model
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.physics.valve import valve_preset
from pneubayes.settings_tree import FieldError
from pneubayes.simulation import SolverConfig


def _tight() -> SolverConfig:
    """The refinement solver, :meth:`SolverConfig.refinement` (kept for old imports)."""
    return SolverConfig.refinement()


@dataclass(frozen=True)
class FitSettings:
    """Every setting of ``pneubayes fit`` (saved in summary.json).

    Attributes
    ----------
    horizon_s, stride_s : float
        Prediction windows of the refinement and the posterior, s (2 s, non-overlapping,
        as in the paper).
    sg_window_s, sg_polyorder : float, int
        Savitzky-Golay derivative of the paper's least squares (eq. 10): window, s;
        polynomial order.
    refine_max_nfev, refine_jacobian_refresh : int
        Residual evaluations of the refinement (multiple shooting); accepted points per
        finite-difference Jacobian, Broyden's update between (1: every point).
    refine_stall_evaluations, refine_stall_tolerance, refine_stall_after : int, float, int
        The refinement ends where its best RMSE fell by under ``refine_stall_tolerance``
        of itself over its last ``refine_stall_evaluations`` evaluations, after at least
        ``refine_stall_after`` (:class:`~pneubayes.inference.refine.Stall`); 0
        evaluations: never (the budget and the trust region's tolerances only).
    refine_solver, sample_solver : SolverConfig
        The refinement's solver; the likelihood's for emcee and the Laplace posterior.
    sampler : SamplerSettings
        The emcee run.
    position_cutoff_Hz, supply_cutoff_Hz : float or None
        Zero-phase low-passes of the measured position and supply, Hz (None: raw).
    despike_pressure : bool
        Replace isolated one-sample spikes of the measured pressure by their
        neighbours' mean (off by default).
    pressure_filter : PressureFilter or None
        The pressure channel's declared anti-alias filter (None: none).
    """

    horizon_s: float = PAPER_HORIZON_S
    stride_s: float = PAPER_HORIZON_S
    sg_window_s: float = 0.011
    sg_polyorder: int = 3
    refine_max_nfev: int = 60
    #: accepted points per finite-difference Jacobian of the refinement, Broyden's
    #: update between (:class:`~pneubayes.inference.refine.TrajectoryRefiner`); 1: a
    #: finite-difference Jacobian at every accepted point (4: docs/history.md, 2026-11-28)
    refine_jacobian_refresh: int = 4
    #: the refinement's stall rule (:class:`~pneubayes.inference.refine.Stall`; 0
    #: evaluations: off; the choice: docs/history.md, 2026-12-08)
    refine_stall_evaluations: int = 10
    refine_stall_tolerance: float = 1e-4
    refine_stall_after: int = 25
    refine_solver: SolverConfig = field(default_factory=SolverConfig.refinement)
    #: the likelihood's solver for emcee and the Laplace posterior (dense output: a
    #: step crosses the samples where the command holds; :meth:`SolverConfig.sampling`)
    sample_solver: SolverConfig = field(default_factory=SolverConfig.sampling)
    sampler: SamplerSettings = field(default_factory=SamplerSettings)
    #: zero-phase low-pass of the measured position before it drives the model, Hz
    #: (None: raw); see :func:`pneubayes.io.smooth_position`. Saved in the model card,
    #: and ``pneubayes predict`` applies the same.
    position_cutoff_Hz: float | None = 50.0
    #: zero-phase low-pass of the measured supply before it drives a model (with
    #: supply_fluctuation), Hz (None: raw); see :func:`pneubayes.io.smooth_supply`.
    #: Saved in the model card like the position's.
    supply_cutoff_Hz: float | None = 100.0
    #: replace each isolated one-sample spike of the measured pressure by its neighbours'
    #: mean before fitting (:func:`pneubayes.io.spikes.find_spikes`; glitches no model
    #: follows). Off by default; saved in the model card like the cutoffs.
    despike_pressure: bool = False
    #: the pressure channel's zero-phase anti-alias filter (None: the reading is the
    #: chamber pressure). The recording format does not carry it; declare the DAQ's
    #: (the bench's: order 2 at 1 kHz). Saved in the model card like the cutoffs.
    pressure_filter: PressureFilter | None = None

    def __post_init__(self):
        if (int(self.refine_jacobian_refresh) != self.refine_jacobian_refresh
                or self.refine_jacobian_refresh < 1):
            raise FieldError("refine_jacobian_refresh",
                             f"must be an integer >= 1, got {self.refine_jacobian_refresh!r}")
        n = self.refine_stall_evaluations
        if not (isinstance(n, int) and not isinstance(n, bool) and n >= 0):
            raise FieldError("refine_stall_evaluations",
                             f"must be an integer >= 0 (0: off), got {n!r}")
        try:  # the rule checks its other fields (with 0, off, as well)
            Stall(n or 1, self.refine_stall_tolerance, self.refine_stall_after)
        except FieldError as e:
            raise FieldError(f"refine_stall_{e.key}", e.message) from None
        if not isinstance(self.despike_pressure, bool):
            raise FieldError("despike_pressure",
                             f"must be true or false, got {self.despike_pressure!r}")
        if self.pressure_filter is not None and not isinstance(self.pressure_filter,
                                                               PressureFilter):
            raise TypeError("FitSettings.pressure_filter must be a PressureFilter or None, "
                            f"got {type(self.pressure_filter).__name__}")

    def stall(self) -> Stall | None:
        """The refinement's stall rule (None: off)."""
        if not self.refine_stall_evaluations:
            return None
        return Stall(self.refine_stall_evaluations, self.refine_stall_tolerance,
                     self.refine_stall_after)

    def to_dict(self) -> dict:
        return asdict(self)

    def preparation(self) -> dict:
        """How the recordings are prepared (:func:`pneubayes.io.prepare_recording`): the
        input low-passes, the pressure's despiking and the declared pressure filter, as the
        model card records them."""
        return {"position_cutoff_Hz": self.position_cutoff_Hz,
                "supply_cutoff_Hz": self.supply_cutoff_Hz,
                "despike_pressure": self.despike_pressure,
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
    for effect in model.effects:  # each effect's own generic start
        start.update(effect.start_values())
    notes.append("started from the Table II valve1 maps and a 1e-6 m^3 dead volume")
    return start, notes, "generic"


METHODS = ("lsq", "refine", "mcmc", "laplace")


def _emcee_summary(bi: BayesianIdentification) -> dict:
    return {"steps": bi.diagnostics_["steps"], "burn": bi.burn_,
            "n_walkers": int(bi.chain_.shape[1]), "tau_max": bi.diagnostics_["tau_max"],
            "acceptance_fraction": bi.acceptance_fraction_, "resumed": bi.resumed_}


def _laplace_summary(lap: LaplaceIdentification) -> dict:
    """A Laplace posterior's record in the summary: no chain (0 steps, no walkers); its
    draws, the negative Hessian's eigenvalues in the whitened coordinates and the centre.
    ``converged`` (beside it) says whether the log-posterior is concave there and the
    importance check finds the draws reliable."""
    d = lap.diagnostics_
    return {"steps": 0, "draws": d["draws"], "n_walkers": None, "tau_max": None,
            "hessian_eigenvalues": d["hessian_eigenvalues"],
            "non_concave_directions": d["non_concave_directions"],
            "mode_on_prior_bound": d["mode_on_prior_bound"],
            "importance_check": d["importance_check"],
            "centre": lap.centre_, "resumed": False}

#: A fit or held-out error above this x the noise floor is reported as misfit, never as
#: explained (fit, predict, the discovery report); an AR(1) noise coefficient above the
#: other limit means the noise model stands in for the misfit.
MISFIT_RATIO = 1.5
ABSORBING_AR1 = 0.9


#: A 90 % interval within this fraction of the bounds' width from a bound "sits" there.
BOUND_FRACTION = 0.01


def bound_scale(lower: float, upper: float):
    """The scale a parameter's closeness to its bounds is judged on: ``log10`` for
    bounds over two decades (a dead volume, 1e-8..1e-4 m^3; a time constant, 1e-4..20
    s), else the value itself."""
    return np.log10 if lower > 0 and upper / lower > 100 else (lambda v: v)


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
        f = bound_scale(a, b)
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




def posterior_draws(model: Model, idata, n_draws: int, rng: np.random.Generator,
                    source: str = "posterior"):
    """``(model draws (N, P), noise draws (N, 2))``: ``n_draws`` stored samples of
    ``idata`` (arviz InferenceData of a fit of ``model``) picked without replacement."""
    post = idata.posterior
    names = list(model.parameter_names) + ["noise_scale_Pa", "noise_ar1"]
    missing = [n for n in names if n not in post]
    if missing:
        raise ValueError(f"{source}: missing variables {missing}")
    flat = np.column_stack([np.asarray(post[n]).reshape(-1) for n in names])
    pick = rng.choice(flat.shape[0], size=min(n_draws, flat.shape[0]), replace=False)
    draws = flat[pick]
    return draws[:, : model.n_parameters], draws[:, model.n_parameters:]


class PosteriorDraws:
    """Draws and the controller API for a result with ``model``, ``posterior`` (arviz
    InferenceData or None) and a ``method`` that names it in errors."""

    def draws(self, n_draws: int, rng: np.random.Generator):
        """``(model draws (N, P), noise draws (N, 2))`` from the posterior."""
        if self.posterior is None:
            raise ValueError(f"a {self.method!r} result has no posterior; sample one "
                             "(fit: method 'mcmc'; discovery: posterior method 'emcee' "
                             "or 'laplace', `pneubayes discover --posterior`) for draws")
        return posterior_draws(self.model, self.posterior, n_draws, rng)

    def predictor(self, rig, solver: SolverConfig, n_draws: int,
                  rng: np.random.Generator) -> PressurePredictor:
        """The controller API over ``n_draws`` posterior draws."""
        return PressurePredictor(self.model, self.draws(n_draws, rng)[0], rig, solver)


@dataclass(frozen=True, eq=False)
class Fit(PosteriorDraws):
    """What a fit found, in memory.

    Attributes
    ----------
    model : Model
    method : "lsq", "refine" or "mcmc"
    params : the point estimate (the posterior median for "mcmc"), by parameter name
    summary : the diagnostics ``summary.json`` holds (start, refinement, posterior
        quantiles, R-hat and ESS, misfit against the noise floor, settings)
    preparation : how the recordings were prepared (the model card records it, and
        predictions prepare theirs the same way)
    posterior : arviz InferenceData of the chain ("mcmc"; None otherwise)
    recordings : the prepared recordings the fit saw
    """

    model: Model
    method: str
    params: dict
    summary: dict
    preparation: dict
    posterior: object | None = None
    recordings: tuple = field(default=(), repr=False)

    @property
    def noise_floor_Pa(self) -> float:
        """The recordings' white-noise floor (median over recordings), Pa."""
        return float(self.summary["noise_floor_Pa"])

    def card_extra(self) -> dict:
        """The model card's ``fit`` entry: what the estimate is and the preparation."""
        if self.method in ("mcmc", "laplace"):
            return {"fit": {"estimate": "posterior median", "posterior": "posterior.nc",
                            "posterior_method": "emcee" if self.method == "mcmc"
                            else "laplace",
                            "summary": "summary.json", **self.preparation}}
        return {"fit": {"estimate": self.method, **self.preparation}}


def identify(recordings, model: Model, settings: FitSettings, method: str = "mcmc",
             checkpoint_dir=None, progress: bool = False, log=None,
             laplace_draws: int = LAPLACE_DRAWS,
             laplace_check_draws: int = IMPORTANCE_CHECK_DRAWS) -> Fit:
    """Fit ``model`` to ``recordings`` in memory.

    Parameters
    ----------
    recordings : sequence of Recording
        The training recordings.
    model : Model
        The model to fit.
    settings : FitSettings
        Every setting of the fit.
    method : {"lsq", "refine", "mcmc", "laplace"}
        ``"lsq"`` stops after the paper's least squares (section VI-B), ``"refine"``
        after multiple shooting, ``"mcmc"`` (default) samples the posterior with emcee,
        ``"laplace"`` approximates it by a Gaussian at its mode
        (:mod:`pneubayes.inference.laplace`).
    checkpoint_dir : path or None
        A folder that keeps the chain (``chain.h5``) and the refined start
        (``refined.json``) as they are made, and resumes from them.
    progress : bool
        Show emcee's progress bar (``"mcmc"``).
    log : callable or None
        Receives progress lines (None: silent).
    laplace_draws, laplace_check_draws : int
        With ``"laplace"``: draws in place of a chain, and how many of the first are
        checked against the posterior's density.

    Returns
    -------
    Fit
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    log = log if log is not None else (lambda m: None)
    ckpt = None if checkpoint_dir is None else Path(checkpoint_dir)
    if ckpt is not None:
        ckpt.mkdir(parents=True, exist_ok=True)
    inputs_card = settings.preparation()
    recs = [prepare_recording(r, inputs_card) for r in recordings]
    t0 = time.perf_counter()
    noise = noise_floor_Pa(recs)
    stages = (_StageCache(ckpt / "refined.json", model, recs, settings)
              if ckpt is not None else None)
    saved = (stages.load() if stages is not None and method in ("mcmc", "laplace")
             else None)
    if saved is not None:
        start, notes, how = saved["start"], saved["notes"], saved["how"]
        log("fit: least squares and refinement skipped: their result is saved in "
            f"{stages.path}")
    else:
        start, notes, how = starting_point(model, recs, settings, noise)
        log(f"fit: start from {how}")

    def point(params, refined=None):
        return Fit(model, method, dict(params),
                   _point_summary(method, recs, start, notes, how, noise, settings, t0,
                                  refined), inputs_card, None, tuple(recs))

    if method == "lsq":
        if how != "paper least squares (eq. 10)":
            raise ValueError("--method lsq needs fixed-volume recordings at two or more "
                             "positions: " + "; ".join(notes))
        return point(start)
    data = WindowSet(recs, settings.horizon_s, settings.stride_s)
    if saved is not None:
        ref = saved["refined"]
    else:
        ref = TrajectoryRefiner(model, settings.refine_solver,
                                max_nfev=settings.refine_max_nfev,
                                jacobian_refresh=settings.refine_jacobian_refresh,
                                stall=settings.stall()).fit(data, start)
        log(f"fit: refined {settings.horizon_s:g}-s RMSE {ref.start_rmse_Pa_:.0f} -> "
            f"{ref.rmse_Pa_:.0f} Pa "
            f"({ref.n_evaluations_} evaluations)")
        if method in ("mcmc", "laplace") and stages is not None:
            stages.save(start, notes, how, ref)
    if method == "refine":
        return point(ref.params_, {"parameters": ref.params_, "rmse_Pa": ref.rmse_Pa_,
                                   "start_rmse_Pa": ref.start_rmse_Pa_})
    if method == "laplace":
        bi = LaplaceIdentification.from_sampler(model, settings.sample_solver,
                                                settings.sampler, laplace_draws,
                                                laplace_check_draws, log)
        bi.fit(data, ref.params_, ref.information_)
    else:
        bi = BayesianIdentification(model, settings.sample_solver, settings.sampler,
                                    backend_path=None if ckpt is None else ckpt / "chain.h5",
                                    progress=progress, log=log)
        bi.fit(data, ref.params_, information=ref.information_)
        log(f"fit: emcee {bi.diagnostics_['steps']} steps x {bi.chain_.shape[1]} walkers, "
            f"converged={bi.converged_}, {bi.wall_time_s_:.0f} s (solver rtol "
            f"{bi.solver_.rtol:.0e}, log-density roughness "
            f"{bi.diagnostics_['solver_jitter_nats']:.2f} nat)")
    median = bi.median_params()
    idata = bi.inference_data({"seed": settings.sampler.seed,
                               "pneubayes_version": pneubayes.__version__,
                               "model_card": json.dumps(model.to_card(median))})
    ident = identifiability_report(model, bi.names_, bi.samples())
    posterior = bi.summary()
    summary = {
        "format": "pneubayes-fit-summary/1", "method": method,
        "recordings": [str(r.source) for r in recs],
        "input_findings": recorded_findings(recs),
        "parameters": posterior,
        "converged": bi.converged_,
        **(_laplace_summary(bi) if method == "laplace" else _emcee_summary(bi)),
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
    return Fit(model, method, median, summary, inputs_card, idata, tuple(recs))
