"""Chamber pressure dynamics, paper eqs. 4, 5 and 9.

``dp/dt = n / V (Rs T mdot - p dV/dt)`` (eq. 5) with the net inflow
``mdot = a_c f(P_c, p) - a_a f(p, P_r) - a_l f(p, P_r)`` (eqs. 4 and 9).
"""

from __future__ import annotations

import numpy as np

from pneubayes.physics.gas import GasConstants
from pneubayes.physics.orifice import flow_function


def pressure_rate(pressure_Pa, volume_m3, volume_rate_m3_per_s, mass_flow_kg_per_s,
                  gas: GasConstants):
    """Eq. 5: dp/dt in Pa/s for net inflow ``mass_flow_kg_per_s`` (vectorised)."""
    n = gas.heat_capacity_ratio
    rs_t = gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
    p = np.asarray(pressure_Pa, dtype=np.float64)
    return n / np.asarray(volume_m3) * (rs_t * np.asarray(mass_flow_kg_per_s)
                                         - p * np.asarray(volume_rate_m3_per_s))


def net_mass_flow(pressure_Pa, inlet_area_m2, exhaust_area_m2, supply_Pa, atmosphere_Pa,
                  gas: GasConstants, leak_area_m2=0.0):
    """Eqs. 4 and 9: net mass flow into the chamber, kg/s."""
    p = np.asarray(pressure_Pa, dtype=np.float64)
    inflow = np.asarray(inlet_area_m2) * flow_function(supply_Pa, p, gas)
    outflow = (np.asarray(exhaust_area_m2) + np.asarray(leak_area_m2)) * flow_function(
        p, atmosphere_Pa, gas)
    return inflow - outflow
