"""Trajectory-level refinement: multiple shooting on prediction windows.

Minimises the squared error of open-loop predictions over windows started from the
measured pressure (the paper's metric), with ``scipy.optimize.least_squares``
(trust-region reflective, within the model's bounds). The Jacobian is taken by forward
differences in ONE batched call of the compiled simulator (one perturbed copy per free
parameter), at accepted points only: a rejected trial step costs one simulation. The
trust region accepts nearly every step, so with ``jacobian_refresh`` k > 1 the
finite-difference Jacobian is taken at every k-th accepted point and updated between by
Broyden's secant from the residuals already simulated (on a refit beside Table III's
AIR37 wave tube, 17 parameters: 57 of 60 evaluations had asked for a Jacobian; every
4th took one pass from 1268 to 321 s, 1.2 Pa higher). Its result is the point that
starts the sampler.

An effect that takes part of the dead volume out of the chamber (an acoustic line,
:meth:`~pneubayes.effects.Effect.volume_taken_m3`) makes ``chamber = dead volume - taken
> 0`` a constraint across parameters, which a trust region confined to bounds cannot
follow: a step across it fails to simulate and is rejected, so a fit can stall there.
The refiner therefore moves the chamber's own volume in place of the dead volume (a box
bound: the dead volume's), and maps back, so a fit slides along the wall instead. On a
spent blind case (a 2.9-m, 1.8-mm tube holding 94 % of the dead volume, 508-Pa noise)
the discovery loop's line fit had stopped at the wall (chamber ~0) at 4530 Pa; refitted
from a start inside (the line at half the dead volume) it reached 1919 Pa this way and
2074 Pa moving the dead volume (one case: the start mattered more than the
coordinates).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from pneubayes import interrupt
from pneubayes.evaluation import PAPER_HORIZON_S
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.settings_tree import FieldError
from pneubayes.simulation import SolverConfig

#: Residual (Pa) returned for a trial point that does not simulate: far above any real
#: prediction error, so least squares never accepts the step.
FAILED_RESIDUAL_PA = 1e7


@dataclass(frozen=True)
class GaussianAnchor:
    """A Gaussian prior on free parameters, added to the least squares as rows.

    Each named parameter gets the row ``error_Pa (theta - mean) / sd``, so the fit
    minimises ``sum r^2 + error_Pa^2 sum ((theta - mean) / sd)^2``: the posterior mode
    when the window residuals ``r`` (Pa) are Gaussian with the scale ``error_Pa``.
    ``mean`` and ``sd`` map parameter names to values in the parameters' units (``sd`` >
    0); a free parameter absent from ``sd`` has no prior row. Residuals within a window
    are correlated, so ``error_Pa`` above their RMSE weighs the data as the fewer
    independent samples they are. A free dead volume's row is on the chamber's own
    volume (the coordinate the refiner moves), its mean shifted by what the effects
    take at ``mean``.
    """

    mean: Mapping[str, float]
    sd: Mapping[str, float]
    error_Pa: float

    def __post_init__(self):
        if not (np.isfinite(self.error_Pa) and self.error_Pa > 0):
            raise ValueError(f"GaussianAnchor: error_Pa must be > 0, got {self.error_Pa!r}")
        bad = [n for n, v in self.sd.items() if not (np.isfinite(v) and v > 0)]
        if bad:
            raise ValueError(f"GaussianAnchor: sd must be > 0 and finite, not for {bad}")
        missing = [n for n in self.sd if n not in self.mean]
        if missing:
            raise ValueError(f"GaussianAnchor: no mean for {missing}")

    @classmethod
    def relative(cls, model: Model, params: Mapping[str, float], names,
                 relative_sd: float | Mapping[str, float], error_Pa: float) -> "GaussianAnchor":
        """Centred on ``params`` with ``sd = relative_sd x`` each parameter's scale (its
        magnitude, or 1 % of its bounds' width where larger: the refiner's own scale).
        ``relative_sd`` is one fraction for all, or each name's own (a mapping: e.g. the
        spread of per-run fits, :func:`relative_spread`)."""
        all_names = list(model.parameter_names)
        unknown = [n for n in names if n not in all_names]
        if unknown:
            raise ValueError(f"GaussianAnchor.relative: {unknown} are not parameters of "
                             f"{model}")
        if isinstance(relative_sd, Mapping):
            missing = [n for n in names if n not in relative_sd]
            if missing:
                raise ValueError(f"GaussianAnchor.relative: relative_sd has no value for "
                                 f"{missing}")
            fraction = {n: float(relative_sd[n]) for n in names}
        else:
            fraction = {n: float(relative_sd) for n in names}
        bad = {n: v for n, v in fraction.items() if not (np.isfinite(v) and v > 0)}
        if bad:
            raise ValueError(f"relative_sd must be > 0, got {bad}")
        scale = parameter_scales(model, model.vector(params))
        return cls({n: float(params[n]) for n in names},
                   {n: fraction[n] * float(scale[all_names.index(n)]) for n in names},
                   float(error_Pa))


def relative_spread(model: Model, centre: Mapping[str, float], fits, names,
                    floor: float) -> dict[str, float]:
    """Each of ``names``' spread over per-run fits about ``centre``, as a fraction of its
    scale (:func:`parameter_scales` at ``centre``): the root mean square of
    ``(fit - centre) / scale`` over ``fits`` (mappings of every parameter), at least
    ``floor`` (> 0): :meth:`GaussianAnchor.relative`'s per-quantity ``relative_sd``.
    Where one run alone pins a quantity poorly its fits wander, and the spread measures
    that as well as how the plant varies between runs."""
    fits = list(fits)
    if not fits:
        raise ValueError("relative_spread: no per-run fits")
    if not (np.isfinite(floor) and floor > 0):
        raise ValueError(f"relative_spread: floor must be > 0, got {floor!r}")
    all_names = list(model.parameter_names)
    scale = parameter_scales(model, model.vector(centre))
    out = {}
    for n in names:
        if n not in all_names:
            raise ValueError(f"relative_spread: {n!r} is not a parameter of {model}")
        z = [(float(f[n]) - float(centre[n])) / scale[all_names.index(n)] for f in fits]
        out[n] = max(float(np.sqrt(np.mean(np.square(z)))), float(floor))
    return out


@dataclass(frozen=True)
class Stall:
    """When a refinement has stopped gaining: after at least ``after`` residual
    evaluations, the best RMSE of the points simulated fell by under ``tolerance`` of
    itself over the last ``evaluations`` of them (rejected trial points count). A trust
    region in a curved valley crawls towards its optimum long after it is within a
    fraction of a pascal of it; a plateau early in a fit can still end in a fall, so the
    rule waits ``after`` evaluations (the choice: docs/history.md, 2026-12-08).
    """

    evaluations: int = 10
    tolerance: float = 1e-4
    after: int = 25

    def __post_init__(self):
        for name in ("evaluations", "after"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                raise FieldError(name, f"must be an integer >= 1, got {v!r}")
        if not (isinstance(self.tolerance, (int, float)) and 0.0 < self.tolerance < 1.0):
            raise FieldError("tolerance", f"must be a number in (0, 1), got "
                             f"{self.tolerance!r}")

    def reached(self, rmse_trace) -> bool:
        """True when ``rmse_trace`` (the RMSE of each point simulated, in order) has
        stalled."""
        n = len(rmse_trace)
        if n < max(self.after, self.evaluations + 1):
            return False
        before = min(rmse_trace[: n - self.evaluations])
        return not min(rmse_trace[n - self.evaluations:]) < before * (1.0 - self.tolerance)


def parameter_scales(model: Model, theta: np.ndarray) -> np.ndarray:
    """Each parameter's scale: its magnitude at ``theta``, or 1 % of its bounds' width
    where larger (the refiner's coordinates are ``theta / scale``)."""
    lo, hi = model.bounds
    return np.maximum(np.abs(theta), 1e-2 * (hi - lo))


def _volume_taken(model: Model, rig):
    """``theta -> m^3`` the model's effects take out of the dead volume (an acoustic
    line's volume), or None when none takes any."""
    takers = [e for e in model.effects
              if e.volume_taken_m3(e.neutral_values() | model.neutral_values(), rig)
              is not None]
    if not takers:
        return None

    def taken(theta):
        values = model.as_dict(theta)
        return float(sum(e.volume_taken_m3(values, rig) for e in takers))
    return taken


def late_gain(rmse_trace) -> float:
    """The share by which the best RMSE of a fit's points (``rmse_trace_``, Pa, in the
    order simulated) fell over their second half: ``1 - best / best of the first half``;
    near 0 for a fit that crawls at its end. inf for fewer than 2 points."""
    trace = np.asarray(rmse_trace, dtype=float)
    if trace.size < 2:
        return float("inf")
    early = float(np.min(trace[: trace.size // 2]))
    return 1.0 - float(np.min(trace)) / early if early > 0 else 0.0


def _chamber_map(taken, theta, idx, dead, scale) -> np.ndarray:
    """``d x / d theta`` of the free parameters, x being theta with the dead volume
    replaced by the chamber's (dead minus ``taken``): the identity but for the chamber's
    row, ``-d taken / d theta_k`` (central differences, 1e-6 of each scale)."""
    m = np.eye(idx.size)
    for k in range(idx.size):
        if k == dead:
            continue
        step = 1e-6 * scale[k]
        up, dn = theta.copy(), theta.copy()
        up[idx[k]] += step
        dn[idx[k]] -= step
        m[dead, k] = -(taken(up) - taken(dn)) / (2.0 * step)
    return m


class TrajectoryRefiner:
    """Least squares on window predictions (scikit-learn estimator contract).

    Parameters
    ----------
    model, solver : Model, SolverConfig
        The model; the predictions' solver (tighter than the finite differences' steps).
    horizon_s, stride_s : float
        Prediction windows (2 s, non-overlapping in the paper's metric).
    free : sequence of str or None
        Parameters to fit (default: all); the others stay at their start values.
    relative_step, max_nfev : float, int
        Finite-difference step relative to each parameter's scale; budget of residual
        evaluations (each Jacobian is one more batched call).
    jacobian_refresh : int
        Accepted points per finite-difference Jacobian: k > 1 updates it between by
        Broyden's rank-1 secant (scaled coordinates; Broyden 1965) from the residuals
        the trust region has (the information and covariance: always differences).
    uncertainty : bool
        Take the information and covariance at the fitted point (one more Jacobian
        unless the last was taken there); False: both None.
    xtol, ftol : float
        The trust region's stopping tolerances (scipy's ``least_squares``, scaled
        coordinates: a step, or a predicted and an actual fall of the cost, under them).
    stall : Stall or None
        Also end the fit where its best RMSE stopped falling (:class:`Stall`).
    anchor : GaussianAnchor or None
        A Gaussian prior (rows of the least squares): the fit is its posterior mode.
    extra_residuals : callable or None
        ``f(theta (B, P)) -> (B, M)`` more residual rows, Pa-equivalent (e.g. measured
        flows, :func:`~pneubayes.inference.flow_channels.flow_rows`); not in ``rmse_Pa_``.

    After ``fit``: ``params_``; ``information_``, the Gauss-Newton Fisher information
    ``J^T J / sigma^2`` of the free parameters at ``params_`` (natural units), and
    ``covariance_``, its pseudo-inverse (the Laplace covariance; both None without
    ``uncertainty``; with an anchor, the information at ``anchor.error_Pa`` and the
    covariance with the anchor's precision added); ``rmse_Pa_``;
    ``rmse_trace_``, the RMSE (Pa) of every point simulated, in order (rejected trials
    too, failed ones left out); ``success_``: False when the budget ended the fit
    (``stalled_``: ``stall`` ended it, a success).
    """

    def __init__(self, model: Model, solver: SolverConfig, horizon_s: float = PAPER_HORIZON_S,
                 stride_s: float = PAPER_HORIZON_S, free=None, relative_step: float = 1e-3,
                 max_nfev: int = 60, jacobian_refresh: int = 1, uncertainty: bool = True,
                 xtol: float = 1e-8, ftol: float = 1e-10, anchor: GaussianAnchor | None = None,
                 extra_residuals=None, stall: "Stall | None" = None):
        if stall is not None and not isinstance(stall, Stall):
            raise TypeError(f"stall must be a Stall or None, got {stall!r}")
        if extra_residuals is not None and not callable(extra_residuals):
            raise TypeError("extra_residuals must be a callable or None")
        if anchor is not None and not isinstance(anchor, GaussianAnchor):
            raise TypeError(f"anchor must be a GaussianAnchor or None, got {anchor!r}")
        if int(jacobian_refresh) != jacobian_refresh or jacobian_refresh < 1:
            raise ValueError(f"jacobian_refresh must be an integer >= 1, got "
                             f"{jacobian_refresh!r}")
        for name, tol in (("xtol", xtol), ("ftol", ftol)):
            if not (isinstance(tol, (int, float)) and 0.0 < tol < 1.0):
                raise ValueError(f"{name} must be a number in (0, 1), got {tol!r}")
        self.model = model
        self.solver = solver
        self.horizon_s = horizon_s
        self.stride_s = stride_s
        self.free = free
        self.relative_step = relative_step
        self.max_nfev = max_nfev
        self.jacobian_refresh = int(jacobian_refresh)
        self.uncertainty = uncertainty
        self.xtol = float(xtol)
        self.ftol = float(ftol)
        self.anchor = anchor
        self.extra_residuals = extra_residuals
        self.stall = stall

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
        scale = parameter_scales(model, theta0)[idx]
        taken = _volume_taken(model, data.blocks[0].rig)
        # the chamber's own volume moves in place of a free dead volume (module docstring)
        dead = free.index("dead_volume_m3") if (taken is not None
                                                and "dead_volume_m3" in free) else None
        theta_start = theta0.copy()
        if dead is not None:
            theta_start[idx[dead]] = theta0[idx[dead]] - taken(theta0)
        x0 = np.clip(theta_start[idx], flo + 1e-9 * (fhi - flo), fhi - 1e-9 * (fhi - flo))
        res_cache: dict = {}
        failed: set = set()
        trace: list = []  # the RMSE of each point simulated, in order (failed: none)

        def full(x):
            th = theta0.copy()
            th[idx] = x
            if dead is not None:  # dead volume = chamber + what the effects take
                th[idx[dead]] = min(x[dead] + taken(th), fhi[dead])
            return th

        def residual(x):
            # one simulation per trial point: the trust region rejects many trials, and
            # those need no Jacobian (it is asked for at accepted points only)
            key = x.tobytes()
            if key not in res_cache:
                interrupt.check()  # between compiled calls: a clean stop point
                r = data.residuals(model, full(x)[None], self.solver, on_failure="nan")
                r = r.reshape(-1)
                if not np.all(np.isfinite(r)):
                    if np.array_equal(x, x0) and not res_cache:
                        raise FloatingPointError("refinement: the simulation fails at the "
                                                 f"start parameters {model.as_dict(full(x))}")
                    # a trial step the solver cannot simulate: a residual so large that
                    # the trust region rejects the step and shrinks
                    r = np.full(r.size, FAILED_RESIDUAL_PA)
                    failed.add(key)
                else:
                    trace.append(float(np.sqrt(np.mean(r * r))))
                if len(res_cache) > 8:
                    res_cache.clear()
                res_cache[key] = r
            return res_cache[key]

        last: dict = {}  # the last Jacobian: its point (key, x), residuals there, age

        def perturbed(x):
            """Forward-difference steps (inward at the upper bound) and the perturbed
            full parameter sets, one per free parameter."""
            steps = self.relative_step * scale
            steps = np.where(x + steps > fhi, -steps, steps)
            rows = []
            for j in range(x.size):
                xj = x.copy()
                xj[j] += steps[j]
                rows.append(full(xj))
            return steps, np.array(rows)

        def jacobian(x, fresh=False):
            key = x.tobytes()
            if last and last["key"] == key and not (fresh and last["age"]):
                return last["jac"]
            interrupt.check()
            r0 = residual(x)
            if key in failed:  # never accepted; no slope to take
                return np.zeros((r0.size, x.size))
            if not fresh and last and last["age"] + 1 < self.jacobian_refresh:
                # Broyden's update in the scaled coordinates: the secant through the
                # previous accepted point, the least change to its Jacobian
                ds = (x - last["x"]) / scale
                js = last["jac"] * scale
                den = float(ds @ ds)
                if den > 0.0:
                    js = js + np.outer(r0 - last["r"] - js @ ds, ds / den)
                jac, age = js / scale, last["age"] + 1
            else:
                steps, rows = perturbed(x)
                # the perturbed copies in ONE batched call of the compiled simulator
                r = data.residuals(model, rows, self.solver, on_failure="nan")
                r = r.reshape(r.shape[0], -1)
                jac, age = (r - r0).T / steps, 0
                jac[~np.isfinite(jac)] = 0.0
            last.update(key=key, x=x.copy(), r=r0, jac=jac, age=age)
            return jac

        w_prior, mu_prior = self._anchor_rows(free, taken, dead, theta0)
        anchored = np.flatnonzero(w_prior)
        extra = self.extra_residuals

        def extra_rows(x):
            return extra(full(x)[None])[0]

        def extra_jacobian(x):
            steps, rows = perturbed(x)  # the same differences, in one call
            return (extra(rows) - extra_rows(x)).T / steps

        def fun(u):
            r = residual(u * scale)
            if extra is not None:
                r = np.concatenate([r, extra_rows(u * scale)])
            if not anchored.size:
                return r
            return np.concatenate([r, w_prior[anchored] * (u * scale - mu_prior)[anchored]])

        def jac(u):
            j = jacobian(u * scale) * scale
            if extra is not None:
                j = np.vstack([j, extra_jacobian(u * scale) * scale])
            if not anchored.size:
                return j
            return np.vstack([j, np.diag(w_prior * scale)[anchored]])

        # least squares runs on x / scale, every variable of order 1: scipy's trust region
        # keeps its start strictly feasible with an absolute margin of 1e-10, which for a
        # parameter of order 1e-16 (a laminar leak conductance, kg/(s Pa^2)) moved it to
        # the middle of its bounds before the first evaluation
        def stop_if_stalled(x):  # after each accepted step (scipy's status -2)
            if self.stall.reached(trace):
                raise StopIteration

        sol = optimize.least_squares(fun, x0 / scale, jac=jac,
                                     bounds=(flo / scale, fhi / scale), method="trf",
                                     max_nfev=self.max_nfev, xtol=self.xtol, ftol=self.ftol,
                                     callback=None if self.stall is None
                                     else stop_if_stalled)
        x_sol = np.clip(sol.x * scale, flo, fhi)  # the product may round past a bound
        theta = full(x_sol)
        r = residual(x_sol)
        self.covariance_ = self.information_ = None
        if self.uncertainty:
            jac = jacobian(x_sol, fresh=True)
            if extra is not None:
                jac = np.vstack([jac, extra_jacobian(x_sol)])
            if dead is not None:  # dr/dtheta = dr/dx dx/dtheta (chamber -> dead volume)
                jac = jac @ _chamber_map(taken, theta, idx, dead, scale)
            n, p = r.size, idx.size
            sigma2 = (float(r @ r) / max(n - p, 1) if self.anchor is None
                      else self.anchor.error_Pa ** 2)
            # pseudo-inverse in scaled coordinates: the columns differ by many orders of
            # magnitude (areas ~1e-6 m^2, slopes ~10 /V), and pinv's cut-off is relative
            # to the largest singular value, so unscaled it drops informed directions too
            js = jac * scale
            # the prior's precision in the same scaled coordinates (w = error / sd)
            prior_s = np.diag((w_prior * scale) ** 2)
            self.covariance_ = sigma2 * (scale[:, None] * np.linalg.pinv(js.T @ js + prior_s)
                                         * scale[None, :])
            self.information_ = (jac.T @ jac) / sigma2
        self.params_ = model.as_dict(theta)
        self.free_ = tuple(free)
        self.rmse_Pa_ = float(np.sqrt(np.mean(r * r)))
        r0 = data.residuals(model, theta0[None], self.solver)
        self.start_rmse_Pa_ = float(np.sqrt(np.mean(r0 * r0)))
        self.n_evaluations_ = int(sol.nfev)
        self.rmse_trace_ = np.array(trace)
        self.stalled_ = sol.status == -2  # StopIteration from stop_if_stalled
        self.success_ = bool(sol.success) or self.stalled_
        self.message_ = (f"stalled: the best RMSE fell by under {self.stall.tolerance:g} of "
                         f"itself over the last {self.stall.evaluations} evaluations"
                         if self.stalled_ else str(sol.message))
        return self

    def _anchor_rows(self, free, taken, dead, theta0) -> tuple[np.ndarray, np.ndarray]:
        """The anchor's weights ``error_Pa / sd`` (0: no row) and means, per free
        parameter in the refiner's coordinates."""
        w = np.zeros(len(free))
        mu = np.zeros(len(free))
        a = self.anchor
        if a is None:
            return w, mu
        unknown = [n for n in a.sd if n not in free]
        if unknown:
            raise ValueError(f"anchor: {unknown} are not free parameters of the fit")
        mean_theta = theta0.copy()
        names = list(self.model.parameter_names)
        for n in a.sd:
            mean_theta[names.index(n)] = float(a.mean[n])
        for j, n in enumerate(free):
            if n in a.sd:
                w[j] = a.error_Pa / float(a.sd[n])
                mu[j] = float(a.mean[n])
                if dead is not None and j == dead:
                    mu[j] -= taken(mean_theta)
        return w, mu
