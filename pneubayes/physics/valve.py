"""Valve port-area maps: the Gompertz curve of eq. 11, a switching valve's opening, a
tabulated command -> area map, and the Table II valves.

``area(cmd) = offset + a exp(-b exp(-c (cmd + d)))``, m^2, command in V (-5..+5).
Inlet maps have c > 0 (area grows with the command); exhaust maps have c < 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


@njit(cache=True)
def gompertz_scalar(cmd, offset, a, b, c, d):
    """Eq. 11 for one command value, m^2."""
    return offset + a * math.exp(-b * math.exp(-c * (cmd + d)))


def gompertz_area(command_V, offset_m2, a_m2, b, c_per_V, d_V):
    """Port area against valve command, eq. 11, vectorised (m^2)."""
    cmd = np.asarray(command_V, dtype=np.float64)
    return offset_m2 + a_m2 * np.exp(-b * np.exp(-c_per_V * (cmd + d_V)))


def gompertz_partials(command_V, offset_m2, a_m2, b, c_per_V, d_V):
    """Eq. 11's partial derivatives at each command, shape ``(n, 5)``: d area / d
    (offset_m2, a_m2, b, c_per_V, d_V), in m^2 per each parameter's unit."""
    cmd = np.asarray(command_V, dtype=np.float64)
    inner = np.exp(-c_per_V * (cmd + d_V))
    outer = np.exp(-b * inner)
    abe = a_m2 * b * inner * outer
    return np.stack((np.ones_like(cmd), outer, -a_m2 * inner * outer, abe * (cmd + d_V),
                     abe * c_per_V), axis=-1)


@njit(cache=True)
def switching_scalar(u, inlet_open_m2, exhaust_open_m2):
    """A switching (on/off) valve's port areas for opening ``u`` (0 closed, 1 open), m^2:
    the inlet ``A_in clip(u, 0, 1)``, the exhaust ``A_ex clip(1 - u, 0, 1)``."""
    f = 0.0 if u <= 0.0 else (1.0 if u >= 1.0 else u)
    return inlet_open_m2 * f, exhaust_open_m2 * (1.0 - f)


def switching_areas(u, inlet_open_m2, exhaust_open_m2):
    """:func:`switching_scalar`, vectorised: ``(inlet_m2, exhaust_m2)``."""
    f = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
    return inlet_open_m2 * f, exhaust_open_m2 * (1.0 - f)


@njit(cache=True)
def table_scalar(u, commands, areas, n):
    """A tabulated map's area at command ``u``, m^2: linear between the first ``n``
    points ``(commands[k], areas[k])`` (commands increasing), held flat beyond the ends.
    Returns ``(area, d area / du)``."""
    if u <= commands[0]:
        return areas[0], 0.0
    if u >= commands[n - 1]:
        return areas[n - 1], 0.0
    k = 0
    while commands[k + 1] < u:
        k += 1
    slope = (areas[k + 1] - areas[k]) / (commands[k + 1] - commands[k])
    return areas[k] + slope * (u - commands[k]), slope


@dataclass(frozen=True)
class GompertzMap:
    """One port's area map (eq. 11). Areas in m^2, ``c`` in 1/V, ``d`` in V."""

    offset_m2: float
    a_m2: float
    b: float
    c_per_V: float
    d_V: float

    def area(self, command_V):
        """Port area for the given command(s), m^2."""
        return gompertz_area(command_V, self.offset_m2, self.a_m2, self.b, self.c_per_V,
                             self.d_V)


@dataclass(frozen=True)
class ValvePreset:
    """A valve's inlet and exhaust maps."""

    name: str
    inlet: GompertzMap
    exhaust: GompertzMap

    def parameters(self) -> dict[str, float]:
        """The ten base Gompertz parameters under their model-card names."""
        out = {}
        for port, m in (("inlet", self.inlet), ("exhaust", self.exhaust)):
            out[f"{port}_offset_m2"] = m.offset_m2
            out[f"{port}_a_m2"] = m.a_m2
            out[f"{port}_b"] = m.b
            out[f"{port}_c_per_V"] = m.c_per_V
            out[f"{port}_d_V"] = m.d_V
        return out


#: Table II of the paper, both FESTO MPYE-5-1/8-LF-010-B valves.
VALVES: dict[str, ValvePreset] = {
    "valve1": ValvePreset(
        "valve1",
        inlet=GompertzMap(2.9274e-08, 5.501e-07, 3.539, 1.564, 0.12),
        exhaust=GompertzMap(2.6076e-08, 6.079e-07, 3.149, -1.365, -0.1),
    ),
    "valve2": ValvePreset(
        "valve2",
        inlet=GompertzMap(2.627e-08, 8.731e-07, 4.029, 0.929, -0.1505),
        exhaust=GompertzMap(2.964e-08, 8.659e-07, 3.942, -0.9816, 0.1584),
    ),
}


def valve_preset(name: str) -> ValvePreset:
    """Look up a Table II valve by name (``valve1`` or ``valve2``)."""
    try:
        return VALVES[name]
    except KeyError:
        raise KeyError(f"unknown valve {name!r}; known: {sorted(VALVES)}") from None
