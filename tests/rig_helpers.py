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
