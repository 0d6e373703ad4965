"""A Laplace approximation of the window posterior: the fast alternative to emcee.

The posterior is the one emcee samples (:class:`~pneubayes.inference.likelihood.WindowLikelihood`:
the AR(1) window likelihood with each window's start error integrated out, the priors of
the model's parameters), approximated by a Gaussian in the sampling coordinates at its
mode:

1. the centre: Newton steps on the log-posterior from the refined point
   (:func:`~pneubayes.inference.walker_start.posterior_centre`, whitened by the refined
   point's Fisher information);
2. the curvature there: the Hessian of the log-posterior by second differences in the
   same whitened coordinates, at +-2 SDs
   (:func:`~pneubayes.inference.walker_start.whitened_curvature`: 2 k + k (k - 1) / 2
   posterior evaluations for k identified coordinates, in one batched call), its
   inverse the covariance; taken again in coordinates whitened by the one before where
   the information is far from it (:func:`laplace_approximation`). Directions in which
   it is not negative definite keep the whitening's variance and are reported (a
   warning: their widths are not the posterior's);
3. draws: the identified coordinates from that Gaussian, each nuisance coordinate (one
   only the prior informs) uniformly over the range the others allow, as emcee's walkers
   start (:func:`~pneubayes.inference.walker_start.walker_ball`); draws outside the
   priors' bounds are drawn again (a truncated Gaussian); the noise's scale and AR(1)
   coefficient from their conditional posterior at the centre.

Its cost is a few hundred posterior evaluations in a handful of batched calls, against
emcee's tens of thousands (``benchmarks/mcmc.py``: 4.1 s against 219 s, medians within
0.03 emcee SDs, interval widths 0.96-1.08 x emcee's). What it does not see: skew, several
modes, a posterior cut by a bound (a leak near 0), a log-density rough at the scale of
its differences, a mode on a prior bound (there the Hessian cannot be taken: an error
that names emcee; GTDynamics' valve area). The result records the Hessian's eigenvalues
and whether it is concave; emcee stays the default.

Results follow :class:`~pneubayes.inference.sampler.BayesianIdentification`'s
(:class:`~pneubayes.inference.sampler.ChainDraws`' ``samples``, ``model_samples``,
``median_params``; ``summary``, ``inference_data``).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from pneubayes.inference.likelihood import WindowLikelihood
from pneubayes.inference.sampler import ChainDraws, SamplerSettings, arviz, settle_solver
from pneubayes.inference.walker_start import (
    gaussian_draws,
    laplace_in_sampling,
    posterior_centre,
    spread_nuisance,
    walker_ball,
    whitened_basis,
    whitened_curvature,
)
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

#: Draws of a Laplace posterior unless asked otherwise (``pneubayes fit --method laplace``,
#: :attr:`DiscoverySettings.laplace_draws <pneubayes.discovery.settings.DiscoverySettings>`).
LAPLACE_DRAWS = 4000

#: Steps (whitened SDs) of the Hessian's differences, tried in turn until every point has
#: a finite density: 2 keeps the solver's roughness small against the differences; the
#: shorter ones serve a centre near a prior bound (a valve area at its upper bound on
#: GTDynamics' recordings, the bound 0.6 refined SDs away).
DIFFERENCE_STEPS = (2.0, 1.0, 0.5, 0.25)

#: Rounds of whitening again, the stretch of a flat direction per round and the factor
#: within which the whitened Hessian's eigenvalues must be of 1
#: (:func:`laplace_approximation`).
RESCALE_ROUNDS = 6
EXPAND = 10.0
SELF_CONSISTENT = 4.0

#: Chains the draws are split into in :meth:`LaplaceIdentification.inference_data`
#: (independent draws: any split is a set of chains with R-hat 1).
CHAINS = 4


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
    centre_iterations : int
        Newton steps from the refined point to the posterior's centre.
    seed : int
        Seed of every draw (recorded).
    max_solver_jitter_nats, max_solver_tightenings : float, int
        See ``solver``.
    log : callable or None
        Progress lines (None: silent).
    """

    method = "laplace"

    def __init__(self, model: Model, solver: SolverConfig, n_draws: int,
                 centre_iterations: int, seed: int, max_solver_jitter_nats: float,
                 max_solver_tightenings: int, log=None):
        self.model = model
        self.solver = solver
        self.n_draws = n_draws
        self.centre_iterations = centre_iterations
        self.seed = seed
        self.max_solver_jitter_nats = max_solver_jitter_nats
        self.max_solver_tightenings = max_solver_tightenings
        self.log = log

    @classmethod
    def from_sampler(cls, model: Model, solver: SolverConfig, sampler: SamplerSettings,
                     n_draws: int, log=None) -> "LaplaceIdentification":
        """The approximation with the settings emcee would use (``sampler``: its seed,
        centring iterations and solver roughness), in place of the chain."""
        return cls(model, solver, n_draws, sampler.centre_iterations, sampler.seed,
                   sampler.max_solver_jitter_nats, sampler.max_solver_tightenings, log)

    def fit(self, data: WindowSet, start: dict, information) -> "LaplaceIdentification":
        """Approximate the posterior on ``data`` from the refined point ``start`` (a full
        parameter dict) and its Fisher information (natural parameters,
        :attr:`TrajectoryRefiner.information_ <pneubayes.inference.refine.TrajectoryRefiner>`)."""
        if not (isinstance(self.n_draws, int) and self.n_draws >= CHAINS
                and self.n_draws % CHAINS == 0):
            raise ValueError(f"n_draws must be a positive multiple of {CHAINS}, got "
                             f"{self.n_draws!r}")
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
        xc, zc, ident, cov_z, lam, lp_c, sums_c, h, rounds = laplace_approximation(
            like, x0, information, self.centre_iterations)
        z = truncated_draws(like, zc, ident, cov_z, rng, self.n_draws)
        concave = lam > 0
        x = like.from_sampling(z)
        noise = like.draw_noise(np.repeat(sums_c, x.shape[0], axis=0), rng)
        self.names_ = like.names + like.noise_names
        self.chain_ = np.concatenate([x, noise], axis=1).reshape(
            self.n_draws // CHAINS, CHAINS, -1)
        self.centre_ = self.model.as_dict(xc)
        self.likelihood_ = like
        self.solver_ = solver
        self.converged_ = bool(np.all(concave))
        self.wall_time_s_ = time.perf_counter() - t0
        self.diagnostics_ = {
            "method": self.method, "steps": 0, "draws": self.n_draws,
            "solver": solver.to_dict(), "solver_jitter_nats": jitter,
            "centre_log_posterior": float(lp_c[0]),
            "hessian_eigenvalues": [float(v) for v in lam],
            "non_concave_directions": int(np.sum(~concave)),
            "difference_step_sd": h, "rewhitening_rounds": rounds}
        if self.log is not None:
            self.log(f"laplace: {self.n_draws} draws, {np.sum(~concave)} non-concave "
                     f"direction(s) of {lam.size}, {self.wall_time_s_:.0f} s")
            if not self.converged_:
                self.log("laplace: WARNING the log-posterior is not concave at its mode in "
                         f"{np.sum(~concave)} direction(s): their widths are not the "
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


def laplace_approximation(like, start: np.ndarray, information, iterations: int):
    """The Gaussian at the log-posterior's mode in sampling coordinates (module docstring,
    steps 1-2). ``like``: the posterior (:class:`WindowLikelihood` or anything with its
    sampling interface); ``start``: natural parameters; ``information``: their Fisher
    information there (whitens the search and the differences).

    Returns ``(xc, zc, ident, cov_z, lam, lp_c, sums_c, h, rounds)``: the centre in natural and
    sampling coordinates, the identified columns, their covariance, the eigenvalues of
    the negative Hessian in the whitened coordinates (a non-positive one: a direction
    that keeps the whitening's unit variance), the log-density and noise summary at the
    centre (``(1,)``, ``(1, 5)``), the differences' step in whitened SDs: the first of
    :data:`DIFFERENCE_STEPS` whose points all have a density (a centre near a prior
    bound: a shorter step stays inside it), and the rounds of whitening again.

    The information whitens the differences; where it is far from the posterior's own
    curvature (least squares' information takes 2-s prediction errors for independent
    samples, and on a misfitting model with AR(1) noise of 0.9 it is hundreds of times
    too large), the steps resolve only the solver's roughness. So the Hessian is taken
    again in coordinates whitened by the one before (its non-concave directions
    stretched ``EXPAND`` x), until its eigenvalues are within a factor
    ``SELF_CONSISTENT`` of 1 (the steps were near 2 posterior SDs), at most
    ``RESCALE_ROUNDS`` times, or until the stretched steps leave the prior (the round
    before stands)."""
    xc = posterior_centre(like, start, information, iterations)
    _, zc, ident, cz = laplace_in_sampling(like, xc, information)
    basis = whitened_basis(cz)
    target = like.emcee_target(zc[None])  # log-density in sampling coordinates, sums
    lp_c, sums_c = target[:, 0], target[:, 1:]
    if basis is None or not np.isfinite(lp_c[0]):
        raise FloatingPointError("laplace: the information has a non-positive variance, "
                                 "or the centre has no finite posterior density")
    done = None  # (basis, lam, q, h) of the last round whose Hessian could be taken
    for rounds in range(RESCALE_ROUNDS + 1):
        for h in DIFFERENCE_STEPS:
            curv = whitened_curvature(like, zc, ident, basis, float(lp_c[0]), h)
            if curv is not None:
                break
        else:
            if done is None:
                raise FloatingPointError(
                    f"laplace: points {DIFFERENCE_STEPS[-1]:g} SDs from the centre have no "
                    "finite posterior density (the centre is at a prior bound); the "
                    "Hessian cannot be taken: use emcee")
            rounds -= 1  # the stretched steps leave the prior: the round before stands
            break
        lam, q = np.linalg.eigh(-curv[1])
        done = (basis, lam, q, h)
        if (np.all((lam > 1.0 / SELF_CONSISTENT) & (lam < SELF_CONSISTENT))
                or rounds == RESCALE_ROUNDS):
            break
        # whiten again: each concave direction by its own curvature, a flat or convex
        # one (the differences saw only the solver's roughness) stretched EXPAND x
        basis = basis @ (q * np.where(lam > 0, 1.0 / np.sqrt(np.abs(lam)), EXPAND))
    basis, lam, q, h = done
    cov_y = (q / np.where(lam > 0, lam, 1.0)) @ q.T
    return xc, zc, ident, basis @ cov_y @ basis.T, lam, lp_c, sums_c, h, rounds


def truncated_draws(like, zc: np.ndarray, ident: np.ndarray, cov_z: np.ndarray,
                    rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` draws in sampling coordinates (module docstring, step 3): the identified
    columns from N(zc, cov_z), each nuisance one uniform over the range the others
    allow; draws outside the priors' bounds are drawn again."""
    lo, hi = like.bounds
    out, have = [], 0
    for _ in range(100):
        m = 2 * (n - have) + 16
        z = np.tile(zc, (m, 1))
        z[:, ident] = gaussian_draws(zc[ident], cov_z, rng, m)
        spread_nuisance(like, z, rng)
        x = like.from_sampling(z)
        ok = np.all(np.isfinite(x), axis=1) & np.all((x >= lo) & (x <= hi), axis=1)
        out.append(z[ok])
        have += int(ok.sum())
        if have >= n:
            return np.concatenate(out)[:n]
    raise FloatingPointError(f"laplace: fewer than {n} of the Gaussian's draws fall inside "
                             "the priors' bounds in 100 rounds")
