"""Compiled integrator for the chamber ODE: adaptive exponential Rosenbrock (exprb32).

The chamber pressure obeys a scalar, stiff ODE ``dp/dt = F(t, p)`` (eq. 5) whose
Jacobian ``J = dF/dp`` is known analytically. One step of length h is

    U      = p + h phi1(hJ) F(t, p) + h^2 phi2(hJ) v   (exponential Rosenbrock-Euler)
    D      = F(t + h, U) - F(t, p) - J (U - p) - h v   (nonlinear remainder)
    p_next = U + 2 h phi3(hJ) D                        (exprb32, order 3)

with ``v = dF/dt`` at fixed p, the explicit time dependence through the moving volume,
the supply ramp and a moving spool; without it the method drops to first order
whenever the inputs change within a step.

and ``|2 h phi3(hJ) D|`` estimates the local error for step-size control. Exponential
integrators are exact for linear problems, so stiffness (tiny volumes, J ~ -1e8 /s)
costs nothing; near pressure equilibrium, where F has a square-root singularity, the
step behaves like a damped Newton step instead of chattering.

Inputs follow the recording: the command is held between samples (zero-order hold),
position and supply are linear between samples. A transport delay shifts the held
command, which adds one break point inside some sample intervals; the integrator
stops exactly on every break point. The spool lag is integrated in closed form. With
heat transfer on (either form), the chamber temperature is a second state, stepped by
the same method with the full 2 x 2 Jacobian (a diagonal one leaves the method first
order in the p-T coupling). With the tube as an acoustic line, the state is the
chamber's pressure and the line's cells and flows, stepped by the same method with the
full Jacobian (:mod:`pneubayes.simulation.line`).

Status codes per task: 0 ok, 1 step size underflow, 2 step budget exhausted,
3 non-finite state, 4 an acoustic line not smaller than the dead volume. This module and
:mod:`pneubayes.simulation.line` are the only compiled code of the simulator.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from pneubayes.effects.path import LINE_MAX_SEGMENTS, SLOT_INDEX
from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.physics.valve import gompertz_scalar
from pneubayes.simulation.layout import (  # noqa: F401  (N_CONSTS, N_SOLVER re-exported)
    C_ALPHA,
    C_BETA,
    C_BORE_AREA,
    C_KAPPA,
    C_P_ATM,
    C_P_NOM,
    C_RS,
    C_T_SUPPLY,
    C_THETA,
    N_CONSTS,
    N_SOLVER,
    S_ATOL_P,
    S_ATOL_T,
    S_MAX_STEP,
    S_MAX_STEPS_PER_S,
    S_MIN_STEP,
    S_RTOL,
)
from pneubayes.simulation.line import line_step

OK, STEP_UNDERFLOW, STEP_BUDGET, NONFINITE, LINE_VOLUME = 0, 1, 2, 3, 4
STATUS_TEXT = {OK: "ok", STEP_UNDERFLOW: "step size fell below min_step_s",
               STEP_BUDGET: "more steps in one window than max_steps_per_s allows",
               NONFINITE: "state became non-finite",
               LINE_VOLUME: "the acoustic line's volume is not smaller than the dead volume"}
#: Length of the state carried from one window to the next: the chamber temperature
#: and an acoustic line's cell pressures and flows (NaN: start the line at rest).
N_CARRY = 1 + 2 * LINE_MAX_SEGMENTS


_IN = SLOT_INDEX["inlet_offset_m2"]
_EX = SLOT_INDEX["exhaust_offset_m2"]
_VOL = SLOT_INDEX["volume_m3"]
_DELAY = SLOT_INDEX["command_delay_s"]
_SPOOL = SLOT_INDEX["spool_time_constant_s"]
_DEAD = SLOT_INDEX["deadband_halfwidth_V"]
_SUPG = SLOT_INDEX["supply_gain"]
_ATT = SLOT_INDEX["flow_attenuation_Pa"]
_LEAK_O = SLOT_INDEX["leak_orifice_area_m2"]
_LEAK_L = SLOT_INDEX["leak_laminar_kg_per_s_Pa2"]
_LEAK_LG = SLOT_INDEX["leak_laminar_gradient_kg_per_s_Pa2_m"]
_HEAT = SLOT_INDEX["heat_rate_per_s"]
_HCONV = SLOT_INDEX["heat_coefficient_W_per_m2_K"]
_LLEN = SLOT_INDEX["line_length_m"]
_LDIA = SLOT_INDEX["line_diameter_m"]
_LSEG = SLOT_INDEX["line_segments"]


@njit(cache=True, inline="always", error_model="numpy")
def _phi123(z):
    """phi_k(z) = (e^z - sum_{j<k} z^j/j!) / z^k for k = 1, 2, 3; stable for all z <= ~0."""
    if abs(z) < 0.1:
        phi1 = 1.0 + z * (0.5 + z * (1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0
                                                                          + z / 720.0))))
        phi2 = 0.5 + z * (1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0 + z * (
            1.0 / 720.0 + z / 5040.0))))
        phi3 = 1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0 + z * (1.0 / 720.0 + z * (
            1.0 / 5040.0 + z / 40320.0))))
        return phi1, phi2, phi3
    em1 = math.expm1(z)
    phi1 = em1 / z
    phi2 = (phi1 - 1.0) / z
    phi3 = (phi2 - 0.5) / z
    return phi1, phi2, phi3


@njit(cache=True, inline="always", error_model="numpy")
def _gompertz_rate(u, a, b, c, d):
    """d(area)/du of eq. 11 (without the offset), m^2/V."""
    inner = math.exp(-c * (u + d))
    return a * math.exp(-b * inner) * b * c * inner


@njit(cache=True, inline="always", error_model="numpy")
def _areas(spool, dead, sl):
    """Port areas (eq. 11) for spool position ``spool`` behind a dead band of half-width dead."""
    mag = abs(spool) - dead
    u = 0.0 if mag <= 0.0 else (mag if spool > 0.0 else -mag)
    a_in = gompertz_scalar(u, sl[_IN], sl[_IN + 1], sl[_IN + 2], sl[_IN + 3], sl[_IN + 4])
    a_ex = gompertz_scalar(u, sl[_EX], sl[_EX + 1], sl[_EX + 2], sl[_EX + 3], sl[_EX + 4])
    return a_in, a_ex


@njit(cache=True, inline="always", error_model="numpy")
def _area_rates(spool, spool_rate, dead, sl):
    """Time derivatives of the two port areas for a spool moving at ``spool_rate`` V/s."""
    mag = abs(spool) - dead
    if mag <= 0.0:
        return 0.0, 0.0
    u = mag if spool > 0.0 else -mag
    r_in = _gompertz_rate(u, sl[_IN + 1], sl[_IN + 2], sl[_IN + 3], sl[_IN + 4])
    r_ex = _gompertz_rate(u, sl[_EX + 1], sl[_EX + 2], sl[_EX + 3], sl[_EX + 4])
    return r_in * spool_rate, r_ex * spool_rate


@njit(cache=True, inline="always", error_model="numpy")
def _rhs(p, temp, a_in, a_ex, vol, vdot, p_sup, sl, cs, h, need_j, dsup, da_in, da_ex):
    """Chamber right-hand side: ``(dp/dt, J_pp, dT/dt, J_TT, v_p, J_pT, J_Tp, v_T)``.

    ``v_p`` and ``v_T`` are the explicit time derivatives of dp/dt and dT/dt at fixed
    state, from the volume changing at ``vdot``, the supply ramping at ``dsup`` Pa/s and
    the port areas moving at ``da_in``, ``da_ex`` m^2/s (the non-autonomous terms of the
    exponential method). ``J_xy`` is d(dx/dt)/dy; the temperature's entries and ``v_T``
    are 0 without heat transfer.

    Eqs. 1-5 and 9, plus the laminar leak, tube attenuation and wall heat exchange
    (a rate, or a convective coefficient on the wall area with orifice outflows at the
    chamber's temperature; see :mod:`pneubayes.effects.heat_transfer`).
    ``J_p`` approximates d(dp/dt)/dp: exact except that the square-root singularity of
    a port at pressure balance is replaced by the secant over the step's expected
    movement ``|dp/dt| h``, so a chamber starting exactly at a port's pressure is not
    frozen by an infinite slope (a W-method Jacobian; the error control checks it).
    Jacobians are only computed when ``need_j``.
    """
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    p_atm = cs[C_P_ATM]
    f_in, sg_i, dg_i, r_i, rev_i = flow_terms(p_sup, p, alpha, beta, theta, kappa)
    f_ex, sg_e, dg_e, r_e, rev_e = flow_terms(p, p_atm, alpha, beta, theta, kappa)
    t_wall = cs[C_T_SUPPLY]
    hconv = sl[_HCONV]
    # convective form: orifice flows leaving the chamber at T scale by sqrt(T_w / T)
    sq_in, sq_ex = 1.0, 1.0
    if hconv > 0.0:
        sq = math.sqrt(t_wall / temp)
        if f_in < 0.0:
            sq_in = sq
        if f_ex > 0.0:
            sq_ex = sq
        f_in *= sq_in
        f_ex *= sq_ex
    valve = a_in * f_in - a_ex * f_ex
    att = sl[_ATT]
    phi = math.exp(-att / p) if att > 0.0 else 1.0
    leak_o, leak_g = sl[_LEAK_O], sl[_LEAK_LG]
    # laminar k at the piston's position x = (V - V_0) / A (never negative)
    leak_l = sl[_LEAK_L] + leak_g * (vol - sl[_VOL]) / cs[C_BORE_AREA]
    if leak_l < 0.0:
        leak_l, leak_g = 0.0, 0.0
    lam = p * p - p_atm * p_atm
    mdot = phi * valve - leak_o * f_ex - leak_l * lam
    rs = cs[C_RS]
    rs_t = rs * t_wall
    n_over_v = kappa / vol
    heat = sl[_HEAT]
    thermal = heat > 0.0 or hconv > 0.0
    # With a temperature state, air leaving the chamber carries the chamber's enthalpy
    # (T), air entering the supply's (T_w): Rs (T_w m_in - T m_out) = Rs T_w mdot +
    # Rs (T_w - T) m_out. Without it T = T_w and this is eq. 5.
    m_out = 0.0
    if thermal:
        leak_out = leak_o * f_ex + leak_l * lam
        m_out = (phi * (a_ex * max(f_ex, 0.0) + a_in * max(-f_in, 0.0))
                 + max(leak_out, 0.0))
    fp_eq5 = n_over_v * (rs_t * mdot + rs * (t_wall - temp) * m_out - p * vdot)
    fp = fp_eq5
    ft = 0.0
    # wall heat flow (kappa - 1) Q / V of the convective form: Q = h A_w (T_w - T) with
    # A_w / V = 2 A / V + pi D / A (end caps and barrel; D = 2 sqrt(A / pi))
    c_wall = 0.0
    if hconv > 0.0:
        bore_a = cs[C_BORE_AREA]
        c_wall = (kappa - 1.0) * hconv * (2.0 * bore_a / vol + 2.0 * math.sqrt(math.pi / bore_a))
        fp += c_wall * (t_wall - temp)
    if heat > 0.0:
        fp += p * heat * (t_wall - temp) / temp
    if thermal:
        ft = temp * (fp / p + vdot / vol - rs * temp * mdot / (p * vol))
    if not need_j:
        return fp, 0.0, ft, 0.0, 0.0, 0.0, 0.0, 0.0
    dfloor = abs(fp) * h
    dfin_dsup, dfin_dp = flow_slopes(p_sup, p, sg_i, dg_i, r_i, rev_i, alpha, beta, kappa,
                                     dfloor)
    dfex_dp, _ = flow_slopes(p, p_atm, sg_e, dg_e, r_e, rev_e, alpha, beta, kappa, dfloor)
    dfin_dp *= sq_in
    dfin_dsup *= sq_in
    dfex_dp *= sq_ex
    dvalve = a_in * dfin_dp - a_ex * dfex_dp
    dmdot = phi * dvalve + phi * att / (p * p) * valve - leak_o * dfex_dp - 2.0 * leak_l * p
    jp = n_over_v * (rs_t * dmdot - vdot)
    if heat > 0.0:
        jp += heat * (t_wall - temp) / temp
    # explicit time dependence: d(eq. 5)/dV * dV/dt + inputs moving the flows
    dmdot_dt = (phi * (a_in * dfin_dsup * dsup + f_in * da_in - f_ex * da_ex)
                - leak_g * vdot / cs[C_BORE_AREA] * lam)
    vp = -fp_eq5 / vol * vdot + n_over_v * rs_t * dmdot_dt
    if hconv > 0.0:
        vp -= (kappa - 1.0) * hconv * (t_wall - temp) * 2.0 * cs[C_BORE_AREA] * vdot / (vol * vol)
    if not thermal:
        return fp, jp, ft, 0.0, vp, 0.0, 0.0, 0.0
    # The temperature's entries (the full 2 x 2 Jacobian keeps the method's order).
    # Outflow m_out (air leaving at T) and its slopes in p, T and t:
    dmout_dp = phi * att / (p * p) * (a_ex * max(f_ex, 0.0) + a_in * max(-f_in, 0.0))
    dmout_dt = 0.0
    if f_ex > 0.0:
        dmout_dp += phi * a_ex * dfex_dp
        dmout_dt += phi * f_ex * da_ex
    if f_in < 0.0:
        dmout_dp -= phi * a_in * dfin_dp
        dmout_dt -= phi * (f_in * da_in + a_in * dfin_dsup * dsup)
    if leak_o * f_ex + leak_l * lam > 0.0:
        dmout_dp += leak_o * dfex_dp + 2.0 * leak_l * p
        dmout_dt += leak_g * vdot / cs[C_BORE_AREA] * lam
    # the convective form's outflows scale by sqrt(T_w / T): d/dT = -1 / (2 T) of each
    dmdot_dT, dmout_dT = 0.0, 0.0
    if hconv > 0.0:
        half = -0.5 / temp
        if f_in < 0.0:
            dmdot_dT += phi * a_in * f_in * half
            dmout_dT -= phi * a_in * f_in * half
        if f_ex > 0.0:
            dmdot_dT -= (phi * a_ex + leak_o) * f_ex * half
            dmout_dT += (phi * a_ex + leak_o) * f_ex * half
    jp += n_over_v * rs * (t_wall - temp) * dmout_dp
    vp += n_over_v * rs * (t_wall - temp) * dmout_dt
    jpt = n_over_v * (rs_t * dmdot_dT - rs * m_out + rs * (t_wall - temp) * dmout_dT) - c_wall
    if heat > 0.0:
        jpt -= p * heat * t_wall / (temp * temp)
    # ft = T (fp / p + vdot / V - Rs T mdot / (p V))
    g = rs * temp / (p * vol)
    jtp = temp * (jp / p - fp / (p * p) - g * dmdot + g * mdot / p)
    jt = ft / temp + temp * (jpt / p - rs * mdot / (p * vol) - g * dmdot_dT)
    vt = temp * (vp / p - (vdot / vol) ** 2 - g * dmdot_dt + g * mdot * vdot / vol)
    return fp, jp, ft, jt, vp, jpt, jtp, vt


_INV_FACT = tuple(1.0 / math.factorial(j) for j in range(17))


@njit(cache=True, inline="always", error_model="numpy")
def _mm2(x, y):
    """Product of 2 x 2 matrices stored row-major as 4-tuples."""
    return (x[0] * y[0] + x[1] * y[2], x[0] * y[1] + x[1] * y[3],
            x[2] * y[0] + x[3] * y[2], x[2] * y[1] + x[3] * y[3])


@njit(cache=True, error_model="numpy")
def _phi0123_2x2(m):
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


@njit(cache=True, error_model="numpy")
def _thermal_step(p, temp, hh, a_in, a_ex, vol, vdot, psup, dsup, da_in, da_ex, a_in2, a_ex2,
                  vol2, psup2, sl, cs, atol_p, atol_t, rtol):
    """One exprb32 step of the state (p, T) with its full 2 x 2 Jacobian.

    The phi-functions are taken of the balanced ``S^-1 h J S``, ``S = diag(p, T)``
    (:func:`_phi0123_2x2`). Returns ``(err, p_new, T_new, exp(h J))``, the propagator
    as a row-major 4-tuple; ``err`` <= 1 accepts the step.
    """
    fp, jpp, ft, jtt, vp, jpt, jtp, vt = _rhs(p, temp, a_in, a_ex, vol, vdot, psup, sl, cs,
                                              hh, True, dsup, da_in, da_ex)
    r = temp / p
    f0, f1, f2, f3 = _phi0123_2x2((hh * jpp, hh * jpt * r, hh * jtp / r, hh * jtt))
    prop = (f0[0], f0[1] / r, f0[2] * r, f0[3])
    # in balanced units (state / S)
    w1p, w1t = hh * fp / p, hh * ft / temp
    w2p, w2t = hh * hh * vp / p, hh * hh * vt / temp
    up = p + p * (f1[0] * w1p + f1[1] * w1t + f2[0] * w2p + f2[1] * w2t)
    ut = temp + temp * (f1[2] * w1p + f1[3] * w1t + f2[2] * w2p + f2[3] * w2t)
    if not (up > 0.0 and math.isfinite(up) and ut > 0.0 and math.isfinite(ut)):
        return 10.0, p, temp, prop
    fp2, _, ft2, _, _, _, _, _ = _rhs(up, ut, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh,
                                      False, 0.0, 0.0, 0.0)
    dp, dt = up - p, ut - temp
    w3p = 2.0 * hh * (fp2 - fp - jpp * dp - jpt * dt - hh * vp) / p
    w3t = 2.0 * hh * (ft2 - ft - jtp * dp - jtt * dt - hh * vt) / temp
    ep = p * (f3[0] * w3p + f3[1] * w3t)
    et = temp * (f3[2] * w3p + f3[3] * w3t)
    pn, tn = up + ep, ut + et
    if not (pn > 0.0 and math.isfinite(pn) and tn > 0.0 and math.isfinite(tn)):
        return 10.0, p, temp, prop
    err = max(abs(ep) / (atol_p + rtol * max(abs(p), abs(pn))),
              abs(et) / (atol_t + rtol * max(temp, tn)))
    return err, pn, tn, prop


@njit(cache=True, error_model="numpy")
def _window(sl, cs, sv, t, u, x, ps, i0, length, p0, out, sens, carry):
    """Integrate one window of ``length`` samples from ``t[i0]`` with p(t[i0]) = p0.

    ``sens`` (``length`` long, or empty to skip) receives dp(t)/dp0, the sensitivity of
    the pressure to the initial pressure: the product of the accepted steps'
    ``exp(h J_p)`` (first order in h; with heat transfer or an acoustic line the
    propagators ``exp(h J)`` of the whole state).
    ``carry`` (``N_CARRY``) holds the unmeasured states at the start and receives them
    at the end: ``carry[0]`` the chamber temperature (K; used with heat transfer),
    ``carry[1:]`` an acoustic line's cell pressures and flows (NaN: at rest at p0).
    """
    rtol, atol_p, atol_t = sv[S_RTOL], sv[S_ATOL_P], sv[S_ATOL_T]
    hmax, hmin = sv[S_MAX_STEP], sv[S_MIN_STEP]
    n = t.shape[0]
    # step budget: max_steps_per_s per simulated second, beyond the one step each
    # sample interval takes at least
    max_steps = (length - 1) + int(sv[S_MAX_STEPS_PER_S] * (t[i0 + length - 1] - t[i0]))
    delay, tau_s, dead = sl[_DELAY], sl[_SPOOL], sl[_DEAD]
    gain = sl[_SUPG]
    p_nom = cs[C_P_NOM]
    v0, bore = sl[_VOL], cs[C_BORE_AREA]
    thermal = sl[_HEAT] > 0.0 or sl[_HCONV] > 0.0
    p = p0
    temp = carry[0] if thermal else cs[C_T_SUPPLY]
    out[0] = p
    want_sens = sens.shape[0] > 0
    s_p0, s_t0 = 1.0, 0.0  # d(p, T)/dp0
    prop_t = (1.0, 0.0, 0.0, 1.0)  # a thermal step's propagator (row-major)
    if want_sens:
        sens[0] = 1.0
    # acoustic line: state [p, cell pressures, flows]; its volume leaves the chamber's
    nseg = int(sl[_LSEG]) if sl[_LLEN] > 0.0 else 0
    line = nseg > 0
    ny = 1 + 2 * nseg
    y = np.empty(ny)
    y_new = np.empty(ny)
    s_vec = np.zeros(ny)
    prop = np.eye(ny)
    if line:
        v0 = v0 - 0.25 * math.pi * sl[_LDIA] ** 2 * sl[_LLEN]
        if not v0 > 0.0:
            return LINE_VOLUME
        y[0] = p0
        s_vec[0] = 1.0
        if math.isnan(carry[1]):
            y[1:1 + nseg] = p0  # at rest at the chamber's pressure
            y[1 + nseg:] = 0.0
            s_vec[1:1 + nseg] = 1.0
        else:
            y[1:] = carry[1:ny]
    # Delayed-command pointer: index j of the sample held at time t - delay.
    j = 0
    t_start = t[i0]
    while j + 1 < n and t[j + 1] + delay <= t_start:
        j += 1
    spool = u[j]  # steady spool at the start of the recording
    if tau_s > 0.0 and i0 > 0:
        # mid-recording: the spool state follows from the command history (the lag in
        # closed form over the held samples of up to 20 time constants before t_start)
        jj = j
        while jj > 0 and t_start - (t[jj] + delay) < 20.0 * tau_s:
            jj -= 1
        spool = u[jj]
        for k in range(jj, j):
            spool = u[k] + (spool - u[k]) * math.exp(-(t[k + 1] - t[k]) / tau_s)
        span = t_start - (t[j] + delay)
        if span > 0.0:
            spool = u[j] + (spool - u[j]) * math.exp(-span / tau_s)
    h = hmax
    steps = 0
    s_cached = math.nan
    a_in_c, a_ex_c = 0.0, 0.0
    for k in range(i0, i0 + length - 1):
        ta, tb = t[k], t[k + 1]
        seg = tb - ta
        inv_seg = 1.0 / seg
        xa, xb = x[k], x[k + 1]
        vdot = bore * (xb - xa) * inv_seg
        sa, sb = ps[k], ps[k + 1]
        dsup = gain * (sb - sa) * inv_seg
        tau = ta
        while tau < tb:
            # Sub-interval [tau, t_end) on which the delayed command is constant.
            while j + 1 < n and t[j + 1] + delay <= tau:
                j += 1
            cmd = u[j]
            t_end = tb
            if j + 1 < n and t[j + 1] + delay < tb:
                t_end = t[j + 1] + delay
            spool_a, t_sub = spool, tau
            # Port areas are constant on the sub-interval unless the spool moves; the
            # command is held for many samples, so reuse them while it is unchanged.
            moving = tau_s > 0.0 and spool_a != cmd
            s_eff = spool_a if tau_s > 0.0 else cmd
            if s_eff != s_cached:
                a_in_c, a_ex_c = _areas(s_eff, dead, sl)
                s_cached = s_eff
            a_in, a_ex = a_in_c, a_ex_c
            while tau < t_end:
                hh = h if h < t_end - tau else t_end - tau
                if t_end - tau - hh < 1e-3 * hh:
                    hh = t_end - tau
                steps += 1
                if steps > max_steps:
                    return STEP_BUDGET
                # state and inputs at tau
                fr = (tau - ta) * inv_seg
                vol = v0 + bore * (xa + fr * (xb - xa))
                psup = p_nom + gain * (sa + fr * (sb - sa) - p_nom)
                da_in = 0.0
                da_ex = 0.0
                if moving:
                    s_now = cmd + (spool_a - cmd) * math.exp(-(tau - t_sub) / tau_s)
                    a_in, a_ex = _areas(s_now, dead, sl)
                    da_in, da_ex = _area_rates(s_now, (cmd - s_now) / tau_s, dead, sl)
                # inputs at tau + hh (stage 2)
                fr2 = (tau + hh - ta) * inv_seg
                vol2 = v0 + bore * (xa + fr2 * (xb - xa))
                psup2 = p_nom + gain * (sa + fr2 * (sb - sa) - p_nom)
                if moving:
                    s2 = cmd + (spool_a - cmd) * math.exp(-(tau + hh - t_sub) / tau_s)
                    a_in2, a_ex2 = _areas(s2, dead, sl)
                else:
                    a_in2, a_ex2 = a_in, a_ex
                err = 10.0
                pn, tn = p, temp
                zp = 0.0
                if line:
                    err, prop = line_step(y, nseg, hh, a_in, a_ex, vol, vdot, psup, dsup,
                                          da_in, da_ex, a_in2, a_ex2, vol2, psup2, sl, cs,
                                          atol_p, rtol, y_new)
                    pn = y_new[0]
                elif thermal:
                    err, pn, tn, prop_t = _thermal_step(p, temp, hh, a_in, a_ex, vol, vdot,
                                                      psup, dsup, da_in, da_ex, a_in2, a_ex2,
                                                      vol2, psup2, sl, cs, atol_p, atol_t,
                                                      rtol)
                else:
                    fp, jp, _, _, vp, _, _, _ = _rhs(p, temp, a_in, a_ex, vol, vdot, psup, sl,
                                                     cs, hh, True, dsup, da_in, da_ex)
                    zp = hh * jp
                    phi1p, phi2p, phi3p = _phi123(zp)
                    up = p + hh * (phi1p * fp + hh * phi2p * vp)
                    if up > 0.0 and math.isfinite(up):
                        fp2 = _rhs(up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh, False,
                                   0.0, 0.0, 0.0)[0]
                        ep = 2.0 * hh * phi3p * (fp2 - fp - jp * (up - p) - hh * vp)
                        pn = up + ep
                        err = abs(ep) / (atol_p + rtol * max(abs(p), abs(pn)))
                        if not (pn > 0.0 and math.isfinite(pn)):
                            err = 10.0
                if err <= 1.0:
                    tau = tau + hh if hh < t_end - tau else t_end
                    p, temp = pn, tn
                    if line:
                        y[:] = y_new
                        if want_sens:
                            s_next = np.zeros(ny)
                            for ii in range(ny):
                                for kk in range(ny):
                                    s_next[ii] += prop[ii, kk] * s_vec[kk]
                            s_vec = s_next
                            s_p0 = s_vec[0]
                    elif thermal:
                        if want_sens:  # (dp, dT)/dp0 through the step's propagator
                            s_p0, s_t0 = (prop_t[0] * s_p0 + prop_t[1] * s_t0,
                                          prop_t[2] * s_p0 + prop_t[3] * s_t0)
                    elif want_sens:
                        s_p0 *= math.exp(zp)
                    fac = 5.0 if err < 1e-4 else min(5.0, 0.9 / np.cbrt(err))
                    if hh >= h or fac < 1.0:
                        h = min(hmax, hh * fac)
                else:
                    if not math.isfinite(err):
                        err = 10.0
                    h = hh * max(0.1, 0.9 / np.cbrt(err))
                    if h < hmin:
                        if not (math.isfinite(p) and math.isfinite(temp)):
                            return NONFINITE
                        return STEP_UNDERFLOW
            # spool position at the end of the sub-interval (closed form)
            if tau_s > 0.0:
                spool = cmd + (spool_a - cmd) * math.exp(-(t_end - t_sub) / tau_s)
            else:
                spool = cmd
        out[k + 1 - i0] = p
        if want_sens:
            sens[k + 1 - i0] = s_p0
    carry[0] = temp
    if line:
        carry[1:ny] = y[1:]
    return OK


@njit(cache=True, parallel=True, error_model="numpy")
def _simulate(slots, consts, solver, t, u, x, ps, starts, length, p0, with_sensitivity):
    """Every (parameter set, window) pair; see :func:`simulate_windows`."""
    nb = slots.shape[0]
    nw = starts.shape[0]
    out = np.empty((nb, nw, length))
    sens = np.empty((nb, nw, length if with_sensitivity else 0))
    status = np.zeros((nb, nw), dtype=np.int64)
    # Contiguous windows (each starts on the previous one's last sample) carry the
    # states the recording does not measure (chamber temperature, an acoustic line) from
    # one window to the next; only the measured pressure is reset at each start.
    chained = nw > 1
    for w in range(1, nw):
        if starts[w] != starts[w - 1] + length - 1:
            chained = False
    hidden = False  # a state the recording does not measure
    for b in range(nb):
        if slots[b, _HEAT] > 0.0 or slots[b, _HCONV] > 0.0 or slots[b, _LLEN] > 0.0:
            hidden = True
    # chained with a hidden state: one task per parameter set runs its windows in order;
    # otherwise one task per (parameter set, window) pair
    per_task = nw if chained and hidden else 1  # windows per task
    tasks_per_set = nw // per_task
    for task in prange(nb * tasks_per_set):
        b = task // tasks_per_set
        w0 = (task % tasks_per_set) * per_task
        carry = _fresh_carry(consts)
        for w in range(w0, w0 + per_task):
            status[b, w] = _window(slots[b], consts, solver, t, u, x, ps, starts[w],
                                   length, p0[w], out[b, w], sens[b, w], carry)
            if status[b, w] != OK:
                carry = _fresh_carry(consts)
    return out, sens, status


@njit(cache=True, error_model="numpy")
def _fresh_carry(consts):
    """Unmeasured states at a recording's start: supply temperature, line at rest."""
    carry = np.full(N_CARRY, np.nan)
    carry[0] = consts[C_T_SUPPLY]
    return carry


def simulate_windows(slots, consts, solver, t, u, x, ps, starts, length, p0):
    """Simulate every (parameter set, window) pair.

    The chamber temperature (a state only with heat transfer) starts at the supply's in
    the first window, an acoustic line at rest at the chamber's pressure; when every
    window starts on the previous one's last sample, each later window starts from the
    temperature and line state the previous one ended with.

    Parameters
    ----------
    slots : (B, N_SLOTS) float64      lowered parameters (see effects.path)
    consts, solver : float64 vectors  rig/gas constants and solver settings (layouts above)
    t, u, x, ps : (N,) float64        time (s), command (V), position (m), supply (Pa)
    starts : (W,) int64               first sample of each window
    length : int                      samples per window (output includes the start)
    p0 : (W,) float64                 initial pressure of each window (Pa)

    Returns
    -------
    out : (B, W, length) float64 pressures (Pa); status : (B, W) int64
    """
    out, _, status = _simulate(slots, consts, solver, t, u, x, ps, starts, length, p0, False)
    return out, status


def simulate_windows_sensitivity(slots, consts, solver, t, u, x, ps, starts, length, p0):
    """:func:`simulate_windows` plus dp(t)/dp0 per sample: ``(out, sens, status)``."""
    return _simulate(slots, consts, solver, t, u, x, ps, starts, length, p0, True)
