"""The sampler's moves beyond emcee's own: an exact Gibbs move for the coordinates only
the prior informs, and a Student-t independence proposal fitted to a previous round.
:class:`~pneubayes.inference.sampler.BayesianIdentification` mixes them with
differential evolution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.inference.likelihood import WindowLikelihood
from pneubayes.inference.walker_start import correlation_form


def nuisance_gibbs_move(like: WindowLikelihood):
    """An emcee move that redraws every nuisance coordinate uniformly over the range the
    other coordinates allow (:meth:`WindowLikelihood.nuisance_ranges`).

    The posterior is flat in those coordinates within that range, so this is an exact
    Gibbs update (always accepted); it mixes the directions only the prior informs in
    one step instead of a random walk.
    """
    import emcee

    cols = np.array(sorted(like.nuisance()))

    def propose(x0, random):
        lo, hi = like.nuisance_ranges(x0)
        x = x0.copy()
        ok = hi > lo
        draw = lo + (hi - lo) * random.random_sample(lo.shape)
        x[:, cols] = np.where(ok, draw, x0[:, cols])
        return x, np.zeros(x.shape[0])  # symmetric: the range depends on the others only

    return emcee.moves.MHMove(propose)


@dataclass(frozen=True)
class StudentTProposal:
    """The independence proposal: a multivariate Student-t over the identified
    coordinates, and each nuisance coordinate uniform over the range the proposed
    identified ones allow (the posterior is flat there).

    ``columns`` are the Student-t coordinates; ``nuisance`` the others.
    """

    columns: np.ndarray
    nuisance: np.ndarray
    mean: np.ndarray
    chol: np.ndarray  # lower Cholesky factor of the scale matrix
    df: float

    @classmethod
    def fit(cls, samples: np.ndarray, nuisance, df: float, scale: float):
        """Fit to ``samples (N, D)``: their mean, and covariance x ``scale**2``."""
        nuis = np.array(sorted(nuisance), dtype=np.int64)
        cols = np.array([j for j in range(samples.shape[1]) if j not in set(nuis.tolist())],
                        dtype=np.int64)
        x = samples[:, cols]
        cov = np.atleast_2d(np.cov(x, rowvar=False)) * scale**2
        jitter = 1e-10 * np.maximum(np.diag(cov), 1e-300)
        chol = np.linalg.cholesky(cov + np.diag(jitter))
        return cls(cols, nuis, x.mean(axis=0), chol, float(df))

    @classmethod
    def from_gaussian(cls, mean: np.ndarray, cov: np.ndarray, columns: np.ndarray,
                      nuisance, df: float, scale: float):
        """The proposal over ``columns`` with location ``mean`` and scale matrix ``cov``
        x ``scale**2`` (a Laplace approximation's Gaussian)."""
        nuis = np.array(sorted(nuisance), dtype=np.int64)
        sd, _, r = correlation_form(cov)
        chol = sd[:, None] * np.linalg.cholesky(r) * scale
        return cls(np.asarray(columns, dtype=np.int64), nuis, np.asarray(mean, float),
                   chol, float(df))

    def log_density(self, x: np.ndarray, ranges=None) -> np.ndarray:
        """Log-density of rows ``x (B, D)`` up to a constant; ``ranges = (lo, hi)`` of
        the nuisance coordinates given the others (uniform factors)."""
        from scipy.linalg import solve_triangular

        y = solve_triangular(self.chol, (x[:, self.columns] - self.mean).T, lower=True)
        k = self.columns.size
        out = -0.5 * (self.df + k) * np.log1p(np.sum(y * y, axis=0) / self.df)
        if ranges is not None and self.nuisance.size:
            lo, hi = ranges
            with np.errstate(divide="ignore", invalid="ignore"):
                out = out - np.sum(np.log(np.where(hi > lo, hi - lo, np.nan)), axis=1)
            out[~np.isfinite(out)] = -np.inf
        return out

    def move(self, like: WindowLikelihood):
        """An emcee MH move proposing from this distribution, independently of x."""
        import emcee

        def propose(x0, random):
            n, k = x0.shape[0], self.columns.size
            g = random.standard_normal((n, k)) @ self.chol.T
            w = random.chisquare(self.df, n) / self.df
            x = x0.copy()
            x[:, self.columns] = self.mean + g / np.sqrt(w)[:, None]
            r_new = r_old = None
            if self.nuisance.size:
                r_old = like.nuisance_ranges(x0)
                r_new = like.nuisance_ranges(x)
                lo, hi = r_new
                x[:, self.nuisance] = lo + (hi - lo) * random.random_sample(lo.shape)
            with np.errstate(invalid="ignore"):
                factor = self.log_density(x0, r_old) - self.log_density(x, r_new)
            # an empty range: the proposal lies outside the prior; reject it
            factor[~np.isfinite(factor)] = -np.inf
            return x, factor

        return emcee.moves.MHMove(propose)


def moved_fraction(chain: np.ndarray) -> float:
    """Fraction of walker steps that moved in ``chain (steps + 1, walkers, D)``: the
    acceptance rate of the move mixture (a Gibbs move always moves)."""
    return float(np.mean(np.any(np.diff(chain, axis=0) != 0, axis=2)))
