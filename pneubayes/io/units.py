"""Declared units: names like ``pressure_kPa_gauge`` or ``bore_mm`` and their SI values.

A recording of format 2 (``"format": "pneubayes-recording/2"`` in its JSON; see the
README) may give a quantity in another unit by naming it ``<quantity>_<unit>``, and a
pressure as gauge by a ``_gauge`` suffix (then ``absolute = gauge + atmosphere``). The
reader converts every such column and key to the SI, absolute name of format 1 before
any check, so everything downstream sees pascals, seconds, metres and kelvin.

This module is the one table of those units; :mod:`pneubayes.io.plausibility` uses it
to say which unit a slipped value was probably in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Pressure units -> Pa per unit.
PRESSURE_UNITS: dict[str, float] = {
    "Pa": 1.0, "hPa": 100.0, "kPa": 1e3, "MPa": 1e6, "mbar": 100.0, "bar": 1e5,
    "psi": 6894.757293168361, "atm": 101325.0, "Torr": 101325.0 / 760.0,
    "mmHg": 133.322387415, "cmH2O": 98.0665, "inH2O": 249.08891,
}
#: Time units -> s per unit.
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0}
#: Length units -> m per unit.
LENGTH_UNITS: dict[str, float] = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254}
#: Temperature units -> (scale, offset): kelvin = scale * value + offset.
TEMPERATURE_UNITS: dict[str, tuple[float, float]] = {
    "K": (1.0, 0.0), "C": (1.0, 273.15), "F": (5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0)}

#: Quantity name -> (SI name, unit table, gauge allowed). Longest names first, so that
#: ``supply_pressure_kPa`` is the supply, not a ``pressure`` in unit ``supply_...``.
QUANTITIES: dict[str, tuple[str, str, bool]] = {
    "atmospheric_pressure": ("atmospheric_pressure_Pa", "pressure", False),
    "supply_pressure": ("supply_pressure_Pa", "pressure", True),
    "temperature": ("temperature_K", "temperature", False),
    "pressure": ("pressure_Pa", "pressure", True),
    "position": ("position_m", "length", False),
    "stroke": ("stroke_m", "length", False),
    "bore": ("bore_m", "length", False),
    "time": ("time_s", "time", False),
}
#: A pneumatic chamber's usual swing (a shop supply of a few bar gauge), Pa: ranks the
#: readings of a slipped pressure column.
TYPICAL_SWING_Pa = 400e3
#: How much more a reading's distance from the resting pressure counts than its swing's
#: distance from the usual one (in log ratio): a chamber rests near the atmosphere
#: (within a few %), while swings range from a few kPa (ventilators) to MPa.
REST_WEIGHT = 40.0
_TABLES = {"pressure": PRESSURE_UNITS, "time": TIME_UNITS, "length": LENGTH_UNITS,
           "temperature": TEMPERATURE_UNITS}


@dataclass(frozen=True)
class DeclaredUnit:
    """How one declared name maps to its SI name: ``si = scale * value + offset``, plus
    the atmosphere when ``gauge``.

    Parameters
    ----------
    name : str
        The name as written (``pressure_kPa_gauge``).
    si_name : str
        The format-1 name it stands for (``pressure_Pa``).
    unit : str
        The declared unit (``kPa``).
    gauge : bool
        A gauge pressure: the atmospheric pressure is added after scaling.
    scale, offset : float
        ``scale * value + offset`` is the SI value (before adding the atmosphere).
    """

    name: str
    si_name: str
    unit: str
    gauge: bool
    scale: float
    offset: float = 0.0

    @property
    def is_si(self) -> bool:
        """True for the SI, absolute name itself (nothing to convert)."""
        return self.name == self.si_name

    def describe(self) -> str:
        """E.g. ``'pressure_kPa_gauge': kPa gauge -> pressure_Pa (absolute)``."""
        ref = " gauge" if self.gauge else ""
        tail = " (absolute)" if "pressure" in self.si_name else ""
        return f"{self.name!r}: {self.unit}{ref} -> {self.si_name}{tail}"

    def to_si(self, value, atmospheric_pressure_Pa: float | None = None):
        """The SI value(s); a gauge pressure needs ``atmospheric_pressure_Pa``."""
        out = value * self.scale + self.offset
        if self.gauge:
            if atmospheric_pressure_Pa is None:
                raise ValueError(f"{self.name}: a gauge pressure needs the atmospheric "
                                 "pressure")
            out = out + atmospheric_pressure_Pa
        return out


def parse_declared(name: str) -> DeclaredUnit | None:
    """The :class:`DeclaredUnit` of ``name``, or None when it names no known quantity in a
    known unit (names and units are case-sensitive: ``kPa``, not ``kpa``)."""
    for quantity, (si_name, table, gauge_ok) in QUANTITIES.items():
        if not name.startswith(quantity + "_"):
            continue
        rest = name[len(quantity) + 1:]
        gauge = gauge_ok and rest.endswith("_gauge")
        unit = rest[: -len("_gauge")] if gauge else rest
        units = _TABLES[table]
        if unit not in units:
            return None
        factor = units[unit]
        scale, offset = factor if isinstance(factor, tuple) else (factor, 0.0)
        return DeclaredUnit(name, si_name, unit, gauge, scale, offset)
    return None


def unit_names(si_name: str) -> list[str]:
    """Every declarable name of the quantity whose SI name is ``si_name``."""
    for quantity, (si, table, gauge_ok) in QUANTITIES.items():
        if si == si_name:
            names = [f"{quantity}_{u}" for u in _TABLES[table]]
            return names + ([f"{n}_gauge" for n in names] if gauge_ok else [])
    return []


def pressure_readings(values_Pa, low_Pa: float, high_Pa: float,
                      atmospheric_pressure_Pa: float = 101325.0,
                      min_span_Pa: float = 0.0, limit: int = 3,
                      rest_Pa: float | None = None) -> list[str]:
    """Units in which the numbers ``values_Pa`` would all be plausible absolute pressures.

    A unit qualifies, read as absolute or as gauge (plus ``atmospheric_pressure_Pa``),
    when every value lands in ``[low_Pa, high_Pa]`` and their spread is at least
    ``min_span_Pa``. The best ``limit`` readings come first, each a fragment such as
    ``"bar (5.5 bar = 550000 Pa absolute)"``: with ``rest_Pa`` (a chamber's resting
    pressure, the atmosphere) those whose smallest value lands closest to it and whose
    spread is closest to :data:`TYPICAL_SWING_Pa`, in ratio; else those
    whose largest value lands closest to the middle of the range. Used to say which unit
    a slipped value was probably in.
    """
    values = [float(v) for v in values_Pa]
    middle = math.sqrt(low_Pa * high_Pa)
    found = []
    for unit, factor in PRESSURE_UNITS.items():
        for gauge in (False, True):
            if unit == "Pa" and not gauge:
                continue
            si = [v * factor + (atmospheric_pressure_Pa if gauge else 0.0) for v in values]
            if (all(low_Pa <= x <= high_Pa for x in si)
                    and max(si) - min(si) >= min_span_Pa):
                name = f"{unit} gauge" if gauge else unit
                v = max(values, key=abs)
                x = v * factor + (atmospheric_pressure_Pa if gauge else 0.0)
                text = f"{name} ({v:g} {name} = {x:.6g} Pa absolute)"
                if rest_Pa is None:
                    score = abs(math.log(max(si) / middle))
                else:  # rests near rest_Pa (strongly) and swings over a working range
                    swing = max(max(si) - min(si), 1.0) / TYPICAL_SWING_Pa
                    score = (REST_WEIGHT * abs(math.log(min(si) / rest_Pa))
                             + abs(math.log(swing)))
                found.append((score, text))
    return [text for _, text in sorted(found)[:limit]]
