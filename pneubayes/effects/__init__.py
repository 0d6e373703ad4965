"""The effect catalogue: each physical effect is one small object behind one interface.

Names are exactly the catalogue's: ``cylinder_leak``, ``tube_delay``, ``valve_deadzone``,
``supply_fluctuation``, ``heat_transfer``, ``spool_lag``.
"""

from __future__ import annotations

from pneubayes.effects.base import Component, Effect, Parameter
from pneubayes.effects.cylinder_leak import CylinderLeak
from pneubayes.effects.heat_transfer import HeatTransfer
from pneubayes.effects.spool_lag import SpoolLag
from pneubayes.effects.supply_fluctuation import SupplyFluctuation
from pneubayes.effects.thin_port import ThinPort
from pneubayes.effects.tube_delay import TubeDelay
from pneubayes.effects.valve_deadzone import ValveDeadzone

CATALOGUE: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (CylinderLeak, TubeDelay, ValveDeadzone, SupplyFluctuation, HeatTransfer,
                SpoolLag)
}


def make_effect(name: str, **options) -> Effect:
    """Build a catalogue effect by name, e.g. ``make_effect("cylinder_leak", form="laminar")``."""
    try:
        cls = CATALOGUE[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; the catalogue has {sorted(CATALOGUE)}") \
            from None
    try:
        return cls(**options)
    except TypeError as exc:
        raise ValueError(f"effect {name!r}: bad options {options!r} ({exc})") from None


__all__ = ["CATALOGUE", "Component", "CylinderLeak", "Effect", "HeatTransfer", "Parameter",
           "SpoolLag", "SupplyFluctuation", "ThinPort", "TubeDelay", "ValveDeadzone",
           "make_effect"]
