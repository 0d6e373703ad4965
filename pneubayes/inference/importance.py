"""Whether draws of an approximation stand for the posterior: Pareto-smoothed importance
sampling's diagnostic (Vehtari et al. 2024, JMLR 25(72)), as the Laplace posterior
(:mod:`pneubayes.inference.laplace`) checks its own draws."""

from __future__ import annotations

import numpy as np

from pneubayes.inference.sampler import arviz
from pneubayes.inference.walker_start import correlation_form

#: Draws whose posterior density checks the approximation (:func:`importance_check`):
#: 200 puts 42 in the Pareto tail fit (``min(0.2 S, 3 sqrt S)``).
IMPORTANCE_CHECK_DRAWS = 200


def importance_check(like, z: np.ndarray, mean_z: np.ndarray, ident: np.ndarray,
                     cov_z: np.ndarray) -> dict:
    """How well draws ``z`` (sampling coordinates) of a Gaussian ``N(mean_z[ident],
    cov_z)`` on the identified columns ``ident``, cut at the priors' bounds
    (:func:`~pneubayes.inference.laplace.truncated_draws`), stand for the posterior
    ``like``: the Pareto-smoothed importance sampling diagnostic of Vehtari et al.
    (2024, JMLR 25(72)) on the log-ratios of the
    posterior to the draws' density (the Gaussian on the identified coordinates, each
    nuisance one uniform over its allowed range; constants drop out). ``pareto_k``
    (None where the ratios are constant: the draws' density is the posterior's) above
    ``khat_threshold`` (``min(1 - 1/log10 S, 0.7)`` for S draws): the posterior has mass
    the Gaussian misses (skew, a heavy tail, a mode on a bound that is not a cut
    Gaussian) and its intervals are not the posterior's; a Gaussian wider than the
    posterior passes (importance sampling from it is reliable) but its intervals are too
    wide: ``ess_fraction`` (the smoothed weights' effective sample size over S) falls.
    Costs S posterior evaluations (one call)."""
    n = z.shape[0]
    lp = like.log_prob_sampling(z)
    sd, _, r = correlation_form(cov_z)
    u = (z[:, ident] - mean_z[ident]) / sd
    chol = np.linalg.cholesky(r)
    white = np.linalg.solve(chol, u.T)
    log_q = -0.5 * np.sum(white**2, axis=0)
    if like.nuisance():
        rlo, rhi = like.nuisance_ranges(z)
        log_q -= np.sum(np.log(np.maximum(rhi - rlo, 1e-300)), axis=1)
    log_w = lp - log_q
    out = {"draws": int(n), "khat_threshold": _khat_threshold(n)}
    if not np.all(np.isfinite(log_w)):  # a draw without a density: nothing to weigh
        return {**out, "pareto_k": float("inf"), "ess_fraction": 0.0}
    if np.ptp(log_w) < 1e-9:  # the draws' density is the posterior's: no tail to fit
        return {**out, "pareto_k": None, "ess_fraction": 1.0}
    with np.errstate(all="ignore"):
        lw, k = arviz().psislw(log_w - log_w.max())
    w = np.exp(lw - lw.max())
    w /= w.sum()
    return {**out, "pareto_k": float(k), "ess_fraction": float(1.0 / (n * w @ w))}


def _khat_threshold(n: int) -> float:
    """The largest Pareto k at which ``n`` importance draws are reliable (Vehtari et al.
    2024: ``min(1 - 1/log10 n, 0.7)``)."""
    return float(min(1.0 - 1.0 / np.log10(n), 0.7))
