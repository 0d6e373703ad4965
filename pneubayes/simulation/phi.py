"""The exponential integrator's phi functions: scalar (:mod:`pneubayes.simulation.kernel`'s
pressure step and its dense output; :mod:`pneubayes.simulation.chord`) and of a 2 x 2
matrix (the (p, T) step of :mod:`pneubayes.simulation.thermal`)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
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


_INV_FACT = tuple(1.0 / math.factorial(j) for j in range(17))


@njit(cache=True, error_model="numpy")
def _mm2(x, y):
    """Product of 2 x 2 matrices stored row-major as 4-tuples."""
    return (x[0] * y[0] + x[1] * y[2], x[0] * y[1] + x[1] * y[3],
            x[2] * y[0] + x[3] * y[2], x[2] * y[1] + x[3] * y[3])


@njit(cache=True, error_model="numpy")
def phi0123_2x2(m):
    """``phi_k(M)`` for k = 0..3 of a 2 x 2 matrix (row-major 4-tuple): scaling and
    squaring with the doubling rule ``phi_k(2M) = 2^-k (phi_0(M) phi_k(M) +
    sum_{j=1..k} phi_j(M) / (k - j)!)`` (Skaflestad and Wright 2009) from a 13-term
    Taylor series at 1-norm <= 1/4 (truncation below 1e-17). A non-finite ``m`` gives NaN.
    """
    norm = max(abs(m[0]) + abs(m[2]), abs(m[1]) + abs(m[3]))
    if not math.isfinite(norm):
        nan = (math.nan, math.nan, math.nan, math.nan)
        return nan, nan, nan, nan
    sq = 0
    if norm > 0.25:
        sq = int(math.ceil(math.log2(norm / 0.25)))
    c = 0.5 ** sq
    x = (m[0] * c, m[1] * c, m[2] * c, m[3] * c)
    pw = (1.0, 0.0, 0.0, 1.0)
    f0 = (0.0, 0.0, 0.0, 0.0)
    f1, f2, f3 = f0, f0, f0
    for j in range(13):
        a0, a1, a2, a3 = _INV_FACT[j], _INV_FACT[j + 1], _INV_FACT[j + 2], _INV_FACT[j + 3]
        f0 = (f0[0] + a0 * pw[0], f0[1] + a0 * pw[1], f0[2] + a0 * pw[2], f0[3] + a0 * pw[3])
        f1 = (f1[0] + a1 * pw[0], f1[1] + a1 * pw[1], f1[2] + a1 * pw[2], f1[3] + a1 * pw[3])
        f2 = (f2[0] + a2 * pw[0], f2[1] + a2 * pw[1], f2[2] + a2 * pw[2], f2[3] + a2 * pw[3])
        f3 = (f3[0] + a3 * pw[0], f3[1] + a3 * pw[1], f3[2] + a3 * pw[2], f3[3] + a3 * pw[3])
        pw = _mm2(pw, x)
    for _ in range(sq):
        e3, e2, e1 = _mm2(f0, f3), _mm2(f0, f2), _mm2(f0, f1)
        f3 = ((e3[0] + 0.5 * f1[0] + f2[0] + f3[0]) * 0.125,
              (e3[1] + 0.5 * f1[1] + f2[1] + f3[1]) * 0.125,
              (e3[2] + 0.5 * f1[2] + f2[2] + f3[2]) * 0.125,
              (e3[3] + 0.5 * f1[3] + f2[3] + f3[3]) * 0.125)
        f2 = ((e2[0] + f1[0] + f2[0]) * 0.25, (e2[1] + f1[1] + f2[1]) * 0.25,
              (e2[2] + f1[2] + f2[2]) * 0.25, (e2[3] + f1[3] + f2[3]) * 0.25)
        f1 = ((e1[0] + f1[0]) * 0.5, (e1[1] + f1[1]) * 0.5, (e1[2] + f1[2]) * 0.5,
              (e1[3] + f1[3]) * 0.5)
        f0 = _mm2(f0, f0)
    return f0, f1, f2, f3
