"""One column of a window residual's regression, with its errors clustered by window.

The open-form searches on prediction windows (:mod:`~pneubayes.discovery.openform.reading`,
:mod:`~pneubayes.discovery.openform.volume`) regress the windows' residual on a few
columns; a window's residual is one correlated trace, so a column's standard error is
the sandwich estimate summed by window, not over independent samples.
"""

from __future__ import annotations

import numpy as np


def last_column_fit(cols, y, ok, windows, total: float) -> tuple[float, float, float]:
    """The last of ``cols`` fitted beside the others on the residual ``y``.

    Parameters
    ----------
    cols : list of (N,) arrays
        The columns, each 0 where ``ok`` is False.
    y, ok : (N,) arrays
        The residual and where it is finite.
    windows : (N,) int array
        Each sample's window (the clusters).
    total : float
        The residual's uncentred sum of squares.

    Returns
    -------
    (coefficient, explained, t)
        The last column's coefficient, its own share of ``total`` beside the others and
        its coefficient over its window-clustered standard error.
    """
    x = np.stack(cols, axis=1)
    yy = np.where(ok, y, 0.0)
    g, *_ = np.linalg.lstsq(x, yy, rcond=None)
    e = yy - x @ g
    # the last column's part orthogonal to the others, its sandwich variance by window
    last = x[:, -1]
    if x.shape[1] > 1:
        last = last - x[:, :-1] @ np.linalg.lstsq(x[:, :-1], last, rcond=None)[0]
    xx = float(last @ last)
    if xx <= 0.0:
        return 0.0, 0.0, 0.0
    sums = np.bincount(windows, weights=last * e)
    se = float(np.sqrt(np.sum(sums**2))) / xx
    coef = float(g[-1])
    explained = float(last @ yy) ** 2 / xx / total
    return coef, explained, coef / se if se > 0 else np.inf


def stacked_residual(residuals) -> tuple[np.ndarray, np.ndarray]:
    """``(y, windows)``: the recordings' window residuals (each ``(W, L - 1)``) flattened
    into one vector in order, and each sample's window (the clusters: windows numbered
    across the recordings)."""
    y = np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1) for r in residuals])
    sizes = [np.shape(r) for r in residuals]
    first = np.cumsum([0] + [w for w, _ in sizes[:-1]])
    windows = np.concatenate([np.repeat(np.arange(w) + f, n)
                              for f, (w, n) in zip(first, sizes)])
    return y, windows


__all__ = ["last_column_fit", "stacked_residual"]
