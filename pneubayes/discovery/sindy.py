"""Grouped sparse regression of the dp/dt residual (pysindy STLSQ, block bagging).

Steps (:class:`GroupedSINDy`):

1. Project the absorbers (the fitted parameters' sensitivities) out of the target and
   of every candidate column: only what no small change of the fitted parameters can
   explain is left to the effects (Frisch-Waugh-Lovell).
2. Orthonormalise each group's columns (QR, in the grid's order). Inside a group the
   trial strengths are strongly collinear; orthonormal columns keep their coefficients
   from inflating each other.
3. Scale each orthonormal column by its cluster-robust standard error (clusters =
   chunks of ``chunk_rows`` rows, or the recordings where they are more): residuals
   are larger right after command steps, exactly where the delay and dead-band terms
   live, and correlated over a few rows, so one global noise level would overstate
   significance there. A coefficient on a scaled column is then its t statistic, and
   pysindy's STLSQ with threshold ``threshold_t`` keeps only terms significant at that
   level.
4. Bagging over *blocks of rows* (``chunk_s`` of recording each), not single rows:
   residuals are autocorrelated, and a row bootstrap would be overconfident. The
   inclusion probability of a group is the fraction of bags in which any of its columns
   survives the threshold.

Each group's evidence also has its single-term t statistic (the best raw column, same
robust standard error) and the fraction of the residual sum of squares it explains.

A column whose energy lies in fewer than ``min_chunks`` effective chunks (``(sum_c
E_c)^2 / sum_c E_c^2`` over its per-chunk energies ``E_c``) has no cluster-robust
standard error worth the name: within one chunk its score sums to (nearly) zero. It
carries no evidence (t = 0) and takes no part in the selection. Short recordings (real
fills of 30-120 ms) make such columns.
"""

from __future__ import annotations

import warnings

import numpy as np

from pneubayes.discovery.absorbers import orthonormal_basis, project_out
from pneubayes.discovery.library import CandidateLibrary


def cluster_se(x: np.ndarray, e: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """Cluster-robust standard error of the coefficient on each unit column of ``x``
    for residual ``e``: ``sqrt(sum_c (sum_{i in c} x_ij e_i)^2) / |x_j|^2``."""
    n_c = int(cluster.max()) + 1
    score = np.zeros((n_c, x.shape[1]))
    np.add.at(score, cluster, x * e[:, None])
    norm2 = np.sum(x * x, axis=0)
    return np.sqrt(np.sum(score**2, axis=0)) / np.where(norm2 > 0, norm2, 1.0)


def effective_chunks(x: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """Per column of ``x``, how many clusters its energy is spread over: ``(sum_c
    E_c)^2 / sum_c E_c^2`` with ``E_c`` the column's sum of squares in cluster ``c`` (1
    for a column inside one cluster, the cluster count for an even spread; 0 for a
    zero column)."""
    n_c = int(cluster.max()) + 1 if cluster.size else 0
    energy = np.zeros((n_c, x.shape[1]))
    np.add.at(energy, cluster, x * x)
    total, sq = energy.sum(axis=0), np.sum(energy ** 2, axis=0)
    return np.where(sq > 0, total ** 2 / np.where(sq > 0, sq, 1.0), 0.0)


class GroupedSINDy:
    """Which candidate group explains the residual (scikit-learn contract).

    Parameters
    ----------
    threshold_t : float
        STLSQ threshold on t statistics (coefficient / cluster-robust standard error).
    n_models : int
        Bagged fits.
    chunk_rows : int
        Rows per bootstrap chunk.
    alpha : float
        Ridge weight of STLSQ (on unit columns).
    seed : int
        Bagging seed.
    min_chunks : float
        Fewest effective chunks a column's energy must spread over for its t statistic
        to count (:func:`effective_chunks`); below, the column is no evidence.
    """

    def __init__(self, threshold_t: float = 5.0, n_models: int = 40,
                 chunk_rows: int = 200, alpha: float = 1e-8, seed: int = 0,
                 min_chunks: float = 2.0):
        self.threshold_t = threshold_t
        self.n_models = n_models
        self.chunk_rows = chunk_rows
        self.alpha = alpha
        self.seed = seed
        self.min_chunks = min_chunks

    def _stlsq(self, x: np.ndarray, y: np.ndarray, threshold: float) -> np.ndarray:
        import pysindy as ps

        opt = ps.STLSQ(threshold=threshold, alpha=self.alpha, max_iter=20, unbias=True)
        with warnings.catch_warnings():
            # "eliminated all coefficients" is an answer here (nothing is missing)
            warnings.filterwarnings("ignore", message="Sparsity parameter is too big",
                                    category=UserWarning)
            opt.fit(x, y)
        return np.asarray(opt.coef_).ravel()

    def fit(self, library: CandidateLibrary) -> "GroupedSINDy":
        lib = library
        y = np.asarray(lib.target, dtype=np.float64)
        if not np.all(np.isfinite(y)) or not np.all(np.isfinite(lib.columns)):
            raise ValueError("GroupedSINDy.fit: the library holds non-finite values")
        q_abs = orthonormal_basis(lib.absorbers)
        y_p = project_out(q_abs, y)
        raw = project_out(q_abs, lib.columns)
        # per group: an orthonormal basis of what the absorbers leave of its columns
        names = lib.group_names
        blocks, col_group = [], []
        raw_norm = np.linalg.norm(lib.columns, axis=0)
        left = np.linalg.norm(raw, axis=0) / np.where(raw_norm > 0, raw_norm, 1.0)
        for g in names:
            idx = [j for j, gg in enumerate(lib.groups) if gg == g and left[j] > 1e-6]
            basis = orthonormal_basis(raw[:, idx]) if idx else np.zeros((y.size, 0))
            blocks.append(basis)
            col_group += [g] * basis.shape[1]
        x = np.concatenate(blocks, axis=1) if blocks else np.zeros((y.size, 0))
        col_group = np.array(col_group)
        n = y.size
        n_chunks = max(1, n // self.chunk_rows)
        chunk_of = np.minimum(np.arange(n) // self.chunk_rows, n_chunks - 1)
        rec = np.asarray(lib.row_recording)
        if rec.size == n:
            # short recordings (real fills of tens of ms): fewer chunks than recordings,
            # so each recording is a chunk (recordings are independent; a chunk that
            # spans several mixes them and leaves too few for a standard error)
            ids, rec_chunk = np.unique(rec, return_inverse=True)
            if ids.size > n_chunks:
                n_chunks, chunk_of = int(ids.size), rec_chunk.astype(np.int64)
        # standard errors from the residual of the full least-squares fit, so that a
        # strong term does not inflate its own (and every other term's) error
        e_full = y_p - x @ np.linalg.lstsq(x, y_p, rcond=None)[0] if x.shape[1] else y_p
        se = cluster_se(x, e_full, chunk_of)
        # a column inside (nearly) one chunk has no usable standard error: no evidence
        usable = (se > 0) & (effective_chunks(x, chunk_of) >= self.min_chunks)
        se = np.where(usable, se, 1.0)
        x = np.where(usable, x, 0.0)
        x = x * se  # y = c x = (c / se)(se x): coefficients on se x are t statistics
        thr = self.threshold_t
        self.residual_std_ = float(np.std(y_p))
        self.absorbed_fraction_ = dict(zip(lib.labels, (1.0 - left).tolist()))
        if x.shape[1] == 0:
            self.coef_ = np.zeros(0)
            self.inclusion_probability_ = {g: 0.0 for g in names}
            self.evidence_ = {g: {"inclusion_probability": 0.0, "t_max": 0.0,
                                  "best_term": None, "best_term_start": None,
                                  "explained_fraction": 0.0}
                              for g in names}
            self.ranking_ = []
            return self
        self.coef_ = self._stlsq(x, y_p, thr)
        rng = np.random.default_rng(self.seed)
        members = [np.nonzero(chunk_of == c)[0] for c in range(n_chunks)]
        hits = np.zeros((self.n_models, x.shape[1]), dtype=bool)
        for m in range(self.n_models):
            pick = rng.integers(0, n_chunks, n_chunks)
            rows = np.concatenate([members[c] for c in pick])
            hits[m] = self._stlsq(x[rows], y_p[rows], thr) != 0
        rss0 = float(y_p @ y_p)
        raw_spread = effective_chunks(raw, chunk_of)  # per raw column, for its own t
        self.inclusion_probability_ = {}
        self.evidence_ = {}
        for g in names:
            cols = col_group == g
            p_inc = float(np.mean(hits[:, cols].any(axis=1))) if cols.any() else 0.0
            xg = x[:, cols]
            xo = xg / (se[cols] if cols.any() else 1.0)  # back to orthonormal
            explained = float(np.sum((xo.T @ y_p) ** 2)) / rss0 if cols.any() else 0.0
            t_best, term, term_start = 0.0, None, None
            for j, (gg, lab) in enumerate(zip(lib.groups, lib.labels)):
                nj = np.linalg.norm(raw[:, j])
                if gg != g or nj <= 1e-6 * max(raw_norm[j], 1e-300):
                    continue
                if raw_spread[j] < self.min_chunks:
                    continue
                xj = raw[:, j:j + 1] / nj
                c = float(xj[:, 0] @ y_p)
                se_j = float(cluster_se(xj, y_p - c * xj[:, 0], chunk_of)[0])
                t = abs(c) / se_j if se_j > 0 else 0.0
                if t > t_best:
                    t_best, term = t, lab
                    term_start = dict(lib.starts[j]) if lib.starts else None
            self.inclusion_probability_[g] = p_inc
            self.evidence_[g] = {"inclusion_probability": p_inc, "t_max": t_best,
                                 "best_term": term, "best_term_start": term_start,
                                 "explained_fraction": explained,
                                 "selected_in_full_fit": bool(np.any(self.coef_[cols] != 0))}
        self.ranking_ = sorted(names, key=lambda g: (self.evidence_[g]["inclusion_probability"],
                                                     self.evidence_[g]["t_max"]), reverse=True)
        return self

    def supported(self, min_inclusion: float) -> list[str]:
        """Groups with inclusion probability >= ``min_inclusion``, strongest first."""
        return [g for g in self.ranking_
                if self.evidence_[g]["inclusion_probability"] >= min_inclusion]
