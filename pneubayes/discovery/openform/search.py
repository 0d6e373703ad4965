"""Open-form search: which closure terms explain the missing mass flow.

:class:`OpenFormSearch` regresses the missing mass flow (kg/s,
:func:`~pneubayes.discovery.openform.signals.missing_mass_flow`) on the candidate terms
of :mod:`~pneubayes.discovery.openform.features`:

1. Rows are block sums of ``block`` consecutive intervals of each recording (as
   :mod:`~pneubayes.discovery.one_step`'s rows); columns that are zero, or that these
   data cannot tell from an earlier, simpler column (``duplicate_tolerance``), are
   dropped; every column and the target are scaled to unit RMS.
2. Bagging: ``n_models`` bootstrap draws of chunks of ``chunk_rows`` consecutive rows
   (residuals are autocorrelated; pysindy's ``EnsembleOptimizer`` draws single rows,
   which would be overconfident), each fitted by a pysindy sparse optimizer
   (``optimizer``). FROLS, the default, is stopped where the next term's error
   reduction falls below ``min_explained_fraction``, and its pick then gives way to a
   better or a simpler column (``swap_min_gain``). A *family* (a term without its
   thresholds) is included in a bag when any of its columns is; its inclusion
   probability is the fraction of bags, and its threshold the column selected most often.
3. The families with inclusion probability >= ``min_inclusion`` enter a least-squares
   refit on the physical columns (hinge thresholds then refined, with the others held,
   between the neighbouring grid thresholds); while more than ``max_terms`` remain, or
   the weakest explains less than ``min_explained_fraction`` of the target's
   (uncentred) sum of squares on its own (its drop-one loss), the weakest is dropped
   and the rest refitted. A term is thus kept only if it is supported across bags and
   explains a meaningful share of the target: on noise nothing passes both.

Why FROLS: on the planted-term cases (``benchmarks/openform_optimizers.py``) it returned
exactly the planted families in 24 of 24 fits, STLSQ (threshold 0.05 or 0.2) and SR3 in
4 of 14 (the two null controls and two planted terms): a thresholded regression on ~280
strongly collinear columns keeps a collinear neighbour of the term, or several. SBR
needs numpyro, which is not installed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from pneubayes.discovery.absorbers import orthonormal_basis, project_out
from pneubayes.discovery.openform.features import (
    DEFAULT_QUANTILES,
    HINGE_SOURCES,
    Candidate,
    candidate_terms,
    dead_time_range,
    design_matrix,
    distinct_columns,
    hinge_source_values,
    hinge_thresholds,
    relaxation_range,
)
from pneubayes.discovery.openform.sparse import (
    OPTIMIZERS,
    bag_coefficients,
    candidate_rank,
    least_squares,
)
from pneubayes.effects.closure_features import (
    DEAD_TIME_FEATURES,
    LOW_PASS_HISTORIES,
    SIGNALS,
    feature,
)
from pneubayes.effects.closure_terms import (
    CLOSURE_MAX_TERMS,
    Term,
)


@dataclass(frozen=True)
class FoundTerm:
    """One term of the search's answer (also a tuple, in this order).

    ``coefficient`` is in the term's unit (``term.unit``: kg/s over the features'
    units); ``inclusion_probability`` the fraction of bags that selected its family;
    ``share`` its share of the explained target (``c_j x_j . y / (yhat . y)``, the
    shares sum to 1); ``explained_fraction`` the fraction of the target's uncentred sum
    of squares lost when it alone is dropped from the refit.
    """

    term: Term
    threshold_a: float
    threshold_b: float
    coefficient: float
    inclusion_probability: float
    share: float
    explained_fraction: float

    def __iter__(self):
        return iter((self.term, self.threshold_a, self.threshold_b, self.coefficient,
                     self.inclusion_probability, self.share))


def closure_spec(terms: Sequence[FoundTerm]) -> str:
    """The ``Closure(terms=...)`` text of found terms, e.g. ``"inlet_flow; one"``."""
    return "; ".join(str(t.term) for t in terms)


#: A candidate keeps at least this share of its norm outside the nuisance columns' span,
#: or it is dropped (what is left is the nuisance's round-off and noise).
NUISANCE_KEEP = 0.01


def _block_sums(values: np.ndarray, block: int) -> np.ndarray:
    """Sum ``(M, ...)`` per-interval values over consecutive blocks of ``block``."""
    n = (values.shape[0] // block) * block
    return values[:n].reshape(n // block, block, *values.shape[1:]).sum(axis=1)


class OpenFormSearch:
    """Sparse search of closure terms for the missing mass flow (scikit-learn contract).

    Parameters
    ----------
    max_terms, block : int
        Most terms returned (1..4, a closure's slots); sample intervals per row.
    optimizer : {"frols", "stlsq", "sr3", "sbr"}
        The sparse regression (pysindy's; SBR needs numpyro).
    threshold, ridge : float
        STLSQ's and SR3's threshold on unit-norm coefficients; ridge (STLSQ, FROLS).
    n_models, chunk_rows, seed : int
        Bagged fits; consecutive rows per bootstrap chunk; the bagging's seed.
    min_inclusion, min_explained_fraction : float
        A family's least inclusion probability to be refitted; a kept term's least share
        of the target's uncentred sum of squares on its own (FROLS stops below it too).
    quantiles, duplicate_tolerance, swap_min_gain : sequence of float, float, float
        The hinge thresholds' quantiles; a column within this of |cos| 1 of an earlier
        one is dropped; FROLS swaps a bag's column for a better or simpler one
        (:func:`~pneubayes.discovery.openform.sparse.swap_columns`).
    refine_thresholds, exclude, without_features : bool, sequence of str, idem
        Refine the kept hinges' thresholds; families left out (a search again); base
        features no candidate reads (beside a wave tube, the valve's ports).
    alias_cos : float
        Families whose best columns are within this |cosine| stand in for each other
        (:meth:`_aliases`).

    Attributes
    ----------
    terms_ : list of FoundTerm
        The kept terms, strongest first (:class:`FoundTerm`).
    inclusion_probability_ : dict
        Family -> fraction of bags that selected it.
    evidence_ : dict
        Family -> ``{"inclusion_probability", "best_label", "selections"}`` (and any
        ``"aliases"``: the families that stood in for it, the group's inclusion).
    explained_fraction_ : float
        Fraction of the target's uncentred sum of squares the kept terms explain.
    n_candidates_, n_rows_ : int
        Distinct candidate columns searched; regression rows.
    """

    def __init__(self, max_terms: int = CLOSURE_MAX_TERMS, block: int = 5,
                 optimizer: str = "frols", threshold: float = 0.05, ridge: float = 1e-6,
                 n_models: int = 40, chunk_rows: int = 25, min_inclusion: float = 0.6,
                 min_explained_fraction: float = 0.02,
                 quantiles: Sequence[float] = DEFAULT_QUANTILES,
                 duplicate_tolerance: float = 2e-3, swap_min_gain: float = 0.02,
                 refine_thresholds: bool = True, seed: int = 0,
                 exclude: Sequence[str] = (), alias_cos: float = 0.95,
                 without_features: Sequence[str] = ()):
        self.max_terms = max_terms
        self.block = block
        self.optimizer = optimizer
        self.threshold = threshold
        self.ridge = ridge
        self.n_models = n_models
        self.chunk_rows = chunk_rows
        self.min_inclusion = min_inclusion
        self.min_explained_fraction = min_explained_fraction
        self.quantiles = quantiles
        self.duplicate_tolerance = duplicate_tolerance
        self.swap_min_gain = swap_min_gain
        self.refine_thresholds = refine_thresholds
        self.seed = seed
        self.exclude = exclude
        self.alias_cos = alias_cos
        self.without_features = without_features

    # ------------------------------------------------------------------ validation
    def _validate(self, signals_list, target_list, row_maps=None):
        if not isinstance(self.max_terms, int) or not 1 <= self.max_terms <= CLOSURE_MAX_TERMS:
            raise ValueError(f"max_terms must be an integer in 1..{CLOSURE_MAX_TERMS}, "
                             f"got {self.max_terms!r}")
        if not isinstance(self.block, int) or self.block < 1:
            raise ValueError(f"block must be an integer >= 1, got {self.block!r}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        for name in ("threshold", "min_explained_fraction"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 < v < 1.0):
                raise ValueError(f"{name} must lie in (0, 1), got {v!r}")
        if not 0.0 < self.min_inclusion <= 1.0:
            raise ValueError(f"min_inclusion must lie in (0, 1], got {self.min_inclusion!r}")
        if not (isinstance(self.alias_cos, (int, float)) and 0.0 < self.alias_cos <= 1.0):
            raise ValueError(f"alias_cos must lie in (0, 1], got {self.alias_cos!r}")
        if not self.ridge >= 0.0:
            raise ValueError(f"ridge must be >= 0, got {self.ridge!r}")
        if not isinstance(self.n_models, int) or self.n_models < 1:
            raise ValueError(f"n_models must be an integer >= 1, got {self.n_models!r}")
        if not isinstance(self.chunk_rows, int) or self.chunk_rows < 1:
            raise ValueError(f"chunk_rows must be an integer >= 1, got {self.chunk_rows!r}")
        if isinstance(self.exclude, str) or not all(isinstance(f, str)
                                                    for f in self.exclude):
            raise ValueError("exclude must be a sequence of families such as "
                             f"'inlet_flow*pressure_hinge', got {self.exclude!r}")
        for f in self.exclude:
            Term.parse(f)  # (a misspelt family raises, naming it)
        if isinstance(self.without_features, str):
            raise ValueError("without_features must be a sequence of feature names, got "
                             f"{self.without_features!r}")
        for name in self.without_features:
            feature(name)  # (an unknown name raises, naming the known ones)
        if isinstance(signals_list, dict) or isinstance(target_list, np.ndarray):
            raise ValueError("fit takes a list of signal dicts and a list of targets "
                             "(one per recording)")
        if len(signals_list) != len(target_list) or not signals_list:
            raise ValueError(f"fit: {len(signals_list)} signal dicts for {len(target_list)} "
                             "targets; give one of each per recording (at least one)")
        if row_maps is not None and len(row_maps) != len(signals_list):
            raise ValueError(f"fit: {len(row_maps)} row maps for {len(signals_list)} "
                             "recordings; give one per recording")
        for i, (s, y) in enumerate(zip(signals_list, target_list)):
            missing = [k for k in SIGNALS if k not in s]
            if missing:
                raise ValueError(f"recording {i}: signals lack {missing}")
            n = np.asarray(y).shape
            if row_maps is not None:
                rows = getattr(row_maps[i], "n_rows", n[0] if len(n) == 1 else None)
                if len(n) != 1 or rows != n[0]:
                    raise ValueError(f"recording {i}: with row maps the target is the "
                                     f"map's {rows} rows, got shape {n}")
                continue
            if len(n) != 1 or np.broadcast_shapes(*(np.shape(s[k]) for k in SIGNALS), n) != n:
                raise ValueError(f"recording {i}: the target and the signals must be 1-D "
                                 f"of one length, got target {n}")

    # ------------------------------------------------------------------ rows
    def _to_rows(self, values: np.ndarray, i: int) -> np.ndarray:
        """Per-interval values of recording ``i`` -> its regression rows: block sums of
        :attr:`block` intervals, or the fit's ``row_maps[i]``."""
        if self._row_maps is None:
            return _block_sums(values, self.block)
        return self._row_maps[i](values)

    def _rows(self, candidate: Candidate, signals_list, finite: np.ndarray) -> np.ndarray:
        """One candidate's rows over all recordings (the ``finite`` ones only)."""
        col = np.concatenate([self._to_rows(candidate.evaluate(s), i)
                              for i, s in enumerate(signals_list)])[finite]
        return col if self._basis is None else project_out(self._basis, col)

    def _sparse(self, x: np.ndarray, y: np.ndarray, rank: np.ndarray) -> np.ndarray:
        """One bag's coefficients on unit-RMS columns (:func:`~pneubayes.discovery.
        openform.sparse.bag_coefficients` with this search's settings)."""
        return bag_coefficients(x, y, rank, optimizer=self.optimizer,
                                max_terms=self.max_terms, ridge=self.ridge,
                                threshold=self.threshold,
                                min_explained_fraction=self.min_explained_fraction,
                                swap_min_gain=self.swap_min_gain)

    # ------------------------------------------------------------------ refit
    def _refine(self, sel: list[Candidate], cols: list[np.ndarray], y, signals_list,
                finite, grid: dict, ranges: dict) -> None:
        """Refine each hinge threshold of ``sel`` in place (one pass, others held)."""
        for j, cand in enumerate(sel):
            for side in cand.term.hinges():
                name = getattr(cand.term, side)
                th = cand.threshold_a if side == "a" else cand.threshold_b
                g = grid[name]
                i = int(np.argmin(np.abs(g - th)))
                lo = g[i - 1] if i > 0 else ranges[name][0]
                hi = g[i + 1] if i + 1 < g.size else ranges[name][1]
                if not hi > lo:
                    continue

                def with_threshold(v, cand=cand, side=side):
                    return Candidate(cand.term, v if side == "a" else cand.threshold_a,
                                     v if side == "b" else cand.threshold_b)

                def rss(v, j=j, with_threshold=with_threshold):
                    col = self._rows(with_threshold(v), signals_list, finite)
                    trial = cols[:j] + [col] + cols[j + 1:]
                    return least_squares(trial, y)[1]

                best = minimize_scalar(rss, bounds=(lo, hi), method="bounded",
                                       options={"xatol": 1e-4 * (hi - lo)})
                if best.fun < rss(th):
                    sel[j] = with_threshold(float(best.x))
                    cols[j] = self._rows(sel[j], signals_list, finite)

    # ------------------------------------------------------------------ fit
    def _aliases(self, inclusion: dict, best: dict, hits, fam_of, xs, ys) -> dict:
        """Family -> its support: its inclusion probability, or, for the member of a
        group of stand-ins (best columns within :attr:`alias_cos`, none of them supported
        alone) that explains most of ``ys`` alone, the share of bags that chose any of
        the group (the others' support 0)."""
        out = dict(inclusion)
        weak = [f for f, p in inclusion.items() if 0.0 < p < self.min_inclusion]
        if len(weak) < 2:
            return out
        cols = xs[:, [best[f] for f in weak]]
        unit = cols / np.linalg.norm(cols, axis=0)
        close = np.abs(unit.T @ unit) > self.alias_cos
        group = list(range(len(weak)))  # union-find over the weak families
        for i, j in zip(*np.nonzero(np.triu(close, 1))):
            gi, gj = group[i], group[j]
            group = [gi if g == gj else g for g in group]
        alone = (unit.T @ ys) ** 2  # each column's explained sum of squares alone
        for g in set(group):
            members = [k for k in range(len(weak)) if group[k] == g]
            if len(members) < 2:
                continue
            fams = [weak[k] for k in members]
            union = float(np.mean(hits[:, np.isin(fam_of, fams)].any(axis=1)))
            lead = fams[int(np.argmax(alone[members]))]
            for f in fams:
                out[f] = union if f == lead else 0.0
            self.evidence_[lead]["aliases"] = {"families": [f for f in fams if f != lead],
                                               "group_inclusion": union}
        return out

    def fit(self, signals_list: Sequence[dict], target_list: Sequence[np.ndarray],
            row_maps=None, nuisance=None) -> "OpenFormSearch":
        """Search the terms of the missing mass flow.

        Parameters
        ----------
        signals_list : sequence of dict
            Per recording, the signals (:data:`~pneubayes.effects.closure_features.SIGNALS`;
            :func:`~pneubayes.discovery.openform.signals.path_signals`), arrays ``(M,)``.
        target_list : sequence of (M,) arrays
            Per recording, the missing mass flow into the chamber, kg/s
            (:func:`~pneubayes.discovery.openform.signals.missing_mass_flow`). A row
            holding a non-finite value, or an interval a signal dict's optional
            ``"valid"`` array marks False, is left out.
        row_maps : sequence of callables, optional
            Per recording, the map from per-interval values ``(M, ...)`` to the
            regression's rows ``(R, ...)`` in place of block sums (e.g.
            :class:`~pneubayes.discovery.openform.trajectory.WindowResponse`); the
            targets are then given as rows, ``(R,)`` each (``"valid"`` is not read:
            the maps' rows are the caller's to choose).
        nuisance : sequence of (M, K) arrays, optional
            Per recording, per-interval columns the target may contain in any amount
            (the current model's own parameter sensitivities,
            :func:`~pneubayes.discovery.openform.signals.parameter_flows`): the rows
            are taken through the same block sums or maps and projected out of the
            target and of every candidate (Frisch-Waugh-Lovell: the coefficients are
            those of the regression with them beside), so a term is kept for what
            they cannot absorb; a candidate left with less than
            :data:`NUISANCE_KEEP` of its norm is dropped.

        Returns
        -------
        OpenFormSearch
            self, with the attributes of the class doc.
        """
        self._validate(signals_list, target_list, row_maps)
        if nuisance is not None:
            if len(nuisance) != len(signals_list):
                raise ValueError(f"fit: {len(nuisance)} nuisance arrays for "
                                 f"{len(signals_list)} recordings; give one per recording")
            for i, (z, sig) in enumerate(zip(nuisance, signals_list)):
                n = np.shape(sig["pressure_Pa"])[0]
                if np.ndim(z) != 2 or np.shape(z)[0] != n:
                    raise ValueError(f"recording {i}: the nuisance must be (M, K) with M = "
                                     f"{n} intervals, got shape {np.shape(z)}")
        self._row_maps = None if row_maps is None else list(row_maps)
        self._nuisance = None if nuisance is None else [np.asarray(z, dtype=np.float64)
                                                        for z in nuisance]
        self._basis = None
        from threadpoolctl import threadpool_limits

        # the regressions are small (~1e3 x 1e2): BLAS threads only contend for cores
        with threadpool_limits(limits=1):
            return self._fit(signals_list, target_list)

    def _fit(self, signals_list, target_list) -> "OpenFormSearch":
        left_out = set(self.without_features)
        cands = [c for c in candidate_terms(signals_list, self.quantiles)
                 if c.family not in set(self.exclude)
                 and not {c.term.a, c.term.b} & left_out]
        # an interval a signal dict marks invalid ("valid" False) leaves out its row
        if self._row_maps is None:
            y = np.concatenate([_block_sums(np.where(np.asarray(s.get("valid", True), bool),
                                                     np.asarray(t, dtype=np.float64),
                                                     np.nan), self.block)
                                for s, t in zip(signals_list, target_list)])
        else:
            y = np.concatenate([np.asarray(t, dtype=np.float64) for t in target_list])
        x = np.concatenate([self._to_rows(design_matrix(cands, s), i)
                            for i, s in enumerate(signals_list)])
        finite = np.isfinite(y) & np.all(np.isfinite(x), axis=1)
        if self._nuisance is not None:
            z = np.concatenate([self._to_rows(n, i) for i, n in enumerate(self._nuisance)])
            finite &= np.all(np.isfinite(z), axis=1)
            self._basis = orthonormal_basis(z[finite])
        y, x = y[finite], x[finite]
        if self._basis is not None:
            norm0 = np.linalg.norm(x, axis=0)
            y, x = project_out(self._basis, y), project_out(self._basis, x)
            absorbed = np.linalg.norm(x, axis=0) < NUISANCE_KEEP * norm0
            x[:, absorbed] = 0.0  # (a zero column is a duplicate of none and never live)
        keep = distinct_columns(x, self.duplicate_tolerance)
        cands = [c for c, k in zip(cands, keep) if k]
        x = x[:, keep]
        self.n_candidates_, self.n_rows_ = len(cands), int(y.size)
        self.terms_, self.inclusion_probability_, self.evidence_ = [], {}, {}
        self.explained_fraction_ = 0.0
        y_rms = float(np.sqrt(np.mean(y * y))) if y.size else 0.0
        if y.size < 2 or y_rms == 0.0 or not cands:
            return self
        xs = x / np.sqrt(np.mean(x * x, axis=0))
        rank = np.array([candidate_rank(c) for c in cands])
        ys = y / y_rms
        n = y.size
        n_chunks = max(1, n // self.chunk_rows)
        chunk_of = np.minimum(np.arange(n) // self.chunk_rows, n_chunks - 1)
        members = [np.nonzero(chunk_of == c)[0] for c in range(n_chunks)]
        rng = np.random.default_rng(self.seed)
        coefs = np.zeros((self.n_models, len(cands)))
        for m in range(self.n_models):
            rows = np.concatenate([members[c] for c in rng.integers(0, n_chunks, n_chunks)])
            coefs[m] = self._sparse(xs[rows], ys[rows], rank)
        hits = coefs != 0
        counts = hits.sum(axis=0)
        fam_of = np.array([c.family for c in cands])
        best: dict[str, int] = {}
        for f in dict.fromkeys(fam_of.tolist()):
            cols = np.nonzero(fam_of == f)[0]
            p_inc = float(np.mean(hits[:, cols].any(axis=1)))
            mean_abs = np.abs(coefs[:, cols]).mean(axis=0)
            j = int(cols[np.lexsort((-mean_abs, -counts[cols]))[0]])
            self.inclusion_probability_[f] = p_inc
            self.evidence_[f] = {"inclusion_probability": p_inc,
                                 "best_label": cands[j].label,
                                 "selections": int(counts[j])}
            best[f] = j
        support = self._aliases(dict(self.inclusion_probability_), best, hits, fam_of, xs,
                                ys)
        supported = sorted((f for f, p in support.items() if p >= self.min_inclusion),
                           key=lambda f: (-support[f], -counts[best[f]]))
        sel = [cands[best[f]] for f in supported]
        cols = [x[:, best[f]] for f in supported]
        grid = hinge_thresholds(signals_list, self.quantiles)
        ranges = {}
        for h in HINGE_SOURCES:
            v = np.concatenate([hinge_source_values(h, s) for s in signals_list])
            ranges[h] = (float(np.nanmin(v)), float(np.nanmax(v)))
        tau_range = relaxation_range(signals_list)
        ranges.update((name, tau_range) for name in LOW_PASS_HISTORIES)
        ranges.update((name, dead_time_range(signals_list)) for name in DEAD_TIME_FEATURES)
        tss = float(y @ y)
        while sel:
            if self.refine_thresholds:
                self._refine(sel, cols, y, signals_list, finite, grid, ranges)
            coef, rss = least_squares(cols, y)
            drop = np.array([(least_squares(cols[:j] + cols[j + 1:], y)[1] if len(cols) > 1
                              else tss) - rss for j in range(len(cols))]) / tss
            worst = int(np.argmin(drop))
            if len(sel) > self.max_terms or drop[worst] < self.min_explained_fraction:
                del sel[worst], cols[worst]
                continue
            break
        if not sel:
            return self
        fitted = np.column_stack(cols) @ coef
        explained = float(fitted @ y)
        self.explained_fraction_ = 1.0 - rss / tss
        found = [FoundTerm(c.term, c.threshold_a, c.threshold_b, float(k),
                           support[c.family],
                           float(k * (col @ y) / explained), float(d))
                 for c, k, col, d in zip(sel, coef, cols, drop)]
        self.terms_ = sorted(found, key=lambda t: -t.explained_fraction)
        return self
