"""Thin-port orifice mass flow, paper eqs. 1-3 (and 6-8 for the leak).

``mdot = a * f(p_u, p_d)`` (eq. 1). For ``p_u >= p_d`` the flow function is
``z(p_u, p_d)`` (eq. 3): subsonic ``alpha p_u sqrt((p_d/p_u)^(2/k) - (p_d/p_u)^((k+1)/k))``
while ``p_u/p_d <= theta`` and choked ``beta p_u`` beyond. Eq. 2 as printed writes
``-z(p_u, p_d)`` for reverse flow, which is the square root of a negative number; we
follow NOTES.md and use ``-z(p_d, p_u)``: the roles swap and the flow changes sign.

The scalar kernels are compiled once with numba and shared by the vectorised API and
the simulator, so there is one implementation of the law.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit, vectorize

from pneubayes.physics.gas import GasConstants

#: Absolute floor on sqrt(g) in slopes: keeps dz/dp finite at p_up == p_down.
_SQRT_G_FLOOR = 1e-12


@njit(cache=True)
def z_terms(p_up, p_down, alpha, beta, theta, kappa):
    """Eq. 3 for ``p_up >= p_down``: ``(z, sqrt_g, dg_dr, r)``.

    ``z`` in kg/(s m^2); ``sqrt_g`` < 0 flags the choked branch. The other terms feed
    :func:`z_slopes` so the power is computed once per evaluation.
    """
    if p_up > theta * p_down:  # choked
        return beta * p_up, -1.0, 0.0, 0.0
    r = p_down / p_up
    ik = 1.0 / kappa
    q = math.exp(math.log(r) * ik)  # r^(1/k)
    g = q * q - r * q  # r^(2/k) - r^((k+1)/k)
    sg = math.sqrt(g) if g > 0.0 else 0.0
    dg_dr = (2.0 * ik) * q * q / r - (1.0 + ik) * q
    return alpha * p_up * sg, sg, dg_dr, r


@njit(cache=True)
def z_slopes(p_up, sg, dg_dr, r, alpha, beta, kappa, dp_floor):
    """Partials ``(dz/dp_up, dz/dp_down)`` from :func:`z_terms`' output.

    The subsonic slope has a square-root singularity at ``p_up == p_down``. ``dp_floor``
    (Pa, >= 0) replaces it by the secant over a pressure difference of ``dp_floor``:
    sqrt(g) is floored at its value ``sqrt((k-1)/k * dp_floor / p_up)``. With 0 the exact
    slope is returned (up to a 1e-12 floor).
    """
    if sg < 0.0:
        return beta, 0.0
    floor2 = (kappa - 1.0) / kappa * dp_floor / p_up
    if floor2 < _SQRT_G_FLOOR * _SQRT_G_FLOOR:
        floor2 = _SQRT_G_FLOOR * _SQRT_G_FLOOR
    sgd = sg if sg * sg > floor2 else math.sqrt(floor2)
    dz_dpd = alpha * dg_dr / (2.0 * sgd)
    return alpha * sg - r * dz_dpd, dz_dpd


@njit(cache=True)
def flow_terms(p_up, p_down, alpha, beta, theta, kappa):
    """Signed eq. 2, ``(f, sqrt_g, dg_dr, r, reversed)``: f > 0 from p_up to p_down.

    For reverse flow (p_up < p_down) the roles swap: ``f = -z(p_down, p_up)``.
    """
    if p_up >= p_down:
        z, sg, dg, r = z_terms(p_up, p_down, alpha, beta, theta, kappa)
        return z, sg, dg, r, False
    z, sg, dg, r = z_terms(p_down, p_up, alpha, beta, theta, kappa)
    return -z, sg, dg, r, True


@njit(cache=True)
def flow_slopes(p_up, p_down, sg, dg_dr, r, rev, alpha, beta, kappa, dp_floor):
    """Partials ``(df/dp_up, df/dp_down)`` of the signed flow from :func:`flow_terms`."""
    if not rev:
        return z_slopes(p_up, sg, dg_dr, r, alpha, beta, kappa, dp_floor)
    dz_dhi, dz_dlo = z_slopes(p_down, sg, dg_dr, r, alpha, beta, kappa, dp_floor)
    return -dz_dlo, -dz_dhi


@njit(cache=True)
def flow_partials(p_up, p_down, alpha, beta, theta, kappa, dp_floor):
    """Convenience: ``(f, df/dp_up, df/dp_down)`` in one call (tests, Python callers)."""
    f, sg, dg, r, rev = flow_terms(p_up, p_down, alpha, beta, theta, kappa)
    du, dd = flow_slopes(p_up, p_down, sg, dg, r, rev, alpha, beta, kappa, dp_floor)
    return f, du, dd


def _flow_scalar(p_up, p_down, alpha, beta, theta, kappa):
    return flow_terms(p_up, p_down, alpha, beta, theta, kappa)[0]


@functools.cache
def _flow_ufunc():
    """:func:`_flow_scalar` as a compiled ufunc, built on first use: built at import it
    cost every import of the simulator about 1 s, even from numba's cache."""
    return vectorize(["float64(float64, float64, float64, float64, float64, float64)"],
                     cache=True)(_flow_scalar)


def flow_function(p_up_Pa, p_down_Pa, gas: GasConstants):
    """Signed flow per unit area f(p_u, p_d), kg/(s m^2) (eqs. 2-3), vectorised.

    Parameters
    ----------
    p_up_Pa, p_down_Pa : array_like
        Absolute pressures on the two sides of the port, Pa (> 0).
    gas : GasConstants
        Supplies alpha, beta, theta and kappa at the upstream temperature.
    """
    p_up = np.asarray(p_up_Pa, dtype=np.float64)
    p_down = np.asarray(p_down_Pa, dtype=np.float64)
    if np.any(~(p_up > 0)) or np.any(~(p_down > 0)):
        raise ValueError("flow_function: absolute pressures must be finite and > 0 Pa")
    return _flow_ufunc()(p_up, p_down, gas.alpha_s_per_m, gas.beta_s_per_m, gas.theta,
                         gas.heat_capacity_ratio)


def mass_flow(area_m2, p_up_Pa, p_down_Pa, gas: GasConstants):
    """Port mass flow, eq. 1: ``mdot = a f(p_u, p_d)``, kg/s (positive up -> down)."""
    return np.asarray(area_m2, dtype=np.float64) * flow_function(p_up_Pa, p_down_Pa, gas)
