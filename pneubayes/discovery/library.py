"""Physically named candidate terms for the dp/dt residual, one group per effect.

Rows are blocks of one-step prediction errors (:mod:`one_step`, Pa). A candidate term
is the change of the one-step predictions when one mechanism is switched on at a trial
strength -- through the *same effect objects* the bench plants and a model adds -- so
a group holds one catalogue effect over a grid of strengths:

- ``tube_delay``: the port flows delayed by a grid of lags (with the tube's friction);
- ``spool_lag``: the command through first-order lags of a grid of time constants;
- ``valve_deadzone``: dead bands of a grid of half-widths;
- ``supply_fluctuation``: the inlet at the measured instead of the nominal supply (the
  supply deviation times the inlet flow's sensitivity, to all orders);
- ``cylinder_leak``: the laminar leak law ``k (p^2 - P_atm^2)`` (one column: a second,
  for the leak's change along the stroke, split the group's evidence and lost a planted
  leak on SMC; the loop fits the graded form once the leak is named). The paper's orifice
  leak (eq. 9) has the exhaust port's own law, so a model with a free exhaust offset
  already contains it (eq. 10 sees only their sum): it can never be *missing*;
- ``heat_transfer``: wall heat exchange. A one-step prediction starts at the wall
  temperature, so it cannot show heat transfer; its terms are ``-(p - LP_r[p]) dt``
  for a grid of rates r instead: after a fill or a vent the air relaxes to the wall
  temperature and, to first order, the pressure error is a high-passed pressure.

The fitted parameters' own sensitivities (d prediction / d theta) form the *absorber*
block: a residual that a small change of the fitted parameters explains is not a
missing effect. Effects already in the model are not offered again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pneubayes.discovery.one_step import OneStepData, first_order_lag
from pneubayes.effects import make_effect
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

EFFECT_GROUPS = ("tube_delay", "spool_lag", "valve_deadzone", "supply_fluctuation",
                 "cylinder_leak", "heat_transfer")

#: The parameter of each effect that the grid varies (the laminar leak is added apart).
_GRID_PARAMETER = {"tube_delay": "tube_delay_s", "valve_deadzone": "deadzone_halfwidth_V",
                   "supply_fluctuation": "supply_gain"}


@dataclass(frozen=True)
class LibraryGrid:
    """Trial strengths of the candidate terms (SI units)."""

    delays_s: tuple[float, ...] = (0.001, 0.002, 0.004, 0.007, 0.012, 0.02)
    lags_s: tuple[float, ...] = (0.001, 0.002, 0.004, 0.007, 0.012, 0.02)
    deadbands_V: tuple[float, ...] = (0.05, 0.1, 0.2, 0.35, 0.6, 1.0)
    supply_gains: tuple[float, ...] = (1.0,)
    leak_conductance_kg_per_s_Pa2: float = 1e-16
    heat_rates_per_s: tuple[float, ...] = (1.0, 3.0, 10.0, 30.0, 100.0)

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class CandidateLibrary:
    """Rows = blocks of all recordings; columns = named candidate terms and absorbers."""

    target: np.ndarray            # (n,) block sums of one-step errors, Pa
    columns: np.ndarray           # (n, m) candidate terms, Pa
    labels: list[str]
    groups: list[str]             # effect name per column
    absorbers: np.ndarray         # (n, q) parameter sensitivities x step, Pa
    absorber_labels: list[str]
    row_recording: np.ndarray     # recording index per row
    row_sample: np.ndarray        # first sample of each row's block
    meta: dict = field(default_factory=dict)

    @property
    def group_names(self) -> list[str]:
        return list(dict.fromkeys(self.groups))


def _sensitivity_points(model: Model, theta: np.ndarray):
    lo, hi = model.bounds
    steps = np.maximum(1e-4 * np.abs(theta), 1e-6 * (hi - lo))
    plus, minus = np.minimum(theta + steps, hi), np.maximum(theta - steps, lo)
    rows = []
    for j in range(theta.size):
        a, b = theta.copy(), theta.copy()
        a[j], b[j] = plus[j], minus[j]
        rows += [a, b]
    return np.array(rows), plus - minus, steps


def _augmented(model: Model, params: dict, effects: Sequence):
    """The model plus the given candidate effects (neutral), and its base parameters."""
    aug = model
    for e in effects:
        aug = aug.with_effect(e)
    base = dict(aug.neutral_values())
    base.update(params)
    return aug, base


def build_library(model: Model, params: dict, data: Sequence[OneStepData],
                  grid: LibraryGrid, solver: SolverConfig,
                  groups: Sequence[str] | None = None) -> CandidateLibrary:
    """Candidate terms and absorbers for ``model`` at ``params`` on ``data``.

    ``groups`` defaults to every catalogue effect the model does not already have.
    """
    if groups is None:
        groups = [g for g in EFFECT_GROUPS if not model.has(g)]
    theta = model.vector(params)
    sens_points, widths, steps = _sensitivity_points(model, theta)
    aug, base = _augmented(model, params, [g for g in groups if g in _GRID_PARAMETER])
    trials, trial_labels = [aug.vector(base)], []
    for g in groups:
        if g not in _GRID_PARAMETER:
            continue
        name = _GRID_PARAMETER[g]
        values = {"tube_delay": grid.delays_s, "valve_deadzone": grid.deadbands_V,
                  "supply_fluctuation": grid.supply_gains}[g]
        for v in values:
            trials.append(aug.vector({**base, name: v}))
            unit = {"tube_delay": ("delay", 1e3, "ms"), "valve_deadzone": ("dead band", 1, "V"),
                    "supply_fluctuation": ("measured supply x", 1, "")}[g]
            trial_labels.append((g, f"{unit[0]} {v * unit[1]:g} {unit[2]}".strip()))
    lam = None
    if "cylinder_leak" in groups:
        lam, lam_base = _augmented(model, params, [make_effect("cylinder_leak",
                                                                form="laminar")])
    targets, cols, absorbers, rec_idx, first, keep = [], [], [], [], [], []
    labels, group_of = [], []
    for i, d in enumerate(data):
        pred = d.predict(aug, np.array(trials), solver)
        base_pred = pred[0]
        p = np.asarray(d.recording.pressure_Pa, dtype=np.float64)
        targets.append(d.rows(p[1:] - base_pred))
        rec_cols, rec_labels = [], []
        for (g, lab), row in zip(trial_labels, pred[1:]):
            rec_cols.append(d.rows(row - base_pred))
            rec_labels.append((g, lab))
        if lam is not None:
            pl = d.predict(lam, np.array([lam.vector({**lam_base,
                           "leak_conductance_kg_per_s_Pa2": grid.leak_conductance_kg_per_s_Pa2})]),
                           solver)[0]
            rec_cols.append(d.rows(pl - base_pred))
            rec_labels.append(("cylinder_leak", "laminar leak"))
        if "spool_lag" in groups:
            for tau in grid.lags_s:
                pl = d.predict(aug, np.array([aug.vector(base)]), solver,
                               inputs=d.lagged_inputs(tau))[0]
                rec_cols.append(d.rows(pl - base_pred))
                rec_labels.append(("spool_lag", f"lag {1e3 * tau:g} ms"))
        if "heat_transfer" in groups:
            dt = float(np.median(np.diff(d.recording.time_s)))
            for r in grid.heat_rates_per_s:
                hp = p - first_order_lag(p, dt, 1.0 / r)
                rec_cols.append(d.rows(-0.5 * (hp[1:] + hp[:-1]) * dt))
                rec_labels.append(("heat_transfer", f"heat {r:g}/s"))
        if i == 0:
            labels = [lab for _, lab in rec_labels]
            group_of = [g for g, _ in rec_labels]
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
        labels=labels, groups=group_of, absorbers=np.concatenate(absorbers)[k],
        absorber_labels=[f"d/d {n}" for n in model.parameter_names],
        row_recording=np.concatenate(rec_idx)[k], row_sample=np.concatenate(first)[k],
        meta={"grid": grid.to_dict(), "groups": list(groups)})
