"""A closure hinge whose threshold went to a bound beyond its signal, written without
the hinge: the same flow on the data, fewer parameters at a bound."""

from __future__ import annotations

import numpy as np
import pytest
from openform_synthetic import synthetic_signals

from pneubayes.discovery.openform.linear_hinge import ValuedTerm, linear_terms
from pneubayes.effects.closure_terms import Term


def _flow(terms, signals):
    return sum(t.coefficient * t.term.evaluate(signals, t.threshold_a, t.threshold_b)
               for t in terms)


@pytest.fixture(scope="module")
def signals():
    return [synthetic_signals(seed) for seed in (1, 2)]


def test_a_hinge_active_on_all_the_data_becomes_its_linear_terms(signals):
    # |p_s - p| / P_atm stays under 7 here: theta = 10 is beyond it
    old = [ValuedTerm(Term.parse("inlet_flow*inlet_drop_hinge"), 0.3, 0.0, 10.0),
           ValuedTerm(Term.parse("spool*inlet_flow"), -0.1)]
    new = linear_terms(old, [(0, "b")], signals)
    assert [str(t.term) for t in new] == ["inlet_flow*inlet_drop", "inlet_flow",
                                          "spool*inlet_flow"]
    assert [t.coefficient for t in new] == pytest.approx([-0.3, 3.0, -0.1])
    for s in signals:
        np.testing.assert_allclose(_flow(new, s), _flow(old, s), rtol=1e-12, atol=1e-15)
    # a hinge alone: its linear feature and the constant; a term that repeats one of the
    # rewrite's is merged with it (coefficients summed)
    old = [ValuedTerm(Term.parse("pressure_hinge"), 2e-5, 0.5),
           ValuedTerm(Term.parse("one"), 1e-6)]
    new = linear_terms(old, [(0, "a")], signals)
    assert [str(t.term) for t in new] == ["pressure_ratio", "one"]
    assert [t.coefficient for t in new] == pytest.approx([2e-5, -1e-5 + 1e-6])
    for s in signals:
        np.testing.assert_allclose(_flow(new, s), _flow(old, s), rtol=1e-12, atol=1e-18)
    # the partner keeps its own threshold
    old = [ValuedTerm(Term.parse("spool_hinge_up*pressure_hinge_down"), 1e-5, 4.0, 10.0)]
    new = linear_terms(old, [(0, "b")], signals)
    assert [(str(t.term), t.threshold_a) for t in new] == [
        ("spool_hinge_up*pressure_ratio", 4.0), ("spool_hinge_up", 4.0)]
    for s in signals:
        np.testing.assert_allclose(_flow(new, s), _flow(old, s), rtol=1e-12, atol=1e-18)


def test_a_hinge_active_nowhere_is_dropped_and_one_inside_its_signal_is_left(signals):
    old = [ValuedTerm(Term.parse("inlet_flow*pressure_hinge"), 0.3, 0.0, 10.0),
           ValuedTerm(Term.parse("one"), 1e-6)]
    new = linear_terms(old, [(0, "b")], signals)
    assert [str(t.term) for t in new] == ["one"]
    for s in signals:
        np.testing.assert_allclose(_flow(new, s), _flow(old, s), atol=1e-18)
    # a threshold inside the pressure's range: the bound is a real limit, no rewrite
    p = np.concatenate([s["pressure_Pa"] / s["atmospheric_pressure_Pa"] for s in signals])
    inside = float(np.median(p))
    assert linear_terms([ValuedTerm(Term.parse("pressure_hinge"), 1e-5, inside)],
                        [(0, "a")], signals) is None
    # the null hinge has no linear feature; a rewrite past the closure's four slots
    assert linear_terms([ValuedTerm(Term.parse("spool_null_hinge"), 1e-5, 20.0)],
                        [(0, "a")], signals) is None
    full = [ValuedTerm(Term.parse("pressure_hinge_down"), 1e-5, 10.0)] + [
        ValuedTerm(Term.parse(t), 1e-6) for t in ("spool", "inlet_flow", "exhaust_flow")]
    assert linear_terms(full, [(0, "a")], signals) is None
    with pytest.raises(ValueError, match="min_share"):
        linear_terms(full, [(0, "a")], signals, min_share=0.4)
