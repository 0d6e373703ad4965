"""Compiled step of the acoustic-line model (``tube_delay`` form ``"line"``).

The state is ``y = [p, p_1 .. p_n, q_1 .. q_n]``: the chamber pressure, the line's
cell pressures (cell 1 at the valve) and the mass flows from each cell into the next
(the last into the chamber); with heat transfer the chamber temperature follows
(:func:`_thermal_chamber`). With ``A = pi D^2 / 4``, ``dx = L / n`` and the supply
temperature T (the line's gas stays at it; its cells change pressure by kappa Rs T per
kg, as eq. 5's chamber does and as the line's waves, at the speed sqrt(kappa Rs T),
need: the slow limit of a narrow tube, whose gas exchanges heat with its wall within
r^2 / alpha ~ 0.05 s at 1-mm radius, is isothermal instead)::

    dp_1/dt = kappa Rs T / (A dx) (m_valve(p_1) - q_1)
    dp_i/dt = kappa Rs T / (A dx) (q_{i-1} - q_i)
    dq_i/dt = A / l_i (p_i - p_{i+1}) - f Re mu q_i / (2 rho_i D^2),  p_{n+1} = p
    dp/dt   = kappa / V (Rs T (q_n - m_leak(p)) - p dV/dt)                    (eq. 5)

with ``rho_i`` the mean density of the two cells and ``f Re`` the smooth-pipe
correlation of :mod:`pneubayes.physics.tube`. The valve's port flows (eqs. 1-3) see the
first cell's pressure.

The grid is staggered: each cell's pressure is that of its centre, so a flow's link is
``l_i = dx`` long between two cells and ``l_n = dx / 2`` from the last cell's centre to
the chamber. This is the second-order (centred) lumping of the continuous line: with 3
cells its first resonance is within about 1 % of the continuous tube's closed form,
where cells lumped at their upstream end (every link dx long) put it 8-14 % low, and
still 4-7 % low with 6 cells (``tests/test_simulator.py``), so a fitted transit time read
short by as much. The half link from the valve to the first cell's centre
is left out: a choked port's flow does not depend on the pressure downstream, so it
changes nothing there; for a subsonic port its inertia is small next to the port's
resistance.

Waves make this system oscillatory and the orifice into a small cell makes it stiff, so
the step is the kernel's exponential Rosenbrock method (exprb32) with the *full*
Jacobian: the phi-functions of the small matrix ``h J`` act on vectors through the
exponential of an augmented matrix (Al-Mohy and Higham 2011, Thm. 2.1), computed by
scaling and squaring with a [6/6] Pade approximant. The method is exact for linear
problems, so the waves cost no stability, only the accuracy the error control asks for.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pneubayes.effects.path import JET_FLOW_REF_KG_PER_S, SLOT_INDEX
from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.physics.tube import churchill_fre_and_slope_table
from pneubayes.simulation.chamber import wall_exchange
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

_VOL = SLOT_INDEX["volume_m3"]
_LEAK_O = SLOT_INDEX["leak_orifice_area_m2"]
_LEAK_L = SLOT_INDEX["leak_laminar_kg_per_s_Pa2"]
_LEAK_LG = SLOT_INDEX["leak_laminar_gradient_kg_per_s_Pa2_m"]
_LEN = SLOT_INDEX["line_length_m"]
_DIA = SLOT_INDEX["line_diameter_m"]
_MU = SLOT_INDEX["line_viscosity_Pa_s"]
_HEAT = SLOT_INDEX["heat_rate_per_s"]
_HCONV = SLOT_INDEX["heat_coefficient_W_per_m2_K"]
_HCOUP = SLOT_INDEX["heat_coupling"]
_HJET = SLOT_INDEX["heat_jet_coefficient_W_per_m2_K"]
_HWOFF = SLOT_INDEX["heat_wall_offset_K"]
_B_IN = SLOT_INDEX["inlet_critical_ratio"]
_B_EX = SLOT_INDEX["exhaust_critical_ratio"]
_M_SUB = SLOT_INDEX["port_subsonic_index"]

_PADE6 = tuple(math.factorial(12 - k) * math.factorial(6)
               / (math.factorial(12) * math.factorial(k) * math.factorial(6 - k))
               for k in range(7))


@njit(cache=True, error_model="numpy")
def _matmul_into(a, b, c):
    """``c = a @ b`` for small matrices (plain loops: no BLAS to compile or call); ``c``
    must not share memory with ``a`` or ``b``."""
    n, k = a.shape
    m = b.shape[1]
    for i in range(n):
        for j in range(m):
            c[i, j] = 0.0
        for p in range(k):
            aip = a[i, p]
            if aip != 0.0:
                for j in range(m):
                    c[i, j] += aip * b[p, j]


@njit(cache=True, error_model="numpy")
def _solve_in_place(lu, x):
    """``x <- lu^-1 x`` by Gaussian elimination with partial pivoting, overwriting ``lu``
    (small, well-conditioned: the Pade denominator at norm <= 0.5); a singular ``lu``
    gives NaN."""
    n = lu.shape[0]
    m = x.shape[1]
    for k in range(n):
        piv = k
        big = abs(lu[k, k])
        for i in range(k + 1, n):
            if abs(lu[i, k]) > big:
                big = abs(lu[i, k])
                piv = i
        if big == 0.0:
            x[:, :] = np.nan
            return
        if piv != k:
            for j in range(n):
                lu[k, j], lu[piv, j] = lu[piv, j], lu[k, j]
            for j in range(m):
                x[k, j], x[piv, j] = x[piv, j], x[k, j]
        for i in range(k + 1, n):
            f = lu[i, k] / lu[k, k]
            if f != 0.0:
                for j in range(k + 1, n):
                    lu[i, j] -= f * lu[k, j]
                for j in range(m):
                    x[i, j] -= f * x[k, j]
    for k in range(n - 1, -1, -1):
        for j in range(m):
            acc = x[k, j]
            for i in range(k + 1, n):
                acc -= lu[k, i] * x[i, j]
            x[k, j] = acc / lu[k, k]


@njit(cache=True, error_model="numpy")
def expm_into(a, work):
    """Matrix exponential of a small square ``(n, n)`` matrix: [6/6] Pade, scaling and
    squaring, in the scratch ``work`` ``(6, n, n)``; returns the index k of the slice
    ``work[k]`` that holds the result (no allocation: the line's step calls this once).

    The matrix is scaled by 2^-s until its 1-norm is <= 1, where the approximant's
    relative error is below 2e-13, and the result squared s times. A matrix with a
    non-finite entry gives a matrix of NaN (the step that asked is rejected): the
    compiled solve would raise, and an exception cannot leave the kernel's parallel
    loop cleanly.
    """
    n = a.shape[0]
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(a[i, j])
        if not math.isfinite(col):  # (max() would drop a NaN)
            work[0, :, :] = np.nan
            return 0
        norm = max(norm, col)
    s = 0
    if norm > 1.0:
        s = int(math.ceil(math.log2(norm)))
    x, x2, x4, x6, even, odd = work[0], work[1], work[2], work[3], work[4], work[5]
    c = 0.5 ** s
    for i in range(n):
        for j in range(n):
            x[i, j] = a[i, j] * c
    _matmul_into(x, x, x2)
    _matmul_into(x2, x2, x4)
    _matmul_into(x4, x2, x6)
    # even and odd parts: num = V + U, den = V - U (four products instead of six)
    for i in range(n):
        for j in range(n):
            even[i, j] = (_PADE6[2] * x2[i, j] + _PADE6[4] * x4[i, j]) + _PADE6[6] * x6[i, j]
            eye = 1.0 if i == j else 0.0
            odd[i, j] = (_PADE6[1] * eye + _PADE6[3] * x2[i, j]) + _PADE6[5] * x4[i, j]
    for i in range(n):
        even[i, i] += _PADE6[0]
    _matmul_into(x, odd, x2)  # x2 <- x @ odd (the odd part)
    for i in range(n):
        for j in range(n):
            x4[i, j] = even[i, j] - x2[i, j]
            x6[i, j] = even[i, j] + x2[i, j]
    _solve_in_place(x4, x6)
    cur, other = 3, 0
    for _ in range(s):
        _matmul_into(work[cur], work[cur], work[other])
        cur, other = other, cur
    return cur


@njit(cache=True, error_model="numpy")
def expm_small(a):
    """Matrix exponential of a small square matrix into a new array (:func:`expm_into`)."""
    n = a.shape[0]
    work = np.empty((6, n, n))
    return work[expm_into(a, work)].copy()


@njit(cache=True, error_model="numpy")
def phi_combination_into(hj, vectors, scale, out, prop, work):
    """``out = sum_k phi_k(hJ) b_k`` for the columns ``vectors = [b_1, ..., b_m]``
    ``(n, m)``, and ``prop = exp(hJ)``: the top rows of the exponential of
    ``[[hJ, W], [0, K]]`` with ``W = [b_m, ..., b_1]`` and K the m x m shift (Al-Mohy and
    Higham 2011, Thm. 2.1). ``work`` ``(7, n + m, n + m)`` is scratch.

    ``scale`` (n,) are the states' natural sizes: the exponential is taken of the
    balanced ``S^-1 hJ S`` (S = diag(scale)), whose norm -- and so the number of
    squarings -- does not depend on the units of the states.
    """
    n, m = vectors.shape
    big = work[6]
    big[:, :] = 0.0
    for i in range(n):
        for j in range(n):
            big[i, j] = hj[i, j] * scale[j] / scale[i]
    # each column is also scaled to unit size (the result is linear in it)
    size = 0.0
    for i in range(n):
        for k in range(m):
            size = max(size, abs(vectors[i, k]) / scale[i])
    if size == 0.0:
        size = 1.0
    for k in range(m):
        for i in range(n):
            big[i, n + k] = vectors[i, m - 1 - k] / (scale[i] * size)
    for k in range(m - 1):
        big[n + k, n + k + 1] = 1.0
    e = work[expm_into(big, work)]
    for i in range(n):
        out[i] = e[i, n + m - 1] * size * scale[i]
        for j in range(n):
            prop[i, j] = e[i, j] * scale[i] / scale[j]


@njit(cache=True, error_model="numpy")
def phi_combination(hj, vectors, scale):
    """:func:`phi_combination_into` into new arrays: returns ``(out, prop)``."""
    n, m = vectors.shape
    out = np.empty(n)
    prop = np.empty((n, n))
    phi_combination_into(hj, vectors, scale, out, prop, np.empty((7, n + m, n + m)))
    return out, prop


@njit(cache=True, error_model="numpy")
def phi3_correction_into(hj, b, scale, out, a, rhs, cols, ework):
    """The correction ``out = phi_3(hJ) b`` of exprb32's second stage, with
    ``phi_3(Z) ~ (6 I - 2 Z)^-1``: exact at Z = 0 and as Z -> -inf (-1 / (2 Z)), within
    20 % of phi_3 on the whole closed left half-plane (waves on the imaginary axis
    included). The correction is both the step's third-order term and its error
    estimate, so 20 % of it is a fraction of the tolerance the step met, and the order is
    kept (the approximant is phi_3 + O(Z)). One solve instead of a second exponential
    of the augmented matrix. The approximant has a pole at Z = 3: a step whose chamber
    grows on its own (a piston compressing a small chamber, ``hJ[0, 0]`` > 0.5) takes
    the exact combination (:func:`phi_combination_into`). ``a`` ``(n, n)``, ``rhs``
    ``(n, 1)``, ``cols`` ``(n, 3)`` and ``ework`` ``(7, n + 3, n + 3)`` are scratch (no
    allocation: the kernel steps a window without the runtime's reference counts)."""
    n = b.shape[0]
    if hj[0, 0] > 0.5:
        for i in range(n):
            cols[i, 0], cols[i, 1], cols[i, 2] = 0.0, 0.0, b[i]
        phi_combination_into(hj, cols, scale, out, a, ework)
        return
    # balanced as in phi_combination: (6 I - 2 S^-1 hJ S) (S^-1 x) = S^-1 b
    for i in range(n):
        for j in range(n):
            a[i, j] = -2.0 * hj[i, j] * scale[j] / scale[i]
        a[i, i] += 6.0
        rhs[i, 0] = b[i] / scale[i]
    _solve_in_place(a, rhs)
    for i in range(n):
        out[i] = rhs[i, 0] * scale[i]


@njit(cache=True, error_model="numpy")
def phi3_correction(hj, b, scale):
    """:func:`phi3_correction_into` into a new array."""
    n = b.shape[0]
    out = np.empty(n)
    phi3_correction_into(hj, b, scale, out, np.empty((n, n)), np.empty((n, 1)),
                         np.empty((n, 3)), np.empty((7, n + 3, n + 3)))
    return out


@njit(cache=True, error_model="numpy")
def line_rhs(y, nseg, a_in, a_ex, vol, vdot, p_sup, sl, cs, h, need_j, dsup, da_in, da_ex,
             f, jac, vt):
    """Right-hand side ``f`` of the line model at state ``y``; with ``need_j`` also its
    Jacobian ``jac`` and the explicit time derivative ``vt`` (volume, supply and port
    areas moving at ``vdot`` m^3/s, ``dsup`` Pa/s, ``da_in``/``da_ex`` m^2/s).

    The port's square-root singularity at pressure balance is replaced by the secant
    over the step's expected movement, as in the scalar kernel (a W-method Jacobian).
    """
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    p_atm, rs, temp = cs[C_P_ATM], cs[C_RS], cs[C_T_SUPPLY]
    rs_t = rs * temp
    length, dia, mu = sl[_LEN], sl[_DIA], sl[_MU]
    area = 0.25 * math.pi * dia * dia
    dx = length / nseg
    c_cell = kappa * rs_t / (area * dx)
    inert = area / dx
    p = y[0]
    p1 = y[1]
    b_in, b_ex, m_sub = sl[_B_IN], sl[_B_EX], sl[_M_SUB]  # (the ports' own laws; 0 eq. 3's)
    f_in, sg_i, dg_i, r_i, rev_i = flow_terms(p_sup, p1, alpha, beta, theta, kappa, b_in, m_sub)
    f_ex, sg_e, dg_e, r_e, rev_e = flow_terms(p1, p_atm, alpha, beta, theta, kappa, b_ex, m_sub)
    m_valve = a_in * f_in - a_ex * f_ex
    iq = 1 + nseg
    q_prev = m_valve
    if need_j:
        jac[:, :] = 0.0
        vt[:] = 0.0
    for i in range(nseg):
        p_i = y[1 + i]
        inext = 2 + i if i < nseg - 1 else 0
        p_next = y[inext]
        q = y[iq + i]
        f[1 + i] = c_cell * (q_prev - q)
        rho = 0.5 * (p_i + p_next) / rs_t
        re = abs(q) * dia / (area * mu)
        fre, fre_slope = churchill_fre_and_slope_table(re)
        k_f = fre * mu / (2.0 * rho * dia * dia)
        # (staggered grid: the last link, cell centre to chamber, is dx / 2 long)
        inert_i = inert if i < nseg - 1 else 2.0 * inert
        f[iq + i] = inert_i * (p_i - p_next) - k_f * q
        if need_j:
            jac[1 + i, iq + i] = -c_cell
            if i > 0:
                jac[1 + i, iq + i - 1] = c_cell
            dfric_dp = k_f * q / (p_i + p_next)  # d(-k_f q)/dp through rho
            jac[iq + i, 1 + i] = inert_i + dfric_dp
            jac[iq + i, inext] += -inert_i + dfric_dp
            jac[iq + i, iq + i] = -k_f * (1.0 + fre_slope)
        q_prev = q
    # chamber: the last line flow in, leaks out (laminar k graded along the stroke)
    leak_o, leak_g = sl[_LEAK_O], sl[_LEAK_LG]
    leak_l = sl[_LEAK_L] + leak_g * (vol - sl[_VOL] + area * length) / cs[C_BORE_AREA]
    if leak_l < 0.0:
        leak_l, leak_g = 0.0, 0.0
    f_l = 0.0
    sg_l, dg_l, r_l, rev_l = 0.0, 0.0, 0.0, False
    if leak_o > 0.0:
        f_l, sg_l, dg_l, r_l, rev_l = flow_terms(p, p_atm, alpha, beta, theta, kappa)
    lam = p * p - p_atm * p_atm
    if y.shape[0] > iq + nseg:  # a temperature state: heat transfer beside the line
        _thermal_chamber(y, nseg, vol, vdot, sl, cs, h, need_j, q_prev, f_l, sg_l, dg_l,
                         r_l, rev_l, leak_o, leak_l, leak_g, lam, f, jac, vt)
    else:
        mdot = q_prev - leak_o * f_l - leak_l * lam
        f[0] = kappa / vol * (rs_t * mdot - p * vdot)
        if need_j:
            dleak = 2.0 * leak_l * p
            if leak_o > 0.0:
                dfl_dp, _ = flow_slopes(p, p_atm, sg_l, dg_l, r_l, rev_l, alpha, beta, kappa,
                                        abs(f[0]) * h)
                dleak += leak_o * dfl_dp
            jac[0, 0] += kappa / vol * (-rs_t * dleak - vdot)
            jac[0, iq + nseg - 1] += kappa / vol * rs_t
            vt[0] = (-f[0] / vol * vdot
                     - kappa / vol * rs_t * leak_g * vdot / cs[C_BORE_AREA] * lam)
    if not need_j:
        return
    dfloor = abs(f[1]) * h
    dfin_dsup, dfin_dp1 = flow_slopes(p_sup, p1, sg_i, dg_i, r_i, rev_i, alpha, beta, kappa,
                                      dfloor)
    dfex_dp1, _ = flow_slopes(p1, p_atm, sg_e, dg_e, r_e, rev_e, alpha, beta, kappa, dfloor)
    jac[1, 1] += c_cell * (a_in * dfin_dp1 - a_ex * dfex_dp1)
    vt[1] = c_cell * (a_in * dfin_dsup * dsup + f_in * da_in - f_ex * da_ex)


@njit(cache=True, error_model="numpy")
def _thermal_chamber(y, nseg, vol, vdot, sl, cs, h, need_j, q, f_l, sg_l, dg_l, r_l, rev_l,
                     leak_o, leak_l, leak_g, lam, f, jac, vt):
    """The chamber's pressure and temperature rows of :func:`line_rhs` with heat transfer:
    the last state ``y[-1]`` is the chamber temperature T (K).

    The line's gas is at the supply (wall) temperature T_w, so air enters the chamber
    at T_w and leaves it, into the line or through a leak, at T (the energy equation;
    eq. 5 is its case T = T_w)::

        dp/dt = kappa / V (Rs T_w mdot + Rs (T_w - T) m_out - p dV/dt) + Q_wall
        dT/dt = T (dp/dt / p + dV/dt / V - Rs T mdot / (p V))

    with ``mdot = q_n - m_leak``, ``m_out`` the mass leaving, and the wall term of each
    heat form, as :func:`pneubayes.simulation.chamber.chamber_rhs` has them (the
    convective form's leak orifice passes gas at T: its flow scales by sqrt(T_w / T);
    the forced form's jet is the line's inflow ``q_n``), the pressure's row reading
    ``T_w + c (T - T_w)`` for T (c the slot ``heat_coupling``) and ``T_w + c dT_w`` for
    the wall (slot ``heat_wall_offset_K``).
    Writes rows 0 and -1 of ``f``, ``jac`` and ``vt``.
    """
    kappa, p_atm, rs, t_w = cs[C_KAPPA], cs[C_P_ATM], cs[C_RS], cs[C_T_SUPPLY]
    alpha, beta = cs[C_ALPHA], cs[C_BETA]
    bore = cs[C_BORE_AREA]
    rs_t = rs * t_w
    it = y.shape[0] - 1
    iqn = 2 * nseg
    p, temp = y[0], y[it]
    heat, hconv, coup, hjet = sl[_HEAT], sl[_HCONV], sl[_HCOUP], sl[_HJET]
    te = t_w + coup * (temp - t_w)  # the temperature the pressure feels
    t_hot = t_w + coup * sl[_HWOFF]  # and the wall's: T_w + c dT_w
    conv = hconv > 0.0 or hjet > 0.0
    stir = max(q, 0.0) if hjet > 0.0 else 0.0  # the forced form's jet: the line's inflow
    sq = 1.0
    if conv and f_l > 0.0:
        sq = math.sqrt(t_w / te)
    leak_out = leak_o * f_l * sq + leak_l * lam
    mdot = q - leak_out
    m_out = max(-q, 0.0) + max(leak_out, 0.0)
    n_v = kappa / vol
    fp_eq5 = n_v * (rs_t * mdot + rs * (t_w - te) * m_out - p * vdot)
    fp = fp_eq5
    # wall heat flow (kappa - 1) Q / V of the convective form: Q = h A_w (T_w - T)
    c_wall, dc_wall_dv = 0.0, 0.0
    if conv:
        c_wall, dc_wall_dv = wall_exchange(kappa, hconv + hjet * stir / JET_FLOW_REF_KG_PER_S,
                                           bore, vol)
        fp += c_wall * (t_hot - te)
    if heat > 0.0:
        fp += p * heat * (t_hot - te) / te
    g = rs * temp / (p * vol)
    ft = temp * (fp / p + vdot / vol - g * mdot)
    f[0] = fp
    f[it] = ft
    if not need_j:
        return
    dleak_dp = 2.0 * leak_l * p
    dleak_dt = 0.0  # d(leak)/dT through the convective form's sqrt(T_w / T)
    if leak_o > 0.0:
        dfl_dp, _ = flow_slopes(p, p_atm, sg_l, dg_l, r_l, rev_l, alpha, beta, kappa,
                                abs(fp) * h)
        dleak_dp += leak_o * sq * dfl_dp
        if sq != 1.0:
            dleak_dt = -0.5 * coup * leak_o * f_l * sq / te
    dmout_dp, dmout_dt, dmout_dq = 0.0, 0.0, 0.0
    if leak_out > 0.0:
        dmout_dp, dmout_dt = dleak_dp, dleak_dt
    if q < 0.0:
        dmout_dq = -1.0
    jpp = n_v * (rs_t * (-dleak_dp) + rs * (t_w - te) * dmout_dp - vdot)
    jpq = n_v * (rs_t + rs * (t_w - te) * dmout_dq)
    if stir > 0.0:  # the forced form's coefficient follows the line's inflow
        jpq += (hjet / JET_FLOW_REF_KG_PER_S * (t_hot - te)
                * wall_exchange(kappa, 1.0, bore, vol)[0])
    jpt = (n_v * (-rs_t * dleak_dt - coup * rs * m_out + rs * (t_w - te) * dmout_dt)
           - coup * c_wall)
    if heat > 0.0:
        jpp += heat * (t_hot - te) / te
        jpt -= coup * p * heat * t_hot / (te * te)
    jac[0, 0] += jpp
    jac[0, iqn] += jpq
    jac[0, it] += jpt
    jac[it, 0] += temp * (jpp / p - fp / (p * p) + g * dleak_dp + g * mdot / p)
    jac[it, iqn] += temp * (jpq / p - g)
    jac[it, it] += ft / temp + temp * (jpt / p - rs * mdot / (p * vol) + g * dleak_dt)
    # explicit time dependence: the volume (eq. 5's V, the wall's area, the graded leak)
    dleak_dtime = leak_g * vdot / bore * lam
    dmout_dtime = dleak_dtime if leak_out > 0.0 else 0.0
    vp = (-fp_eq5 / vol * vdot + n_v * (-rs_t * dleak_dtime + rs * (t_w - te) * dmout_dtime))
    vp += dc_wall_dv * vdot * (t_hot - te)
    vt[0] = vp
    vt[it] = temp * (vp / p - (vdot / vol) ** 2 + g * dleak_dtime + g * mdot * vdot / vol)


@njit(cache=True, error_model="numpy")
def line_workspace(ny):
    """Scratch for one trajectory's line steps (:func:`line_step`, :func:`line_accept`)
    with ``ny`` states: allocated once per window, not per step."""
    return (np.empty((8, ny)), np.empty((3, ny, ny)), np.empty((ny, 2)), np.empty((ny, 1)),
            np.empty((7, ny + 2, ny + 2)), np.empty((ny, 3)), np.empty((7, ny + 3, ny + 3)))


@njit(cache=True, inline="always", error_model="numpy")
def line_chamber_rates(work):
    """The chamber pressure's rate (Pa/s) at the last :func:`line_step`'s start and at
    its uncorrected end (its stage), from that step's workspace."""
    return work[0][0, 0], work[0][5, 0]


@njit(cache=True, error_model="numpy")
def line_step(y, nseg, hh, a_in, a_ex, vol, vdot, p_sup, dsup, da_in, da_ex,
              a_in2, a_ex2, vol2, p_sup2, sl, cs, atol_p, atol_t, rtol, y_new, prop, work):
    """One exprb32 step of length ``hh`` from ``y`` (inputs at both ends of the step);
    with heat transfer the last state is the chamber temperature (tolerance ``atol_t``
    K), else ``atol_t`` is unused.

    Writes the new state to ``y_new`` and ``exp(hh J)``, which carries sensitivities to
    the initial state, to ``prop``; returns the error norm (<= 1 accepts). ``work``:
    :func:`line_workspace`.
    """
    n = y.shape[0]
    vecs, mats, b, rhs, ework, cols, ework3 = work
    f, vt, scale, incr, u, f2, d, corr = (vecs[0], vecs[1], vecs[2], vecs[3], vecs[4],
                                          vecs[5], vecs[6], vecs[7])
    jac, hj, a3 = mats[0], mats[1], mats[2]
    line_rhs(y, nseg, a_in, a_ex, vol, vdot, p_sup, sl, cs, hh, True, dsup, da_in, da_ex,
             f, jac, vt)
    hh2 = hh * hh
    for i in range(n):
        for k in range(n):
            hj[i, k] = hh * jac[i, k]
        b[i, 0] = hh * f[i]
        b[i, 1] = hh2 * vt[i]
    # a flow's natural size: that of an acoustic wave of 1 Pa, A / c (kg/s)
    area = 0.25 * math.pi * sl[_DIA] ** 2
    wave = area / math.sqrt(cs[C_KAPPA] * cs[C_RS] * cs[C_T_SUPPLY])
    # a temperature's: the isentropic change of 1 Pa about atmospheric pressure (K)
    it = 1 + 2 * nseg  # (== n with no temperature state)
    temp_scale = ((cs[C_KAPPA] - 1.0) / cs[C_KAPPA] * cs[C_T_SUPPLY] / cs[C_P_ATM])
    for i in range(n):
        scale[i] = 1.0 if i <= nseg else (wave if i < it else temp_scale)
    phi_combination_into(hj, b, scale, incr, prop, ework)
    for i in range(n):
        u[i] = y[i] + incr[i]
    for i in range(1 + nseg):
        if not (u[i] > 0.0 and math.isfinite(u[i])):
            return 10.0
    for i in range(1 + nseg, n):
        if not math.isfinite(u[i]) or (i == it and not u[i] > 0.0):
            return 10.0
    # need_j False: jac and vt keep the values at y
    line_rhs(u, nseg, a_in2, a_ex2, vol2, vdot, p_sup2, sl, cs, hh, False, 0.0, 0.0, 0.0,
             f2, jac, vt)
    for i in range(n):
        d[i] = f2[i] - f[i] - hh * vt[i]
    for i in range(n):
        for k in range(n):
            d[i] -= jac[i, k] * (u[k] - y[k])
    c2 = 2.0 * hh
    for i in range(n):
        d[i] = c2 * d[i]
    phi3_correction_into(hj, d, scale, corr, a3, rhs, cols, ework3)
    # flows are weighed by the flow of an acoustic wave of atol_p
    atol_q = atol_p * wave
    err = 0.0
    for i in range(n):
        y_new[i] = u[i] + corr[i]
        tol = atol_p if i <= nseg else (atol_q if i < it else atol_t)
        e = abs(corr[i]) / (tol + rtol * max(abs(y[i]), abs(y_new[i])))
        if not math.isfinite(y_new[i]) or ((i <= nseg or i == it) and y_new[i] <= 0.0):
            e = 10.0
        err = max(err, e)
    return err


@njit(cache=True, error_model="numpy")
def line_volume(sl):
    """The line's volume, m^3 (it leaves the chamber's dead volume)."""
    return 0.25 * math.pi * sl[_DIA] ** 2 * sl[_LEN]


@njit(cache=True, error_model="numpy")
def line_start(y, s_vec, p0, carry, nseg, temp):
    """A window's start: ``y`` = [p0, cells, flows] from ``carry`` (NaN: at rest at p0),
    then the chamber temperature ``temp`` (K) when ``y`` has room for it, and ``s_vec`` =
    dy/dp0 (1 for p and cells at rest, 0 otherwise)."""
    ny = 1 + 2 * nseg
    if y.shape[0] > ny:
        y[ny] = temp
        s_vec[ny] = 0.0
    y[0] = p0
    for i in range(ny):
        s_vec[i] = 0.0
    s_vec[0] = 1.0
    if math.isnan(carry[1]):
        for i in range(1, 1 + nseg):
            y[i] = p0
            s_vec[i] = 1.0
        for i in range(1 + nseg, ny):
            y[i] = 0.0
    else:
        for i in range(1, ny):
            y[i] = carry[i]


@njit(cache=True, error_model="numpy")
def line_accept(y, y_new, prop, s_vec, want_sens, work):
    """An accepted step: ``y <- y_new`` and, when ``want_sens``, ``s_vec <- prop s_vec``;
    returns dp/dp0 (``s_vec[0]``). ``work``: :func:`line_workspace`."""
    ny = y.shape[0]
    for i in range(ny):
        y[i] = y_new[i]
    if want_sens:
        s_next = work[0][3]
        for i in range(ny):
            acc = 0.0
            for k in range(ny):
                pik = prop[i, k]
                if pik != 0.0:
                    acc += pik * s_vec[k]
            s_next[i] = acc
        for i in range(ny):
            s_vec[i] = s_next[i]
    return s_vec[0]


@njit(cache=True, error_model="numpy")
def line_finish(y, carry, nseg):
    """A window's end: the cells and flows into ``carry[1:]`` (the kernel carries the
    temperature)."""
    for i in range(1, 1 + 2 * nseg):
        carry[i] = y[i]
