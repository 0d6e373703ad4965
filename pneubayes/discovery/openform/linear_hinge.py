"""A hinge whose threshold went to a bound beyond its signal: the same term, written
without the hinge.

A hinge ``max(0, s (x - theta))`` (``s`` = +1 for ``max(0, x - theta)``, -1 for
``max(0, theta - x)``; ``x`` its source feature,
:data:`~pneubayes.discovery.openform.features.HINGE_SOURCES`) whose threshold the fit
drove to a bound outside the range ``x`` takes on the data is either active everywhere,
where it equals ``s x - s theta``, or nowhere, where it is 0. A term ``c F * hinge``
is then exactly ``s c F * x - s c theta F``: two terms without a threshold, which
the fit can go on moving without a bound in the way (a flow that scales with the drop
across the inlet, fitted as a hinge whose kink the fit pushed out of the data). A term
whose hinge is active nowhere contributes nothing and is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.features import HINGE_SOURCES, MAGNITUDE_HINGES
from pneubayes.effects.closure_features import evaluate_feature
from pneubayes.effects.closure_terms import (
    CLOSURE_MAX_TERMS,
    Term,
)

#: Each hinge's side: +1 for ``max(0, x - theta)``, -1 for ``max(0, theta - x)``
#: (the null hinge, ``max(0, theta - |s|)``, has no linear feature and is left out).
HINGE_SIDES = {"pressure_hinge": 1.0, "pressure_hinge_down": -1.0,
               "spool_hinge_up": 1.0, "spool_hinge_down": -1.0,
               "volume_hinge_up": 1.0, "volume_hinge_down": -1.0,
               "inlet_drop_hinge": -1.0, "inlet_area_hinge": 1.0,
               "exhaust_area_hinge": 1.0}


@dataclass(frozen=True)
class ValuedTerm:
    """A closure term with its values: coefficient (the term's unit) and thresholds."""

    term: Term
    coefficient: float
    threshold_a: float = 0.0
    threshold_b: float = 0.0

    def threshold(self, side: str) -> float:
        return self.threshold_a if side == "a" else self.threshold_b


def _activity(name: str, theta: float, signals_list) -> tuple[float, float]:
    """``(share active, share inactive)`` of hinge ``name`` at ``theta`` over the
    finite samples of ``signals_list``."""
    x = np.concatenate([np.asarray(evaluate_feature(HINGE_SOURCES[name], s), float)
                        for s in signals_list])
    x = x[np.isfinite(x)]
    if not x.size:
        return 0.0, 0.0
    arg = HINGE_SIDES[name] * (x - theta)  # (at 0 the hinge and its line agree)
    return float(np.mean(arg >= 0)), float(np.mean(arg <= 0))


def linear_terms(terms, bounded_sides, signals_list, min_share: float = 1.0):
    """``terms`` with each hinge in ``bounded_sides`` written without it, or None.

    Parameters
    ----------
    terms : sequence of ValuedTerm
        A closure's terms as fitted.
    bounded_sides : iterable of (int, str)
        ``(term index, "a" or "b")`` of the hinges whose thresholds sit at a bound.
    signals_list : sequence of dict
        The signals the hinges are evaluated on (the training recordings'; see
        :data:`~pneubayes.effects.closure_features.SIGNALS`).
    min_share : float
        A hinge is linear where it is active on at least this share of the samples, and
        dropped where inactive on at least this share (1: on all of them; a hinge off on
        a few samples of a chamber the piston compresses far above the supply can carry
        the largest flows of the recording there).

    Returns
    -------
    list of ValuedTerm or None
        The rewritten terms (equal terms merged, coefficients summed), or None when a
        bounded hinge is active only on part of the data (its bound is a real limit), has
        no linear form, or the rewrite needs more than the closure's slots.
    """
    if not 0.5 < min_share <= 1.0:
        raise ValueError(f"min_share must lie in (0.5, 1], got {min_share!r}")
    bounded = {}
    for k, side in bounded_sides:
        bounded.setdefault(int(k), []).append(side)
    out: list[ValuedTerm] = []
    for k, t in enumerate(terms):
        sides = bounded.get(k, [])
        if not sides:
            out.append(t)
            continue
        if len(sides) > 1:
            return None  # (a product of two bounded hinges: not one linear step)
        side = sides[0]
        name = getattr(t.term, side)
        if name not in HINGE_SIDES or name in MAGNITUDE_HINGES:
            return None
        theta = t.threshold(side)
        active, inactive = _activity(name, theta, signals_list)
        if inactive >= min_share:
            continue  # zero on the data: the term goes
        if active < min_share:
            return None
        other = t.term.b if side == "a" else t.term.a
        other_theta = t.threshold_b if side == "a" else t.threshold_a
        s = HINGE_SIDES[name]
        source = HINGE_SOURCES[name]
        linear = Term(source) if other == "one" else Term(other, source)
        out.append(ValuedTerm(linear, s * t.coefficient, other_theta, 0.0))
        if other != "one":
            out.append(ValuedTerm(Term(other), -s * theta * t.coefficient, other_theta, 0.0))
        else:
            out.append(ValuedTerm(Term("one"), -s * theta * t.coefficient))
    merged: dict = {}
    for t in out:
        key = (str(t.term), t.threshold_a, t.threshold_b)
        if key in merged:
            m = merged[key]
            merged[key] = ValuedTerm(m.term, m.coefficient + t.coefficient, m.threshold_a,
                                     m.threshold_b)
        else:
            merged[key] = t
    result = list(merged.values())
    if not result or len(result) > CLOSURE_MAX_TERMS:
        return None
    return result
