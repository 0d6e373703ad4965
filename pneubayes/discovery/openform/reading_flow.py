"""The open-form search at the reading driven by the port flows: terms of the valve's
inlet and exhaust mass flows in the prediction windows' residual.

A reading flow term (:class:`~pneubayes.effects.reading_flow.ReadingFlow`) adds ``c F``
to a window's reading, ``F`` a feature of the ports' mass flows at the sample
(:func:`~pneubayes.simulation.reading_flow.feature_values`). Its effect on a window's
prediction, to first order in ``c``, is ``F`` along the predicted pressure less the
chamber's start moved by ``F(start)`` along the start sensitivity (the chamber reads the
start less the term). :class:`FlowSearch` regresses the windows' residual (measured
minus predicted) on those columns, one per feature, greedily: the best column, then the
best on what is left, each kept when it explains at least ``min_explained_fraction``
of the residual's uncentred sum of squares and its gain is ``min_t`` standard errors
from zero, the errors clustered by window.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.clustered import last_column_fit, stacked_residual
from pneubayes.discovery.openform.reading import ReadingWindows, reading_windows
from pneubayes.effects.reading_flow import FLOW_FEATURE_UNITS, FLOW_FEATURES, FLOW_MAX_TERMS
from pneubayes.simulation.reading_flow import PortFlows, feature_values


@dataclass(frozen=True)
class FlowTerm:
    """A kept term: its ``feature`` (one of
    :data:`~pneubayes.effects.reading_flow.FLOW_FEATURES`), ``gain`` (Pa per the feature's
    unit), the share of the residual's uncentred sum of squares it explains (beside the
    terms kept before it: ``explained``) and its gain over its window-clustered standard
    error (``t``)."""

    feature: str
    gain: float
    explained: float
    t: float

    def __str__(self) -> str:
        return f"{self.gain:+.4g} Pa per {FLOW_FEATURE_UNITS[self.feature]} x {self.feature}"


@dataclass(frozen=True)
class FlowWindows:
    """One recording's windows as the search reads them: the windows (``windows``, a
    :class:`~pneubayes.discovery.openform.reading.ReadingWindows`) and each feature's
    values along the predicted pressure (``features``: name -> ``(W, L)``)."""

    windows: ReadingWindows
    features: dict

    def column(self, name: str) -> np.ndarray:
        """d(reading)/dc at c = 0 for feature ``name``: its values less the chamber's start
        moved by its value at the start along the start sensitivity; samples 1..L-1 of
        every window, flattened (feature units)."""
        f = np.asarray(self.features[name], dtype=np.float64)
        s = self.windows.sensitivity
        sens = 1.0 if s is None else np.asarray(s)
        return (f - sens * f[:, :1])[:, 1:].reshape(-1)


def flow_windows(window_set, model, params, solver) -> list[FlowWindows]:
    """The windows of ``window_set`` as ``model`` at ``params`` (one set) predicts them
    (:func:`~pneubayes.discovery.openform.reading.reading_windows`), with every feature of
    the model's port flows along each window's predicted pressure."""
    theta = model.as_matrix(params)
    out = []
    for b, rw in zip(window_set.blocks, reading_windows(window_set, model, params, solver)):
        slots = model.lower(theta, b.rig)[0]
        flows = PortFlows(b.inputs, b.rig, b.starts, window_set.length)
        p = np.asarray(rw.predicted_Pa, dtype=np.float64)
        ok = np.isfinite(p) & (p > 0.0)
        q_in, q_ex = flows.flows(slots, np.where(ok, p, 1.0e5))
        feats = {n: np.where(ok, feature_values(n, q_in, q_ex), np.nan) for n in FLOW_FEATURES}
        out.append(FlowWindows(rw, feats))
    return out


class FlowSearch:
    """Greedy search of the port flows' terms in the windows' residual (scikit-learn
    contract: settings in the constructor, :meth:`fit` sets the ``_`` attributes).

    Parameters
    ----------
    features : sequence of str
        The features tried (of :data:`~pneubayes.effects.reading_flow.FLOW_FEATURES`).
    max_terms : int
        Most terms kept (1..2, the component's room).
    min_explained_fraction : float
        A kept term's least share of the residual's uncentred sum of squares.
    min_t : float
        A kept term's least gain over its window-clustered standard error.

    Attributes
    ----------
    terms_ : list of FlowTerm
        Kept terms, in the order found (gains refitted together).
    explained_fraction_ : float
        Share of the residual's uncentred sum of squares the kept terms explain together.
    best_ : FlowTerm or None
        The best single column's fit, kept or not (what the search saw).
    """

    def __init__(self, features: Sequence[str] = FLOW_FEATURES,
                 max_terms: int = FLOW_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0):
        self.features = features
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"features": self.features, "max_terms": self.max_terms,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t}

    def _validate(self, blocks) -> tuple[str, ...]:
        feats = tuple(self.features)
        if not feats or len(set(feats)) != len(feats) \
                or any(f not in FLOW_FEATURES for f in feats):
            raise ValueError(f"features must be distinct names of {FLOW_FEATURES}, got "
                             f"{self.features!r}")
        if not (isinstance(self.max_terms, int) and 1 <= self.max_terms <= FLOW_MAX_TERMS):
            raise ValueError(f"max_terms must be an integer in 1..{FLOW_MAX_TERMS}, got "
                             f"{self.max_terms!r}")
        if not 0.0 < self.min_explained_fraction < 1.0 or not self.min_t > 0.0:
            raise ValueError("min_explained_fraction must be in (0, 1) and min_t > 0, got "
                             f"{self.min_explained_fraction!r}, {self.min_t!r}")
        if isinstance(blocks, FlowWindows) or not len(blocks) \
                or not all(isinstance(b, FlowWindows) for b in blocks):
            raise ValueError("fit takes a list of FlowWindows, one per recording (at least "
                             "one)")
        return feats

    def fit(self, blocks: Sequence[FlowWindows]) -> "FlowSearch":
        """Search the windows' residual, one :class:`FlowWindows` per recording."""
        feats = self._validate(blocks)
        blocks = list(blocks)
        y, windows = stacked_residual([b.windows.residual_Pa for b in blocks])
        raw = {n: np.concatenate([b.column(n) for b in blocks]) for n in feats}
        ok = np.isfinite(y) & np.all([np.isfinite(x) for x in raw.values()], axis=0)
        cols = {n: np.where(ok, x, 0.0) for n, x in raw.items()}
        yy = np.where(ok, y, 0.0)
        total = float(yy @ yy)
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        if total <= 0.0:
            return self
        kept: list[str] = []
        for _ in range(self.max_terms):
            basis = np.stack([cols[n] for n in kept], axis=1) if kept else None

            def gain_of(name, basis=basis):  # the sum of squares it adds beside the kept
                x = cols[name]
                own = float(x @ x)
                if basis is not None:
                    x = x - basis @ np.linalg.lstsq(basis, x, rcond=None)[0]
                xx = float(x @ x)
                return 0.0 if xx <= 1e-9 * own else float(x @ yy) ** 2 / xx
            left = [n for n in feats if n not in kept]
            if not left:
                break
            name = max(left, key=gain_of)
            gain, explained, t = last_column_fit([cols[n] for n in kept + [name]], y, ok,
                                                 windows, total)
            term = FlowTerm(name, gain, explained, t)
            if self.best_ is None:
                self.best_ = term
            if explained < self.min_explained_fraction or abs(t) < self.min_t:
                break
            kept.append(name)
            self.terms_.append(term)
        if kept:
            x = np.stack([cols[n] for n in kept], axis=1)
            g = np.linalg.lstsq(x, yy, rcond=None)[0]
            e = yy - x @ g
            self.explained_fraction_ = 1.0 - float(e @ e) / total
            self.terms_ = [FlowTerm(k.feature, float(gk), k.explained, k.t)
                           for gk, k in zip(g, self.terms_)]
        return self
