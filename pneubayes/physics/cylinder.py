"""Cylinder geometry: the Table I presets and the volume map.

Volume = dead volume + bore area x position (section VI-B-2; Fig. 5b is linear).
PRN (PRNA20S-180-45) is a rotary actuator that the paper gives only as a swept volume
of 3.50e-6 m^3; we represent it as an equivalent linear cylinder of 20 mm bore whose
stroke gives that swept volume.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def bore_area_m2(bore_m: float) -> float:
    """Piston area pi/4 d^2, m^2."""
    return math.pi / 4.0 * bore_m * bore_m


def chamber_volume(position_m, dead_volume_m3: float, bore_m: float):
    """Chamber volume V = V_dead + A_bore x, m^3 (position 0 = fully retracted)."""
    return dead_volume_m3 + bore_area_m2(bore_m) * np.asarray(position_m, dtype=np.float64)


def wall_area_m2(volume_m3, bore_area: float):
    """Inner wall area of a cylinder of section ``bore_area`` (m^2) holding ``volume_m3``:
    two end caps and the barrel, ``2 A + pi D V / A`` with ``D = 2 sqrt(A / pi)``, m^2
    (the convective heat form of :mod:`pneubayes.effects.heat_transfer`)."""
    bore_d = 2.0 * math.sqrt(bore_area / math.pi)
    return 2.0 * bore_area + math.pi * bore_d * np.asarray(volume_m3, np.float64) / bore_area


@dataclass(frozen=True)
class CylinderPreset:
    """A Table I cylinder: name, part number, bore and stroke (m)."""

    name: str
    part_number: str
    bore_m: float
    stroke_m: float
    characteristics: str

    @property
    def swept_volume_m3(self) -> float:
        """Bore area x stroke, m^3 (Table I's 'Volume')."""
        return bore_area_m2(self.bore_m) * self.stroke_m


_PRN_BORE_M = 0.020
CYLINDERS: dict[str, CylinderPreset] = {
    "AIR37": CylinderPreset("AIR37", "AIRPEL M9D37.5", 0.009, 0.0375, "High leak, small volume"),
    "AIR200": CylinderPreset("AIR200", "AIRPEL M9D200", 0.009, 0.200, "High leak, large volume"),
    "SMC": CylinderPreset("SMC", "SMC CQ2A32-25DC", 0.032, 0.025, "Low leak, large volume"),
    "PRN": CylinderPreset("PRN", "PRNA20S-180-45 (rotary, equivalent linear)", _PRN_BORE_M,
                          3.50e-06 / bore_area_m2(_PRN_BORE_M), "Low leak, small volume"),
}


def cylinder_preset(name: str) -> CylinderPreset:
    """Look up a Table I cylinder by name (AIR37, AIR200, SMC, PRN)."""
    try:
        return CYLINDERS[name]
    except KeyError:
        raise KeyError(f"unknown cylinder {name!r}; known: {sorted(CYLINDERS)}") from None
