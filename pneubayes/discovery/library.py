"""Physically named candidate terms for the dp/dt residual, one group per effect.

Rows are blocks of one-step prediction errors (:mod:`one_step`, Pa). A candidate term
is the change of the one-step predictions when one mechanism is switched on at a trial
strength -- through the *same effect objects* the bench plants and a model adds -- so
a group holds one catalogue effect over a grid of strengths. Each effect declares its
own terms in its file (:meth:`~pneubayes.effects.Effect.library_terms`; the tube's
delays, the spool's lags, the dead bands, the measured supply, the laminar leak, the
heat exchange's relaxation rates); this module computes the four kinds of term
(:mod:`pneubayes.effects.discovery`) for every catalogue effect the model lacks.

The fitted parameters' own sensitivities (d prediction / d theta) form the *absorber*
block (:mod:`~pneubayes.discovery.absorbers`): a residual that a small change of the
fitted parameters explains is not a missing effect. Effects already in the model are
not offered again.

Columns come in the order of their kind -- the trials of every effect (simulated in one
batch per recording), then other forms, lagged inputs and relaxations -- and within a
kind in catalogue order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pneubayes.discovery.absorbers import sensitivity_points
from pneubayes.discovery.one_step import OneStepData, first_order_lag
from pneubayes.effects import CATALOGUE, make_effect
from pneubayes.effects.discovery import (
    FormTrialTerm,
    InputLagTerm,
    LibraryTerm,
    RelaxationTerm,
    TrialTerm,
)
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig, combination_error

#: The order of the kinds of term among the library's columns.
_KIND_ORDER = (TrialTerm, FormTrialTerm, InputLagTerm, RelaxationTerm)


@dataclass(frozen=True)
class LibraryGrid:
    """Trial strengths of the candidate terms: effect name -> strengths, replacing that
    effect's own :attr:`~pneubayes.effects.Effect.library_strengths` (the unit of the
    parameter its terms vary: the tube's delay in s, the dead band's half-width in V,
    ...). Effects not named keep their own."""

    strengths: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.strengths, dict):
            raise ValueError(f"LibraryGrid.strengths must be a dict effect name -> "
                             f"strengths, got {self.strengths!r}")
        clean = {}
        for name, values in self.strengths.items():
            if name not in CATALOGUE:
                raise ValueError(f"LibraryGrid.strengths: unknown effect {name!r}; the "
                                 f"catalogue has {sorted(CATALOGUE)}")
            vals = tuple(values) if isinstance(values, (list, tuple)) else None
            if not vals or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                   and math.isfinite(v) and v > 0 for v in vals):
                raise ValueError(f"LibraryGrid.strengths[{name!r}] must be a non-empty list "
                                 f"of finite numbers > 0, got {values!r}")
            clean[name] = tuple(float(v) for v in vals)
        object.__setattr__(self, "strengths", clean)

    def for_effect(self, name: str) -> tuple[float, ...]:
        """The trial strengths of the named effect's terms."""
        return self.strengths.get(name, CATALOGUE[name].library_strengths)

    def to_dict(self) -> dict:
        """Every catalogue effect's strengths, as used."""
        return {name: list(self.for_effect(name)) for name in CATALOGUE}


@dataclass
class CandidateLibrary:
    """Rows = blocks of all recordings; columns = named candidate terms and absorbers.

    ``starts`` holds, per column, the parameter values its term stands for (a named
    effect's candidate starts there; empty for a library built by hand)."""

    target: np.ndarray            # (n,) block sums of one-step errors, Pa
    columns: np.ndarray           # (n, m) candidate terms, Pa
    labels: list[str]
    groups: list[str]             # effect name per column
    absorbers: np.ndarray         # (n, q) parameter sensitivities x step, Pa
    absorber_labels: list[str]
    row_recording: np.ndarray     # recording index per row
    row_sample: np.ndarray        # first sample of each row's block
    meta: dict = field(default_factory=dict)
    starts: list[dict] = field(default_factory=list)

    @property
    def group_names(self) -> list[str]:
        return list(dict.fromkeys(self.groups))


def _augmented(model: Model, params: dict, effects: Sequence):
    """The model plus the given candidate effects (neutral), and its base parameters."""
    aug = model
    for e in effects:
        aug = aug.with_effect(e)
    base = dict(aug.neutral_values())
    base.update(params)
    return aug, base


def _terms(model: Model, groups: Sequence[str], grid: LibraryGrid):
    """``[(effect, term), ...]`` of the named groups, in the columns' order."""
    effects = [make_effect(g, **model.effect_options(g)) for g in groups]
    terms = [(e, t) for e in effects for t in e.library_terms(grid.for_effect(e.name))]
    for _, t in terms:
        if type(t) not in _KIND_ORDER:
            raise TypeError(f"library term {t!r}: unknown kind {type(t).__name__}")
    return sorted(terms, key=lambda et: _KIND_ORDER.index(type(et[1])))


def _simulated(term: LibraryTerm, model: Model, params: dict, aug: Model, base: dict):
    """``(model, parameter row (1, P))`` a term that is not a batched trial simulates
    (None for a term from the measured pressure alone); once per library, not per
    recording."""
    if isinstance(term, FormTrialTerm):
        alone, alone_base = _augmented(model, params, [term.effect])
        return alone, np.array([alone.vector({**alone_base, **term.values})])
    if isinstance(term, InputLagTerm):
        return aug, np.array([aug.vector(base)])
    return None


def _column(term: LibraryTerm, sim, d: OneStepData, base_pred: np.ndarray, p: np.ndarray,
            solver: SolverConfig) -> np.ndarray:
    """The block sums of one term that is not a batched trial (Pa); ``sim`` is its
    :func:`_simulated`."""
    if isinstance(term, (FormTrialTerm, InputLagTerm)):
        inputs = d.lagged_inputs(term.lag_s) if isinstance(term, InputLagTerm) else None
        pred = d.predict(*sim, solver, inputs=inputs)[0]
        return d.rows(pred - base_pred)
    dt = float(np.median(np.diff(d.recording.time_s)))
    hp = p - first_order_lag(p, dt, 1.0 / term.rate_per_s)
    return d.rows(-0.5 * (hp[1:] + hp[:-1]) * dt)


def steppable_beside(model: Model, params: dict, name: str, rig) -> bool:
    """Whether the simulator steps catalogue effect ``name`` (neutral, with the rig
    card's options) beside ``model`` at ``params`` on ``rig``
    (:func:`pneubayes.simulation.combination_error`): a port's own critical ratio is
    not stepped beside a restriction at the port, for one; the loop proposes no such
    pair."""
    aug, base = _augmented(model, params, [make_effect(name, **model.effect_options(name))])
    return combination_error(aug, base, rig) is None


def build_library(model: Model, params: dict, data: Sequence[OneStepData],
                  grid: LibraryGrid, solver: SolverConfig,
                  groups: Sequence[str] | None = None) -> CandidateLibrary:
    """Candidate terms and absorbers for ``model`` at ``params`` on ``data``.

    ``groups`` defaults to every catalogue effect the model does not already have (nor
    its rig card state: :meth:`Model.covers`) that the simulator can step beside it
    (:func:`steppable_beside`); those it cannot are in ``meta["not_steppable"]``.
    """
    apart = []
    if groups is None:
        missing = [g for g in CATALOGUE if not model.covers(g)]
        apart = [g for g in missing if not steppable_beside(model, params, g, data[0].rig)]
        groups = [g for g in missing if g not in apart]
    theta = model.vector(params)
    sens_points, widths, steps = sensitivity_points(model, theta)
    terms = _terms(model, groups, grid)
    trials = [(e, t) for e, t in terms if isinstance(t, TrialTerm)]
    others = [t for _, t in terms if not isinstance(t, TrialTerm)]
    aug, base = _augmented(model, params, list(dict.fromkeys(e for e, _ in trials)))
    vectors = np.array([aug.vector(base)] + [aug.vector({**base, **t.values})
                                              for _, t in trials])
    sims = [_simulated(t, model, params, aug, base) for t in others]
    targets, cols, absorbers, rec_idx, first, keep = [], [], [], [], [], []
    for i, d in enumerate(data):
        pred = d.predict(aug, vectors, solver)
        base_pred = pred[0]
        p = np.asarray(d.recording.pressure_Pa, dtype=np.float64)
        targets.append(d.rows(p[1:] - base_pred))
        rec_cols = [d.rows(row - base_pred) for row in pred[1:]]
        rec_cols += [_column(t, sim, d, base_pred, p, solver)
                     for t, sim in zip(others, sims)]
        cols.append(np.column_stack(rec_cols) if rec_cols else np.zeros((d.n_rows, 0)))
        sp = d.predict(model, sens_points, solver)
        sens = (sp[0::2] - sp[1::2]) / widths[:, None] * steps[:, None]
        absorbers.append(d.rows(sens).T)
        rec_idx.append(np.full(d.n_rows, i))
        first.append(np.arange(d.n_rows) * d.block)
        keep.append(d.valid_rows())
    k = np.concatenate(keep)  # rows touching a masked sample are left out
    return CandidateLibrary(
        target=np.concatenate(targets)[k], columns=np.concatenate(cols)[k],
        labels=[t.label for _, t in terms], groups=[e.name for e, _ in terms],
        absorbers=np.concatenate(absorbers)[k],
        absorber_labels=[f"d/d {n}" for n in model.parameter_names],
        row_recording=np.concatenate(rec_idx)[k], row_sample=np.concatenate(first)[k],
        meta={"grid": grid.to_dict(), "groups": list(groups), "not_steppable": apart},
        starts=[dict(t.start) for _, t in terms])
