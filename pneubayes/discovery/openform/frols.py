"""pysindy's FROLS with its per-column loops done as array operations.

:class:`pysindy.optimizers.FROLS` (forward regression with orthogonal least squares)
orthogonalises every candidate column against the selected ones one column at a time
(strided column copies, each normalised covariance inside its own ``warnings``
context), and its ``fit`` first solves the full least squares for a starting guess that
FROLS then discards. On the open-form search's libraries (hundreds of columns, tens of
bags per search) those are nearly all of the search's time. :class:`ArrayFROLS` keeps
pysindy's algorithm and its fitted attributes (``history_``, ``ERR_global``, ``loss_``,
``coef_``, the same greedy order and the same ridge inversion) and does each step on
all columns at once:

- the library is orthogonalised incrementally: after each selection every column loses
  its projection on the newly selected orthogonal function, which is the modified
  Gram-Schmidt sequence pysindy applies to each column afresh, done in place as one
  BLAS rank-1 update (no library-sized temporary);
- every column's coefficient ``<q_m, y> / <q_m, q_m>`` and error reduction
  ``g_m^2 <q_m, q_m> / <y, y>`` in one product;
- no full least-squares start and no condition number unless ``kappa`` is set.

The result equals pysindy's up to floating-point summation order (tested).
"""

from __future__ import annotations

import numpy as np
from pysindy import FROLS
from scipy.linalg.blas import dger
from sklearn.linear_model import ridge_regression

_DEPENDENT = "Trying to orthogonalize linearly dependent columns created NaNs"


class ArrayFROLS(FROLS):
    """:class:`pysindy.FROLS` (same parameters, same fitted attributes) with its
    per-column loops vectorised; ``verbose`` runs pysindy's own loop."""

    def fit(self, x_, y, sample_weight=None, **reduce_kws):
        if self.verbose or self.initial_guess is not None:
            return super().fit(x_, y, sample_weight=sample_weight, **reduce_kws)
        n_targets = 1 if np.ndim(y) == 1 else np.shape(y)[1]
        # FROLS discards the start: a zero guess spares the base class's least squares
        self.initial_guess = np.zeros((n_targets, np.shape(x_)[1]))
        try:
            return super().fit(x_, y, sample_weight=sample_weight, **reduce_kws)
        finally:
            self.initial_guess = None

    def _reduce(self, x, y):
        if self.verbose:
            return super()._reduce(x, y)
        n_samples, n_features = x.shape
        n_targets = y.shape[1]
        l0_penalty = self.kappa * np.linalg.cond(x) if self.kappa is not None else 0.0
        self.history_ = []
        self.ERR_global = np.zeros((n_features, n_targets))
        n_steps = min(n_features, self.max_iter + 1)
        per_target = [_Forward(x) for _ in range(n_targets)]
        for i in range(n_steps):
            coef_i = np.zeros((n_targets, n_features), dtype=x.dtype)
            for k, fwd in enumerate(per_target):
                self.ERR_global[i, k] = fwd.select(y[:, k])
                coef_i[k] = fwd.coefficients(self.alpha, self.ridge_kw or {})
            self.history_.append(coef_i)
        l2_err = np.cumsum(self.ERR_global, axis=1)
        l0_norm = np.arange(1, n_features + 1)[:, None]
        self.loss_ = l2_err + l0_penalty * l0_norm
        loss_min = np.argmin(self.loss_[: self.max_iter + 1, :], axis=0)
        self.coef_ = np.zeros((n_targets, n_features), dtype=x.dtype)
        for k in range(n_targets):
            self.coef_[k, :] = self.history_[loss_min[k]][k, :]


class _Forward:
    """One target's forward selection: the library orthogonalised so far, the selected
    columns in order, their orthogonal coefficients and the triangular map back."""

    def __init__(self, x: np.ndarray):
        self.x = x
        self.qs = np.array(x, dtype=x.dtype, order="C", copy=True)
        self.order: list[int] = []
        self.g: list[float] = []
        self.a = np.zeros((x.shape[1], x.shape[1]), dtype=x.dtype)
        self.q: list[np.ndarray] = []

    def select(self, y: np.ndarray) -> float:
        """Pick the next column (largest error reduction); returns its reduction."""
        i = len(self.order)
        real = not np.iscomplexobj(self.qs)
        if i:  # remove every column's projection on the newest orthogonal function
            qn = self.q[-1]
            c = (qn @ self.qs if real else np.conj(qn) @ self.qs) / _norm2(qn)
            if real and self.qs.dtype == np.float64 and self.qs.flags.c_contiguous:
                # in place on the transpose (Fortran order), no (n, m) temporary
                self.qs = dger(-1.0, c, qn, a=self.qs.T, overwrite_a=True).T
            else:
                self.qs -= np.outer(qn, c)
        qs = self.qs
        norm2 = (np.einsum("ij,ij->j", qs, qs) if real
                 else np.real(np.einsum("ij,ij->j", np.conj(qs), qs)))
        live = np.ones(self.x.shape[1], dtype=bool)
        live[self.order] = False
        if np.any(norm2[live] == 0) or not np.all(np.isfinite(norm2[live])):
            raise ValueError(_DEPENDENT)
        g = np.zeros(self.x.shape[1], dtype=np.result_type(self.x, y))
        proj = qs.T @ y if real else np.conj(qs).T @ y
        g[live] = proj[live] / norm2[live]
        err = np.zeros(self.x.shape[1])
        err[live] = np.abs(g[live]) ** 2 * norm2[live] / np.real(np.vdot(y, y))
        best = int(np.argmax(err))
        for j, qj in enumerate(self.q):
            self.a[j, i] = np.vdot(qj, self.x[:, best]) / _norm2(qj)
        self.a[i, i] = 1.0
        self.order.append(best)
        self.g.append(g[best])
        self.q.append(qs[:, best].copy())
        return float(err[best])

    def coefficients(self, alpha: float, ridge_kw: dict) -> np.ndarray:
        """The library's coefficients from the columns selected before the newest one
        (pysindy's history entry of this step)."""
        i = len(self.order) - 1
        coef = np.zeros(self.x.shape[1], dtype=self.x.dtype)
        if i > 0:
            coef[self.order[:i]] = ridge_regression(self.a[:i, :i], np.asarray(self.g[:i]),
                                                    alpha, **ridge_kw)
        coef[np.abs(coef) < 1e-10] = 0
        return coef


def _norm2(v: np.ndarray) -> float:
    n2 = np.real(np.vdot(v, v))
    if n2 == 0 or not np.isfinite(n2):
        raise ValueError(_DEPENDENT)
    return n2
