"""The chamber's right-hand side and its Jacobian: eqs. 1-5 and 9 with every effect.

Shared by the compiled integrator's pressure step (:mod:`pneubayes.simulation.kernel`)
and its (p, T) step (:mod:`pneubayes.simulation.thermal`).
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import JET_FLOW_REF_KG_PER_S, SLOT_INDEX
from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.simulation.layout import (
    C_ALPHA,
    C_BETA,
    C_BORE_AREA,
    C_KAPPA,
    C_P_ATM,
    C_RS,
    C_T_SUPPLY,
    C_THETA,
)
from pneubayes.simulation.restriction import node_pressure, series_slopes
from pneubayes.simulation.supply_restriction import supply_node, supply_slopes

_VOL = SLOT_INDEX["volume_m3"]
_ATT = SLOT_INDEX["flow_attenuation_Pa"]
_LEAK_O = SLOT_INDEX["leak_orifice_area_m2"]
_LEAK_L = SLOT_INDEX["leak_laminar_kg_per_s_Pa2"]
_LEAK_LG = SLOT_INDEX["leak_laminar_gradient_kg_per_s_Pa2_m"]
_HEAT = SLOT_INDEX["heat_rate_per_s"]
_HCONV = SLOT_INDEX["heat_coefficient_W_per_m2_K"]
_HCOUP = SLOT_INDEX["heat_coupling"]
_HJET = SLOT_INDEX["heat_jet_coefficient_W_per_m2_K"]
_HWOFF = SLOT_INDEX["heat_wall_offset_K"]
_COMPL = SLOT_INDEX["compliance_m3_per_Pa"]
_VT_N = SLOT_INDEX["volume_table_points"]
_VT_P = SLOT_INDEX["volume_table_pressure_Pa_0"]
_VT_V = SLOT_INDEX["volume_table_volume_m3_0"]
_CL_N = SLOT_INDEX["closure_terms"]
_RES_F = SLOT_INDEX["restriction_fill_inverse_area_per_m2"]
_RES_V = SLOT_INDEX["restriction_vent_inverse_area_per_m2"]
_RES_C = SLOT_INDEX["restriction_crack_Pa"]
_SUP_R = SLOT_INDEX["supply_restriction_inverse_area_per_m2"]
_B_IN = SLOT_INDEX["inlet_critical_ratio"]
_B_EX = SLOT_INDEX["exhaust_critical_ratio"]
_M_SUB = SLOT_INDEX["port_subsonic_index"]
_CL_FA = SLOT_INDEX["closure_feature_a_0"]
_CL_FB = SLOT_INDEX["closure_feature_b_0"]
_CL_TA = SLOT_INDEX["closure_threshold_a_0"]
_CL_TB = SLOT_INDEX["closure_threshold_b_0"]
_CL_C = SLOT_INDEX["closure_coefficient_0"]
_CL_RA = SLOT_INDEX["closure_relaxed_a_0"]
_CL_RB = SLOT_INDEX["closure_relaxed_b_0"]
#: The closure's area and volume features' scales (m^2 and m^3 per feature unit; the
#: values of :mod:`pneubayes.effects.closure_features`, which a test checks).
_AREA_SCALE = 1e-6
_VOLUME_SCALE = 1e-6


@njit(cache=True, inline="always", error_model="numpy")
def compliant_volume(p, vol, sl, p_atm):
    """The chamber's volume and compliance at pressure ``p``: ``(V, dV/dp)`` in m^3 and
    m^3/Pa, from ``vol`` (before compliance) plus ``C (p - P_atm)`` (slot
    ``compliance_m3_per_Pa``) plus a tabulated ``dV(p)`` (slots ``volume_table_*``:
    linear between points, the end segments extended, so dV/dp is piecewise constant)."""
    compl = sl[_COMPL]
    if compl > 0.0:
        vol = vol + compl * (p - p_atm)
    n = int(sl[_VT_N])
    if n > 0:
        k = 0
        while k < n - 2 and sl[_VT_P + k + 1] < p:
            k += 1
        slope = ((sl[_VT_V + k + 1] - sl[_VT_V + k])
                 / (sl[_VT_P + k + 1] - sl[_VT_P + k]))
        vol = vol + sl[_VT_V + k] + slope * (p - sl[_VT_P + k])
        compl = compl + slope
    return vol, compl


@njit(cache=True, error_model="numpy")
def table_crossing_factor(p_from, p_to, vol, sl, p_atm, kappa):
    """The jump of dp/dp0 where a step from ``p_from`` to ``p_to`` (Pa) crosses the
    points of a compliant chamber's volume table, at ``vol`` (m^3, before compliance).

    There dV/dp jumps, so eq. 5's rate ``N / (V + n p dV/dp)`` jumps with its numerator
    ``N`` continuous, and a trajectory's sensitivity to its start is scaled by the rates'
    ratio after and before (the saltation of a piecewise-smooth ODE): the product over
    the crossed points ``p_k`` of ``(V + n p_k C_before) / (V + n p_k C_after)``. 1 without
    a table or a crossing."""
    n = int(sl[_VT_N])
    f = 1.0
    if n < 3 or p_from == p_to:
        return f
    lo, hi = min(p_from, p_to), max(p_from, p_to)
    for k in range(1, n - 1):
        pk = sl[_VT_P + k]
        if lo < pk <= hi:
            below = ((sl[_VT_V + k] - sl[_VT_V + k - 1])
                     / (sl[_VT_P + k] - sl[_VT_P + k - 1]))
            above = ((sl[_VT_V + k + 1] - sl[_VT_V + k])
                     / (sl[_VT_P + k + 1] - sl[_VT_P + k]))
            v = vol + sl[_COMPL] * (pk - p_atm) + sl[_VT_V + k]
            c_lo = sl[_COMPL] + below
            c_hi = sl[_COMPL] + above
            if p_to > p_from:
                f *= (v + kappa * pk * c_lo) / (v + kappa * pk * c_hi)
            else:
                f *= (v + kappa * pk * c_hi) / (v + kappa * pk * c_lo)
    return f


@njit(cache=True, inline="always", error_model="numpy")
def crossed_tables(s, rigid, p_from, p_to, vol, sl, p_atm, kappa):
    """A step's dp/dp0 ``s`` after its jumps at the volume table's points
    (:func:`table_crossing_factor`; ``s`` itself for a ``rigid`` chamber)."""
    if rigid:
        return s
    return s * table_crossing_factor(p_from, p_to, vol, sl, p_atm, kappa)


@njit(cache=True, inline="always", error_model="numpy")
def rigid_chamber(sl):
    """Whether the chamber's volume is independent of its pressure (no compliance, no
    volume table): :func:`compliant_volume` returns ``vol`` unchanged."""
    return sl[_COMPL] == 0.0 and sl[_VT_N] == 0.0


@njit(cache=True, inline="always", error_model="numpy")
def wall_exchange(kappa, hconv, bore_a, vol):
    """The convective heat form's wall term per kelvin, ``(kappa - 1) h A_w / V`` (Pa/(s K);
    dp/dt gains it times T_w - T), with ``A_w / V = 2 A / V + pi D / A`` (end caps and
    barrel, D = 2 sqrt(A / pi)), and its slope in the volume, Pa/(s K m^3)."""
    c = kappa - 1.0
    return (c * hconv * (2.0 * bore_a / vol + 2.0 * math.sqrt(math.pi / bore_a)),
            -c * hconv * 2.0 * bore_a / (vol * vol))


@njit(cache=True, error_model="numpy")
def net_port_flow(p, a_in, a_ex, p_sup, cs, sl):
    """The ports' net mass flow into the chamber ``a_in f(p_s, x) - a_ex f(x, P_atm)``
    (kg/s; eqs. 1-3, before the attenuation and the convective form's temperature
    scaling), as a closure's flow features read it: ``x`` the pressure the ports see, a
    restriction's node in series (slots ``sl``) or the chamber's ``p``; the inlet fed
    at a supply restriction's node where there is one. (An acoustic or wave line's first
    cell is not read here: beside a line the features read the ports at the chamber.)"""
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    x = p
    if sl[_RES_F] > 0.0 or sl[_RES_V] > 0.0:
        x = node_pressure(p, p_sup, a_in, a_ex, sl[_RES_F], sl[_RES_V], sl[_RES_C], cs)
    if sl[_SUP_R] > 0.0:
        p_sup = supply_node(p_sup, x, a_in, sl[_SUP_R], cs)
    m_sub = sl[_M_SUB]
    return (a_in * flow_terms(p_sup, x, alpha, beta, theta, kappa, sl[_B_IN], m_sub)[0]
            - a_ex * flow_terms(x, cs[C_P_ATM], alpha, beta, theta, kappa, sl[_B_EX],
                                m_sub)[0])


@njit(cache=True, error_model="numpy")
def closure_feature(code, theta, p, p_atm, p_sup, spool, a_in, a_ex, q_in, q_ex, vol, compl,
                    vdot, dq_in_dp, dq_ex_dp, dsup, dspool, da_in, da_ex, dq_in_dt, dq_ex_dt,
                    cdir, pbar, f_in, f_ex, df_in_dp, df_ex_dp, df_in_dt):
    """One closure feature (:data:`pneubayes.effects.closure_features.FEATURES`, by its
    ``code``) as ``(F, dF/dp, dF/dt)``: its value, its slope in the chamber pressure and
    its explicit time derivative at fixed pressure.

    ``q_in``, ``q_ex`` are the port mass flows ``a f`` (kg/s) before the attenuation and
    the convective form's temperature scaling, ``dq_*_dp`` their slopes in p and
    ``dq_*_dt`` their explicit rates; ``vol`` is the chamber's volume after compliance
    (``compl`` = dV/dp), ``vdot`` the piston's dV/dt (m^3/s), ``dsup``, ``dspool``,
    ``da_in``, ``da_ex`` the rates of the supply, spool and port areas. ``theta`` is a
    hinge's threshold. The volume rate's explicit derivative holds ``vdot`` fixed (the
    position is linear between samples). ``cdir`` is the delayed command's direction
    (+1, -1 or 0), constant between the command's changes; ``pbar`` a low-pass feature's
    low-passed value (a relaxation's pressure, Pa; a flow lag's net flow, kg/s; a command
    lag's spool position, command unit; a dead-time feature's port area change, m^2,
    constant between the command's changes), which the kernel holds over a step at its
    value half-way through (so its explicit time derivative is taken as 0). ``f_in``,
    ``f_ex`` are the ports' flow functions (kg/(s m^2), the flows per unit area),
    ``df_*_dp`` their slopes in p and ``df_in_dt`` the inlet's explicit rate (the
    supply's)."""
    if code == 0:
        return 1.0, 0.0, 0.0
    if code == 1:
        return p / p_atm, 1.0 / p_atm, 0.0
    if code == 2:
        return p_sup / p_atm, 0.0, dsup / p_atm
    if code == 3:
        return spool, 0.0, dspool
    if code == 4:
        return a_in / _AREA_SCALE, 0.0, da_in / _AREA_SCALE
    if code == 5:
        return a_ex / _AREA_SCALE, 0.0, da_ex / _AREA_SCALE
    if code == 6:
        return q_in, dq_in_dp, dq_in_dt
    if code == 7:
        return q_ex, dq_ex_dp, dq_ex_dt
    if code == 8:
        return vol / _VOLUME_SCALE, compl / _VOLUME_SCALE, vdot / _VOLUME_SCALE
    if code == 9:
        r = vdot / vol
        return r, -r * compl / vol, -r * r
    if code == 10:
        z = p / p_atm - theta
        return (z, 1.0 / p_atm, 0.0) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 11:
        z = spool - theta
        return (z, 0.0, dspool) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 12:
        z = theta - spool
        return (z, 0.0, -dspool) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 13:
        return q_in - q_ex, dq_in_dp - dq_ex_dp, dq_in_dt - dq_ex_dt
    if code == 14:
        z = theta - p / p_atm
        return (z, -1.0 / p_atm, 0.0) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 16:
        return (p - pbar) / p_atm, 1.0 / p_atm, 0.0
    if code == 19:
        return pbar - (q_in - q_ex), -(dq_in_dp - dq_ex_dp), -(dq_in_dt - dq_ex_dt)
    if code == 28:
        return pbar - spool, 0.0, -dspool
    if code == 29:  # its one-way parts: the fall not yet followed, the rise
        z = pbar - spool
        return (z, 0.0, -dspool) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 30:
        z = spool - pbar
        return (z, 0.0, dspool) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 17:
        z = vol / _VOLUME_SCALE - theta
        return ((z, compl / _VOLUME_SCALE, vdot / _VOLUME_SCALE) if z > 0.0
                else (0.0, 0.0, 0.0))
    if code == 20 or code == 21:  # |p_s - p| / P_atm and its hinge
        sg = 1.0 if p_sup >= p else -1.0
        drop = sg * (p_sup - p) / p_atm
        if code == 20:
            return drop, -sg / p_atm, sg * dsup / p_atm
        z = theta - drop
        return (z, sg / p_atm, -sg * dsup / p_atm) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 22:
        return f_in * _AREA_SCALE, df_in_dp * _AREA_SCALE, df_in_dt * _AREA_SCALE
    if code == 23:
        return f_ex * _AREA_SCALE, df_ex_dp * _AREA_SCALE, 0.0
    if code == 25:
        return ((f_in - f_ex) * _AREA_SCALE, (df_in_dp - df_ex_dp) * _AREA_SCALE,
                df_in_dt * _AREA_SCALE)
    if code == 24:  # max(0, theta - |s|)
        sg = 1.0 if spool >= 0.0 else -1.0
        z = theta - sg * spool
        return (z, 0.0, -sg * dspool) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 26:  # max(0, a_in / 1 mm^2 - theta)
        z = a_in / _AREA_SCALE - theta
        return (z, 0.0, da_in / _AREA_SCALE) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 27:
        z = a_ex / _AREA_SCALE - theta
        return (z, 0.0, da_ex / _AREA_SCALE) if z > 0.0 else (0.0, 0.0, 0.0)
    if code == 18:
        z = theta - vol / _VOLUME_SCALE
        return ((z, -compl / _VOLUME_SCALE, -vdot / _VOLUME_SCALE) if z > 0.0
                else (0.0, 0.0, 0.0))
    if code == 35:  # |dV/dt| (the piston's: vdot held over the step)
        return abs(vdot) / _VOLUME_SCALE, 0.0, 0.0
    if 31 <= code <= 34:  # a late valve's area change (m^2; the kernel's, per command stretch)
        return pbar / _AREA_SCALE, 0.0, 0.0
    return cdir, 0.0, 0.0


@njit(cache=True, error_model="numpy")
def closure_flow(sl, p, p_atm, p_sup, spool, a_in, a_ex, f_in, f_ex, vol, compl, vdot,
                 df_in_dp, df_ex_dp, dsup, dspool, da_in, da_ex, df_in_dt, cdir):
    """The closure's mass flow into the chamber, ``sum_k c_k F_a F_b`` (kg/s; slots
    ``closure_*``), with its slope in p (kg/(s Pa)) and its explicit time derivative
    (kg/s^2), then the part of it that leaves at the chamber's temperature (kg/s, an
    outflow positive) with its two slopes; the arguments as :func:`closure_feature`
    takes them, the port flows ``q = a f`` formed here from the areas and the flow
    functions.

    A term that reads a port's flow (``inlet_flow``, ``exhaust_flow``, ``net_flow``; its
    first such feature) modulates that port: the port's terms add to ``q s`` and the
    factor ``s`` is clipped so the port's flow never reverses
    (:data:`pneubayes.effects.closure_terms.PORT_FACTOR_LIMITS`). Such a term carries
    its port's enthalpy: ``q s`` is more or less of an inflow (at the supply's
    temperature) or of an outflow (at the chamber's), whatever its sign; ``net_flow``'s
    factor scales both parts. Any other term's flow leaves at the chamber's temperature
    when negative."""
    q_in, q_ex = a_in * f_in, a_ex * f_ex
    dq_in_dp, dq_ex_dp = a_in * df_in_dp, a_ex * df_ex_dp
    dq_in_dt, dq_ex_dt = a_in * df_in_dt + f_in * da_in, f_ex * da_ex
    m, dm_dp, dm_dt = 0.0, 0.0, 0.0
    # each modulated port's factor s with its slopes in p and t, and its flow q likewise
    s_i, si_p, si_t, q_i, qi_p, qi_t = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    s_e, se_p, se_t, q_e, qe_p, qe_t = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    s_n, sn_p, sn_t, q_n, qn_p, qn_t = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for k in range(int(sl[_CL_N])):
        c = sl[_CL_C + k]
        ca, cb = int(sl[_CL_FA + k]), int(sl[_CL_FB + k])
        fa, da_p, da_t = closure_feature(ca, sl[_CL_TA + k], p, p_atm,
                                         p_sup, spool, a_in, a_ex, q_in, q_ex, vol, compl,
                                         vdot, dq_in_dp, dq_ex_dp, dsup, dspool, da_in,
                                         da_ex, dq_in_dt, dq_ex_dt, cdir, sl[_CL_RA + k],
                                         f_in, f_ex, df_in_dp, df_ex_dp, df_in_dt)
        fb, db_p, db_t = closure_feature(cb, sl[_CL_TB + k], p, p_atm,
                                         p_sup, spool, a_in, a_ex, q_in, q_ex, vol, compl,
                                         vdot, dq_in_dp, dq_ex_dp, dsup, dspool, da_in,
                                         da_ex, dq_in_dt, dq_ex_dt, cdir, sl[_CL_RB + k],
                                         f_in, f_ex, df_in_dp, df_ex_dp, df_in_dt)
        if not _is_port_flow(ca) and _is_port_flow(cb):  # the port flow first
            ca, fa, da_p, da_t, fb, db_p, db_t = cb, fb, db_p, db_t, fa, da_p, da_t
        if ca == 6:
            s_i, si_p, si_t = s_i + c * fb, si_p + c * db_p, si_t + c * db_t
            q_i, qi_p, qi_t = fa, da_p, da_t
        elif ca == 7:
            s_e, se_p, se_t = s_e + c * fb, se_p + c * db_p, se_t + c * db_t
            q_e, qe_p, qe_t = fa, da_p, da_t
        elif ca == 13:
            s_n, sn_p, sn_t = s_n + c * fb, sn_p + c * db_p, sn_t + c * db_t
            q_n, qn_p, qn_t = fa, da_p, da_t
        else:
            m += c * (fa * fb)
            dm_dp += c * (da_p * fb + fa * db_p)
            dm_dt += c * (da_t * fb + fa * db_t)
    # the inlet's and the net flow q (1 + s) never reverse (s >= -1), nor the exhaust's
    # outflow -q (1 - s) (s <= 1); a clipped factor is constant
    if s_i < -1.0:
        s_i, si_p, si_t = -1.0, 0.0, 0.0
    if s_e > 1.0:
        s_e, se_p, se_t = 1.0, 0.0, 0.0
    if s_n < -1.0:
        s_n, sn_p, sn_t = -1.0, 0.0, 0.0
    # the outflow at the chamber's temperature: the free terms' when they take air out,
    # a reversed inlet's or an exhaust's change, the net flow's share of the outflows
    o, o_p, o_t = 0.0, 0.0, 0.0
    if m < 0.0:
        o, o_p, o_t = -m, -dm_dp, -dm_dt
    if q_i < 0.0:
        o, o_p, o_t = (o - q_i * s_i, o_p - qi_p * s_i - q_i * si_p,
                       o_t - qi_t * s_i - q_i * si_t)
    if q_e > 0.0:
        o, o_p, o_t = (o - q_e * s_e, o_p - qe_p * s_e - q_e * se_p,
                       o_t - qe_t * s_e - q_e * se_t)
    if s_n != 0.0:
        ov, ov_p, ov_t = 0.0, 0.0, 0.0
        if q_ex > 0.0:
            ov, ov_p, ov_t = q_ex, dq_ex_dp, dq_ex_dt
        if q_in < 0.0:
            ov, ov_p, ov_t = ov - q_in, ov_p - dq_in_dp, ov_t - dq_in_dt
        o, o_p, o_t = o + s_n * ov, o_p + sn_p * ov + s_n * ov_p, o_t + sn_t * ov + s_n * ov_t
    m += q_i * s_i + q_e * s_e + q_n * s_n
    dm_dp += qi_p * s_i + q_i * si_p + qe_p * s_e + q_e * se_p + qn_p * s_n + q_n * sn_p
    dm_dt += qi_t * s_i + q_i * si_t + qe_t * s_e + q_e * se_t + qn_t * s_n + q_n * sn_t
    return m, dm_dp, dm_dt, o, o_p, o_t


@njit(cache=True, inline="always")
def _is_port_flow(code):
    """Whether feature ``code`` is a port's flow: ``inlet_flow`` (6), ``exhaust_flow``
    (7) or ``net_flow`` (13)."""
    return code == 6 or code == 7 or code == 13


@njit(cache=True, error_model="numpy")
def _chamber_rhs_closure(p, temp, a_in, a_ex, vol, vdot, p_sup, sl, cs, h, need_j, dsup, da_in,
                         da_ex, spool, dspool, cdir):
    """:func:`chamber_rhs` with an open-form closure (slot ``closure_terms`` > 0): the
    same body plus the closure's terms, written apart so that the plain model's code is
    unchanged (inside one body the closure's live values slowed the plain model's steps
    by about 4 %). ``tests/test_closure.py`` checks that the two bodies agree."""
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    p_atm = cs[C_P_ATM]
    x = p  # the valve's ports' pressure: a restriction's node in series, or the chamber
    if sl[_RES_F] > 0.0 or sl[_RES_V] > 0.0:
        x = node_pressure(p, p_sup, a_in, a_ex, sl[_RES_F], sl[_RES_V], sl[_RES_C], cs)
    p_in = p_sup  # the inlet's upstream pressure: a supply restriction's node, or p_s
    if sl[_SUP_R] > 0.0:
        p_in = supply_node(p_sup, x, a_in, sl[_SUP_R], cs)
    b_in, b_ex, m_sub = sl[_B_IN], sl[_B_EX], sl[_M_SUB]  # (the ports' laws; 0 eq. 3's)
    f_in, sg_i, dg_i, r_i, rev_i = flow_terms(p_in, x, alpha, beta, theta, kappa, b_in, m_sub)
    f_ex, sg_e, dg_e, r_e, rev_e = flow_terms(x, p_atm, alpha, beta, theta, kappa, b_ex, m_sub)
    # the leak's: the chamber's own flow function to the atmosphere (eq. 3's ratio)
    f_lk, sg_l, dg_l, r_l, rev_l = f_ex, sg_e, dg_e, r_e, rev_e
    if x != p or b_ex > 0.0:
        f_lk, sg_l, dg_l, r_l, rev_l = flow_terms(p, p_atm, alpha, beta, theta, kappa)
    f_in0, f_ex0 = f_in, f_ex  # (before the convective scaling: the closure's features)
    t_wall = cs[C_T_SUPPLY]
    # The temperature is a state where the pressure feels it (a coupling c > 0); the
    # pressure equation reads te = T_w + c (T - T_w) for T (eq. 5 at c = 0)
    coup = sl[_HCOUP]
    thermal = coup > 0.0
    te = t_wall + coup * (temp - t_wall) if thermal else t_wall
    # the wall's temperature as the heat terms read it: the coupling's share of its
    # offset above the supply's, T_w + c dT_w (eq. 5 at c = 0)
    t_hot = t_wall + coup * sl[_HWOFF] if thermal else t_wall
    hconv = sl[_HCONV] if thermal else 0.0
    hjet = sl[_HJET] if thermal else 0.0
    conv = hconv > 0.0 or hjet > 0.0
    heat = sl[_HEAT] if thermal else 0.0
    # convective form: orifice flows leaving the chamber at T scale by sqrt(T_w / T)
    sq_in, sq_ex, sq_lk = 1.0, 1.0, 1.0
    if conv:
        sq = math.sqrt(t_wall / te)
        if f_in < 0.0:
            sq_in = sq
        if f_ex > 0.0:
            sq_ex = sq
        if f_lk > 0.0:
            sq_lk = sq
        f_in *= sq_in
        f_ex *= sq_ex
        f_lk *= sq_lk
    valve = a_in * f_in - a_ex * f_ex
    att = sl[_ATT]
    phi = math.exp(-att / p) if att > 0.0 else 1.0
    leak_o, leak_g = sl[_LEAK_O], sl[_LEAK_LG]
    # laminar k at the piston's position x = (V - V_0) / A (never negative)
    leak_l = sl[_LEAK_L]
    if leak_g != 0.0:
        leak_l += leak_g * (vol - sl[_VOL]) / cs[C_BORE_AREA]
    if leak_l < 0.0:
        leak_l, leak_g = 0.0, 0.0
    lam = p * p - p_atm * p_atm
    mdot = phi * valve - leak_o * f_lk - leak_l * lam
    rs = cs[C_RS]
    rs_t = rs * t_wall
    # a compliant chamber, V = vol + C (p - P_atm): eq. 5 with dV/dt = vdot + C dp/dt
    # gives dp/dt = n (Rs T mdot - p vdot) / (V + n p C)
    vol, compl = compliant_volume(p, vol, sl, p_atm)
    closure = sl[_CL_N] > 0.0
    m_cl, o_cl = 0.0, 0.0
    if closure:
        m_cl, _, _, o_cl, _, _ = closure_flow(sl, p, p_atm, p_sup, spool, a_in, a_ex, f_in0,
                                              f_ex0, vol, compl, vdot, 0.0, 0.0, 0.0, 0.0,
                                              0.0, 0.0, 0.0, cdir)
        mdot += m_cl
    denom = vol + kappa * p * compl
    inv_denom = 1.0 / denom
    n_over_v = kappa * inv_denom
    # With a temperature state, air leaving the chamber carries the chamber's enthalpy
    # (te), air entering the supply's (T_w): Rs (T_w m_in - te m_out) = Rs T_w mdot +
    # Rs (T_w - te) m_out. Without it te = T_w and this is eq. 5.
    m_out = 0.0
    leak_out = leak_o * f_lk + leak_l * lam
    if thermal:
        m_out = (phi * (a_ex * max(f_ex, 0.0) + a_in * max(-f_in, 0.0))
                 + max(leak_out, 0.0))
        m_out += o_cl  # (the closure's part at the chamber's temperature)
    fp_eq5 = n_over_v * (rs_t * mdot + rs * (t_wall - te) * m_out - p * vdot)
    fp = fp_eq5
    ft = 0.0
    # wall heat flow (kappa - 1) Q / V of the convective form: Q = h A_w (T_w - T)
    c_wall, dc_wall_dv = 0.0, 0.0
    stir = 0.0  # the inflow that stirs the gas (the forced form's coefficient), kg/s
    if conv:
        if hjet > 0.0 and f_in > 0.0:
            stir = phi * a_in * f_in
        c_wall, dc_wall_dv = wall_exchange(kappa, hconv + hjet * stir / JET_FLOW_REF_KG_PER_S,
                                           cs[C_BORE_AREA], vol)
        fp += c_wall * (t_hot - te)
    if heat > 0.0:
        fp += p * heat * (t_hot - te) / te
    if thermal:
        ft = temp * (fp / p + vdot / vol - rs * temp * mdot / (p * vol))
    if not need_j:
        return fp, 0.0, ft, 0.0, 0.0, 0.0, 0.0, 0.0
    dfloor = abs(fp) * h
    dfin_dsup, dfin_dp = flow_slopes(p_in, x, sg_i, dg_i, r_i, rev_i, alpha, beta, kappa,
                                     dfloor)
    share_in = 1.0  # (the inlet's through a supply restriction's node)
    if p_in != p_sup:
        dfin_dsup, dfin_dp, share_in = supply_slopes(p_sup, p_in, x, a_in, sl[_SUP_R],
                                                     dfin_dsup, dfin_dp, cs, dfloor)
    dfex_dp, _ = flow_slopes(x, p_atm, sg_e, dg_e, r_e, rev_e, alpha, beta, kappa, dfloor)
    dflk_dp = dfex_dp  # (the leak's: the chamber's own)
    share = 1.0  # the part of a port area's change that reaches the chamber's flow
    if x != p:  # the ports' slopes through the node
        dfin_dsup, dfin_dp, dfex_dp, share = series_slopes(
            x, p, a_in, a_ex, sl[_RES_F], sl[_RES_V], sl[_RES_C], dfin_dsup, dfin_dp,
            dfex_dp, cs, dfloor)
    if x != p or b_ex > 0.0:  # the leak's at the chamber, by eq. 3
        dflk_dp = flow_slopes(p, p_atm, sg_l, dg_l, r_l, rev_l, alpha, beta, kappa,
                              dfloor)[0]
    dcl_dp, dcl_dt, dcl_out_dp, dcl_out_dt = 0.0, 0.0, 0.0, 0.0
    if closure:  # (the port flows' slopes before the convective scaling)
        _, dcl_dp, dcl_dt, _, dcl_out_dp, dcl_out_dt = closure_flow(
            sl, p, p_atm, p_sup, spool, a_in, a_ex, f_in0, f_ex0, vol, compl, vdot,
            dfin_dp, dfex_dp, dsup, dspool, da_in, da_ex, dfin_dsup * dsup, cdir)
    dfin_dp *= sq_in
    dfin_dsup *= sq_in
    dfex_dp *= sq_ex
    dflk_dp *= sq_lk
    dvalve = a_in * dfin_dp - a_ex * dfex_dp
    dmdot = phi * dvalve - leak_o * dflk_dp - 2.0 * leak_l * p
    if att > 0.0:
        dmdot += phi * att / (p * p) * valve
    if closure:
        dmdot += dcl_dp
    jp = n_over_v * (rs_t * dmdot - vdot)
    if compl > 0.0:  # d(denominator)/dp = C (1 + n)
        jp -= fp_eq5 * compl * (1.0 + kappa) / denom
    if heat > 0.0:
        jp += heat * (t_hot - te) / te
    # explicit time dependence: d(eq. 5)/dV * dV/dt + inputs moving the flows
    dmdot_dt = phi * (a_in * dfin_dsup * dsup
                      + share * (share_in * f_in * da_in - f_ex * da_ex))
    if leak_g != 0.0:
        dmdot_dt -= leak_g * vdot / cs[C_BORE_AREA] * lam
    if closure:
        dmdot_dt += dcl_dt
    vp = n_over_v * rs_t * dmdot_dt - fp_eq5 * inv_denom * vdot
    if conv:
        vp += dc_wall_dv * vdot * (t_hot - te)
    if stir > 0.0:  # the forced form's coefficient follows the inflow in p and t
        g_jet = (hjet / JET_FLOW_REF_KG_PER_S * (t_hot - te)
                 * wall_exchange(kappa, 1.0, cs[C_BORE_AREA], vol)[0])
        jp += g_jet * phi * a_in * (dfin_dp + att / (p * p) * f_in)
        vp += g_jet * phi * (a_in * dfin_dsup * dsup + share * share_in * f_in * da_in)
    if not thermal:
        return fp, jp, ft, 0.0, vp, 0.0, 0.0, 0.0
    # The temperature's entries (the full 2 x 2 Jacobian keeps the method's order).
    # Outflow m_out (air leaving at T) and its slopes in p, T and t:
    dmout_dp = phi * att / (p * p) * (a_ex * max(f_ex, 0.0) + a_in * max(-f_in, 0.0))
    dmout_dt = 0.0
    if f_ex > 0.0:
        dmout_dp += phi * a_ex * dfex_dp
        dmout_dt += phi * share * f_ex * da_ex
    if f_in < 0.0:
        dmout_dp -= phi * a_in * dfin_dp
        dmout_dt -= phi * (share * share_in * f_in * da_in + a_in * dfin_dsup * dsup)
    if leak_out > 0.0:
        dmout_dp += leak_o * dflk_dp + 2.0 * leak_l * p
        dmout_dt += leak_g * vdot / cs[C_BORE_AREA] * lam
    dmout_dp += dcl_out_dp
    dmout_dt += dcl_out_dt
    # the convective form's outflows scale by sqrt(T_w / te): d/dT = -c / (2 te) of each
    dmdot_dT, dmout_dT = 0.0, 0.0
    if conv:
        half = -0.5 * coup / te
        if f_in < 0.0:
            dmdot_dT += phi * a_in * f_in * half
            dmout_dT -= phi * a_in * f_in * half
        if f_ex > 0.0:
            dmdot_dT -= phi * a_ex * f_ex * half
            dmout_dT += phi * a_ex * f_ex * half
        if f_lk > 0.0:
            dmdot_dT -= leak_o * f_lk * half
            dmout_dT += leak_o * f_lk * half
    jp += n_over_v * rs * (t_wall - te) * dmout_dp
    vp += n_over_v * rs * (t_wall - te) * dmout_dt
    jpt = (n_over_v * (rs_t * dmdot_dT - coup * rs * m_out + rs * (t_wall - te) * dmout_dT)
           - coup * c_wall)
    if heat > 0.0:
        jpt -= coup * p * heat * t_hot / (te * te)
    # ft = T (fp / p + vdot / V - Rs T mdot / (p V))
    g = rs * temp / (p * vol)
    jtp = temp * (jp / p - fp / (p * p) - g * dmdot + g * mdot / p)
    jt = ft / temp + temp * (jpt / p - rs * mdot / (p * vol) - g * dmdot_dT)
    vt = temp * (vp / p - (vdot / vol) ** 2 - g * dmdot_dt + g * mdot * vdot / vol)
    return fp, jp, ft, jt, vp, jpt, jtp, vt


@njit(cache=True, error_model="numpy")
def chamber_rhs(p, temp, a_in, a_ex, vol, vdot, p_sup, sl, cs, h, need_j, dsup, da_in, da_ex,
                spool, dspool, cdir, with_closure):
    """Chamber right-hand side: ``(dp/dt, J_pp, dT/dt, J_TT, v_p, J_pT, J_Tp, v_T)``.

    ``v_p`` and ``v_T`` are the explicit time derivatives of dp/dt and dT/dt at fixed
    state, from the volume changing at ``vdot``, the supply ramping at ``dsup`` Pa/s and
    the port areas moving at ``da_in``, ``da_ex`` m^2/s (the non-autonomous terms of the
    exponential method). ``J_xy`` is d(dx/dt)/dy (the temperature's and ``v_T``: 0 without
    a temperature state).

    Eqs. 1-5 and 9, plus the laminar leak, tube attenuation and wall heat exchange (a
    rate, or a convective coefficient on the wall area with orifice outflows at the
    chamber's temperature, felt at the share ``heat_coupling``, toward a wall at T_s +
    ``heat_wall_offset_K``; :mod:`pneubayes.effects.heat_transfer`). A restriction in
    series at the port (:mod:`pneubayes.simulation.restriction`; the general kernel
    only) has the valve's ports pass their flows at its node's pressure; with heat
    transfer the node's exhaust flow is taken as the chamber's outflow (exact unless
    both ports pass at once). ``J_p`` approximates d(dp/dt)/dp: exact except that the
    square-root singularity of a port at pressure balance is replaced by the secant over
    the step's expected movement ``|dp/dt| h``, so a chamber starting exactly at a
    port's pressure is not frozen by an infinite slope (a W-method Jacobian; the error
    control checks it). Jacobians are only computed when ``need_j``.

    An open-form closure (slot ``closure_terms`` > 0; :func:`closure_flow`) adds its mass
    flow to the chamber's, each part at its enthalpy (a port's term at its port's, any
    other inflow at the supply's, outflow at the chamber's). Its features read the port
    flows ``a f`` before the attenuation and the convective form's sqrt(T_w / T) (so not
    on T), the volume after compliance, and ``spool`` (the command after the
    delay and the spool's lag, before the dead band; moving at ``dspool`` per second,
    which enters ``v_p``) and ``cdir`` (the delayed command's direction, +1, -1 or 0,
    constant between its changes). With ``closure_terms`` 0 none of it is evaluated: the
    closure is stepped by a copy of this body, :func:`_chamber_rhs_closure`. With
    ``with_closure`` None it is not compiled either (the pressure-only kernel's
    specialization: a closure runs in the general one, :func:`~.kernel.needs_general`);
    the general kernel passes True (one compiled specialization: a caller passing
    another type compiles another, tens of seconds).

    Compiled as a function of its own, not inlined at numba's IR level into its callers:
    inlined at the pressure-only step's two call sites it made the kernel's cold compile
    about 1.6 x longer (numba's type inference and SSA over the copies) for 0-5 % of the
    step's speed.
    """
    if with_closure is not None:
        if sl[_CL_N] > 0.0:
            return _chamber_rhs_closure(p, temp, a_in, a_ex, vol, vdot, p_sup, sl, cs, h,
                                        need_j, dsup, da_in, da_ex, spool, dspool, cdir)
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    p_atm = cs[C_P_ATM]
    x = p  # the valve's ports' pressure: a restriction's node in series, or the chamber
    p_in = p_sup  # the inlet's upstream pressure: a supply restriction's node, or p_s
    if with_closure is not None:
        if sl[_RES_F] > 0.0 or sl[_RES_V] > 0.0:
            x = node_pressure(p, p_sup, a_in, a_ex, sl[_RES_F], sl[_RES_V], sl[_RES_C], cs)
        if sl[_SUP_R] > 0.0:
            p_in = supply_node(p_sup, x, a_in, sl[_SUP_R], cs)
    b_in, b_ex, m_sub = sl[_B_IN], sl[_B_EX], sl[_M_SUB]  # (the ports' laws; 0 eq. 3's)
    f_in, sg_i, dg_i, r_i, rev_i = flow_terms(p_in, x, alpha, beta, theta, kappa, b_in, m_sub)
    f_ex, sg_e, dg_e, r_e, rev_e = flow_terms(x, p_atm, alpha, beta, theta, kappa, b_ex, m_sub)
    # the leak's: the chamber's own flow function to the atmosphere (eq. 3's ratio)
    f_lk, sg_l, dg_l, r_l, rev_l = f_ex, sg_e, dg_e, r_e, rev_e
    if x != p or b_ex > 0.0:
        f_lk, sg_l, dg_l, r_l, rev_l = flow_terms(p, p_atm, alpha, beta, theta, kappa)
    t_wall = cs[C_T_SUPPLY]
    # The temperature is a state where the pressure feels it (a coupling c > 0); the
    # pressure equation reads te = T_w + c (T - T_w) for T (eq. 5 at c = 0)
    coup = sl[_HCOUP]
    thermal = coup > 0.0
    te = t_wall + coup * (temp - t_wall) if thermal else t_wall
    # the wall's temperature as the heat terms read it: the coupling's share of its
    # offset above the supply's, T_w + c dT_w (eq. 5 at c = 0)
    t_hot = t_wall + coup * sl[_HWOFF] if thermal else t_wall
    hconv = sl[_HCONV] if thermal else 0.0
    hjet = 0.0
    if with_closure is not None:
        hjet = sl[_HJET] if thermal else 0.0
    conv = hconv > 0.0 or hjet > 0.0
    heat = sl[_HEAT] if thermal else 0.0
    # convective form: orifice flows leaving the chamber at T scale by sqrt(T_w / T)
    sq_in, sq_ex, sq_lk = 1.0, 1.0, 1.0
    if conv:
        sq = math.sqrt(t_wall / te)
        if f_in < 0.0:
            sq_in = sq
        if f_ex > 0.0:
            sq_ex = sq
        if f_lk > 0.0:
            sq_lk = sq
        f_in *= sq_in
        f_ex *= sq_ex
        f_lk *= sq_lk
    valve = a_in * f_in - a_ex * f_ex
    att = sl[_ATT]
    phi = math.exp(-att / p) if att > 0.0 else 1.0
    leak_o, leak_g = sl[_LEAK_O], sl[_LEAK_LG]
    # laminar k at the piston's position x = (V - V_0) / A (never negative)
    leak_l = sl[_LEAK_L]
    if leak_g != 0.0:
        leak_l += leak_g * (vol - sl[_VOL]) / cs[C_BORE_AREA]
    if leak_l < 0.0:
        leak_l, leak_g = 0.0, 0.0
    lam = p * p - p_atm * p_atm
    mdot = phi * valve - leak_o * f_lk - leak_l * lam
    rs = cs[C_RS]
    rs_t = rs * t_wall
    # a compliant chamber, V = vol + C (p - P_atm): eq. 5 with dV/dt = vdot + C dp/dt
    # gives dp/dt = n (Rs T mdot - p vdot) / (V + n p C)
    vol, compl = compliant_volume(p, vol, sl, p_atm)
    denom = vol + kappa * p * compl
    inv_denom = 1.0 / denom
    n_over_v = kappa * inv_denom
    # With a temperature state, air leaving the chamber carries the chamber's enthalpy
    # (te), air entering the supply's (T_w): Rs (T_w m_in - te m_out) = Rs T_w mdot +
    # Rs (T_w - te) m_out. Without it te = T_w and this is eq. 5.
    m_out = 0.0
    leak_out = leak_o * f_lk + leak_l * lam
    if thermal:
        m_out = (phi * (a_ex * max(f_ex, 0.0) + a_in * max(-f_in, 0.0))
                 + max(leak_out, 0.0))
    fp_eq5 = n_over_v * (rs_t * mdot + rs * (t_wall - te) * m_out - p * vdot)
    fp = fp_eq5
    ft = 0.0
    # wall heat flow (kappa - 1) Q / V of the convective form: Q = h A_w (T_w - T)
    c_wall, dc_wall_dv = 0.0, 0.0
    stir = 0.0  # the inflow that stirs the gas (the forced form's coefficient), kg/s
    if conv:
        if hjet > 0.0 and f_in > 0.0:
            stir = phi * a_in * f_in
        c_wall, dc_wall_dv = wall_exchange(kappa, hconv + hjet * stir / JET_FLOW_REF_KG_PER_S,
                                           cs[C_BORE_AREA], vol)
        fp += c_wall * (t_hot - te)
    if heat > 0.0:
        fp += p * heat * (t_hot - te) / te
    if thermal:
        ft = temp * (fp / p + vdot / vol - rs * temp * mdot / (p * vol))
    if not need_j:
        return fp, 0.0, ft, 0.0, 0.0, 0.0, 0.0, 0.0
    dfloor = abs(fp) * h
    dfin_dsup, dfin_dp = flow_slopes(p_in, x, sg_i, dg_i, r_i, rev_i, alpha, beta, kappa,
                                     dfloor)
    dfex_dp, _ = flow_slopes(x, p_atm, sg_e, dg_e, r_e, rev_e, alpha, beta, kappa, dfloor)
    dflk_dp = dfex_dp  # (the leak's: the chamber's own)
    share = 1.0  # the part of a port area's change that reaches the chamber's flow
    share_in = 1.0  # (the inlet's through a supply restriction's node)
    if with_closure is not None:
        if p_in != p_sup:
            dfin_dsup, dfin_dp, share_in = supply_slopes(p_sup, p_in, x, a_in, sl[_SUP_R],
                                                         dfin_dsup, dfin_dp, cs, dfloor)
        if x != p:  # the ports' slopes through the node
            dfin_dsup, dfin_dp, dfex_dp, share = series_slopes(
                x, p, a_in, a_ex, sl[_RES_F], sl[_RES_V], sl[_RES_C], dfin_dsup, dfin_dp,
                dfex_dp, cs, dfloor)
    if x != p or b_ex > 0.0:  # the leak's at the chamber, by eq. 3
        dflk_dp = flow_slopes(p, p_atm, sg_l, dg_l, r_l, rev_l, alpha, beta, kappa,
                              dfloor)[0]
    dfin_dp *= sq_in
    dfin_dsup *= sq_in
    dfex_dp *= sq_ex
    dflk_dp *= sq_lk
    dvalve = a_in * dfin_dp - a_ex * dfex_dp
    dmdot = phi * dvalve - leak_o * dflk_dp - 2.0 * leak_l * p
    if att > 0.0:
        dmdot += phi * att / (p * p) * valve
    jp = n_over_v * (rs_t * dmdot - vdot)
    if compl > 0.0:  # d(denominator)/dp = C (1 + n)
        jp -= fp_eq5 * compl * (1.0 + kappa) / denom
    if heat > 0.0:
        jp += heat * (t_hot - te) / te
    # explicit time dependence: d(eq. 5)/dV * dV/dt + inputs moving the flows
    dmdot_dt = phi * (a_in * dfin_dsup * dsup
                      + share * (share_in * f_in * da_in - f_ex * da_ex))
    if leak_g != 0.0:
        dmdot_dt -= leak_g * vdot / cs[C_BORE_AREA] * lam
    vp = n_over_v * rs_t * dmdot_dt - fp_eq5 * inv_denom * vdot
    if conv:
        vp += dc_wall_dv * vdot * (t_hot - te)
    if stir > 0.0:  # the forced form's coefficient follows the inflow in p and t
        g_jet = (hjet / JET_FLOW_REF_KG_PER_S * (t_hot - te)
                 * wall_exchange(kappa, 1.0, cs[C_BORE_AREA], vol)[0])
        jp += g_jet * phi * a_in * (dfin_dp + att / (p * p) * f_in)
        vp += g_jet * phi * (a_in * dfin_dsup * dsup + share * share_in * f_in * da_in)
    if not thermal:
        return fp, jp, ft, 0.0, vp, 0.0, 0.0, 0.0
    # The temperature's entries (the full 2 x 2 Jacobian keeps the method's order).
    # Outflow m_out (air leaving at T) and its slopes in p, T and t:
    dmout_dp = phi * att / (p * p) * (a_ex * max(f_ex, 0.0) + a_in * max(-f_in, 0.0))
    dmout_dt = 0.0
    if f_ex > 0.0:
        dmout_dp += phi * a_ex * dfex_dp
        dmout_dt += phi * share * f_ex * da_ex
    if f_in < 0.0:
        dmout_dp -= phi * a_in * dfin_dp
        dmout_dt -= phi * (share * share_in * f_in * da_in + a_in * dfin_dsup * dsup)
    if leak_out > 0.0:
        dmout_dp += leak_o * dflk_dp + 2.0 * leak_l * p
        dmout_dt += leak_g * vdot / cs[C_BORE_AREA] * lam
    # the convective form's outflows scale by sqrt(T_w / te): d/dT = -c / (2 te) of each
    dmdot_dT, dmout_dT = 0.0, 0.0
    if conv:
        half = -0.5 * coup / te
        if f_in < 0.0:
            dmdot_dT += phi * a_in * f_in * half
            dmout_dT -= phi * a_in * f_in * half
        if f_ex > 0.0:
            dmdot_dT -= phi * a_ex * f_ex * half
            dmout_dT += phi * a_ex * f_ex * half
        if f_lk > 0.0:
            dmdot_dT -= leak_o * f_lk * half
            dmout_dT += leak_o * f_lk * half
    jp += n_over_v * rs * (t_wall - te) * dmout_dp
    vp += n_over_v * rs * (t_wall - te) * dmout_dt
    jpt = (n_over_v * (rs_t * dmdot_dT - coup * rs * m_out + rs * (t_wall - te) * dmout_dT)
           - coup * c_wall)
    if heat > 0.0:
        jpt -= coup * p * heat * t_hot / (te * te)
    # ft = T (fp / p + vdot / V - Rs T mdot / (p V))
    g = rs * temp / (p * vol)
    jtp = temp * (jp / p - fp / (p * p) - g * dmdot + g * mdot / p)
    jt = ft / temp + temp * (jpt / p - rs * mdot / (p * vol) - g * dmdot_dT)
    vt = temp * (vp / p - (vdot / vol) ** 2 - g * dmdot_dt + g * mdot * vdot / vol)
    return fp, jp, ft, jt, vp, jpt, jtp, vt
