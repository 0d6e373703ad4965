"""A Laplace approximation of the window posterior: the fast alternative to emcee.

The posterior is the one emcee samples (:class:`~pneubayes.inference.likelihood.WindowLikelihood`:
the AR(1) window likelihood with each window's start error integrated out, the priors of
the model's parameters), approximated by a Gaussian in the sampling coordinates at its
mode:

1. the centre: Newton steps on the log-posterior from the refined point
   (:func:`~pneubayes.inference.walker_start.posterior_centre`, whitened by the refined
   point's Fisher information);
2. the curvature there: the Hessian of the log-posterior by second differences at +-2
   SDs in the same coordinates (:func:`~pneubayes.inference.walker_start.whitened_curvature`:
   2 k + k (k - 1) / 2 evaluations for k identified coordinates, one batched call), its
   inverse the covariance; taken again, whitened by the first, where the information is
   far from it. Directions where it is not negative definite keep the whitening's
   variance and are reported. With the mode on a prior bound the Hessian and slope are
   taken at a point moved inside, the Gaussian's mean beyond the bound (:func:`inward_point`);
3. draws: the identified coordinates from that Gaussian, each nuisance coordinate (one
   only the prior informs) uniformly over the range the others allow, as emcee's walkers
   start (:func:`~pneubayes.inference.walker_start.walker_ball`); draws outside the
   priors' bounds are drawn again (a truncated Gaussian); the noise's scale and AR(1)
   coefficient from their conditional posterior at the centre;
4. a check (:func:`~pneubayes.inference.importance.importance_check`): the posterior's
   density at the first 200 draws against theirs, Pareto-smoothed importance sampling's
   k (Vehtari et al. 2024); past its threshold the posterior has mass the Gaussian
   misses: a warning, and the result is not ``converged_``.

Its cost is a few hundred posterior evaluations in a handful of batched calls, against
emcee's tens of thousands (``benchmarks/mcmc.py``; measurements in ``docs/history.md``).
What it does not see: skew, several modes, a posterior cut by a bound far from the mode
(a leak near 0), a log-density rough at the scale of its differences. The check catches
a Gaussian clearly too narrow, often not one moderately narrow, and passes one too wide
(importance sampling from it is reliable; its ESS falls). The result records the
Hessian's eigenvalues, the check, and whether both pass; emcee stays the default.

Results follow :class:`~pneubayes.inference.sampler.BayesianIdentification`'s
(:class:`~pneubayes.inference.sampler.ChainDraws`' ``samples``, ``model_samples``,
``median_params``; ``summary``, ``inference_data``).
"""

from __future__ import annotations

import time
import warnings
from typing import NamedTuple

import numpy as np

from pneubayes.inference.importance import importance_check
from pneubayes.inference.likelihood import WindowLikelihood
from pneubayes.inference.sampler import ChainDraws, arviz, settle_solver
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.inference.walker_start import (
    curvature_stencil,
    gaussian_draws,
    laplace_in_sampling,
    posterior_centre,
    sampling_jacobian,
    spread_nuisance,
    walker_ball,
    whitened_basis,
    whitened_curvature,
)
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

#: Draws of a Laplace posterior unless asked otherwise (``pneubayes fit --method laplace``,
#: :attr:`PosteriorSettings.laplace_draws <pneubayes.discovery.settings.PosteriorSettings>`).
LAPLACE_DRAWS = 4000

#: Steps (whitened SDs) of the Hessian's differences, tried in turn until every point has
#: a finite density: 2 keeps the solver's roughness small against the differences; the
#: shorter ones serve a centre near a prior bound (a valve area at its upper bound on
#: GTDynamics' recordings, the bound 0.6 refined SDs away).
DIFFERENCE_STEPS = (2.0, 1.0, 0.5, 0.25)

#: Moves of :func:`inward_point` (the parameters are not linear in the sampling
#: coordinates: a Gompertz ``b`` is ``exp(z_b + c d)``).
INWARD_ITERATIONS = 10

#: Fewest of the Gaussian's draws that must fall inside the priors' bounds, and the most
#: drawn at once (:func:`truncated_draws`).
MIN_ACCEPTED = 1e-4
MAX_ROUND = 1_000_000

#: Rounds of whitening again, the stretch of a flat direction per round and the factor
#: within which the whitened Hessian's eigenvalues must be of 1
#: (:func:`laplace_approximation`).
RESCALE_ROUNDS = 6
EXPAND = 10.0
SELF_CONSISTENT = 4.0

#: Chains the draws are split into in :meth:`LaplaceIdentification.inference_data`
#: (independent draws: any split is a set of chains with R-hat 1).
CHAINS = 4


def check_draw_counts(n_draws, check_draws, names=("n_draws", "check_draws")) -> None:
    """ValueError unless ``n_draws`` is a positive multiple of :data:`CHAINS` and
    ``check_draws`` is 0 or an integer from 100 to ``n_draws``; ``names``: the two as
    the caller spells them, for the message."""
    if not (isinstance(n_draws, int) and n_draws >= CHAINS and n_draws % CHAINS == 0):
        raise ValueError(f"{names[0]} must be a positive multiple of {CHAINS}, got "
                         f"{n_draws!r}")
    if not (isinstance(check_draws, int)
            and (check_draws == 0 or 100 <= check_draws <= n_draws)):
        raise ValueError(f"{names[1]} must be 0 or an integer from 100 to {names[0]} "
                         f"({n_draws}), got {check_draws!r}")


class LaplaceIdentification(ChainDraws):
    """Laplace approximation of the posterior over a model's parameters.

    Parameters
    ----------
    model : Model
    solver : SolverConfig
        Solver of the posterior evaluations; tightened (10x at a time, at most
        ``max_solver_tightenings`` times) until the log-density's roughness over 16
        points of the refined point's Laplace ball is at most ``max_solver_jitter_nats``,
        as emcee's (:func:`~pneubayes.inference.sampler.settle_solver`).
    n_draws : int
        Draws of the approximation (a multiple of 4).
    check_draws : int
        Of them, how many the posterior's density checks
        (:mod:`~pneubayes.inference.importance`; 0: none, >= 100 otherwise).
    centre_iterations, centre_tolerance_nats : int, float
        Newton steps from the refined point to the posterior's centre, and the
        predicted rise under which they stop
        (:func:`~pneubayes.inference.walker_start.posterior_centre`).
    seed : int
        Seed of every draw (recorded).
    max_solver_jitter_nats, max_solver_tightenings : float, int
        See ``solver``.
    log : callable or None
        Progress lines (None: silent).
    """

    method = "laplace"

    def __init__(self, model: Model, solver: SolverConfig, n_draws: int, check_draws: int,
                 centre_iterations: int, seed: int, max_solver_jitter_nats: float,
                 max_solver_tightenings: int, log=None, centre_tolerance_nats: float = 0.0):
        self.model = model
        self.solver = solver
        self.n_draws = n_draws
        self.check_draws = check_draws
        self.centre_iterations = centre_iterations
        self.centre_tolerance_nats = centre_tolerance_nats
        self.seed = seed
        self.max_solver_jitter_nats = max_solver_jitter_nats
        self.max_solver_tightenings = max_solver_tightenings
        self.log = log

    @classmethod
    def from_sampler(cls, model: Model, solver: SolverConfig, sampler: SamplerSettings,
                     n_draws: int, check_draws: int, log=None) -> "LaplaceIdentification":
        """The approximation with the settings emcee would use (``sampler``: its seed,
        centring iterations and solver roughness), in place of the chain."""
        return cls(model, solver, n_draws, check_draws, sampler.centre_iterations,
                   sampler.seed,
                   sampler.max_solver_jitter_nats, sampler.max_solver_tightenings, log,
                   sampler.centre_tolerance_nats)

    def fit(self, data: WindowSet, start: dict, information) -> "LaplaceIdentification":
        """Approximate the posterior on ``data`` from the refined point ``start`` (a full
        parameter dict) and its Fisher information (natural parameters,
        :attr:`TrajectoryRefiner.information_ <pneubayes.inference.refine.TrajectoryRefiner>`)."""
        check_draw_counts(self.n_draws, self.check_draws)
        if not (isinstance(self.centre_iterations, int) and self.centre_iterations >= 0):
            raise ValueError(f"centre_iterations must be an integer >= 0, got "
                             f"{self.centre_iterations!r}")
        t0 = time.perf_counter()
        rng = np.random.default_rng([self.seed, 2])
        x0 = self.model.vector(start)
        ball = walker_ball(WindowLikelihood(self.model, data, self.solver), x0,
                           information, rng, 16, 1.0)
        like, solver, jitter = settle_solver(self.model, data, self.solver, ball,
                                             self.max_solver_jitter_nats,
                                             self.max_solver_tightenings)
        fit = laplace_approximation(like, x0, information, self.centre_iterations,
                                    self.centre_tolerance_nats)
        z = truncated_draws(like, fit.mean_z, fit.ident, fit.cov_z, rng, self.n_draws)
        lam = fit.eigenvalues
        concave = lam > 0
        check = (importance_check(like, z[:self.check_draws], fit.mean_z, fit.ident,
                                  fit.cov_z) if self.check_draws else None)
        fits_draws = (check is None or check["pareto_k"] is None
                      or check["pareto_k"] <= check["khat_threshold"])
        x = like.from_sampling(z)
        noise = like.draw_noise(np.repeat(fit.noise_sums, x.shape[0], axis=0), rng)
        self.names_ = like.names + like.noise_names
        self.chain_ = np.concatenate([x, noise], axis=1).reshape(
            self.n_draws // CHAINS, CHAINS, -1)
        self.centre_ = self.model.as_dict(fit.x_centre)
        self.likelihood_ = like
        self.solver_ = solver
        self.converged_ = bool(np.all(concave)) and fits_draws
        self.wall_time_s_ = time.perf_counter() - t0
        self.diagnostics_ = {
            "method": self.method, "steps": 0, "draws": self.n_draws,
            "solver": solver.to_dict(), "solver_jitter_nats": jitter,
            "centre_log_posterior": float(fit.log_posterior[0]),
            "hessian_eigenvalues": [float(v) for v in lam],
            "non_concave_directions": int(np.sum(~concave)),
            "difference_step_sd": fit.step_sd, "rewhitening_rounds": fit.rounds,
            "centre_rises_nats": [float(v) for v in fit.centre_rises],
            "mode_on_prior_bound": list(fit.bounded), "inside_shift_sd": fit.shift_sd,
            "importance_check": check}
        if self.log is not None:
            self.log(f"laplace: {self.n_draws} draws, {np.sum(~concave)} non-concave "
                     f"direction(s) of {lam.size}, {self.wall_time_s_:.0f} s")
            if fit.bounded:
                self.log(f"laplace: the mode is on the prior bound of "
                         f"{', '.join(fit.bounded)}: the Hessian taken {fit.shift_sd:.2g} "
                         "SDs inside, the Gaussian cut at the bound")
            if check is not None:
                self.log(f"laplace: importance check on {check['draws']} draws: Pareto k "
                         f"{_fmt_k(check['pareto_k'])} (reliable <= "
                         f"{check['khat_threshold']:.2f}), ESS {check['ess_fraction']:.0%}")
            if not np.all(concave):
                self.log("laplace: WARNING the log-posterior is not concave at its mode in "
                         f"{np.sum(~concave)} direction(s): their widths are not the "
                         "posterior's: sample it with emcee")
            if not fits_draws:
                self.log("laplace: WARNING the posterior has mass the Gaussian misses "
                         f"(Pareto k {_fmt_k(check['pareto_k'])}): its intervals are not the "
                         "posterior's: sample it with emcee")
        return self

    # ------------------------------------------------------------------ results
    def summary(self) -> dict:
        """Per parameter: median, 5 % and 95 % quantiles; R-hat and tau are not defined
        for independent draws (NaN), the ESS is the number of draws."""
        x = self.samples()
        q = np.quantile(x, [0.05, 0.5, 0.95], axis=0)
        return {n: {"median": float(q[1, j]), "q05": float(q[0, j]),
                    "q95": float(q[2, j]), "rhat": float("nan"),
                    "ess": float(x.shape[0]), "tau": float("nan")}
                for j, n in enumerate(self.names_)}

    def inference_data(self, attrs: dict | None = None):
        """The draws as arviz InferenceData, split into 4 chains."""
        az = arviz()
        c = self.chain_
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
            return az.from_dict(
                posterior={n: c[:, :, j].T for j, n in enumerate(self.names_)},
                attrs={**(attrs or {}), "sampler": "laplace", "draws": int(self.n_draws)})


class LaplaceFit(NamedTuple):
    """A Laplace approximation in sampling coordinates (:func:`laplace_approximation`).

    ``x_centre``, ``z_centre``: the log-posterior's mode found (natural and sampling
    coordinates); ``ident``: the identified columns; ``cov_z``: their covariance;
    ``mean_z``: the Gaussian's mean (all columns): the mode, or where the mode is on a
    prior bound the mean of the Gaussian fitted inside, which may lie beyond the bound
    (its draws are truncated there); ``eigenvalues``: the negative Hessian's in the
    whitened coordinates (a non-positive one: a direction that keeps the whitening's unit
    variance); ``log_posterior``, ``noise_sums``: at the mode (``(1,)``, ``(1, 5)``);
    ``step_sd``: the differences' step in whitened SDs; ``rounds``: rounds of whitening
    again; ``shift_sd``: how far inside (whitened SDs) the Hessian was taken from a mode on
    a bound (0: at the mode); ``bounded``: the parameters whose bounds moved it there;
    ``centre_rises``: the predicted rise of each centring Newton step (nats)."""

    x_centre: np.ndarray
    z_centre: np.ndarray
    ident: np.ndarray
    cov_z: np.ndarray
    mean_z: np.ndarray
    eigenvalues: np.ndarray
    log_posterior: np.ndarray
    noise_sums: np.ndarray
    step_sd: float
    rounds: int
    shift_sd: float
    bounded: tuple
    centre_rises: tuple = ()


def inward_point(like, z: np.ndarray, ident: np.ndarray, basis: np.ndarray, h: float):
    """A point near ``z`` (sampling coordinates) whose :func:`curvature_stencil` of step
    ``h`` lies inside the priors' bounds, or None: each bound a stencil point crosses moves
    the point inward, by the stencil's reach past the bound plus a quarter, along the
    whitened direction in which that parameter changes fastest (the shortest move in
    posterior SDs); repeated, as the parameters are not linear in the sampling
    coordinates, at most :data:`INWARD_ITERATIONS` times. Returns ``(point, names)``: the
    point and the parameters whose bounds moved it."""
    lo, hi = like.bounds
    y = curvature_stencil(basis.shape[1], h)
    names = []
    for _ in range(INWARD_ITERATIONS):
        rows = np.tile(z, (y.shape[0], 1))
        rows[:, ident] += y @ basis.T
        x = like.from_sampling(rows)
        out = [(j, s) for j in range(lo.size) for s, past in
               ((1.0, x[:, j] > hi[j]), (-1.0, x[:, j] < lo[j])) if np.any(past)]
        if not out:
            return z, tuple(names)
        x0 = like.from_sampling(z[None])[0]
        if np.any((x0 < lo) | (x0 > hi)):
            return None
        # dx / dy: the map's own Jacobian (dz/dx) inverted, on the identified columns
        jac = np.linalg.inv(sampling_jacobian(like, x0))[:, ident] @ basis
        move = np.zeros(basis.shape[1])
        for j, s in out:
            c = s * jac[j]  # outward change of x_j per whitened unit
            if not np.any(c != 0):
                return None
            room = s * ((hi[j] if s > 0 else lo[j]) - x0[j])
            reach = np.max(y @ c)
            move -= 1.25 * max(reach - room, 0.0) * c / (c @ c)
            names.append(like.parameters[j].name)
        z = z.copy()
        z[ident] += basis @ move
    return None


def laplace_approximation(like, start: np.ndarray, information,
                          iterations: int, tolerance_nats: float = 0.0) -> LaplaceFit:
    """The Gaussian at the log-posterior's mode in sampling coordinates (module docstring,
    steps 1-2). ``like``: the posterior (:class:`WindowLikelihood` or anything with its
    sampling interface); ``start``: natural parameters; ``information``: their Fisher
    information there (whitens the search and the differences).

    The differences' step is the first of :data:`DIFFERENCE_STEPS` whose points all have
    a density (a centre near a prior bound: a shorter step stays inside it). Where none
    has, and the points cross a prior bound (the mode is on it: the likelihood wants a
    value the prior does not allow), the Hessian and slope are taken at a point moved
    inside (:func:`inward_point`, first with the longest step) and the Gaussian is the
    quadratic they define: mean ``y + H^-1 g``, beyond the bound, and the posterior
    there that Gaussian cut at the bound (:func:`truncated_draws`). Exact on a Gaussian
    cut by a bound; a log-density that is not quadratic over the shift is extrapolated.

    The information whitens the differences; where it is far from the posterior's own
    curvature (least squares' information takes 2-s prediction errors for independent
    samples, and on a misfitting model with AR(1) noise of 0.9 it is hundreds of times
    too large), the steps resolve only the solver's roughness. So the Hessian is taken
    again in coordinates whitened by the one before (its non-concave directions
    stretched ``EXPAND`` x), until its eigenvalues are within a factor
    ``SELF_CONSISTENT`` of 1 (the steps were near 2 posterior SDs), at most
    ``RESCALE_ROUNDS`` times, or until the stretched steps leave the prior (the round
    before stands).

    ``iterations`` and ``tolerance_nats``: the centring's Newton steps
    (:func:`~pneubayes.inference.walker_start.posterior_centre`); where it stopped at a
    point whose Hessian it had just taken (its next step predicted under
    ``tolerance_nats``, or did not rise), that Hessian is the first round's."""
    centre = posterior_centre(like, start, information, iterations, tolerance_nats)
    xc = centre.x
    _, zc, ident, cz = laplace_in_sampling(like, xc, information)
    reuse = centre.curvature is not None
    # where its Hessian was taken: the centring's own point and whitening
    zc, basis = (centre.z, centre.basis) if reuse else (zc, whitened_basis(cz))
    target = like.emcee_target(zc[None])  # log-density in sampling coordinates, sums
    lp_c, sums_c = target[:, 0], target[:, 1:]
    if basis is None or not np.isfinite(lp_c[0]):
        raise FloatingPointError("laplace: the information has a non-positive variance, "
                                 "or the centre has no finite posterior density")
    done = None  # (basis, lam, q, h, point, slope, names) of the last round taken
    for rounds in range(RESCALE_ROUNDS + 1):
        if rounds == 0 and reuse:
            taken = DIFFERENCE_STEPS[0], zc, (), centre.curvature
        else:
            taken = _curvature_inside(like, zc, ident, basis, float(lp_c[0]))
        if taken is None:
            if done is None:
                raise FloatingPointError(
                    f"laplace: points {DIFFERENCE_STEPS[-1]:g} SDs from the centre have no "
                    "finite posterior density, and not for a prior bound a point moved "
                    "inside avoids; the Hessian cannot be taken: use emcee")
            rounds -= 1  # the stretched steps leave the prior: the round before stands
            break
        h, point, names, (grad, hess) = taken
        lam, q = np.linalg.eigh(-hess)
        done = (basis, lam, q, h, point, grad, names)
        if (np.all((lam > 1.0 / SELF_CONSISTENT) & (lam < SELF_CONSISTENT))
                or rounds == RESCALE_ROUNDS):
            break
        # whiten again: each concave direction by its own curvature, a flat or convex
        # one (the differences saw only the solver's roughness) stretched EXPAND x
        basis = basis @ (q * np.where(lam > 0, 1.0 / np.sqrt(np.abs(lam)), EXPAND))
    basis, lam, q, h, point, grad, names = done
    inv_lam = np.where(lam > 0, 1.0 / np.where(lam > 0, lam, 1.0), 0.0)
    cov_y = (q * np.where(lam > 0, inv_lam, 1.0)) @ q.T
    mean_z = zc.copy()
    shift = 0.0
    if names:  # the Newton step of the quadratic at the inside point (concave directions)
        shift = float(np.linalg.norm(np.linalg.lstsq(basis, point[ident] - zc[ident],
                                                     rcond=None)[0]))
        mean_z = point.copy()
        mean_z[ident] += basis @ ((q * inv_lam) @ (q.T @ grad))
    return LaplaceFit(xc, zc, ident, basis @ cov_y @ basis.T, mean_z, lam, lp_c, sums_c,
                      h, rounds, shift, tuple(sorted(set(names))), centre.rises)


def _curvature_inside(like, zc, ident, basis, f0):
    """``(h, point, bounded names, (grad, hess))``: the curvature at the centre with the
    first of :data:`DIFFERENCE_STEPS` whose points have a density, else at a point moved
    inside the priors' bounds (:func:`inward_point`), else None."""
    for h in DIFFERENCE_STEPS:
        curv = whitened_curvature(like, zc, ident, basis, f0, h)
        if curv is not None:
            return h, zc, (), curv
    for h in DIFFERENCE_STEPS:
        moved = inward_point(like, zc, ident, basis, h)
        if moved is None or not moved[1]:
            continue
        point, names = moved
        f = like.log_prob_sampling(point[None])[0]
        if not np.isfinite(f):
            continue
        curv = whitened_curvature(like, point, ident, basis, float(f), h)
        if curv is not None:
            return h, point, names, curv
    return None


def truncated_draws(like, mean_z: np.ndarray, ident: np.ndarray, cov_z: np.ndarray,
                    rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` draws in sampling coordinates (module docstring, step 3): the identified
    columns from N(mean_z, cov_z), each nuisance one uniform over the range the others
    allow; draws outside the priors' bounds are drawn again (each round sized by the
    rate accepted so far: a mean beyond a bound accepts few). Fails where fewer than
    1 in 10^4 fall inside."""
    lo, hi = like.bounds
    out, have, tried = [], 0, 0
    while have < n:
        rate = (have + 1.0) / (tried + 1.0)
        if tried >= 10_000 and rate < MIN_ACCEPTED:
            raise FloatingPointError(
                f"laplace: {have} of {tried} of the Gaussian's draws fall inside the "
                "priors' bounds (its mean is far beyond one): use emcee")
        m = int(min(1.25 * (n - have) / min(rate, 1.0), MAX_ROUND)) + 16
        z = np.tile(mean_z, (m, 1))
        z[:, ident] = gaussian_draws(mean_z[ident], cov_z, rng, m)
        spread_nuisance(like, z, rng)
        x = like.from_sampling(z)
        ok = np.all(np.isfinite(x), axis=1) & np.all((x >= lo) & (x <= hi), axis=1)
        out.append(z[ok])
        have += int(ok.sum())
        tried += m
    return np.concatenate(out)[:n]


def _fmt_k(k) -> str:
    """A Pareto k for a log line (None: the ratios were constant)."""
    return "none (constant ratios)" if k is None else f"{k:.2f}"
