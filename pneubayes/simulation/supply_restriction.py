"""A restriction in series upstream of the valve's inlet: the pressure the inlet sees.

A supply hose or a fitting, a regulator near its flow limit, a blower on its fan curve
(effect ``supply_restriction``; slot ``supply_restriction_inverse_area_per_m2``) feeds
the valve's inlet through one more thin port (eqs. 1-3) of area ``A_s``. The small
volume between the two holds no air of its own (quasi-static), so the node's pressure
``n`` balances the restriction against the inlet::

    A_s f(p_s, n) = a_in f(n, x),

``x`` the pressure the valve's ports see (the chamber's). One root in ``n`` between
``x`` and ``p_s`` (the left side falls with ``n``, the right rises). Where the inlet is
much wider than the restriction the flow is the restriction's whatever the valve's
opening (a flow limit upstream); where it is much narrower, the inlet sees the supply.
The exhaust and the leak do not pass it. An inverse area of 0 is no restriction
(``n = p_s``); a shut inlet passes nothing and sees the supply.

:func:`supply_node` solves for ``n`` (Newton's method in ``sqrt|p_s - n|`` kept inside
a bracket, as :func:`pneubayes.simulation.restriction.node_pressure` does);
:func:`supply_slopes` gives the inlet's flow function's slopes in the ports' pressure
and the supply's with ``n`` following them, by the implicit function theorem, for the
exponential method's Jacobian (:func:`pneubayes.simulation.chamber.chamber_rhs`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.simulation.layout import C_ALPHA, C_BETA, C_KAPPA, C_THETA

#: Newton's iterations at most (each bisects where its step leaves the bracket).
NODE_MAX_ITERATIONS = 80
#: The node's drop's square root is solved to this share of its bracket.
NODE_RELATIVE_TOLERANCE = 1e-12
#: The secant floor (Pa) of the inlet's square-root slope inside the Newton steps.
_NEWTON_FLOOR_PA = 1e-6


@njit(cache=True, error_model="numpy")
def _balance(s, sign, p_sup, x, a_in, area, cs):
    """``sign (A_s f(p_s, n) - a_in f(n, x))`` (kg/s) at ``n = p_s - sign s^2`` and its
    slope in ``s`` (rising in ``s``): in ``s`` the restriction's square-root flow near
    ``n = p_s`` is smooth."""
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    n = p_sup - sign * s * s
    f_r, sg, dg, r, rev = flow_terms(p_sup, n, alpha, beta, theta, kappa)
    _, dr_n = flow_slopes(p_sup, n, sg, dg, r, rev, alpha, beta, kappa, 0.0)
    f_i, sg, dg, r, rev = flow_terms(n, x, alpha, beta, theta, kappa)
    di_n, _ = flow_slopes(n, x, sg, dg, r, rev, alpha, beta, kappa, _NEWTON_FLOOR_PA)
    dn_ds = -2.0 * sign * s
    return (sign * (area * f_r - a_in * f_i),
            sign * (area * dr_n - a_in * di_n) * dn_ds)


@njit(cache=True, error_model="numpy")
def supply_node(p_sup, x, a_in, k, cs):
    """The pressure (Pa) between the supply's restriction of inverse area ``k`` (1/m^2)
    and the valve's inlet of area ``a_in`` (m^2), the ports at ``x`` (Pa): ``p_sup``
    where nothing flows or ``k`` is 0.

    Solved in ``s = sqrt(|p_s - n|)`` by Newton's method kept inside a bracket (bisecting
    where it leaves the bracket or does not halve its step before last), from the split
    two incompressible orifices in series would make of the drop."""
    if not (k > 0.0 and a_in > 0.0) or p_sup == x:
        return p_sup
    sign = 1.0 if p_sup > x else -1.0
    area = 1.0 / k
    lo, hi = 0.0, math.sqrt(abs(p_sup - x))  # the balance < 0 at lo, > 0 at hi (in s)
    tol = NODE_RELATIVE_TOLERANCE * hi
    share = a_in * a_in / (a_in * a_in + area * area)  # (the restriction's drop's)
    s = hi * math.sqrt(min(max(share, 1e-6), 1.0 - 1e-6))
    step_old = step = hi - lo
    for _ in range(NODE_MAX_ITERATIONS):
        h, dh = _balance(s, sign, p_sup, x, a_in, area, cs)
        if h < 0.0:
            lo = s
        elif h > 0.0:
            hi = s
        else:
            break
        newton = dh > 0.0 and lo < s - h / dh < hi and abs(2.0 * h) <= abs(step_old * dh)
        step_old = step
        step = h / dh if newton else s - 0.5 * (lo + hi)
        s -= step
        if abs(step) <= tol or hi - lo <= tol:
            break
    return p_sup - sign * s * s


@njit(cache=True, error_model="numpy")
def supply_slopes(p_sup, n, x, a_in, k, dfin_dn, dfin_dx, cs, dp_floor):
    """The inlet's flow function's slopes ``(df_in/dp_s, df_in/dx, share)`` with the node
    ``n`` following the supply and the ports' pressure ``x``, from its partial slopes at
    the node ``dfin_dn = df(n, x)/dn`` and ``dfin_dx = df(n, x)/dx`` (kg/(s m^2 Pa));
    ``share`` is the part of the inlet area's change that reaches its flow (1 without a
    restriction). ``dp_floor`` (Pa) is the secant floor of the square-root slopes."""
    if n == p_sup or not k > 0.0:
        return dfin_dn, dfin_dx, 1.0
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    _, sg, dg, r, rev = flow_terms(p_sup, n, alpha, beta, theta, kappa)
    dr_s, dr_n = flow_slopes(p_sup, n, sg, dg, r, rev, alpha, beta, kappa, dp_floor)
    area = 1.0 / k
    den = area * dr_n - a_in * dfin_dn  # the balance's slope in n (< 0)
    if den == 0.0:
        return dfin_dn, dfin_dx, 1.0
    share = area * dr_n / den
    return -dfin_dn * area * dr_s / den, dfin_dx * share, share


@njit(cache=True, error_model="numpy")
def _supply_nodes(p_sup, x, a_in, k, cs, out):
    for i in range(p_sup.shape[0]):
        out[i] = supply_node(p_sup[i], x[i], a_in[i], k[i], cs)


def supply_nodes(p_sup, x, a_in, k, cs):
    """:func:`supply_node` elementwise over broadcast arrays (Pa; the inputs as there,
    the restriction's one per parameter set of a batch): the pressure the inlet sees
    along a path of states, for the rates along a measured pressure
    (:func:`pneubayes.simulation.rates.rate_terms`)."""
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (
        p_sup, x, a_in, k)))
    flat = [np.ascontiguousarray(a.ravel()) for a in arrays]
    out = np.empty(flat[0].shape[0])
    _supply_nodes(*flat, np.ascontiguousarray(cs, dtype=np.float64), out)
    return out.reshape(arrays[0].shape)
