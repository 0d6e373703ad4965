"""Rig constants that come from a recording's JSON, not from fitting."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pneubayes.physics.cylinder import bore_area_m2
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.sensor_filter import PressureFilter


@dataclass(frozen=True)
class Rig:
    """What is known about the rig: bore, ambient and nominal supply pressures, gas, and
    the pressure channel's anti-alias filter when it is declared.

    Parameters
    ----------
    bore_m : float
        Piston bore diameter, m.
    atmospheric_pressure_Pa : float
        Absolute exhaust pressure P_r, Pa.
    supply_pressure_Pa : float
        Nominal absolute supply pressure P_c, Pa.
    gas : GasConstants
        Gas constants; ``gas.temperature_K`` is the supply temperature.
    stroke_m : float or None
        Piston stroke, m (None when unknown; an effect that is graded along the stroke
        needs it).
    pressure_filter : PressureFilter or None
        The pressure channel's zero-phase anti-alias filter (None: the reading is the
        chamber pressure); the simulator then predicts what the sensor reads
        (:mod:`pneubayes.simulation.measurement`).
    """

    bore_m: float
    atmospheric_pressure_Pa: float
    supply_pressure_Pa: float
    gas: GasConstants = field(default_factory=GasConstants)
    stroke_m: float | None = None
    pressure_filter: PressureFilter | None = None

    def __post_init__(self):
        if self.pressure_filter is not None and not isinstance(self.pressure_filter,
                                                               PressureFilter):
            raise TypeError(f"Rig.pressure_filter must be a PressureFilter or None, got "
                            f"{type(self.pressure_filter).__name__}")
        names = ("bore_m", "atmospheric_pressure_Pa", "supply_pressure_Pa")
        for name in names + (("stroke_m",) if self.stroke_m is not None else ()):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"Rig.{name} must be a finite number > 0, got {v!r}")
        if self.supply_pressure_Pa <= self.atmospheric_pressure_Pa:
            raise ValueError(
                f"Rig.supply_pressure_Pa ({self.supply_pressure_Pa}) must exceed "
                f"atmospheric_pressure_Pa ({self.atmospheric_pressure_Pa})")

    @property
    def bore_area_m2(self) -> float:
        return bore_area_m2(self.bore_m)

    @property
    def working_range_Pa(self) -> float:
        """Supply minus atmosphere, the denominator of Table III's percentages."""
        return self.supply_pressure_Pa - self.atmospheric_pressure_Pa
