"""The closure component's model algebra: a model with its closure's terms replaced,
one term removed, a tube's line set aside, and the bounds that reach a closure's values.

Pure functions on :class:`~pneubayes.model.Model` and a discovery fit (its ``model`` and
``params``); the open-form stage (:mod:`pneubayes.discovery.stages.open_form`) composes
them. ``CLOSURE`` is the component's name in a model and in the ledger.
"""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.openform.features import HINGE_SOURCES, hinge_source_values
from pneubayes.effects import make_effect
from pneubayes.effects.closure import Closure
from pneubayes.effects.closure_terms import reads_ports
from pneubayes.effects.discovery import inside_bounds
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.inference.fit import bound_scale

#: The name of the closure component in a model and in the ledger.
CLOSURE = "closure"


def closure_model(fit, terms, coefficient_reach: float, signals=()):
    """``(model, start)``: ``fit``'s model with its closure replaced by ``terms``
    (:class:`~pneubayes.discovery.openform.linear_hinge.ValuedTerm`), started at their
    values and ``fit``'s others; bounds widened by :func:`reach`."""
    base = fit.model.without(CLOSURE)
    model = base.with_effect(Closure(terms="; ".join(str(t.term) for t in terms)))
    wide = reach(model, {k: t.coefficient for k, t in enumerate(terms)},
                 [t.term for t in terms], coefficient_reach, signals)
    if wide:
        model = model.with_bounds(wide)
    start = {n: fit.params[n] for n in base.parameter_names}
    for k, t in enumerate(terms):
        start[f"closure_coefficient_{k}"] = inside_bounds(
            model, f"closure_coefficient_{k}", t.coefficient)
        for side in t.term.hinges():
            start[f"closure_threshold_{k}_{side}"] = inside_bounds(
                model, f"closure_threshold_{k}_{side}", t.threshold(side))
    return model, start


def reach(model, coefficients: dict, terms, coefficient_reach: float, signals=()) -> dict:
    """Bounds that reach the closure's values: coefficient ``k`` (``coefficients``: term
    index -> value) widened to +- ``coefficient_reach`` x its value where that exceeds
    its bound (the defaults are sized for typical flows), each hinge threshold of
    ``terms`` to its signal's range on ``signals`` (:func:`threshold_reach`)."""
    wide = {}
    for k, c in coefficients.items():
        name = f"closure_coefficient_{k}"
        r = coefficient_reach * abs(c)
        if r > model.parameter(name).upper:
            wide[name] = (-r, r)
    wide.update(threshold_reach(model, terms, signals))
    return wide


def threshold_reach(model, terms, signals) -> dict:
    """Bounds for the closure's hinge thresholds (term ``k`` of ``terms``) that reach
    the range their signal takes on ``signals`` where their own do not (a chamber the
    piston compresses to 20 bar takes a pressure hinge past its default 10), so that a
    fit is not stopped inside the data; ``{}`` without signals."""
    out = {}
    if not len(signals):
        return out
    for k, term in enumerate(terms):
        for side in term.hinges():
            hinge = getattr(term, side)
            if hinge not in HINGE_SOURCES:
                continue  # (a relaxation's time constant)
            v = np.concatenate([hinge_source_values(hinge, s) for s in signals])
            v = v[np.isfinite(v)]
            if not v.size:
                continue
            name = f"closure_threshold_{k}_{side}"
            p = model.parameter(name)
            lo, hi = min(p.lower, float(v.min())), max(p.upper, float(v.max()))
            if (lo, hi) != (p.lower, p.upper):
                out[name] = (lo, hi)
    return out


def existing_terms(model) -> list:
    """The model's closure terms, ``[(Term, its parameter names), ...]`` (empty without
    a closure)."""
    if not model.has(CLOSURE):
        return []
    eff = model.effect(CLOSURE)
    out = []
    for k, t in enumerate(eff.term_list()):
        names = [f"closure_coefficient_{k}"] + [f"closure_threshold_{k}_{side}"
                                                for side in t.hinges()]
        out.append((t, tuple(names)))
    return out


def without_term(fit, k: int):
    """``(model, start)``: ``fit``'s model with closure term ``k`` removed (the closure
    removed with its last term), started at the fit's values renumbered."""
    model = fit.model
    terms = model.effect(CLOSURE).term_list()
    keep = [j for j in range(len(terms)) if j != k]
    base = model.without(CLOSURE)
    start = {n: fit.params[n] for n in base.parameter_names}
    if not keep:
        return base, start
    closure = Closure(terms="; ".join(str(terms[j]) for j in keep))
    reduced = base.with_effect(closure)
    kept = {f"closure_coefficient_{new}": model.bound_overrides[f"closure_coefficient_{old}"]
            for new, old in enumerate(keep)
            if f"closure_coefficient_{old}" in model.bound_overrides}
    if kept:  # a widened coefficient's bounds go with its term
        reduced = reduced.with_bounds(kept)
    for new, old in enumerate(keep):
        start[f"closure_coefficient_{new}"] = fit.params[f"closure_coefficient_{old}"]
        for side in terms[old].hinges():
            start[f"closure_threshold_{new}_{side}"] = fit.params[
                f"closure_threshold_{old}_{side}"]
    return reduced, start


def families_at_bounds(fit, bounded: list[str], terms) -> tuple[str, ...]:
    """The families of the searched ``terms`` whose closure parameters are among
    ``bounded``; all of them when none is (another parameter went to its bound)."""
    new = {str(t.term) for t in terms}
    hit = tuple(str(t) for t, names in existing_terms(fit.model)
                if str(t) in new and any(n in bounded for n in names))
    return hit or tuple(sorted(new))


def newly_at_bounds(fit, current, share: float = 1e-4) -> list[str]:
    """Parameters of ``fit`` within ``share`` of their bounds' span (in log space for
    bounds over two decades) of a bound that were not there in ``current`` (the
    closure's own always count): a closure that only fits
    by driving parameters to their limits stands in for what it cannot express. An
    earlier effect's parameter that reaches its neutral value at a bound (a spool lag's
    time constant at 0) does not count: the closure explains what that effect stood in
    for, and the loop's backward step removes it. Nor does a bound that is the physics'
    own limit (:attr:`~pneubayes.effects.base.Parameter.limit`: a knee flat as a rail)."""
    out = []
    for name in fit.model.parameter_names:
        p = fit.model.parameter(name)
        f = bound_scale(p.lower, p.upper)  # (2 ms is not at a 0.1-ms bound of 20 s's)
        tol = share * (f(p.upper) - f(p.lower))

        def at(v, p=p, tol=tol, f=f):  # (a bound where the physics ends does not count)
            return (p.limit != "lower" and f(v) - f(p.lower) <= tol) \
                or (p.limit != "upper" and f(p.upper) - f(v) <= tol)

        value = fit.params[name]
        if not at(value) or (name in current.params and at(current.params[name])):
            continue
        switched_off = (not name.startswith("closure_") and p.neutral is not None
                        and at(p.neutral) and abs(value - p.neutral) <= tol)
        if not switched_off:
            out.append(name)
    return out


#: Slots of a tube simulated as a line: the acoustic line (its own states in place of
#: the chamber's right-hand side, beside which the compiled simulator refuses a
#: closure) and the wave tube (beside which a closure may read no port of the valve).
_LINE_SLOTS = ("line_length_m", "wave_length_m")


def beside_closure(model, params: dict, rig, terms=None):
    """``(model, names)``: ``model`` with each effect that lowers onto a line slot at
    ``params`` in its plainest form (its first; options it shares with it kept, a
    same-named fitted parameter as the option's value), and the names of those
    effects. Beside a closure of ``terms`` that reads no port of the valve, the wave
    tube stays (only an acoustic line goes); ``terms`` None: every line goes."""
    slots = model.lower(model.vector(params)[None, :], rig)[0]
    lines = _LINE_SLOTS
    if terms is not None and not reads_ports(terms):
        lines = ("line_length_m",)
    if not any(slots[SLOT_INDEX[s]] > 0 for s in lines):
        return model, []
    names = []
    for name in model.effect_names:
        eff = model.effect(name)
        if not type(eff).forms or eff.options().get("form") == type(eff).forms[0]:
            continue
        wrote = eff.lower({k: np.atleast_1d(params[k]) for k in eff.parameter_names()}, rig)
        if not any(np.any(np.asarray(wrote.get(s, 0.0)) > 0) for s in lines):
            continue
        first = type(eff)(form=type(eff).forms[0])
        opts = {k: (float(params[k]) if k in params else eff.options().get(k, v))
                for k, v in first.options().items() if k != "form"}
        model = model.without(name).with_effect(make_effect(name, form=first.form, **opts))
        names.append(name)
    return model, names
