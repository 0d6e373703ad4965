"""The Tassa et al. (2013) peer baseline (issue 5), fitted on our 2-s window metric.

:class:`TassaModel` fits the ten parameters of the first-order pressure model to
recordings and predicts windows the way :func:`pneubayes.evaluation.predict_windows`
does for the thin-port model, so both are scored alike. The model itself (formulas,
units, the exact zero-order-hold step, the window simulator) lives in
:mod:`pneubayes.baselines.tassa_dynamics`, and its public names are re-exported here.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from pneubayes.baselines.tassa_dynamics import (
    _PA_PER_MPA,
    COMMAND_FULL_SCALE_V,
    LOWER_BOUNDS,
    PARAMETER_NAMES,
    PUBLISHED_PARAMETERS,
    SOFTABS_EPS,
    UPPER_BOUNDS,
    TassaInputs,
    _as_params,
    _simulate_MPa,
    simulate_windows,
    tassa_coefficients,
    tassa_rhs,
    zoh_step,
)
from pneubayes.errors import ParameterError, PneubayesError
from pneubayes.evaluation import PAPER_HORIZON_S, WindowPrediction, window_starts
from pneubayes.io.recording import Recording

__all__ = ["COMMAND_FULL_SCALE_V", "LOWER_BOUNDS", "PARAMETER_NAMES", "PUBLISHED_PARAMETERS",
           "SOFTABS_EPS", "UPPER_BOUNDS", "NotFittedError", "TassaInputs", "TassaModel",
           "simulate_windows", "tassa_coefficients", "tassa_rhs", "zoh_step"]

_RATE_PARAMETERS = (5, 7, 9)  # c5, c7, c9: every rate of the model is proportional to them


class NotFittedError(PneubayesError, ValueError, AttributeError):
    """An estimator was used before ``fit``."""


# ------------------------------------------------------------------ the estimator
@dataclass(frozen=True)
class _Block:
    """One recording cut into windows."""

    inputs: TassaInputs
    pressure_Pa: np.ndarray   # (N,)
    starts: np.ndarray        # (W,)
    length: int
    measured_Pa: np.ndarray   # (W, L)
    working_range_Pa: float

    def simulate(self, c: np.ndarray, softabs_eps: float) -> np.ndarray:
        """Predictions ``(B, W, L)``, Pa, for ``c (B, 10)``, from the measured starts."""
        return _simulate_MPa(c, self.inputs, self.starts, self.length,
                             self.measured_Pa[:, 0] / _PA_PER_MPA, softabs_eps) * _PA_PER_MPA


def _recordings(recordings) -> list[Recording]:
    if isinstance(recordings, Recording):
        recs = [recordings]
    elif isinstance(recordings, (str, bytes)) or not isinstance(recordings, Iterable):
        raise TypeError(f"recordings must be a Recording or a sequence of them, got "
                        f"{type(recordings).__name__} (read files with "
                        f"pneubayes.io.read_recording)")
    else:
        recs = list(recordings)
    if not recs:
        raise ValueError("recordings is empty: fit needs at least one Recording")
    for i, r in enumerate(recs):
        if not isinstance(r, Recording):
            raise TypeError(f"recordings[{i}] is a {type(r).__name__}, not a "
                            f"pneubayes.io.Recording (read one with read_recording)")
    return recs


def _uninformed(blocks) -> tuple[str, ...]:
    """Parameters the data cannot inform, held at their initial values.

    c5 multiplies the velocity: without motion (all v = 0) it has no effect. c6 scales
    the volume ratio 1 + c6 x: at a single position it only rescales c5, c7 and c9.
    """
    x = np.concatenate([b.inputs.position for b in blocks])
    v = np.concatenate([b.inputs.velocity for b in blocks])
    return (("c5",) if not np.any(v) else ()) + (("c6",) if np.ptp(x) == 0 else ())


def _positive(name: str, value, integer: bool = False, minimum: float = 0.0) -> None:
    if integer:
        ok = (isinstance(value, numbers.Integral) and not isinstance(value, bool)
              and value >= minimum)
        want = f"an integer >= {minimum:g}"
    else:
        ok = (isinstance(value, numbers.Real) and not isinstance(value, bool)
              and np.isfinite(value) and value > minimum)
        want = f"a finite number > {minimum:g}"
    if not ok:
        raise ValueError(f"TassaModel({name}=...) must be {want}, got {value!r}")


class TassaModel:
    """The Tassa et al. (2013) baseline, fitted on the paper's 2-s window metric.

    A scikit-learn estimator (``fit`` returns self; learned attributes end in ``_``);
    :meth:`fit` describes its two least-squares stages.

    Parameters
    ----------
    horizon_s, stride_s : float
        Prediction windows, s (2 s, non-overlapping, as in the paper).
    max_nfev, seed : int
        Residual evaluations allowed in the trajectory stage; the restarts' seed.
    initial_params : array_like (10,) or mapping, optional
        Start of both stages; default :data:`PUBLISHED_PARAMETERS`.
    n_restarts, one_step_max_nfev : int
        Extra one-step starts around ``initial_params``; evaluations allowed per start.
    tol : float
        ``ftol = xtol = gtol`` of both least-squares stages.
    tr_solver : {"exact", "lsmr"}
        scipy's trust-region solver: "exact" (an SVD per iteration; fewer iterations in
        the narrow c0, c1, c3, c4 valley) or "lsmr" (no SVD, for a busy machine).
    softabs_eps : float
        Smoothing of softabs (:data:`SOFTABS_EPS`).

    Attributes
    ----------
    params_ : ndarray (10,)
        Fitted c0..c9.
    rmse_Pa_, start_rmse_Pa_ : float
        Window RMSE on the training recordings, Pa (windows pooled); at the start.
    one_step_params_ : ndarray (10,)
        The stage-1 candidate that started stage 2.
    frozen_ : tuple of str
        Held at ``initial_params``: c5 without motion, c6 at a single position.
    n_evaluations_ : int
        Residual evaluations of both stages (Jacobians not included, as scipy counts).
    success_, message_ : bool, str
        Convergence of the trajectory stage, as scipy reports it.
    """

    def __init__(self, horizon_s: float = PAPER_HORIZON_S,
                 stride_s: float = PAPER_HORIZON_S, max_nfev: int = 200,
                 seed: int = 0, initial_params=None, n_restarts: int = 3,
                 one_step_max_nfev: int = 200, tol: float = 1e-8, tr_solver: str = "exact",
                 softabs_eps: float = SOFTABS_EPS):
        self.horizon_s = horizon_s
        self.stride_s = stride_s
        self.max_nfev = max_nfev
        self.seed = seed
        self.initial_params = initial_params
        self.n_restarts = n_restarts
        self.one_step_max_nfev = one_step_max_nfev
        self.tol = tol
        self.tr_solver = tr_solver
        self.softabs_eps = softabs_eps

    # ------------------------------------------------------------ validation
    def _check_windows(self) -> None:
        _positive("horizon_s", self.horizon_s)
        _positive("stride_s", self.stride_s)
        _positive("softabs_eps", self.softabs_eps)

    def _check_settings(self) -> np.ndarray:
        self._check_windows()
        _positive("max_nfev", self.max_nfev, integer=True, minimum=1)
        _positive("one_step_max_nfev", self.one_step_max_nfev, integer=True, minimum=1)
        _positive("n_restarts", self.n_restarts, integer=True, minimum=0)
        _positive("tol", self.tol)
        if self.tr_solver not in ("exact", "lsmr"):
            raise ValueError(f"TassaModel(tr_solver=...) must be 'exact' or 'lsmr', got "
                             f"{self.tr_solver!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral):
            raise ValueError(f"TassaModel(seed=...) must be an integer, got {self.seed!r}")
        init = PUBLISHED_PARAMETERS if self.initial_params is None else self.initial_params
        c = _as_params(init, "initial_params")
        if c.ndim != 1:
            raise ParameterError(f"initial_params must be one set of 10 values, got shape "
                                 f"{c.shape}")
        lo, hi = np.array(LOWER_BOUNDS), np.array(UPPER_BOUNDS)
        for j in np.flatnonzero((c < lo) | (c > hi)):
            raise ParameterError(f"initial_params: c{j} = {float(c[j])!r} is outside its fitting "
                                 f"bounds [{lo[j]}, {hi[j]}] (tassa.LOWER_BOUNDS/UPPER_BOUNDS)")
        return c

    def _block(self, rec: Recording) -> _Block:
        try:
            starts, length = window_starts(rec.time_s, self.horizon_s, self.stride_s)
            inputs = TassaInputs.from_recording(rec)
        except ValueError as exc:
            raise ValueError(f"recording {rec.source or '(in memory)'}: {exc}") from None
        p = np.asarray(rec.pressure_Pa, dtype=np.float64)
        idx = starts[:, None] + np.arange(length)[None, :]
        return _Block(inputs, p, starts, int(length), p[idx], float(rec.working_range_Pa))

    # ------------------------------------------------------------ fitting
    def fit(self, recordings) -> TassaModel:
        """Fit c0..c9 to one or more recordings (:class:`~pneubayes.io.Recording`).

        Two ``scipy.optimize.least_squares`` stages (trust-region reflective, within
        :data:`LOWER_BOUNDS` / :data:`UPPER_BOUNDS`):

        1. One-step errors ``p[k+1] - zoh_step(p[k])`` from the *measured* ``p[k]``: the
           dp/dt residual in exact integral form (as :mod:`pneubayes.discovery.one_step`),
           with no derivative of the noisy pressure. (a) One factor on the rates c5, c7,
           c9 first adapts the initial set's time scale (the published rates are about
           100 times too slow for small chambers); (b) then every free parameter is
           fitted from there and from ``n_restarts`` seeded log-normal jitters of it.
        2. Errors over windows of ``horizon_s`` every ``stride_s``, each started from the
           measured pressure, its start not scored (:func:`simulate_windows`): the metric
           the thin-port model is refined and scored on. It starts from the stage-1
           candidate with the lowest window error; its Jacobian is forward differences
           (relative step 1e-6) in one batched, exact simulation.

        Returns
        -------
        TassaModel
            ``self``, fitted.
        """
        init = self._check_settings()
        blocks = [self._block(r) for r in _recordings(recordings)]
        eps, tol = float(self.softabs_eps), float(self.tol)
        frozen = _uninformed(blocks)
        free = np.array([j for j in range(init.size) if PARAMETER_NAMES[j] not in frozen])
        lo, hi = np.array(LOWER_BOUNDS)[free], np.array(UPPER_BOUNDS)[free]
        rng = np.random.default_rng(self.seed)
        options = dict(bounds=(lo, hi), x_scale="jac", method="trf", tr_solver=self.tr_solver,
                       ftol=tol, xtol=tol, gtol=tol)

        def full(x2d):
            c = np.repeat(init[None], x2d.shape[0], axis=0)
            c[:, free] = x2d
            return c

        def one_step(x):
            c = full(x[None])[0]
            parts = []
            for b in blocks:
                decay, forcing = b.inputs.step_coefficients(c, eps)
                p = b.pressure_Pa / _PA_PER_MPA
                parts.append((p[1:] - decay * p[:-1] - forcing) * _PA_PER_MPA)
            return np.concatenate(parts)

        # 1a. the published set comes from another rig: first adapt its time scale,
        # multiplying every rate parameter (c5, c7, c9) by one factor exp(z)
        rates = np.isin(free, _RATE_PARAMETERS)

        def rescaled(z):
            x = init[free].copy()
            x[rates] *= np.exp(z[0])
            return x

        scale = optimize.least_squares(lambda z: one_step(rescaled(z)), [0.0], method="trf",
                                       max_nfev=self.one_step_max_nfev, ftol=tol, xtol=tol,
                                       gtol=tol)
        start = np.clip(rescaled(scale.x), lo, hi)
        # 1b. all free parameters, from there and from jitters of it
        starts = [start]
        for _ in range(self.n_restarts):
            jitter = start * np.exp(rng.normal(0.0, 0.5, free.size))
            starts.append(np.clip(jitter, lo + 0.01, hi - 0.01))
        nfev = scale.nfev
        candidates = [start]
        for x0 in starts:
            sol = optimize.least_squares(one_step, x0, max_nfev=self.one_step_max_nfev,
                                         **options)
            nfev += sol.nfev
            candidates.append(sol.x)

        def windows(x2d):
            c = full(x2d)
            res = [(b.simulate(c, eps) - b.measured_Pa[None])[:, :, 1:] for b in blocks]
            return np.concatenate([r.reshape(c.shape[0], -1) for r in res], axis=1)

        last: dict = {}

        def fun(x):
            r = windows(x[None])[0]
            last.update(x=x.copy(), r=r)
            return r

        def jac(x):
            r0 = last["r"] if "x" in last and np.array_equal(last["x"], x) else fun(x)
            h = 1e-6 * np.maximum(np.abs(x), 1e-2)
            h = np.where(x + h > hi, -h, h)  # step inward at an upper bound
            J = ((windows(x[None] + np.diag(h)) - r0[None]) / h[:, None]).T
            J[~np.isfinite(J)] = 0.0
            return J

        def mean_square(x):
            r = windows(x[None])[0]
            return float(np.mean(r * r))

        # 2. from the candidate with the lowest window error (the metric itself)
        start_ms = mean_square(init[free])
        errors = np.array([mean_square(x) for x in candidates])
        if not np.any(np.isfinite(errors)):
            raise FloatingPointError("TassaModel.fit: the window predictions overflow at every "
                                     "stage-1 candidate; pass initial_params closer to the data")
        best = candidates[int(np.argmin(np.where(np.isfinite(errors), errors, np.inf)))]
        x0 = best
        sol = optimize.least_squares(fun, x0, jac=jac, max_nfev=self.max_nfev, **options)
        self.params_ = full(sol.x[None])[0]
        self.one_step_params_ = full(best[None])[0]
        self.frozen_ = frozen
        self.rmse_Pa_ = float(np.sqrt(mean_square(sol.x)))
        self.start_rmse_Pa_ = float(np.sqrt(start_ms))
        self.n_evaluations_ = int(nfev + sol.nfev)
        self.success_ = bool(sol.success)
        self.message_ = str(sol.message)
        return self

    # ------------------------------------------------------------ prediction
    def predict_windows(self, recording: Recording, params=None) -> WindowPrediction:
        """Window predictions on ``recording``, as :func:`pneubayes.evaluation.predict_windows`.

        ``params``: c0..c9 ``(10,)`` or ``(B, 10)`` instead of the fitted ``params_``
        (e.g. :data:`PUBLISHED_PARAMETERS`). ``predicted_Pa`` is ``(B, W, L)`` with B = 1
        for one set; ``rmse_Pa()`` and ``rmse_percent_of_range()`` follow.
        """
        if params is None:
            if not hasattr(self, "params_"):
                raise NotFittedError("TassaModel is not fitted: call fit(recordings) first, "
                                     "or pass params=")
            params = self.params_
        c = np.atleast_2d(_as_params(params))
        self._check_windows()
        if not isinstance(recording, Recording):
            raise TypeError(f"recording must be a pneubayes.io.Recording, got "
                            f"{type(recording).__name__}")
        block = self._block(recording)
        return WindowPrediction(block.starts, block.length,
                                block.simulate(c, float(self.softabs_eps)),
                                block.measured_Pa, block.working_range_Pa)
