"""The absorbers: a fitted model's own parameter sensitivities, and their projection.

A residual that a small change of the fitted parameters explains is not a missing
effect. Both searches (the catalogue's :mod:`~pneubayes.discovery.sindy` and the
open form's :class:`~pneubayes.discovery.openform.OpenFormSearch`) take the model's
sensitivities (d prediction / d theta, by central differences at
:func:`sensitivity_points`) through their rows and project them out of the target and
the candidates before the regression (the Frisch-Waugh-Lovell theorem: the candidates'
coefficients are those of the regression with the parameters refitted beside them).
"""

from __future__ import annotations

import numpy as np


def sensitivity_points(model, theta: np.ndarray):
    """``(points, widths, steps)``: parameter sets ``(2 P, P)`` stepping each of the
    ``P`` parameters up and down (rows ``2 j`` and ``2 j + 1``) by ``max(1e-4 |theta|,
    1e-6 x its bounds' span)``, clipped to the bounds; each pair's width (up minus
    down) and the nominal step, ``(P,)`` each."""
    lo, hi = model.bounds
    steps = np.maximum(1e-4 * np.abs(theta), 1e-6 * (hi - lo))
    plus, minus = np.minimum(theta + steps, hi), np.maximum(theta - steps, lo)
    rows = []
    for j in range(theta.size):
        a, b = theta.copy(), theta.copy()
        a[j], b[j] = plus[j], minus[j]
        rows += [a, b]
    return np.array(rows), plus - minus, steps


def project_out(q: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``a`` (rows, ...) less its part in the span of the orthonormal columns ``q``."""
    return a - q @ (q.T @ a) if q.size else a


def orthonormal_basis(a: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column space of ``a`` (its columns scaled to unit norm,
    zero columns dropped; QR, directions whose diagonal falls under ``rel_tol`` x the
    largest left out)."""
    if a.shape[1] == 0:
        return np.zeros((a.shape[0], 0))
    norms = np.linalg.norm(a, axis=0)
    keep = norms > 0
    a = a[:, keep] / norms[keep]
    q, r = np.linalg.qr(a)
    d = np.abs(np.diag(r))
    return q[:, d > rel_tol * max(d.max(initial=0.0), 1e-300)]
