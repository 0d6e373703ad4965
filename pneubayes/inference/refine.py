"""Trajectory-level refinement: multiple shooting on prediction windows.

Minimises the squared error of open-loop predictions over windows started from the
measured pressure (the paper's metric), with ``scipy.optimize.least_squares``
(trust-region reflective, within the model's bounds). The Jacobian is taken by forward
differences in ONE batched call of the compiled simulator (the base point plus one
perturbed copy per free parameter). Its result is the point that starts the sampler.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

#: Residual (Pa) returned for a trial point that does not simulate: far above any real
#: prediction error, so least squares never accepts the step.
FAILED_RESIDUAL_PA = 1e7


class TrajectoryRefiner:
    """Least squares on window predictions (scikit-learn estimator contract).

    Parameters
    ----------
    model : Model
    solver : SolverConfig
        Solver for the predictions; tighter than the finite-difference steps' effect.
    horizon_s, stride_s : float
        Prediction windows (2 s, non-overlapping in the paper's metric).
    free : sequence of str or None
        Parameters to fit (default: all); the others stay at their start values.
    relative_step : float
        Finite-difference step relative to each parameter's scale.
    max_nfev : int
        Budget of residual evaluations (each Jacobian is one more batched call).
    """

    def __init__(self, model: Model, solver: SolverConfig, horizon_s: float = 2.0,
                 stride_s: float = 2.0, free=None, relative_step: float = 1e-3,
                 max_nfev: int = 60):
        self.model = model
        self.solver = solver
        self.horizon_s = horizon_s
        self.stride_s = stride_s
        self.free = free
        self.relative_step = relative_step
        self.max_nfev = max_nfev

    def _scales(self, theta0: np.ndarray) -> np.ndarray:
        lo, hi = self.model.bounds
        return np.maximum(np.abs(theta0), 1e-2 * (hi - lo))

    def fit(self, recordings, start: dict) -> "TrajectoryRefiner":
        """Refine from ``start`` (a full parameter dict, e.g. the paper's least squares)."""
        model = self.model
        data = recordings if isinstance(recordings, WindowSet) else WindowSet(
            recordings, self.horizon_s, self.stride_s)
        theta0 = model.vector(start)
        names = list(model.parameter_names)
        free = list(self.free) if self.free is not None else names
        unknown = [n for n in free if n not in names]
        if unknown:
            raise ValueError(f"free: {unknown} are not parameters of {model}")
        idx = np.array([names.index(n) for n in free])
        lo, hi = model.bounds
        flo, fhi = lo[idx], hi[idx]
        scale = self._scales(theta0)[idx]
        x0 = np.clip(theta0[idx], flo + 1e-9 * (fhi - flo), fhi - 1e-9 * (fhi - flo))
        cache: dict = {}

        def full(x):
            th = theta0.copy()
            th[idx] = x
            return th

        def batch(x):
            key = x.tobytes()
            if key in cache:
                return cache[key]
            steps = self.relative_step * scale
            up = x + steps > fhi
            steps = np.where(up, -steps, steps)  # step inward at the upper bound
            rows = [full(x)]
            for j in range(x.size):
                xj = x.copy()
                xj[j] += steps[j]
                rows.append(full(xj))
            r = data.residuals(model, np.array(rows), self.solver, on_failure="nan")
            r = r.reshape(r.shape[0], -1)
            if not np.all(np.isfinite(r[0])):
                if not cache and np.array_equal(x, x0):
                    raise FloatingPointError("refinement: the simulation fails at the start "
                                             f"parameters {model.as_dict(full(x))}")
                # a trial step the solver cannot simulate: a residual so large that the
                # trust region rejects the step and shrinks (the cache keeps the last good)
                bad = np.full(r.shape[1], FAILED_RESIDUAL_PA)
                return bad, np.zeros((r.shape[1], x.size))
            jac = (r[1:] - r[0]).T / steps
            jac[~np.isfinite(jac)] = 0.0
            cache.clear()
            cache[key] = (r[0], jac)
            return cache[key]

        sol = optimize.least_squares(lambda x: batch(x)[0], x0, jac=lambda x: batch(x)[1],
                                     bounds=(flo, fhi), x_scale=scale, method="trf",
                                     max_nfev=self.max_nfev, xtol=1e-8, ftol=1e-10)
        theta = full(sol.x)
        r, jac = batch(sol.x)
        n, p = r.size, idx.size
        sigma2 = float(r @ r) / max(n - p, 1)
        cov = sigma2 * np.linalg.pinv(jac.T @ jac)
        self.params_ = model.as_dict(theta)
        self.free_ = tuple(free)
        self.covariance_ = cov
        self.rmse_Pa_ = float(np.sqrt(np.mean(r * r)))
        r0 = data.residuals(model, theta0[None], self.solver)
        self.start_rmse_Pa_ = float(np.sqrt(np.mean(r0 * r0)))
        self.n_evaluations_ = int(sol.nfev)
        self.success_ = bool(sol.success)
        self.message_ = str(sol.message)
        return self
