"""A hierarchical population of the quantities that vary between runs, in log space.

Two stages. Stage 1 (the caller's): each run's varying quantities fitted with the fixed
ones held, the run's likelihood approximated by a Gaussian in the log values (a Laplace
approximation at the run's mode: log mean ``m_j`` and precision ``P_j``, or SDs, or a
covariance). Stage 2 (:class:`HierarchicalPopulation`): each run's log values
``z_j ~ Normal(mu, diag(tau^2))``, the population's log median ``mu`` and log spread
``tau`` per quantity, sampled by emcee. With Gaussian run likelihoods ``z_j`` integrates
out exactly (``m_j ~ Normal(mu, P_j^-1 + T)``, written with ``P_j`` so a direction a run
does not inform has precision 0), so the chain is over the 2 k hyperparameters only: no
funnel between ``tau`` and the ``z_j`` (which a joint chain over a few runs mixes
badly), and each run's shrunk values are drawn exactly from their conditional Gaussian
given each hyperparameter draw.

Priors (weakly informative, in log units): ``mu_i ~ Normal(mu_prior_mean_i,
mu_prior_sd_i)`` (default: the runs' mean log value, SD 5, a factor of e^5 per SD);
``tau_i ~ HalfNormal(tau_prior_scale)`` (default 1: a spread of a factor e between runs
is one prior SD). The chain samples ``log tau`` (the Jacobian is in the density).

Diagnostics: ``n_chains`` independent ensembles (seeds spawned from ``seed``); arviz's
rank-normalised split R-hat between them (each ensemble's walkers pooled as one chain)
and bulk/tail ESS (every walker a chain) on ``mu`` and ``tau``. A new run's value (the
posterior predictive) integrates over the hyperparameter draws:
:meth:`HierarchicalPopulation.prior` gives it as a
:class:`~pneubayes.inference.population.LogNormalPrior` (its median and log SD the
predictive's moments; sampling and density the mixture over draws), which the online
tracker takes as its prior. With few runs ``tau`` is set mostly by its prior: read its
interval against the prior's (``tau_prior_scale``), as :meth:`summary` records.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import emcee
import numpy as np

from pneubayes.inference.population import LogNormalPrior
from pneubayes.inference.sampler import BayesianIdentification
from pneubayes.model import Model

#: the R-hat and bulk-ESS thresholds of ``converged_``
RHAT_MAX = 1.01
ESS_MIN = 400


def run_gaussians(log_mean, log_sd=None, log_cov=None, log_precision=None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Check the runs' Gaussians and return ``(m, P)``: ``(J, k)`` log means and
    ``(J, k, k)`` precisions. Give exactly one of ``log_sd`` ``(J, k)`` (> 0),
    ``log_cov`` ``(J, k, k)`` (positive definite) or ``log_precision`` ``(J, k, k)``
    (symmetric, positive semi-definite: 0 where a run does not inform)."""
    m = np.asarray(log_mean, dtype=np.float64)
    if m.ndim != 2:
        raise ValueError(f"log_mean must be (runs, quantities), got shape {m.shape}")
    j, k = m.shape
    if j < 2:
        raise ValueError(f"log_mean: a population needs at least 2 runs, got {j}")
    if not np.all(np.isfinite(m)):
        raise ValueError("log_mean must be finite")
    given = [n for n, v in (("log_sd", log_sd), ("log_cov", log_cov),
                            ("log_precision", log_precision)) if v is not None]
    if len(given) != 1:
        raise ValueError(f"give exactly one of log_sd, log_cov, log_precision; got {given}")
    if log_sd is not None:
        s = np.asarray(log_sd, dtype=np.float64)
        if s.shape != m.shape:
            raise ValueError(f"log_sd has shape {s.shape}, log_mean {m.shape}")
        if not np.all(s > 0) or not np.all(np.isfinite(s)):
            raise ValueError(f"log_sd must be finite and > 0, got {s.tolist()}")
        return m, np.einsum("ji,ik->jik", s ** -2.0, np.eye(k))
    name, a = given[0], np.asarray(log_cov if log_cov is not None else log_precision,
                                   dtype=np.float64)
    if a.shape != (j, k, k):
        raise ValueError(f"{name} has shape {a.shape}, expected {(j, k, k)} for log_mean "
                         f"{m.shape}")
    if not np.all(np.isfinite(a)) or not np.allclose(a, a.transpose(0, 2, 1),
                                                     rtol=1e-8, atol=0.0):
        raise ValueError(f"{name} must be finite and symmetric")
    ev = np.linalg.eigvalsh(a)
    if name == "log_cov":
        if not np.all(ev > 0):
            raise ValueError(f"log_cov must be positive definite (eigenvalues {ev.tolist()})")
        return m, np.linalg.inv(a)
    if not np.all(ev >= -1e-10 * max(float(np.abs(ev).max()), 1e-300)):
        raise ValueError(f"log_precision must be positive semi-definite (eigenvalues "
                         f"{ev.tolist()})")
    return m, 0.5 * (a + a.transpose(0, 2, 1))


def marginal_log_likelihood(mu, tau, log_mean, log_precision) -> np.ndarray:
    """``(W,)`` log density of the runs' log means given ``(W, k)`` hyperparameters, each
    run's values integrated out: ``sum_j log N(m_j; mu, P_j^-1 + diag(tau^2))`` in the
    precision form (valid for a singular ``P_j``), up to a constant in ``P_j`` alone."""
    mu, tau = np.atleast_2d(mu), np.atleast_2d(tau)
    m, p = np.asarray(log_mean), np.asarray(log_precision)
    tinv = np.einsum("wi,ik->wik", tau ** -2.0, np.eye(mu.shape[1]))
    a = p[None] + tinv[:, None]                                 # (W, J, k, k)
    d = m[None] - mu[:, None]                                   # (W, J, k)
    pd = np.einsum("wjk,jkl->wjl", d, p)                        # (W, J, k)
    q = np.einsum("wjk,wjk->wj", pd, d) - np.einsum(
        "wjk,wjk->wj", pd, np.linalg.solve(a, pd[..., None])[..., 0])
    # log det(I + T P) = log det(A) + log det(T)
    return -0.5 * np.sum(q + np.linalg.slogdet(a)[1], axis=1) - 0.5 * m.shape[0] * np.sum(
        np.log(tau ** 2), axis=1)


class HierarchicalPopulation:
    """The population (log median ``mu``, log SD ``tau`` per quantity) of per-run values
    known through per-run Gaussians (see the module's text).

    Parameters
    ----------
    names : sequence of str
        The varying quantities, in the order of the runs' columns.
    mu_prior_mean, mu_prior_sd : array of k floats or None
        The Normal prior of each ``mu`` (log units); None: the runs' mean, SD 5.
    tau_prior_scale : float or array of k floats
        The half-normal prior's scale of each ``tau`` (log units).
    n_walkers, n_steps, n_chains : int
        Walkers per ensemble (>= 2 x 2 k), steps per walker (the first half discarded),
        independent ensembles.
    seed : int

    Attributes
    ----------
    mu_, tau_ : ndarray
        ``(draws, k)`` posterior draws of the hyperparameters (ensembles pooled).
    run_draws_ : ndarray
        ``(draws, J, k)`` each run's log values from their conditional given each draw.
    run_log_sd_ : ndarray
        ``(J, k)`` each run's own marginal log SDs (inf where it does not inform).
    rhat_, ess_, ess_tail_ : dict
        Per hyperparameter (``mu[name]``, ``tau[name]``).
    converged_ : bool
        Every R-hat <= ``RHAT_MAX`` and bulk ESS >= ``ESS_MIN``.
    acceptance_, wall_s_ : float
    """

    def __init__(self, names: Sequence[str], mu_prior_mean=None, mu_prior_sd=None,
                 tau_prior_scale=1.0, n_walkers: int = 32, n_steps: int = 3000,
                 n_chains: int = 4, seed: int = 0):
        self.names = tuple(names)
        self.mu_prior_mean = mu_prior_mean
        self.mu_prior_sd = mu_prior_sd
        self.tau_prior_scale = tau_prior_scale
        self.n_walkers = int(n_walkers)
        self.n_steps = int(n_steps)
        self.n_chains = int(n_chains)
        self.seed = seed

    @staticmethod
    def _vector(value, default, what: str, k: int) -> np.ndarray:
        v = np.asarray(default if value is None else value, dtype=np.float64)
        v = np.full(k, float(v)) if v.ndim == 0 else v
        if v.shape != (k,):
            raise ValueError(f"{what} has shape {v.shape}, expected ({k},)")
        return v.copy()

    def fit(self, log_mean, log_sd=None, log_cov=None, log_precision=None
            ) -> "HierarchicalPopulation":
        """Sample the hyperparameters given each run's Gaussian (:func:`run_gaussians`)."""
        m, prec = run_gaussians(log_mean, log_sd, log_cov, log_precision)
        j, k = m.shape
        if len(self.names) != k:
            raise ValueError(f"names has {len(self.names)} quantities, log_mean {k} columns")
        mu0 = self._vector(self.mu_prior_mean, m.mean(axis=0), "mu_prior_mean", k)
        mus = self._vector(self.mu_prior_sd, 5.0, "mu_prior_sd", k)
        ts = self._vector(self.tau_prior_scale, 1.0, "tau_prior_scale", k)
        for what, v in (("mu_prior_sd", mus), ("tau_prior_scale", ts)):
            if not np.all(v > 0) or not np.all(np.isfinite(v)):
                raise ValueError(f"{what} must be finite and > 0, got {v.tolist()}")
        ndim = 2 * k
        if self.n_walkers < 2 * ndim or self.n_steps < 100 or self.n_chains < 1:
            raise ValueError(f"n_walkers must be >= {2 * ndim}, n_steps >= 100, n_chains "
                             f">= 1; got {self.n_walkers}, {self.n_steps}, {self.n_chains}")
        self.prior_ = {"mu_mean": mu0, "mu_sd": mus, "tau_scale": ts}

        def log_prob(x):  # (W, 2k) -> (W,): the priors (log tau sampled) + the runs
            mu, ltau = x[:, :k], x[:, k:]
            lp = (-0.5 * np.sum(((mu - mu0) / mus) ** 2, axis=1)
                  - 0.5 * np.sum(np.exp(2.0 * ltau) / ts ** 2, axis=1) + np.sum(ltau, axis=1)
                  + marginal_log_likelihood(mu, np.exp(ltau), m, prec))
            return np.where(np.all(np.abs(ltau) < 30.0, axis=1) & np.isfinite(lp), lp,
                            -np.inf)

        seeds = np.random.SeedSequence(self.seed).spawn(self.n_chains + 1)
        spread = np.std(m, axis=0, ddof=1) + 0.1
        t0 = time.perf_counter()
        chains, acc = [], []
        for c in range(self.n_chains):
            rng = np.random.default_rng(seeds[c])
            start = np.concatenate([
                m.mean(axis=0) + spread * rng.normal(size=(self.n_walkers, k)),
                np.log(spread) + rng.normal(0.0, 0.5, size=(self.n_walkers, k))], axis=1)
            sampler = emcee.EnsembleSampler(self.n_walkers, ndim, log_prob, vectorize=True)
            sampler.random_state = np.random.RandomState(
                int(rng.integers(2 ** 31 - 1))).get_state()
            sampler.run_mcmc(start, self.n_steps, progress=False)
            chains.append(sampler.get_chain(discard=self.n_steps // 2))  # (S, W, 2k)
            acc.append(float(np.mean(sampler.acceptance_fraction)))
        self.wall_s_ = time.perf_counter() - t0
        post = np.concatenate(chains, axis=1)                   # walkers as chains
        post = np.concatenate([post[..., :k], np.exp(post[..., k:])], axis=2)
        labels = [f"mu[{n}]" for n in self.names] + [f"tau[{n}]" for n in self.names]
        # R-hat between the independent ensembles (each one's walkers pooled, in time
        # order); ESS with every walker a chain
        self.rhat_, self.ess_, self.ess_tail_ = BayesianIdentification.rhat_ess(
            post, labels, groups=self.n_chains if self.n_chains > 1 else 0)
        self.converged_ = bool(all(v <= RHAT_MAX for v in self.rhat_.values())
                               and all(v >= ESS_MIN for v in self.ess_.values()))
        self.acceptance_ = float(np.mean(acc))
        flat = post.reshape(-1, ndim)
        self.mu_, self.tau_ = flat[:, :k], flat[:, k:]
        # each run's shrunk log values: z_j | mu, tau ~ N(A^-1 (P m + T^-1 mu), A^-1)
        rng = np.random.default_rng(seeds[-1])
        sel = rng.choice(len(flat), size=min(len(flat), 4000), replace=False)
        mu = self.mu_[sel]
        tinv = np.einsum("wi,ik->wik", self.tau_[sel] ** -2.0, np.eye(k))
        runs = []
        for jj in range(j):
            a = prec[jj][None] + tinv
            cov = np.linalg.inv(a)
            mean = np.einsum("wik,wk->wi", cov, (prec[jj] @ m[jj])[None] + np.einsum(
                "wik,wk->wi", tinv, mu))
            chol = np.linalg.cholesky(0.5 * (cov + cov.transpose(0, 2, 1)))
            runs.append(mean + np.einsum("wik,wk->wi", chol, rng.normal(size=mu.shape)))
        self.run_draws_ = np.stack(runs, axis=1)
        self.n_runs_ = j
        self.log_mean_, self.log_precision_ = m, prec
        # each run's marginal log SDs (inf where the run does not inform)
        self.run_log_sd_ = np.full((j, k), np.inf)
        for jj in range(j):
            inf = np.diag(prec[jj]) > 0
            if inf.any():
                self.run_log_sd_[jj, inf] = np.sqrt(np.diag(np.linalg.pinv(
                    prec[jj][np.ix_(inf, inf)])))
        return self

    def predictive_draws(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, k)`` log values of a new run: ``mu + tau * eps`` over the posterior's
        hyperparameter draws (the posterior predictive)."""
        i = rng.integers(len(self.mu_), size=n)
        return self.mu_[i] + self.tau_[i] * rng.normal(size=(n, len(self.names)))

    def prior(self, model: Model, n_mix: int = 512, seed: int = 0) -> "PredictivePrior":
        """The posterior predictive as the tracker's prior (cut at ``model``'s bounds)."""
        return PredictivePrior(model, self.names, self.mu_, self.tau_, n_mix, seed)

    def summary(self, q=(0.05, 0.5, 0.95)) -> dict:
        """Per quantity, in SI units: the population median ``exp(mu)``, mean
        ``exp(mu + tau^2/2)``, log SD ``tau`` and factor ``exp(tau)``, a new run's
        predictive and each run's shrunk value (quantiles ``q``); R-hat and ESS."""
        qs = list(q)

        def qd(x):
            return dict(zip([f"q{round(100 * v):02d}" for v in qs],
                            np.quantile(x, qs).tolist()))

        out = {}
        rng = np.random.default_rng(0)
        new = self.predictive_draws(20000, rng)
        for i, n in enumerate(self.names):
            mu, tau = self.mu_[:, i], self.tau_[:, i]
            out[n] = {"median": qd(np.exp(mu)), "mean": qd(np.exp(mu + 0.5 * tau ** 2)),
                      "log_sd": qd(tau), "spread_factor": qd(np.exp(tau)),
                      "new_run": qd(np.exp(new[:, i])),
                      "runs": [qd(np.exp(self.run_draws_[:, j, i]))
                               for j in range(self.n_runs_)],
                      "run_log_mean": self.log_mean_[:, i].tolist(),
                      "run_log_sd": self.run_log_sd_[:, i].tolist(),
                      "prior": {"mu_mean": float(self.prior_["mu_mean"][i]),
                                "mu_sd": float(self.prior_["mu_sd"][i]),
                                "tau_half_normal_scale": float(self.prior_["tau_scale"][i])},
                      "rhat": {"mu": self.rhat_[f"mu[{n}]"], "tau": self.rhat_[f"tau[{n}]"]},
                      "ess": {"mu": self.ess_[f"mu[{n}]"], "tau": self.ess_[f"tau[{n}]"]},
                      "ess_tail": {"mu": self.ess_tail_[f"mu[{n}]"],
                                   "tau": self.ess_tail_[f"tau[{n}]"]}}
        return out


class PredictivePrior(LogNormalPrior):
    """A new run's posterior predictive: a mixture over hyperparameter draws of
    independent log-normals, cut at the model's bounds.

    Parameters
    ----------
    model : Model
    names : sequence of str
    mu, tau : ndarray
        ``(draws, k)`` hyperparameter draws (log median, log SD).
    n_mix : int
        Components kept (evenly spaced over the draws) for the density.
    seed : int
        Which draws are kept.

    Attributes
    ----------
    log_median, log_sd : ndarray
        The predictive's mean and SD of the log values (its moments, as a
        :class:`LogNormalPrior` of them would have).
    """

    def __init__(self, model: Model, names: Sequence[str], mu, tau, n_mix: int = 512,
                 seed: int = 0):
        mu, tau = np.asarray(mu, dtype=np.float64), np.asarray(tau, dtype=np.float64)
        if mu.shape != tau.shape or mu.ndim != 2 or mu.shape[1] != len(names):
            raise ValueError(f"mu and tau must both be (draws, {len(names)}), got "
                             f"{mu.shape} and {tau.shape}")
        if not np.all(tau > 0):
            raise ValueError("tau must be > 0")
        mean = mu.mean(axis=0)
        sd = np.sqrt(np.mean(tau ** 2, axis=0) + mu.var(axis=0))
        super().__init__(model, names, dict(zip(names, np.exp(mean))), dict(zip(names, sd)))
        rng = np.random.default_rng(seed)
        keep = rng.choice(len(mu), size=min(int(n_mix), len(mu)), replace=False)
        self.mix_mu, self.mix_tau = mu[keep], tau[keep]

    def _draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        i = rng.integers(len(self.mix_mu), size=n)
        return self.mix_mu[i] + self.mix_tau[i] * rng.normal(size=(n, len(self.names)))

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        out = self._draw(n, rng)
        for _ in range(100):  # cut at the bounds: draw again where outside
            bad = np.any((out < self.log_lower) | (out > self.log_upper), axis=1)
            if not bad.any():
                break
            out[bad] = self._draw(int(bad.sum()), rng)
        return np.clip(out, self.log_lower, self.log_upper)

    def logpdf(self, z) -> np.ndarray:
        z = np.atleast_2d(z)
        r = (z[:, None, :] - self.mix_mu[None]) / self.mix_tau[None]      # (n, M, k)
        comp = -0.5 * np.sum(r ** 2, axis=2) - np.sum(np.log(self.mix_tau), axis=1)[None]
        top = comp.max(axis=1, keepdims=True)
        lp = top[:, 0] + np.log(np.mean(np.exp(comp - top), axis=1))
        inside = np.all((z >= self.log_lower) & (z <= self.log_upper), axis=1)
        return np.where(inside, lp, -np.inf)

    def describe(self) -> dict:
        return {**super().describe(), "kind": "hierarchical predictive (log-normal mixture)",
                "n_mix": int(len(self.mix_mu))}
