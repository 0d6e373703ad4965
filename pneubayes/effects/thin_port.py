"""The thin-port core every model starts from: Gompertz port maps and dead volume.

Parameters are the model card's base names (eq. 11 for each port, and the dead volume
of the volume map, section VI-B-2). Bounds encode physics: areas positive, each map
monotone in the right direction (inlet c > 0, exhaust c < 0), volumes positive.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Component, Parameter
from pneubayes.rig import Rig

_PORT_PARAMS = (
    ("offset_m2", "m^2", 0.0, 2e-7, "uniform", "leakage area at the closed spool"),
    ("a_m2", "m^2", 1e-8, 5e-6, "log-uniform", "area opened by the spool (scale)"),
    ("b", "-", 0.05, 50.0, "log-uniform", "Gompertz displacement"),
)


def _port_parameters(port: str) -> tuple[Parameter, ...]:
    out = [Parameter(f"{port}_{n}", u, lo, hi, pr, f"{port} {d} (eq. 11)")
           for n, u, lo, hi, pr, d in _PORT_PARAMS]
    if port == "inlet":
        out.append(Parameter("inlet_c_per_V", "1/V", 0.05, 20.0, "uniform",
                             "inlet Gompertz growth rate, > 0: area grows with command (eq. 11)"))
    else:
        out.append(Parameter("exhaust_c_per_V", "1/V", -20.0, -0.05, "uniform",
                             "exhaust Gompertz growth rate, < 0: area grows as command falls"))
    out.append(Parameter(f"{port}_d_V", "V", -3.0, 3.0, "uniform",
                         f"{port} Gompertz command shift (eq. 11)"))
    return tuple(out)


class ThinPort(Component):
    """Eqs. 1-5 and 11: two Gompertz-mapped ports and the chamber's dead volume."""

    name = "thin_port"
    acts_on = ("inlet_offset_m2", "inlet_a_m2", "inlet_b", "inlet_c_per_V", "inlet_d_V",
               "exhaust_offset_m2", "exhaust_a_m2", "exhaust_b", "exhaust_c_per_V",
               "exhaust_d_V", "volume_m3")

    def parameters(self) -> tuple[Parameter, ...]:
        return (_port_parameters("inlet") + _port_parameters("exhaust") + (
            Parameter("dead_volume_m3", "m^3", 1e-8, 1e-4, "log-uniform",
                      "chamber volume at position 0, tube volume included (Fig. 5b)"),))

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig) -> dict[str, np.ndarray]:
        out = {name: values[name] for name in self.acts_on if name != "volume_m3"}
        out["volume_m3"] = values["dead_volume_m3"]
        return out
