"""One bag's sparse regression of the open-form search, and the least squares around it.

:func:`bag_coefficients` fits one bootstrap bag's unit-RMS columns with a pysindy
optimizer (FROLS by default, as :class:`~pneubayes.discovery.openform.frols.ArrayFROLS`,
stopped where the next term's error reduction falls under a share; see
:mod:`~pneubayes.discovery.openform.search` for why FROLS);
:func:`swap_columns` lets a greedy pick give way to a better or a simpler column;
:func:`least_squares` refits the kept physical columns; :func:`candidate_rank` is the
complexity order the swap prefers.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from pneubayes.discovery.openform.features import Candidate

#: The pysindy optimizers the search can use.
OPTIMIZERS = ("frols", "stlsq", "sr3", "sbr")


def candidate_rank(candidate: Candidate) -> int:
    """A candidate's complexity: 0 the constant, 1 another base feature, 2 a hinge,
    3 a product, 4 a product with a hinge."""
    term = candidate.term
    if term.b == "one":
        return 0 if term.a == "one" else (2 if term.hinges() else 1)
    return 4 if term.hinges() else 3


def bag_coefficients(x: np.ndarray, y: np.ndarray, rank: np.ndarray, *, optimizer: str,
                     max_terms: int, ridge: float, threshold: float,
                     min_explained_fraction: float, swap_min_gain: float) -> np.ndarray:
    """Coefficients of one bag on unit-RMS columns ``x`` (rows, candidates) for target
    ``y`` (zeros: not selected); columns that vanish in the bag (a hinge no drawn row
    reaches) take no part. ``rank`` is each column's :func:`candidate_rank`; the
    keywords are :class:`~pneubayes.discovery.openform.search.OpenFormSearch`'s
    settings of the same names."""
    live = np.linalg.norm(x, axis=0) > 1e-9 * math.sqrt(y.size)
    coef = np.zeros(x.shape[1])
    if live.any():
        coef[live] = _live_coefficients(x[:, live], y, rank[live], optimizer, max_terms,
                                        ridge, threshold, min_explained_fraction,
                                        swap_min_gain)
    return coef


def _live_coefficients(x, y, rank, optimizer, max_terms, ridge, threshold,
                       min_explained_fraction, swap_min_gain) -> np.ndarray:
    import pysindy as ps

    n = y.size
    xn, yn = x / math.sqrt(n), y / math.sqrt(n)  # unit-norm columns and target
    if optimizer == "frols":
        from pneubayes.discovery.openform.frols import ArrayFROLS

        opt = ArrayFROLS(max_iter=max_terms, alpha=ridge, unbias=False)
        opt.fit(xn, yn)
        err = opt.ERR_global[:, 0]
        k = 0
        most = min(max_terms, len(opt.history_) - 1)
        while k < most and err[k] >= min_explained_fraction:
            k += 1
        if k == 0:
            return np.zeros(x.shape[1])
        # history_[k] holds the first k selected terms; refit them unregularised
        sel = swap_columns(xn, yn, rank,
                           list(np.nonzero(np.asarray(opt.history_[k]).ravel() != 0)[0]),
                           swap_min_gain)
        coef = np.zeros(x.shape[1])
        coef[sel] = np.linalg.lstsq(xn[:, sel], yn, rcond=None)[0]
        return coef
    if optimizer == "stlsq":
        opt = ps.STLSQ(threshold=threshold, alpha=ridge, max_iter=20, unbias=True)
    elif optimizer == "sr3":
        # L0 prox with relax_coeff_nu 1 thresholds at sqrt(2 lam): lam = thr^2 / 2
        opt = ps.SR3(reg_weight_lam=0.5 * threshold**2, regularizer="L0",
                     relax_coeff_nu=1.0, max_iter=100, unbias=True)
    else:
        try:
            import numpyro  # noqa: F401
        except ImportError:
            raise ValueError("optimizer 'sbr' needs numpyro, which is not installed"
                             ) from None
        opt = ps.SBR(num_warmup=200, num_samples=500)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "eliminated all coefficients": an answer
        opt.fit(xn, yn)
    coef = np.asarray(opt.coef_, dtype=np.float64).ravel()
    if optimizer == "sbr":  # posterior means: keep those above the threshold
        coef = np.where(np.abs(coef) >= threshold, coef, 0.0)
    return coef


def swap_columns(x: np.ndarray, y: np.ndarray, rank: np.ndarray, sel: list[int],
                 swap_min_gain: float) -> list[int]:
    """Exchange selected columns for better or simpler ones (unit-norm ``x`` and ``y``):
    each selected column in turn is replaced by the column that, with the others held,
    explains most, when that gains more than ``swap_min_gain`` times the fit's residual
    sum of squares, else by the best simpler column (lower ``rank``,
    :func:`candidate_rank`) when that loses less; passes repeat until nothing changes
    (at most ``len(sel) + 1`` passes). A greedy forward pick can take a column that
    stands in for two true terms at first (a spool offset for a constant beside a flow
    term) and keep it; and a nearly constant product (``volume * volume``) is not to be
    preferred to the constant on less evidence than that. The margin is the residual's,
    not the target's: a strong term (a laminar leak's ``p^2``) is not given up for a
    simpler one that fits it a little worse."""
    sel = list(sel)
    # each column's gain beside the others, (x_p . r)^2 / |x_p|^2 with x_p its part
    # orthogonal to them (orthonormal basis q), from the products with q alone: r is
    # orthogonal to q, so x_p . r = x . y - (q'x) . (q'y), and |x_p|^2 = |x|^2 - |q'x|^2
    # (the projected candidate matrix is never formed)
    xy, xx = x.T @ y, np.sum(x * x, axis=0)
    for _ in range(len(sel) + 1):
        changed = False
        for i in range(len(sel)):
            others = sel[:i] + sel[i + 1:]
            if others:
                q, _ = np.linalg.qr(x[:, others])
                qy, qx = q.T @ y, q.T @ x
                r = y - q @ qy
                xr, norm2 = xy - qx.T @ qy, xx - np.sum(qx * qx, axis=0)
            else:
                r, xr, norm2 = y, xy, xx
            gain = np.where(norm2 > 1e-12, xr**2 / np.where(norm2 > 1e-12, norm2, 1.0), 0.0)
            gain[others] = 0.0
            best = int(np.argmax(gain))
            # the residual sum of squares of the bag's fit as it stands
            margin = swap_min_gain * max(float(r @ r) - gain[sel[i]], 0.0)
            if best != sel[i] and gain[best] > gain[sel[i]] + margin:
                sel[i] = best
                changed = True
                continue
            simpler = np.nonzero(rank < rank[sel[i]])[0]
            simpler = simpler[~np.isin(simpler, others)]
            if simpler.size:
                b = int(simpler[np.argmax(gain[simpler])])
                if gain[b] > gain[sel[i]] - margin:
                    sel[i] = b
                    changed = True
        if not changed:
            break
    return sel


def least_squares(cols: list[np.ndarray], y: np.ndarray):
    """``(coef, rss)`` of least squares on the given columns (scaled internally)."""
    x = np.column_stack(cols)
    s = np.sqrt(np.mean(x * x, axis=0))
    s = np.where(s > 0, s, 1.0)
    c = np.linalg.lstsq(x / s, y, rcond=None)[0] / s
    r = y - x @ c
    return c, float(r @ r)
