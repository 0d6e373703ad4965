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
def z_terms(p_up, p_down, alpha, beta, theta, kappa, b_crit=0.0, m_sub=0.0):
    """Eq. 3 for ``p_up >= p_down``: ``(z, sqrt_g, dg_dr, r)``.

    ``z`` in kg/(s m^2); ``sqrt_g`` < 0 flags the choked branch. The other terms feed
    :func:`z_slopes` so the power is computed once per evaluation. ``b_crit`` > 0 is a
    port's own critical pressure ratio ``p_d / p_u`` (ISO 6358's ``b``): choked below
    it, and above it eq. 3's subsonic curve laid over ``[b_crit, 1]`` (the ratio mapped
    linearly onto ``[1/theta, 1]``; ``dg_dr`` carries the map's slope), its share of the
    choked flow raised to ``2 m_sub`` (ISO 6358's subsonic index ``m``; 0, the default,
    and 1/2 leave it). At ``b_crit = 1/theta`` it is eq. 3; 0 (the default) is eq. 3.
    ``sqrt_g`` and ``dg_dr`` are then those of the effective ``g``, ``(z / (alpha
    p_up))^2``.
    """
    if b_crit > 0.0:
        if p_down < b_crit * p_up:  # choked at the port's own ratio
            return beta * p_up, -1.0, 0.0, 0.0
        r = p_down / p_up
        b_star = 1.0 / theta
        stretch = (1.0 - b_star) / (1.0 - b_crit)
        rr = b_star + (r - b_crit) * stretch
        if rr > 1.0:
            rr = 1.0
        ik = 1.0 / kappa
        q = math.exp(math.log(rr) * ik)
        g = q * q - rr * q
        sg = math.sqrt(g) if g > 0.0 else 0.0
        dg_dr = ((2.0 * ik) * q * q / rr - (1.0 + ik) * q) * stretch
        if m_sub > 0.0 and m_sub != 0.5 and sg > 0.0:
            # sg_eff = sg* (sg / sg*)^(2m), sg* = beta / alpha (the choked share)
            sg_star = beta / alpha
            sg_eff = sg_star * math.exp(2.0 * m_sub * math.log(sg / sg_star))
            dg_dr = 2.0 * m_sub * dg_dr * (sg_eff / sg) ** 2
            sg = sg_eff
        return alpha * p_up * sg, sg, dg_dr, r
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
def flow_terms(p_up, p_down, alpha, beta, theta, kappa, b_crit=0.0, m_sub=0.0):
    """Signed eq. 2, ``(f, sqrt_g, dg_dr, r, reversed)``: f > 0 from p_up to p_down.

    For reverse flow (p_up < p_down) the roles swap: ``f = -z(p_down, p_up)``.
    ``b_crit``, ``m_sub``: the port's critical pressure ratio and subsonic index
    (:func:`z_terms`; 0 eq. 3's).
    """
    if p_up >= p_down:
        z, sg, dg, r = z_terms(p_up, p_down, alpha, beta, theta, kappa, b_crit, m_sub)
        return z, sg, dg, r, False
    z, sg, dg, r = z_terms(p_down, p_up, alpha, beta, theta, kappa, b_crit, m_sub)
    return -z, sg, dg, r, True


@njit(cache=True)
def flow_slopes(p_up, p_down, sg, dg_dr, r, rev, alpha, beta, kappa, dp_floor):
    """Partials ``(df/dp_up, df/dp_down)`` of the signed flow from :func:`flow_terms`."""
    if not rev:
        return z_slopes(p_up, sg, dg_dr, r, alpha, beta, kappa, dp_floor)
    dz_dhi, dz_dlo = z_slopes(p_down, sg, dg_dr, r, alpha, beta, kappa, dp_floor)
    return -dz_dlo, -dz_dhi


@njit(cache=True)
def flow_partials(p_up, p_down, alpha, beta, theta, kappa, dp_floor, b_crit=0.0,
                  m_sub=0.0):
    """Convenience: ``(f, df/dp_up, df/dp_down)`` in one call (tests, Python callers)."""
    f, sg, dg, r, rev = flow_terms(p_up, p_down, alpha, beta, theta, kappa, b_crit, m_sub)
    du, dd = flow_slopes(p_up, p_down, sg, dg, r, rev, alpha, beta, kappa, dp_floor)
    return f, du, dd


def _flow_scalar(p_up, p_down, alpha, beta, theta, kappa, b_crit, m_sub):
    return flow_terms(p_up, p_down, alpha, beta, theta, kappa, b_crit, m_sub)[0]


@functools.cache
def _flow_ufunc():
    """:func:`_flow_scalar` as a compiled ufunc, built on first use: built at import it
    cost every import of the simulator about 1 s, even from numba's cache."""
    return vectorize(["float64(float64, float64, float64, float64, float64, float64, "
                      "float64, float64)"], cache=True)(_flow_scalar)


def flow_function(p_up_Pa, p_down_Pa, gas: GasConstants, critical_ratio=0.0,
                  subsonic_index=0.0):
    """Signed flow per unit area f(p_u, p_d), kg/(s m^2) (eqs. 2-3), vectorised.

    Parameters
    ----------
    p_up_Pa, p_down_Pa : array_like
        Absolute pressures on the two sides of the port, Pa (> 0).
    gas : GasConstants
        Supplies alpha, beta, theta and kappa at the upstream temperature.
    critical_ratio : array_like, optional
        The port's critical pressure ratio ``p_d / p_u`` (ISO 6358's ``b``, in (0, 1);
        :func:`z_terms`); 0 (the default) is eq. 3's ``1 / theta``.
    subsonic_index : array_like, optional
        ISO 6358's subsonic index ``m`` (> 0) beside a critical ratio; 0 (the default)
        is 1/2, eq. 3's shape.
    """
    p_up = np.asarray(p_up_Pa, dtype=np.float64)
    p_down = np.asarray(p_down_Pa, dtype=np.float64)
    if np.any(~(p_up > 0)) or np.any(~(p_down > 0)):
        raise ValueError("flow_function: absolute pressures must be finite and > 0 Pa")
    b = np.asarray(critical_ratio, dtype=np.float64)
    if np.any(~((b == 0.0) | ((b > 0.0) & (b < 1.0)))):
        raise ValueError("flow_function: critical_ratio must be 0 (eq. 3's) or in (0, 1)")
    m = np.asarray(subsonic_index, dtype=np.float64)
    if np.any(~(m >= 0.0)):
        raise ValueError("flow_function: subsonic_index must be 0 (eq. 3's) or > 0")
    return _flow_ufunc()(p_up, p_down, gas.alpha_s_per_m, gas.beta_s_per_m, gas.theta,
                         gas.heat_capacity_ratio, b, m)


def mass_flow(area_m2, p_up_Pa, p_down_Pa, gas: GasConstants, critical_ratio=0.0,
              subsonic_index=0.0):
    """Port mass flow, eq. 1: ``mdot = a f(p_u, p_d)``, kg/s (positive up -> down);
    ``critical_ratio``, ``subsonic_index`` as in :func:`flow_function`."""
    return np.asarray(area_m2, dtype=np.float64) * flow_function(
        p_up_Pa, p_down_Pa, gas, critical_ratio, subsonic_index)
