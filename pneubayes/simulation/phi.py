"""The exponential integrator's scalar phi functions (:mod:`pneubayes.simulation.kernel`'s
pressure step and its dense output; :mod:`pneubayes.simulation.chord`)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always", error_model="numpy")
def phi123(z):
    """phi_k(z) = (e^z - sum_{j<k} z^j/j!) / z^k for k = 1, 2, 3; stable for all z <= ~0."""
    if abs(z) < 0.1:
        phi1 = 1.0 + z * (0.5 + z * (1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0
                                                                          + z / 720.0))))
        phi2 = 0.5 + z * (1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0 + z * (
            1.0 / 720.0 + z / 5040.0))))
        phi3 = 1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0 + z * (1.0 / 720.0 + z * (
            1.0 / 5040.0 + z / 40320.0))))
        return phi1, phi2, phi3
    inv = 1.0 / z  # one division, three products
    phi1 = math.expm1(z) * inv
    phi2 = (phi1 - 1.0) * inv
    phi3 = (phi2 - 0.5) * inv
    return phi1, phi2, phi3
