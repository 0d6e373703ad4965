"""Friction in the valve-chamber tube: the Darcy factor of a smooth pipe.

The momentum balance of a tube segment of length dx and section A carrying mass flow q
(Richer & Hurmuzlu 2000, lumped) is ``dq/dt = A / dx (p_i - p_{i+1}) - f Re mu q /
(2 rho D^2)``; ``f Re`` is 64 in laminar flow (Poiseuille) and grows with Re once the
flow turns turbulent. The 2-mm tubes of the paper carry 1 g/s at Re ~ 3e4, so the
turbulent branch matters.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def churchill_fre(re):
    """Darcy friction factor times Reynolds number for a smooth tube (Churchill 1977).

    ``f = 8 ((8/Re)^12 + (A + B)^-1.5)^(1/12)``, A = (2.457 ln(1 / (7/Re)^0.9))^16,
    B = (37530 / Re)^16; returned as ``f Re`` (64 in laminar flow), smooth in Re.
    Below Re = 1000 the turbulent correction is below 2e-14 of 64, and 64 is returned
    (the transmission-line tube evaluates this at every junction every 0.1 ms).
    """
    if re < 1000.0:
        return 64.0
    a = (2.457 * 0.9 * math.log(re / 7.0)) ** 16
    b = (37530.0 / re) ** 16
    return 8.0 * (8.0**12 + re**12 * (a + b) ** -1.5) ** (1.0 / 12.0)


@njit(cache=True, error_model="numpy")
def churchill_fre_slope(re):
    """``d ln(f Re) / d ln Re`` of :func:`churchill_fre` (0 laminar, ~0.75 turbulent)."""
    if re < 1000.0:
        return 0.0
    step = 1e-4
    return (math.log(churchill_fre(re * math.exp(step)))
            - math.log(churchill_fre(re * math.exp(-step)))) / (2.0 * step)
