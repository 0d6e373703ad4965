"""Heat exchange between the chamber air and its wall (Richer & Hurmuzlu 2000).

The paper's eq. 5 is isentropic with the temperature fixed at the supply's. This effect
makes the chamber temperature T a state and adds the wall heat flow
``Q = m c_v (T_w - T) / tau`` (wall at the supply temperature):

- ``dp/dt = kappa / V (Rs (T_w m_in - T m_out) - p dV/dt) + p (T_w - T) / (T tau)``:
  eq. 5 with the air that leaves carrying the chamber's temperature (inflow at the
  supply's), plus the wall exchange;
- ``dT/dt = T (dp/dt / p + dV/dt / V - Rs T mdot / (p V))`` (ideal gas, mass balance).

(Outflow at the supply's enthalpy, as an earlier version had it, makes T run away once
it exceeds kappa T_w -- after a compression -- whenever the chamber vents.)

Its parameter is the exchange rate ``heat_transfer_rate_per_s`` = 1/tau (tau is the
wall time constant). At rate 0 the pressure equation is eq. 5 exactly (zero strength);
as the rate grows, the pressure relaxes after each fill or vent, which eq. 5 cannot do.
The orifice mass flows keep the paper's supply temperature (no sqrt(T_w / T) on eq. 1),
so the effect is a first-order correction to eq. 5 rather than a full energy equation.
"""

from __future__ import annotations

from pneubayes.effects.base import DirectEffect, Parameter


class HeatTransfer(DirectEffect):
    """Chamber temperature as a state, relaxing to the wall at ``heat_transfer_rate_per_s``."""

    name = "heat_transfer"
    slot = "heat_rate_per_s"
    parameter = Parameter("heat_transfer_rate_per_s", "1/s", 0.0, 100.0, "uniform",
                          "wall heat-exchange rate, 1 / wall time constant", neutral=0.0)
    #: A wall time constant of 0.2 s, typical of small cylinders.
    bench_value = 5.0
