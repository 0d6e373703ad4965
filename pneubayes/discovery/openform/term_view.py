"""What a found closure term does: its mass flow against its main variable, beside the
mass flow the model misses without it.

For each term ``k`` of a fitted model's closure, :func:`term_views` evaluates along
every recording (the signals of :func:`~pneubayes.discovery.openform.signals.path_signals`
at the midpoints of the sample intervals):

- the term's mass flow ``c_k F_a F_b`` (kg/s into the chamber);
- the *missing* mass flow of the same model with this term's coefficient at zero
  (:func:`~pneubayes.discovery.openform.signals.missing_mass_flow` of its one-step
  errors): what the rest of the model leaves for the term to explain;

and bins both along the term's main variable (a hinge's source signal, else its first
non-constant feature; the pressure ratio for a constant). Where the term is right, its
binned flow follows the binned missing flow; the difference left is what it does not
explain. :func:`pneubayes.plotting.plot_found_terms` draws the result.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pneubayes.discovery.one_step import one_step_data
from pneubayes.discovery.openform.features import HINGE_SOURCES
from pneubayes.discovery.openform.signals import missing_mass_flow, path_signals
from pneubayes.effects.closure_features import (
    evaluate_feature,
    feature,
)
from pneubayes.effects.closure_terms import term_formula


def main_variable(term) -> str:
    """The feature a term is plotted against: a hinge's source (a relaxation: itself, at
    its time constant), else its first non-constant feature other than the command's
    direction (a sign, which only splits the points; ``pressure_ratio`` for the constant
    and the direction alone)."""
    for name in (term.a, term.b):
        if feature(name).hinge:
            return HINGE_SOURCES.get(name, name)
    for name in (term.a, term.b):
        if name not in ("one", "command_direction"):
            return name
    return "pressure_ratio"


def _threshold(params: dict, k: int, side: str) -> float:
    return float(params.get(f"closure_threshold_{k}_{side}", 0.0))


def term_views(model, params: dict, recordings: Sequence, block: int, solver,
               n_bins: int = 20) -> list[dict]:
    """Each closure term's mass flow and the model's missing mass flow without it, binned
    along the term's main variable.

    Parameters
    ----------
    model : Model
        A model with a ``closure`` effect.
    params : dict
        Its parameter values (one set).
    recordings : sequence of Recording
        Where to evaluate (e.g. the discovery's training recordings).
    block : int
        Sample intervals per one-step prediction (the search's ``block``).
    solver : SolverConfig
        The one-step predictions' solver.
    n_bins : int
        Bins along the main variable (equal counts of samples).

    Returns
    -------
    list of dict
        One per term, in the closure's order: ``term``, ``formula``, ``variable`` (the
        main variable's feature name), ``unit`` (its unit), ``bin_centre`` (the bins'
        median of the variable), ``term_kg_per_s`` and ``missing_kg_per_s`` (the bins'
        mean term flow and mean missing flow without the term), ``missing_sem_kg_per_s``
        (the missing flow's standard error per bin) and ``explained_fraction`` (1 - the
        sum of squares of missing minus term over that of missing, on every sample).
    """
    if not model.has("closure"):
        raise ValueError("term_views: the model has no closure (no open-form terms)")
    if n_bins < 2:
        raise ValueError(f"n_bins must be >= 2, got {n_bins}")
    params = dict(params)
    out = []
    for k, term in enumerate(model.effect("closure").term_list()):
        without = dict(params, **{f"closure_coefficient_{k}": 0.0})
        variable = main_variable(term)
        # (the variable's own time constant when it is the term's relaxation)
        side = "a" if variable == term.a else ("b" if variable == term.b else None)
        theta = _threshold(params, k, side) if side else 0.0
        xs, flows, missing = [], [], []
        for rec in recordings:
            d = one_step_data(rec, block)
            err = d.errors(model, without, solver)[0]
            sig = path_signals(model, without, rec, d)
            keep = np.asarray(sig["valid"], dtype=bool) & np.isfinite(err)
            xs.append(evaluate_feature(variable, sig, theta)[keep])
            flows.append((params[f"closure_coefficient_{k}"]
                          * term.evaluate(sig, _threshold(params, k, "a"),
                                          _threshold(params, k, "b")))[keep])
            missing.append(missing_mass_flow(sig, err, d.rig)[keep])
        x, f, m = (np.concatenate(v) for v in (xs, flows, missing))
        ok = np.isfinite(x) & np.isfinite(f) & np.isfinite(m)
        x, f, m = x[ok], f[ok], m[ok]
        centre, term_mean, miss_mean, miss_sem, explained = binned(x, f, m, n_bins)
        out.append({"term": str(term), "formula": term_formula(term, k), "variable": variable,
                    "unit": feature(variable).unit, "bin_centre": centre,
                    "term_kg_per_s": term_mean, "missing_kg_per_s": miss_mean,
                    "missing_sem_kg_per_s": miss_sem,
                    "explained_fraction": explained})
    return out


def binned(x, term, missing, n_bins: int):
    """``(centres, term means, missing means, missing standard errors, explained
    fraction)``: ``term`` and ``missing`` (same unit) binned along ``x`` in ``n_bins``
    bins of equal counts (each bin's median ``x``), and 1 - the sum of squares of
    missing minus term over that of missing on every sample (NaN when missing is 0)."""
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, n_bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(edges.size - 2, 0))
    centre, term_mean, miss_mean, miss_sem = [], [], [], []
    for b in range(max(edges.size - 1, 1)):
        sel = idx == b
        if not np.any(sel):
            continue
        centre.append(float(np.median(x[sel])))
        term_mean.append(float(np.mean(term[sel])))
        miss_mean.append(float(np.mean(missing[sel])))
        miss_sem.append(float(np.std(missing[sel]) / np.sqrt(sel.sum())))
    ss = float(missing @ missing)
    r = missing - term
    explained = 1.0 - float(r @ r) / ss if ss > 0 else float("nan")
    return centre, term_mean, miss_mean, miss_sem, explained
