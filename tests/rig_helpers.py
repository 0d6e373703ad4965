"""Helpers the rig-card tests share."""

from __future__ import annotations

import copy

from pneubayes.rigcard import RigCard


def edited_card(base: dict, **changes) -> RigCard:
    """``base`` with ``section__key=value`` (or ``section=table``; ``section=None``
    removes it) applied, read as a card named ``card.json``."""
    d = copy.deepcopy(base)
    for key, value in changes.items():
        section, _, sub = key.partition("__")
        if sub:
            d[section][sub] = value
        elif value is None:
            d.pop(section)
        else:
            d[section] = value
    return RigCard.from_dict(d, "card.json")


def assert_converges_to(reference, standard, tight, *, min_span, std_of_span, shrink):
    """The standard preset's trajectory is within ``std_of_span`` of the reference's
    span, and the 100x tighter one's error at most ``shrink`` of the standard's (the
    error falls with the tolerance: convergence, not a lucky match)."""
    import numpy as np

    span = np.ptp(reference)
    assert span > min_span, span
    err_std = np.max(np.abs(standard - reference))
    err_tight = np.max(np.abs(tight - reference))
    assert err_std < std_of_span * span, (err_std, span)
    assert err_tight < shrink * err_std, (err_tight, err_std)
