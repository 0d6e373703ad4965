"""Synthetic closure signals for the open-form search's tests and benchmark.

A chamber (10 cm^3 dead volume, a 9-mm bore piston moving at 2 Hz) fed by a valve
whose inlet and exhaust areas (0-0.25 mm^2: port flows up to ~3e-4 kg/s) follow a
spool of random steps in 0-10 V (first-order lag, 2 ms), from a ~7-bar supply that
wanders by 10 kPa; the pressure integrated with eq. 5 (explicit Euler at 0.1 ms, read
every 1 ms) stays within 1-7 bar absolute. Built with numpy and the orifice law only.
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.closure_histories import HeldCommand, command_direction
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.orifice import flow_function, flow_terms

P_ATM = 101325.0


def synthetic_signals(seed: int, n: int = 4000, dt_s: float = 1e-3,
                      supply_Pa: float = 7.0e5) -> dict:
    """The :data:`~pneubayes.effects.closure_features.SIGNALS` of ``n`` samples, from a
    supply of ``supply_Pa`` (absolute, Pa; the chamber starts at 3 bar or half-way to
    the supply, whichever is lower)."""
    rng = np.random.default_rng(seed)
    gas = GasConstants()
    t = np.arange(n) * dt_s
    u = np.empty(n)
    i = 0
    while i < n:
        hold = int(rng.integers(40, 300))
        u[i:i + hold] = rng.uniform(0.0, 10.0)
        i += hold
    a = np.exp(-dt_s / 0.002)
    s = np.empty(n)
    s[0] = u[0]
    for k in range(1, n):
        s[k] = u[k - 1] + (s[k - 1] - u[k - 1]) * a
    amax = 0.25e-6

    def areas(spool):
        return (amax / (1.0 + np.exp(-(spool - 6.0) / 0.5)),
                amax / (1.0 + np.exp((spool - 4.0) / 0.5)))
    a_in, a_ex = areas(s)
    p_sup = supply_Pa + 1.0e4 * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6.3))
    bore = np.pi / 4 * 0.009**2
    x = 0.015 + 0.01 * np.sin(2 * np.pi * 2.0 * t)
    xdot = 0.01 * 2 * np.pi * 2.0 * np.cos(2 * np.pi * 2.0 * t)
    vol = 1e-5 + bore * x
    vdot = bore * xdot
    kappa, rs_t = gas.heat_capacity_ratio, gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
    p = np.empty(n)
    p[0] = min(3e5, 0.5 * (supply_Pa + P_ATM))
    sub = 10
    law = (gas.alpha_s_per_m, gas.beta_s_per_m, gas.theta, kappa)
    for k in range(n - 1):
        q = p[k]
        for _ in range(sub):  # (the scalar law: the vectorised one's checks cost 20x)
            m_in = a_in[k] * flow_terms(p_sup[k], q, *law)[0]
            m_ex = a_ex[k] * flow_terms(q, P_ATM, *law)[0]
            q = q + dt_s / sub * (kappa * rs_t / vol[k] * (m_in - m_ex)
                                  - kappa * q * vdot[k] / vol[k])
        p[k + 1] = q
    return {"pressure_Pa": p, "supply_pressure_Pa": p_sup,
            "atmospheric_pressure_Pa": np.full(n, P_ATM), "spool": s,
            "inlet_area_m2": a_in, "exhaust_area_m2": a_ex,
            "inlet_flow_kg_per_s": a_in * flow_function(p_sup, p, gas),
            "exhaust_flow_kg_per_s": a_ex * flow_function(p, P_ATM, gas),
            "inlet_flux_kg_per_s_m2": flow_function(p_sup, p, gas),
            "exhaust_flux_kg_per_s_m2": flow_function(p, P_ATM, gas),
            "volume_m3": vol, "volume_rate_m3_per_s": vdot,
            "command_direction": command_direction(u), "time_s": t,
            "held_command": HeldCommand(t, t, u, 0.0, None, areas),
            "interval_s": np.full(n, dt_s)}
