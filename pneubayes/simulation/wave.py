"""Compiled parts of the wave tube (``tube_delay`` form ``"wave"``): transmission-line
modelling of the valve-chamber tube (TLM; Krus, Jansson and Palmberg 1990, as in Hopsan).

The tube is ``K`` lossless line elements in a row, each of transit time ``tau = T / K``
(``T = L / c``, c = sqrt(kappa Rs T_s): the line's gas at the supply temperature, as in
:mod:`pneubayes.simulation.line`) and characteristic impedance ``Z = c / A`` (Pa s/kg,
A = pi D^2 / 4). The tube's friction is lumped between them: a resistance ``r`` at each
junction and ``r / 2`` at either end, ``r = f Re mu (L / K) / (2 rho A D^2)`` (Poiseuille's
``32 mu (L / K) / (rho A D^2)`` in laminar flow, Churchill's smooth-pipe ``f Re`` beyond,
tabulated: :func:`pneubayes.physics.tube.churchill_fre_table`) at the local density:
at each junction and at the chamber end at the step's own flow (:func:`friction_flow`),
at the valve end at the last accepted step's. Steady flow drops ``R q`` (R = K r).

In element i two waves cross unchanged in ``tau``: ``A_i = p + Z q`` leaves its valve
side, ``B_i = p - Z q`` its chamber side (q: the mass flow towards the chamber). At time
t, with every wave read at t - tau:

* valve end: ``q_a = m_valve(p_v)``, ``p_v = B_1 + (Z + r/2) q_a`` (eqs. 1-3; a monotone
  scalar equation, :func:`valve_end`); it sends ``A_1 = B_1 + 2 Z q_a``;
* junction j: ``q_j (2 Z + r(q_j)) = A_j - B_{j+1}``; it sends ``B_j = A_j - 2 Z q_j``
  and ``A_{j+1} = B_{j+1} + 2 Z q_j``;
* chamber end: ``q_c (Z + r(q_c)/2) = A_K - p`` enters eq. 5 as the port flow; it sends
  ``B_K = p + (r/2 - Z) q_c``.

A weight w > 0 (:func:`wave_state`) adds Zielke's unsteady shear at the valve end and
the junctions (:func:`unsteady_shear`, linear in the step's flow). Without friction a
valve step reaches the chamber after exactly T, undispersed. The tube's volume ``A L``
leaves the chamber's dead volume, as the line's does.

The junctions and ends update on a fixed grid (slot ``wave_grid_s``, or ``tau`` if shorter:
:func:`wave_grid_step`; anchored at the recording's first sample), the waves kept at
its points in a ring buffer (time, the 2K waves and their derivatives in the window's
initial pressure). A read at ``t - tau`` is linear between entries, so the output moves
continuously with the transit time (a fit moves T), a front spread by about a grid
step. A port-area switch reaches the valve end as a ramp centred on it (:func:`wave_switch`),
continuous in the switch's time too; A_K forces the chamber linearly between grid points.
A window starts with the tube at rest at its initial pressure (its first areas from its
start: a ramp centred there would send flow before it), or where the previous contiguous
window ended (:func:`wave_finish`, resampled on ``WAVE_CARRY_POINTS`` per element).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pneubayes.effects.path import SLOT_INDEX, WAVE_CARRY_POINTS, WAVE_MAX_SEGMENTS
from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.physics.tube import (
    churchill_fre_and_slope_table,
    churchill_fre_table,
    vardy_brown_cutoff,
)
from pneubayes.simulation.chamber import chamber_rhs, compliant_volume
from pneubayes.simulation.layout import (
    C_ALPHA,
    C_BETA,
    C_KAPPA,
    C_P_ATM,
    C_RS,
    C_T_SUPPLY,
    C_THETA,
)
from pneubayes.simulation.phi import phi123

_WLEN = SLOT_INDEX["wave_length_m"]
_WDIA = SLOT_INDEX["wave_diameter_m"]
_WMU = SLOT_INDEX["wave_viscosity_Pa_s"]
_WSEG = SLOT_INDEX["wave_segments"]
_WGRID = SLOT_INDEX["wave_grid_s"]
_WUNST = SLOT_INDEX["wave_unsteady_friction"]
_B_IN = SLOT_INDEX["inlet_critical_ratio"]
_B_EX = SLOT_INDEX["exhaust_critical_ratio"]
_M_SUB = SLOT_INDEX["port_subsonic_index"]

#: Entries of the wave history (a transit time of the longest element on the grid).
WAVE_CAPACITY = 1024
#: Shortest element transit time the step is limited to (s): below it a read past the
#: newest entry takes that entry (an element this short is a resistance and a volume).
WAVE_MIN_TRANSIT_S = 5e-5
#: Width of a history row: time, then A_1..A_K, B_1..B_K, their derivatives in p0.
WAVE_WIDTH = 1 + 4 * WAVE_MAX_SEGMENTS
#: Trikha's (1975) three exponentials of Zielke's laminar weighting function,
#: W(t') ~ sum m_k exp(-n_k t'), t' = nu t / R^2: the unsteady wall shear's memory.
UNSTEADY_M = (1.0, 8.1, 40.0)
UNSTEADY_N = (26.4, 200.0, 8000.0)
#: Carried state: [span, then the tube's state (:func:`wave_state`), waves resampled].
WAVE_CARRY_HEAD = 5 + 4 * WAVE_MAX_SEGMENTS
WAVE_CARRY = WAVE_CARRY_HEAD + 2 * WAVE_MAX_SEGMENTS * WAVE_CARRY_POINTS


@njit(cache=True, error_model="numpy")
def wave_constants(sl, cs):
    """``(tau, Z, area, element length, diameter, viscosity, K, grid, b_in, b_ex, m)``:
    an element's transit time (s), the characteristic impedance (Pa s/kg), the section
    (m^2), L / K (m), the bore (m), the viscosity (Pa s), the number of elements, the
    grid's step (s; :func:`wave_grid_step`), the valve's ports' critical pressure
    ratios and their subsonic index (0: eq. 3's)."""
    k = int(sl[_WSEG])
    length, dia, mu = sl[_WLEN], sl[_WDIA], sl[_WMU]
    c = math.sqrt(cs[C_KAPPA] * cs[C_RS] * cs[C_T_SUPPLY])
    area = 0.25 * math.pi * dia * dia
    tau = length / (c * k)
    grid = min(sl[_WGRID], max(tau, WAVE_MIN_TRANSIT_S))
    return (tau, c / area, area, length / k, dia, mu, k, grid, sl[_B_IN], sl[_B_EX],
            sl[_M_SUB])


@njit(cache=True, error_model="numpy")
def wave_state(sl):
    """The tube's state between grid steps for ``K`` elements: ``[q_a, p_v, q_c,
    q_1..q_{K-1}, t_last, y, w]``: the last flows (kg/s) and valve-end pressure (Pa), the
    time of the last send (s), the unsteady shear's memories ``y`` (m/s; three per
    element: the valve end's, then each junction's) and their weight ``w`` (the slot
    ``wave_unsteady_friction``; 0: quasi-steady friction only)."""
    k = max(int(sl[_WSEG]), 1)
    state = np.zeros(4 * k + 4)
    state[4 * k + 3] = sl[_WUNST]
    return state


@njit(cache=True, error_model="numpy")
def unsteady_factors(h, q0, p, cs, area, dia, mu):
    """``(rho, e, f)`` of the unsteady shear's memories over a step of ``h`` s at a
    junction or end whose last flow was ``q0`` (kg/s) at pressure ``p`` (Pa): the
    density (kg/m^3) and, per memory ``y_k`` (decaying at ``x_k / h = (n_k + B*) nu /
    R^2``), its decay ``e_k = exp(-x_k)`` and ``f_k = (1 - e_k) / x_k`` (the weight of a
    velocity change spread evenly over the step), as tuples."""
    rho = p / (cs[C_RS] * cs[C_T_SUPPLY])
    rate = 4.0 * mu / (rho * dia * dia) * h
    cut = vardy_brown_cutoff(abs(q0) * dia / (area * mu))
    x0 = (UNSTEADY_N[0] + cut) * rate
    x1 = (UNSTEADY_N[1] + cut) * rate
    x2 = (UNSTEADY_N[2] + cut) * rate
    e0, e1, e2 = math.exp(-x0), math.exp(-x1), math.exp(-x2)
    return rho, (e0, e1, e2), (_spread(x0, e0), _spread(x1, e1), _spread(x2, e2))


@njit(cache=True, error_model="numpy")
def _spread(x, e):
    """``(1 - e^-x) / x`` (1 at x = 0)."""
    return (1.0 - e) / x if x > 1e-9 else 1.0 - 0.5 * x


@njit(cache=True, error_model="numpy")
def unsteady_shear(state, iy, factors, area, gain):
    """The unsteady wall shear's pressure drop over a step at a junction or end (its
    memories ``state[iy:iy + 3]``; ``factors`` from :func:`unsteady_factors`), linear
    in the step's flow q: ``U = s + r_u (q - q0)``; returns ``(s, r_u)`` (Pa, Pa s/kg).
    ``gain`` is ``w 16 mu l / D^2`` for the length ``l`` it stands for (Zielke: ``tau_u
    = (4 mu / D) sum y_k``, ``dp = 4 l tau / D``)."""
    rho, e, f = factors
    s = e[0] * state[iy] + e[1] * state[iy + 1] + e[2] * state[iy + 2]
    r_u = UNSTEADY_M[0] * f[0] + UNSTEADY_M[1] * f[1] + UNSTEADY_M[2] * f[2]
    return gain * s, gain * r_u / (rho * area)


@njit(cache=True, error_model="numpy")
def unsteady_update(state, iy, factors, q0, q, area):
    """Advance the memories ``state[iy:iy + 3]`` over the step in which the flow went
    from ``q0`` to ``q`` (the mean velocity's change ``(q - q0) / (rho A)``)."""
    rho, e, f = factors
    dv = (q - q0) / (rho * area)
    state[iy] = e[0] * state[iy] + UNSTEADY_M[0] * f[0] * dv
    state[iy + 1] = e[1] * state[iy + 1] + UNSTEADY_M[1] * f[1] * dv
    state[iy + 2] = e[2] * state[iy + 2] + UNSTEADY_M[2] * f[2] * dv


@njit(cache=True, error_model="numpy")
def wave_volume(sl):
    """The tube's volume A L, m^3 (it leaves the chamber's dead volume)."""
    return 0.25 * math.pi * sl[_WDIA] ** 2 * sl[_WLEN]


@njit(cache=True, error_model="numpy")
def _resistance_per_fre(p, cs, area, length, dia, mu):
    """``mu L / (2 rho A D^2)`` (Pa s/kg): the steady resistance of ``length`` of tube
    at pressure ``p`` (the density's) is this times Churchill's ``f Re``."""
    rho = p / (cs[C_RS] * cs[C_T_SUPPLY])
    return mu * length / (2.0 * rho * area * dia * dia)


@njit(cache=True, error_model="numpy")
def wave_resistance(q, p, cs, area, length, dia, mu):
    """Steady resistance (Pa s/kg) of ``length`` of tube at mass flow ``q`` and pressure
    ``p`` (the density's)."""
    re = abs(q) * dia / (area * mu)
    return churchill_fre_table(re) * _resistance_per_fre(p, cs, area, length, dia, mu)


@njit(cache=True, error_model="numpy")
def friction_flow(d, z_lin, q0, p, share, cs, area, length, dia, mu):
    """The mass flow ``q`` (kg/s) through a junction or end whose waves differ by ``d``
    (Pa): ``q (z_lin + share r(q)) = d``, ``r`` the steady resistance of ``length`` of
    tube at flow ``q`` and pressure ``p`` (:func:`wave_resistance`). Solved at the step
    (Newton from the last step's flow ``q0``; the left side rises strictly with q), not
    with the last step's resistance: a resistance one step late rings where the tube's
    friction dominates its impedance (a valve ten times the tube's section, a fit on
    GTDynamics' recordings: pressures of 1.2 MPa on a 0.56-MPa supply for a transit 10 us
    longer). Returns ``(q, share r(q), z_lin + share r (1 + dln(f Re)/dln Re))``: the flow,
    the resistance it sees and the slope of the equation (dd/dq)."""
    k_r = share * _resistance_per_fre(p, cs, area, length, dia, mu)  # r = k_r f Re
    re_per_q = dia / (area * mu)
    q = q0
    for _ in range(30):
        fre, slope = churchill_fre_and_slope_table(abs(q) * re_per_q)
        r = k_r * fre
        gp = z_lin + r * (1.0 + slope)
        q_next = q - (q * (z_lin + r) - d) / gp
        if slope == 0.0 and abs(q_next) * re_per_q < 1000.0:
            return q_next, r, gp  # laminar here and there: r is constant, the step exact
        done = abs(q_next - q) <= 1e-9 * abs(q_next) + 1e-30
        q = q_next
        if done:  # (r and the slope of the last iterate: within 1e-9 relative of q's)
            break
    return q, r, gp


@njit(cache=True, error_model="numpy")
def wave_grid_step(tube):
    """The grid step (s) the junctions and ends update on (``tube``:
    :func:`wave_constants`): the slot ``wave_grid_s``, or an element's transit time
    ``tau`` if shorter (every read at ``t - tau`` is then of the past), at least
    ``WAVE_MIN_TRANSIT_S``. Each read interpolates, so the waves smear by about a step
    per element. The grid does not otherwise depend on ``tau``: the reads fall between
    grid points and are linear there, so the output moves continuously with the transit
    time (a grid proportional to ``tau`` moved every grid point with it, and a fit on
    GTDynamics' fills stalled at 10.6 kPa where the fixed grid reached 7.9 kPa)."""
    return tube[7]


@njit(cache=True, error_model="numpy")
def wave_newest_time(hist, ring):
    """Time (s) of the history's newest entry."""
    return hist[(ring[0] + ring[1] - 1) % WAVE_CAPACITY, 0]


@njit(cache=True, error_model="numpy")
def wave_entry_time(hist, ring, back):
    """Time (s) of the history's entry ``back`` before its newest (0: the newest)."""
    return hist[(ring[0] + ring[1] - 1 - back) % WAVE_CAPACITY, 0]


@njit(cache=True, error_model="numpy")
def wave_pop(ring):
    """Drop the history's newest entry (to send it again); the read cursor stays on an
    entry that remains."""
    ring[1] -= 1
    if ring[2] > ring[1] - 1:
        ring[2] = max(ring[1] - 1, 0)


@njit(cache=True, error_model="numpy")
def wave_ramped(t_s, a_in, a_ex, sw_t, ramp_s, old_in, old_ex):
    """The port areas (m^2) the valve end sees at ``t_s``: a switch at ``sw_t`` from
    ``(old_in, old_ex)`` to ``(a_in, a_ex)`` ramps linearly over ``ramp_s`` (one grid
    step), so the valve's wave is continuous in time and a read of it moves continuously
    with the switch's time and the transit time."""
    fr = (t_s - sw_t) / ramp_s
    if fr >= 1.0:
        return a_in, a_ex
    if fr <= 0.0:
        return old_in, old_ex
    return old_in + fr * (a_in - old_in), old_ex + fr * (a_ex - old_ex)


@njit(cache=True, error_model="numpy")
def wave_workspace(active):
    """The history ring buffer ``(WAVE_CAPACITY, WAVE_WIDTH)`` (one row if not
    ``active``), its state ``[first, count, read]`` (oldest entry, entries, the read
    cursor's offset from the oldest), a row to read into and one to build the next in."""
    return (np.empty((WAVE_CAPACITY if active else 1, WAVE_WIDTH)),
            np.zeros(3, dtype=np.int64), np.empty(WAVE_WIDTH), np.empty(WAVE_WIDTH))


@njit(cache=True, error_model="numpy")
def wave_push(hist, ring, row, k):
    """Append ``row`` (its time after every stored one; the first ``k`` columns of each
    block); when full, drops the entries older than the read cursor's. Returns False if
    every entry is still needed."""
    first, count, read = ring[0], ring[1], ring[2]
    if count == WAVE_CAPACITY:
        if read == 0:
            return False
        first = (first + read) % WAVE_CAPACITY
        count -= read
        read = 0
    e = (first + count) % WAVE_CAPACITY
    hist[e, 0] = row[0]
    m = WAVE_MAX_SEGMENTS
    for b in range(4):
        for i in range(1, k + 1):
            hist[e, b * m + i] = row[b * m + i]
    ring[0], ring[1], ring[2] = first, count + 1, read
    return True


@njit(cache=True, error_model="numpy")
def _cursor(hist, ring, tq):
    """Move the read cursor to the last entry at or before ``tq`` (never past the
    newest); returns ``(k0, k1, w)``: the entries around ``tq`` and the weight of k1
    (k1 = k0, w = 0 before the oldest or after the newest)."""
    first, count, read = ring[0], ring[1], ring[2]
    while read + 1 < count and hist[(first + read + 1) % WAVE_CAPACITY, 0] <= tq:
        read += 1
    while read > 0 and hist[(first + read) % WAVE_CAPACITY, 0] > tq:
        read -= 1
    ring[2] = read
    k0 = (first + read) % WAVE_CAPACITY
    if read + 1 >= count or hist[k0, 0] >= tq:
        return k0, k0, 0.0
    k1 = (first + read + 1) % WAVE_CAPACITY
    return k0, k1, (tq - hist[k0, 0]) / (hist[k1, 0] - hist[k0, 0])


@njit(cache=True, error_model="numpy")
def wave_arriving(hist, ring, tq, k):
    """The valve's wave arriving at the chamber, A_K at ``tq``, and its derivative in
    p0 (the chamber's step reads only these two columns)."""
    k0, k1, w = _cursor(hist, ring, tq)
    ca, cs_ = k, 2 * WAVE_MAX_SEGMENTS + k
    return (hist[k0, ca] + w * (hist[k1, ca] - hist[k0, ca]),
            hist[k0, cs_] + w * (hist[k1, cs_] - hist[k0, cs_]))


@njit(cache=True, error_model="numpy")
def wave_read_k(hist, ring, tq, out, k, blocks):
    """The first ``blocks`` of the history's column blocks (A, B, dA/dp0, dB/dp0), their
    first ``k`` columns each, at time ``tq`` into ``out``: linear between the entries
    around ``tq``."""
    m = WAVE_MAX_SEGMENTS
    k0, k1, w = _cursor(hist, ring, tq)
    for b in range(blocks):
        for i in range(1, k + 1):
            c = b * m + i
            out[c] = hist[k0, c] + w * (hist[k1, c] - hist[k0, c])


@njit(cache=True, error_model="numpy")
def valve_end(w_a, z_v, a_in, a_ex, p_sup, cs, p_guess, b_in, b_ex, m_sub):
    """Solve the valve end: the pressure ``p_v`` (Pa) at which the ports' net mass flow
    into the tube, ``m(p_v) = a_in f(p_sup, p_v) - a_ex f(p_v, P_atm)`` (eqs. 1-3), equals
    ``(p_v - w_a) / z_v``. Returns ``(p_v, q_a, dq_a/dw_a)``. ``b_in``, ``b_ex``,
    ``m_sub``: the ports' critical pressure ratios and subsonic index (0: eq. 3's).

    ``(p_v - w_a) / z_v - m(p_v)`` rises strictly with p_v, and changes sign on
    [min(P_atm, w_a), max(p_sup, w_a)]; Newton steps from ``p_guess`` that leave the
    shrinking bracket are replaced by bisection. Converged when the residual flow times
    ``z_v`` is below 1e-9 of the pressure."""
    alpha, beta, theta, kappa = cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA]
    p_atm = cs[C_P_ATM]
    if a_in == 0.0 and a_ex == 0.0:  # closed: the wave reflects whole
        return w_a, 0.0, 0.0
    lo = min(p_atm, w_a)
    hi = max(p_sup, w_a)
    pv = min(max(p_guess, lo), hi)
    dm = 0.0
    for _ in range(100):
        f_in, sg_i, dg_i, r_i, rev_i = flow_terms(p_sup, pv, alpha, beta, theta, kappa, b_in,
                                                  m_sub)
        f_ex, sg_e, dg_e, r_e, rev_e = flow_terms(pv, p_atm, alpha, beta, theta, kappa, b_ex,
                                                  m_sub)
        m = a_in * f_in - a_ex * f_ex
        g = (pv - w_a) / z_v - m
        # the slopes as secants over 1 Pa (finite at a port's pressure balance)
        _, din = flow_slopes(p_sup, pv, sg_i, dg_i, r_i, rev_i, alpha, beta, kappa, 1.0)
        dex, _ = flow_slopes(pv, p_atm, sg_e, dg_e, r_e, rev_e, alpha, beta, kappa, 1.0)
        dm = a_in * din - a_ex * dex
        if abs(g) * z_v <= 1e-9 * pv:
            break
        if g > 0.0:
            hi = pv
        else:
            lo = pv
        if hi - lo <= 1e-12 * pv:
            break
        nxt = pv - g / (1.0 / z_v - dm)
        if not (lo < nxt < hi):
            nxt = 0.5 * (lo + hi)
        pv = nxt
    q = (pv - w_a) / z_v
    # dq/dw_a from q = m(w_a + z_v q): dq = m' (dw + z_v dq)
    dq = dm / (1.0 - dm * z_v)
    return pv, q, dq


@njit(cache=True, error_model="numpy")
def wave_ends(hist, ring, t_now, tau, z, k, p, s_p, p_sup, a_in, a_ex, cs, area, seg_len,
              dia, mu, state, rd, row, b_in, b_ex, m_sub):
    """An accepted step ending at ``t_now`` with chamber pressure ``p`` (dp/dp0 ``s_p``):
    the valve end, the junctions and the chamber end send their waves (the module's
    equations), appended to the history. ``state``: :func:`wave_state` (the last flows,
    for the friction, and the unsteady shear's memories; updated). Returns False if the
    history is full."""
    m = WAVE_MAX_SEGMENTS
    wave_read_k(hist, ring, t_now - tau, rd, k, 4)
    row[0] = t_now
    # the unsteady shear (weight w; 0: none): a full element's at each junction and a
    # half's at the valve end, scaled so that the K elements' whole is carried
    w = state[4 * k + 3]
    h = max(t_now - state[k + 2], 0.0)
    gain = w * 16.0 * mu * seg_len / (dia * dia) * k / (k - 0.5)
    state[k + 2] = t_now
    # valve end: B_1 arrives
    zv = z + 0.5 * wave_resistance(state[0], state[1], cs, area, seg_len, dia, mu)
    w_a = rd[m + 1]
    fac = (1.0, (1.0, 1.0, 1.0), (1.0, 1.0, 1.0))  # (none: w = 0)
    if w > 0.0:
        fac = unsteady_factors(h, state[0], state[1], cs, area, dia, mu)
        s_u, r_u = unsteady_shear(state, k + 3, fac, area, 0.5 * gain)
        w_a += s_u - r_u * state[0]
        zv += r_u
    p_v, q_a, dq = valve_end(w_a, zv, a_in, a_ex, p_sup, cs, state[1], b_in, b_ex,
                             m_sub)
    row[1] = rd[m + 1] + 2.0 * z * q_a
    row[2 * m + 1] = rd[3 * m + 1] * (1.0 + 2.0 * z * dq)
    if w > 0.0:
        unsteady_update(state, k + 3, fac, state[0], q_a, area)
    state[0], state[1] = q_a, p_v
    # junctions: A_j and B_{j+1} arrive (columns: A_i at i, B_i at m + i, their
    # derivatives at 2m + i and 3m + i)
    for j in range(1, k):
        a_j, b_n = rd[j], rd[m + j + 1]
        sa_j, sb_n = rd[2 * m + j], rd[3 * m + j + 1]
        d, z_lin, p_j = a_j - b_n, 2.0 * z, 0.5 * (a_j + b_n)
        if w > 0.0:
            fac = unsteady_factors(h, state[2 + j], p_j, cs, area, dia, mu)
            s_u, r_u = unsteady_shear(state, k + 3 + 3 * j, fac, area, gain)
            d += r_u * state[2 + j] - s_u
            z_lin += r_u
        q, r, dd_dq = friction_flow(d, z_lin, state[2 + j], p_j, 1.0, cs, area, seg_len,
                                    dia, mu)
        if w > 0.0:
            unsteady_update(state, k + 3 + 3 * j, fac, state[2 + j], q, area)
        sq = (sa_j - sb_n) / dd_dq
        row[m + j] = a_j - 2.0 * z * q
        row[j + 1] = b_n + 2.0 * z * q
        row[3 * m + j] = sa_j - 2.0 * z * sq
        row[2 * m + j + 1] = sb_n + 2.0 * z * sq
        state[2 + j] = q
    # chamber end: A_K arrives
    a_k, sa_k = rd[k], rd[2 * m + k]
    q_c, r_c, dd_dq = friction_flow(a_k - p, z, state[2], p, 0.5, cs, area, seg_len, dia,
                                    mu)
    row[m + k] = p + (r_c - z) * q_c
    # dB_K/dp0 = s_p + (r_c - z) dq_c + q_c dr_c = s_p + (r_c - z + q_c dr_c/dq_c) dq_c
    row[3 * m + k] = s_p + (dd_dq - 2.0 * z) * (sa_k - s_p) / dd_dq
    state[2] = q_c
    return wave_push(hist, ring, row, k)


@njit(cache=True, error_model="numpy")
def wave_start(hist, ring, carry, t0, p0, tau, k, state, row):
    """A window's start at ``t0``: the history at rest at ``p0`` (every wave p0, of
    derivative 1 in p0; no flow), or from ``carry`` (:func:`wave_finish`; derivatives 0:
    the state the previous window left does not depend on this window's p0)."""
    m = WAVE_MAX_SEGMENTS
    ring[0], ring[1], ring[2] = 0, 0, 0
    for c in range(row.shape[0]):
        row[c] = 0.0
    if math.isnan(carry[1]):
        for c in range(1, 1 + 2 * m):
            row[c] = p0
            row[2 * m + c] = 1.0
        for i in range(state.shape[0] - 1):  # (its last entry: the shear's weight)
            state[i] = 0.0
        state[1] = p0
        state[k + 2] = t0
        for tt in (t0 - tau, t0):
            row[0] = tt
            wave_push(hist, ring, row, k)
        return
    n = WAVE_CARRY_POINTS
    span = carry[1]
    for i in range(state.shape[0]):
        state[i] = carry[2 + i]
    for i in range(n):
        row[0] = t0 - span + span * i / (n - 1)
        for c in range(2 * k):
            col = 1 + c if c < k else 1 + m + (c - k)
            row[col] = carry[1 + WAVE_CARRY_HEAD + c * n + i]
        wave_push(hist, ring, row, k)


@njit(cache=True, error_model="numpy")
def wave_finish(hist, ring, carry, t_end, tau, k, state, rd):
    """A window's end: the last ``tau`` of every wave, resampled on
    ``WAVE_CARRY_POINTS``, and ``state`` (the last flows), into ``carry``."""
    m = WAVE_MAX_SEGMENTS
    n = WAVE_CARRY_POINTS
    span = max(tau, WAVE_MIN_TRANSIT_S)
    ring[2] = 0
    for i in range(n):
        wave_read_k(hist, ring, t_end - span + span * i / (n - 1), rd, k, 2)
        for c in range(2 * k):
            col = 1 + c if c < k else 1 + m + (c - k)
            carry[1 + WAVE_CARRY_HEAD + c * n + i] = rd[col]
    carry[1] = span
    for i in range(state.shape[0]):
        carry[2 + i] = state[i]


@njit(cache=True, error_model="numpy")
def wave_gain(p, vol, sl, cs):
    """d(dp/dt)/d(mass inflow) of eq. 5 at pressure ``p`` and volume ``vol`` (before
    compliance): ``kappa Rs T_s / (V + kappa p C)``, Pa/kg."""
    v, compl = compliant_volume(p, vol, sl, cs[C_P_ATM])
    return cs[C_KAPPA] * cs[C_RS] * cs[C_T_SUPPLY] / (v + cs[C_KAPPA] * p * compl)


# The kernel's side of the tube, window by window: ``tube`` is the tuple of
# :func:`wave_constants` (transit time, impedance, area, element length, bore,
# viscosity, elements, grid step), ``work`` the tuple ``(hist, ring, state, rd, row)`` of
# :func:`wave_workspace` and the last flows, ``grid`` the tuple ``(n, t_grid, t_a, A_a,
# dA_a, A_b, dA_b)``: the next grid point's number and time, and the chamber's forcing
# A_K(t - tau) (with dA/dp0) read at the ends of the grid interval ``[t_a, t_grid]``;
# ``switch`` the tuple ``(t_sw, old_in, old_ex, last_in, last_ex)``: the last port-area
# switch's time, the areas before it and those at the last step's end (NaN before the
# first).


@njit(cache=True, inline="always", error_model="numpy")
def _send(work, tube, t_now, p, s_p, p_sup, a_in, a_ex, cs):
    """:func:`wave_ends` with the kernel's tuples."""
    hist, ring, state, rd, row = work
    tau, z, area, seg_len, dia, mu, k, _, b_in, b_ex, m_sub = tube
    return wave_ends(hist, ring, t_now, tau, z, k, p, s_p, p_sup, a_in, a_ex, cs, area,
                     seg_len, dia, mu, state, rd, row, b_in, b_ex, m_sub)


@njit(cache=True, inline="always", error_model="numpy")
def wave_grid(work, tube, t0, n, t_a):
    """The ``grid`` tuple for grid point ``n`` (anchored at the recording's first sample
    ``t0``, every window of it shares the grid) with its interval starting at ``t_a``."""
    hist, ring = work[0], work[1]
    t_grid = t0 + wave_grid_step(tube) * n
    a0, s0 = wave_arriving(hist, ring, t_a - tube[0], tube[6])
    a1, s1 = wave_arriving(hist, ring, t_grid - tube[0], tube[6])
    return n, t_grid, t_a, a0, s0, a1, s1


@njit(cache=True, inline="always", error_model="numpy")
def wave_switch(work, tube, switch, tau, t_end, p, s_p, p_sup, a_in, a_ex, w_near, cs):
    """``(ok, switch, t_end)`` at the start of a held input's stretch at ``tau``: where
    the port areas switched, the valve end's entry there (sent again if the grid put one
    there) with the areas a share ``g / (g + d)`` of the way from those before to the new
    ones (``g`` the grid step, ``d`` the time since the entry before it), then a ramp to
    the new ones over a grid step (whose end cuts ``t_end``): the areas' mean change
    falls at the switch. ``ok`` False: the history is full."""
    t_sw, o_in, o_ex, l_in, l_ex = switch
    w_dt = wave_grid_step(tube)
    if (not math.isnan(l_in) and abs(a_in - l_in) + abs(a_ex - l_ex)
            > 1e-9 * (a_in + a_ex + l_in + l_ex)):
        r_in, r_ex = wave_ramped(tau, l_in, l_ex, t_sw, w_dt, o_in, o_ex)
        hist, ring = work[0], work[1]
        if wave_newest_time(hist, ring) >= tau - w_near and ring[1] > 1:
            d = tau - wave_entry_time(hist, ring, 1)
            wave_pop(ring)  # (the entry at the switch is sent again below)
        else:
            d = tau - wave_newest_time(hist, ring)
        f = w_dt / (w_dt + max(d, 0.0))
        r_in, r_ex = r_in + f * (a_in - r_in), r_ex + f * (a_ex - r_ex)
        if not _send(work, tube, tau, p, s_p, p_sup, r_in, r_ex, cs):
            return False, switch, t_end
        t_sw, o_in, o_ex = tau, r_in, r_ex
        l_in, l_ex = a_in, a_ex
    if tau < t_sw + w_dt - w_near and t_sw + w_dt < t_end - w_near:
        t_end = t_sw + w_dt  # the ramp's end: an entry there
    return True, (t_sw, o_in, o_ex, l_in, l_ex), t_end


@njit(cache=True, inline="always", error_model="numpy")
def wave_chamber_step(p, temp, hh, tau, vol, vdot, psup, vol2, psup2, s_at, ds_at, s_at2,
                      cdir, sl, cs, grid, tube, q_c, ep, atol_p, rtol, general):
    """One exprb32 step of the chamber at the tube's end, driven by the valve's wave
    arriving, A_K(t - tau) linear over the grid interval the step lies in, through the
    inflow ``(A_K - p) / (Z + r/2)`` of eq. 5 (``q_c``: the chamber end's last flow,
    for the friction ``r``; ``general``: the general kernel's flag, ``chamber_rhs``'s
    ``with_closure``).

    Returns ``(err, pn, fp, jp, vp, ep, zp, phi3p, s_gain)``: the error against the
    tolerance (10: failed; ``ep`` then unchanged), the end pressure, the start's rate,
    slope and time derivative, the correction, ``h J``, phi_3(h J) and the arriving
    wave's share of dp/dp0 over the step.
    """
    _, t_grid, t_a, a0, s0, a1, s1 = grid
    z, area, seg_len, dia, mu = tube[1], tube[2], tube[3], tube[4], tube[5]
    w_inv = 1.0 / (t_grid - t_a)
    wb0 = a0 + (a1 - a0) * (tau - t_a) * w_inv
    wb1 = a0 + (a1 - a0) * (tau + hh - t_a) * w_inv
    swb0 = s0 + (s1 - s0) * (tau - t_a) * w_inv
    swb1 = s0 + (s1 - s0) * (tau + hh - t_a) * w_inv
    zc = z + 0.5 * wave_resistance(q_c, p, cs, area, seg_len, dia, mu)
    fp, jp, _, _, vp, _, _, _ = chamber_rhs(p, temp, 0.0, 0.0, vol, vdot, psup, sl, cs, hh,
                                            True, 0.0, 0.0, 0.0, s_at, ds_at, cdir, general)
    # the wave's inflow gw (A_K - p), gw = n Rs T / (Z_c D), D = V + n p dV/dp: its slope
    # in p (D grows by (1 + n) dV/dp) and its time derivative (A_K moves, V with the
    # piston)
    v, compl = compliant_volume(p, vol, sl, cs[C_P_ATM])
    den = v + cs[C_KAPPA] * p * compl
    gw = cs[C_KAPPA] * cs[C_RS] * cs[C_T_SUPPLY] / den / zc
    fw = gw * (wb0 - p)
    fp += fw
    jp -= gw + fw * compl * (1.0 + cs[C_KAPPA]) / den
    vp += gw * (wb1 - wb0) / hh - fw * vdot / den
    zp = hh * jp
    phi1p, phi2p, phi3p = phi123(zp)
    up = p + hh * (phi1p * fp + hh * phi2p * vp)
    err, pn = 10.0, p
    if up > 0.0 and math.isfinite(up):
        fp2 = (chamber_rhs(up, temp, 0.0, 0.0, vol2, vdot, psup2, sl, cs, hh, False, 0.0,
                           0.0, 0.0, s_at2, 0.0, cdir, general)[0]
               + wave_gain(up, vol2, sl, cs) / zc * (wb1 - up))
        ep = 2.0 * hh * phi3p * (fp2 - fp - jp * (up - p) - hh * vp)
        pn = up + ep
        err = abs(ep) / (atol_p + rtol * max(abs(p), abs(pn)))
        if not (pn > 0.0 and math.isfinite(pn)):
            err = 10.0
    return err, pn, fp, jp, vp, ep, zp, phi3p, hh * phi1p * gw * 0.5 * (swb0 + swb1)


@njit(cache=True, inline="always", error_model="numpy")
def wave_accept(work, tube, switch, grid, t0, tau, p, s_p, p_sup, a_in, a_ex, w_near, cs):
    """``(ok, switch, grid)`` after an accepted step ending at ``tau`` with the port areas
    ``a_in``, ``a_ex``: at a grid point or a ramp's end the ends send their waves; at a
    grid point the grid moves on. ``ok`` False: the history is full."""
    t_sw, o_in, o_ex = switch[0], switch[1], switch[2]
    switch = (t_sw, o_in, o_ex, a_in, a_ex)
    w_dt = wave_grid_step(tube)
    on_grid = tau >= grid[1] - w_near
    if on_grid or abs(tau - t_sw - w_dt) <= w_near:
        v_in, v_ex = wave_ramped(tau, a_in, a_ex, t_sw, w_dt, o_in, o_ex)
        if not _send(work, tube, tau, p, s_p, p_sup, v_in, v_ex, cs):
            return False, switch, grid
    if on_grid:
        grid = wave_grid(work, tube, t0, grid[0] + 1.0, tau)
    return True, switch, grid


@njit(cache=True, error_model="numpy")
def wave_window_end(work, tube, switch, carry, t_last, p, s_p, p_sup, a_in, a_ex, w_near,
                    cs):
    """The state at the window's end ``t_last`` (off the grid in general) into
    ``carry``: the ends' waves there, then the last transit time of every wave. False:
    the history is full."""
    hist, ring, state, rd, _ = work
    if wave_newest_time(hist, ring) < t_last - w_near:
        v_in, v_ex = wave_ramped(t_last, a_in, a_ex, switch[0], wave_grid_step(tube),
                                 switch[1], switch[2])
        if not _send(work, tube, t_last, p, s_p, p_sup, v_in, v_ex, cs):
            return False
    wave_finish(hist, ring, carry, t_last, tube[0], tube[6], state, rd)
    return True
