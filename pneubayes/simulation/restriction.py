"""A restriction in series at the chamber's port: the pressure between it and the valve.

A fitting, a flow-control needle or a check valve between the valve and the chamber
(effect ``port_restriction``; slots ``restriction_fill_inverse_area_per_m2``,
``restriction_vent_inverse_area_per_m2`` and ``restriction_crack_Pa``) passes the
chamber's net flow through one more thin port (eqs. 1-3), of area ``A_f`` for flow into
the chamber and ``A_v`` out of it. The small volume between the two holds no air of its
own (quasi-static), so the node's pressure ``x`` balances the valve's ports against the
restriction::

    a_in f(p_s, x) - a_ex f(x, P_atm) = A f(x, p),    A = A_f if x > p else A_v,

one root in ``x`` (the left side falls with ``x``, the right rises). The valve's ports
then pass their flows at ``x`` and the chamber receives their sum. An inverse area of 0
is no restriction in that direction (``x = p``).

A one-way flow control's check valve has a cracking drop ``c``
(:func:`direction_area`): the wider direction passes only the narrower one's area (the
needle both share) below ``c`` and opens smoothly to its own over ``c``-``2c``; its
area still rises with the drop, so the root stays one.

:func:`node_pressure` solves for ``x`` (Newton's method in ``sqrt|x - p|`` kept inside a
bracket);
:func:`series_slopes` gives the slopes of the node's port flows in the chamber's
pressure and the supply's, by the implicit function theorem, for the exponential
method's Jacobian (:func:`pneubayes.simulation.chamber.chamber_rhs`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.simulation.layout import C_ALPHA, C_BETA, C_KAPPA, C_P_ATM, C_THETA

#: Newton's iterations at most (each bisects where its step leaves the bracket).
NODE_MAX_ITERATIONS = 80
#: The node's drop's square root is solved to this share of its bracket.
NODE_RELATIVE_TOLERANCE = 1e-12
#: The secant floor (Pa) of the square-root slopes inside the node's Newton steps.
_NEWTON_FLOOR_PA = 1e-6
#: The area (m^2) of an unrestricted direction whose check valve cracks (1000 mm^2:
#: open beside any valve's port).
OPEN_AREA_M2 = 1e-3


@njit(cache=True, error_model="numpy")
def restricted(k_own, k_other, crack):
    """Whether a direction with inverse area ``k_own`` (1/m^2; the other direction's
    ``k_other``) is restricted: its own area, or a check valve that cracks at ``crack``
    (Pa) beside the other direction's needle."""
    return k_own > 0.0 or (crack > 0.0 and k_other > 0.0)


@njit(cache=True, error_model="numpy")
def direction_area(drop, k_own, k_other, crack):
    """A restricted direction's area ``A`` (m^2) at the forward drop ``drop`` (Pa) across
    it, and ``dA/d drop`` (m^2/Pa).

    Without a crack (``crack`` 0), or where this direction is not the wider, ``1 /
    k_own``. Where it is the wider (``k_own < k_other``; 0 is open, taken as
    :data:`OPEN_AREA_M2`) a check valve passes it beside the narrower direction's needle:
    ``A = A_n + (A_w - A_n) S(drop / c - 1)``, ``S`` the C1 smoothstep on [0, 1], so the
    check cracks at ``c`` and is fully open at ``2 c``."""
    if crack <= 0.0 or not (k_own < k_other):
        return 1.0 / k_own, 0.0
    a_w = 1.0 / k_own if k_own > 0.0 else OPEN_AREA_M2
    a_n = 1.0 / k_other
    z = drop / crack - 1.0
    if z <= 0.0:
        return a_n, 0.0
    if z >= 1.0:
        return a_w, 0.0
    return (a_n + (a_w - a_n) * z * z * (3.0 - 2.0 * z),
            (a_w - a_n) * 6.0 * z * (1.0 - z) / crack)


@njit(cache=True, error_model="numpy")
def _balance(s, sign, p, p_sup, a_in, a_ex, k_own, k_other, crack, cs):
    """The node's surplus ``a_in f(p_s, x) - a_ex f(x, P_atm) - A f(x, p)`` (kg/s) at
    ``x = p + sign s^2`` and its slope in ``s``: in ``s`` the restriction's square-root
    flow near ``x = p`` is smooth, so Newton's method does not crawl there."""
    area, darea = direction_area(s * s, k_own, k_other, crack)
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    x = p + sign * s * s
    f_in, sg, dg, r, rev = flow_terms(p_sup, x, alpha, beta, theta, kappa)
    _, din = flow_slopes(p_sup, x, sg, dg, r, rev, alpha, beta, kappa, _NEWTON_FLOOR_PA)
    f_ex, sg, dg, r, rev = flow_terms(x, cs[C_P_ATM], alpha, beta, theta, kappa)
    dex, _ = flow_slopes(x, cs[C_P_ATM], sg, dg, r, rev, alpha, beta, kappa,
                         _NEWTON_FLOOR_PA)
    f_r, sg, dg, r, rev = flow_terms(x, p, alpha, beta, theta, kappa)
    dr, _ = flow_slopes(x, p, sg, dg, r, rev, alpha, beta, kappa, 0.0)
    dx_ds = 2.0 * sign * s
    return (a_in * f_in - a_ex * f_ex - area * f_r,
            (a_in * din - a_ex * dex) * dx_ds - area * dr * dx_ds
            - darea * 2.0 * s * f_r)


@njit(cache=True, error_model="numpy")
def node_pressure(p, p_sup, a_in, a_ex, k_fill, k_vent, crack, cs):
    """The pressure between the valve and the restriction (Pa; ``p`` where the flow's
    direction has no restriction or nothing flows). ``k_fill``, ``k_vent``: the
    restriction's inverse areas (1/m^2) into and out of the chamber; ``crack`` (Pa): its
    check valve's cracking drop (:func:`direction_area`).

    Solved in ``s = sqrt(|x - p|)`` by Newton's method kept inside a bracket (bisecting
    where it leaves the bracket or does not halve its step before last), from the split
    two incompressible orifices in series would make of the drop."""
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    p_atm = cs[C_P_ATM]
    h0 = (a_in * flow_terms(p_sup, p, alpha, beta, theta, kappa)[0]
          - a_ex * flow_terms(p, p_atm, alpha, beta, theta, kappa)[0])
    if h0 > 0.0:  # a fill: the node above the chamber, below the highest source
        if not restricted(k_fill, k_vent, crack):
            return p
        sign, k_own, k_other = 1.0, k_fill, k_vent
        far, a_v = max(p_sup, p_atm, p) - p, a_in
    elif h0 < 0.0:
        if not restricted(k_vent, k_fill, crack):
            return p
        sign, k_own, k_other = -1.0, k_vent, k_fill
        far, a_v = p - min(p_sup, p_atm, p), a_ex
    else:
        return p
    area = direction_area(0.0, k_own, k_other, crack)[0]  # (the start's split)
    lo, hi = 0.0, math.sqrt(far)  # sign x the surplus: > 0 at lo, <= 0 at hi (in s)
    tol = NODE_RELATIVE_TOLERANCE * hi
    share = a_v * a_v / (a_v * a_v + area * area) if a_v > 0.0 else 0.5
    s = hi * math.sqrt(min(max(share, 1e-6), 1.0 - 1e-6))
    step_old = step = hi - lo
    for _ in range(NODE_MAX_ITERATIONS):
        h, dh = _balance(s, sign, p, p_sup, a_in, a_ex, k_own, k_other, crack, cs)
        h, dh = sign * h, sign * dh  # (falling in s on both sides)
        if h > 0.0:
            lo = s
        elif h < 0.0:
            hi = s
        else:
            break
        # Newton's step, or a bisection where it would leave the bracket or does not
        # halve the step before last (the valve's ports have square roots of their own,
        # across which Newton's method bounces)
        newton = dh < 0.0 and lo < s - h / dh < hi and abs(2.0 * h) <= abs(step_old * dh)
        step_old = step
        step = h / dh if newton else s - 0.5 * (lo + hi)
        s -= step
        if abs(step) <= tol or hi - lo <= tol:
            break
    return p + sign * s * s


@njit(cache=True, error_model="numpy")
def _node_pressures(p, p_sup, a_in, a_ex, k_fill, k_vent, crack, cs, out):
    for i in range(p.shape[0]):
        out[i] = node_pressure(p[i], p_sup[i], a_in[i], a_ex[i], k_fill[i], k_vent[i],
                               crack[i], cs)


def node_pressures(p, p_sup, a_in, a_ex, k_fill, k_vent, crack, cs):
    """:func:`node_pressure` elementwise over broadcast arrays (Pa; the inputs as there,
    the restriction's too: one per parameter set of a batch): the pressure the valve's
    ports see along a path of states, for the rates along a measured pressure
    (:func:`pneubayes.simulation.rates.rate_terms`)."""
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (
        p, p_sup, a_in, a_ex, k_fill, k_vent, crack)))
    flat = [np.ascontiguousarray(a.ravel()) for a in arrays]
    out = np.empty(flat[0].shape[0])
    _node_pressures(*flat, np.ascontiguousarray(cs, dtype=np.float64), out)
    return out.reshape(arrays[0].shape)


@njit(cache=True, error_model="numpy")
def series_slopes(x, p, a_in, a_ex, k_fill, k_vent, crack, din_s, din_x, dex_x, cs,
                  dp_floor):
    """The node's port flow functions' slopes ``(df_in/dp_s, df_in/dp, df_ex/dp, share)``
    with ``x`` following ``p`` (and ``p_s``: the first is the net flow's slope in the
    supply per unit inlet area, where the plain ports' is the inlet's own), from their
    partial slopes at the node ``din_s = df(p_s, x)/dp_s``, ``din_x = df(p_s, x)/dx``,
    ``dex_x = df(x, P_atm)/dx`` (kg/(s m^2 Pa)); ``share`` is the part of a port area's
    change that reaches the chamber's flow (1 without a restriction).
    ``dp_floor`` (Pa) is the secant floor of the square-root slopes (the chamber's)."""
    k_own, k_other = (k_fill, k_vent) if x > p else (k_vent, k_fill)
    if x == p or not restricted(k_own, k_other, crack):  # the node is the chamber
        return din_s, din_x, dex_x, 1.0
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    f_r, sg, dg, r, rev = flow_terms(x, p, alpha, beta, theta, kappa)
    dr_x, dr_p = flow_slopes(x, p, sg, dg, r, rev, alpha, beta, kappa, dp_floor)
    area, darea = direction_area(abs(x - p), k_own, k_other, crack)
    # A(|x - p|) f(x, p): the area's slope carries |f| (x and p with opposite signs)
    dr_x, dr_p = area * dr_x + darea * abs(f_r), area * dr_p - darea * abs(f_r)
    den = a_in * din_x - a_ex * dex_x - dr_x  # the surplus' slope in x (< 0)
    dx_dp = dr_p / den
    share = -dr_x / den
    # the supply's slope of the net flow a_in f_in - a_ex f_ex, carried on the inlet's
    return din_s * share, din_x * dx_dp, dex_x * dx_dp, share
