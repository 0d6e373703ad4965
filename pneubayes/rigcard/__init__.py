"""Rig cards: a lab's own chamber, valve and supply as plug-in components.

Importing this package registers the shipped kinds (one module each):
chamber ``fixed``, ``compliant``, ``compliant_table``, ``piston``, ``polynomial``,
``table`` and ``two_compartment``; valve ``gompertz``, ``switching`` and ``table``;
supply ``measured``, ``constant``, ``tank`` and ``restricted``; a separate exhaust
valve ``gompertz`` and ``linear``; the ports' datasheet rating ``iso6358``.
"""

from pneubayes.rigcard import (  # noqa: F401  (each module registers its kind)
    chamber_compliant,
    chamber_compliant_table,
    chamber_fixed,
    chamber_piston,
    chamber_polynomial,
    chamber_table,
    chamber_two_compartment,
    exhaust_gompertz,
    exhaust_linear,
    ports_iso6358,
    supply_constant,
    supply_measured,
    supply_restricted,
    supply_tank,
    valve_gompertz,
    valve_switching,
    valve_table,
)
from pneubayes.rigcard.card import RIG_FORMAT, CommandSpec, RigCard, Tube, load_rig_card
from pneubayes.rigcard.component import KINDS, RigComponent, kinds_of, register
from pneubayes.rigcard.values import Unknown

__all__ = ["KINDS", "RIG_FORMAT", "CommandSpec", "RigCard", "RigComponent", "Tube",
           "Unknown", "kinds_of", "load_rig_card", "register"]
