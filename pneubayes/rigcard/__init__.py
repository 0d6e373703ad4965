"""Rig cards: a lab's own chamber, valve and supply as plug-in components.

Importing this package registers the shipped kinds (one module each):
chamber ``fixed``, ``compliant``, ``piston`` and ``polynomial``; valve ``gompertz`` and
``switching``; supply ``measured`` and ``constant``.
"""

from pneubayes.rigcard import (  # noqa: F401  (each module registers its kind)
    chamber_compliant,
    chamber_fixed,
    chamber_piston,
    chamber_polynomial,
    supply_constant,
    supply_measured,
    valve_gompertz,
    valve_switching,
)
from pneubayes.rigcard.card import RIG_FORMAT, CommandSpec, RigCard, Tube, load_rig_card
from pneubayes.rigcard.component import KINDS, RigComponent, kinds_of, register
from pneubayes.rigcard.values import Unknown

__all__ = ["KINDS", "RIG_FORMAT", "CommandSpec", "RigCard", "RigComponent", "Tube",
           "Unknown", "kinds_of", "load_rig_card", "register"]
