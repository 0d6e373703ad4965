"""A closure's relaxed pressure ``p_bar`` in the compiled kernel (feature
``pressure_relaxation`` of :mod:`pneubayes.effects.closure_features`).

``tau dp_bar/dt = p - p_bar``. The kernel starts ``p_bar`` from the recorded reading's
history before the window (:func:`relaxation_start`, the same low-pass the open-form
search applies to the measured pressure), holds it over a step at its value half-way
through with the pressure held (:func:`relaxation_mid`: the step's error is second order
in ``h / tau``), and after an accepted step moves it exactly for a pressure linear
between the step's ends (:func:`relaxation_step`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pneubayes.effects.path import CLOSURE_MAX_TERMS, SLOT_INDEX
from pneubayes.physics.calibration import pressure_behind_reading_scalar, reading_zero_scalar

_CL_N = SLOT_INDEX["closure_terms"]
_CL_FA = SLOT_INDEX["closure_feature_a_0"]
_CL_FB = SLOT_INDEX["closure_feature_b_0"]
_CL_TA = SLOT_INDEX["closure_threshold_a_0"]
_CL_TB = SLOT_INDEX["closure_threshold_b_0"]
_CL_RA = SLOT_INDEX["closure_relaxed_a_0"]
_CL_RB = SLOT_INDEX["closure_relaxed_b_0"]

#: How far back, in time constants, the reading's history starts ``p_bar`` (its weight
#: there is e^-5, under 1 %).
RELAXATION_HISTORY = 5.0
#: Most samples of that history read (evenly strided when it holds more).
HISTORY_POINTS = 256


@njit(cache=True, error_model="numpy")
def relaxation_step(pbar, p0, p1, h, tau):
    """``p_bar`` after ``h`` s (Pa) from ``pbar`` for a pressure linear from ``p0`` to
    ``p1`` (Pa) over the step; unchanged for ``h`` <= 0."""
    if not h > 0.0:
        return pbar
    s = (p1 - p0) / h
    return p1 - s * tau + (pbar - p0 + s * tau) * math.exp(-h / tau)


@njit(cache=True, error_model="numpy")
def relaxation_mid(pbar, p, rate, h, tau):
    """``p_bar`` half-way through a step of ``h`` s, the pressure moving from ``p`` (Pa)
    at ``rate`` (Pa/s; the kernel gives the last accepted step's)."""
    return relaxation_step(pbar, p, p + 0.5 * h * rate, 0.5 * h, tau)


@njit(cache=True, error_model="numpy")
def recorded_pressure(t, pm, i, calibrated, p_atm, zero, cal_g):
    """The chamber pressure the recorded reading ``pm[i]`` stands for (Pa): the reading,
    or with ``calibrated`` the pressure behind a miscalibrated sensor's reading at
    ``t[i]``; NaN where the sample is not finite."""
    v = pm[i]
    if math.isfinite(v) and calibrated:
        return pressure_behind_reading_scalar(v, p_atm, reading_zero_scalar(zero, t[i]),
                                              cal_g)
    return v if math.isfinite(v) else math.nan


@njit(cache=True, error_model="numpy")
def relaxation_start(t, pm, k, tau, p_start, calibrated, p_atm, zero, cal_g):
    """``p_bar`` at sample ``k`` (Pa): the recorded reading ``pm`` (chamber pressures
    behind a miscalibrated sensor's readings when ``calibrated``) low-passed from
    :data:`RELAXATION_HISTORY` time constants before ``t[k]`` (or the record's start;
    at most :data:`HISTORY_POINTS` samples of it, strided), non-finite samples skipped;
    ``p_start`` where no sample there is finite."""
    j = k
    while j > 0 and t[k] - t[j - 1] <= RELAXATION_HISTORY * tau:
        j -= 1
    # at most HISTORY_POINTS samples of it, evenly strided (the reading linear between
    # them: a slow low-pass barely sees the difference), so that a one-step prediction
    # at every sample does not walk seconds of history each
    stride = max(1, (k - j) // HISTORY_POINTS)
    j = k - ((k - j) // stride) * stride
    pbar = math.nan
    p_prev = math.nan
    t_prev = 0.0
    for i in range(j, k + 1, stride):
        v = recorded_pressure(t, pm, i, calibrated, p_atm, zero, cal_g)
        if math.isnan(v):
            continue
        if math.isnan(pbar):
            pbar = v
        else:
            pbar = relaxation_step(pbar, p_prev, v, t[i] - t_prev, tau)
        p_prev, t_prev = v, t[i]
    return p_start if math.isnan(pbar) else pbar


@njit(cache=True, error_model="numpy")
def closure_plan(sl):
    """What an open-form closure in the lowered slots ``sl`` reads, which the kernel's
    reuse of a step's end must respect, and its low-passes.

    Returns ``(spool, volume_rate, direction, n, slot, kind, tau, value, pointer,
    held)``: whether a term reads the spool (codes 3, 11, 12, 28-30) or the command's
    direction (code 15; both change only with the command), or the volume rate (code 9;
    a volume hinge's rate, codes 17 and 18); its ``n`` low-passes (code 16 the
    pressure's, 19 the net port flow's, 28 the spool's, for codes 28-30) and dead-time
    windows (codes 31-34, :mod:`pneubayes.simulation.held`): each one's slot, code, time
    constant or dead time (s), value (NaN until started; a window's: the command's
    extreme over it) and a window's command sample at its start; and whether there is
    a window (``held``).
    """
    cl_spool, cl_vdot, cl_dir = False, False, False
    rx_n = 0
    rx_idx = np.zeros(2 * CLOSURE_MAX_TERMS, dtype=np.int64)
    rx_kind = np.zeros(2 * CLOSURE_MAX_TERMS)
    rx_tau = np.zeros(2 * CLOSURE_MAX_TERMS)
    rx_val = np.zeros(2 * CLOSURE_MAX_TERMS)
    rx_ptr = np.zeros(2 * CLOSURE_MAX_TERMS, dtype=np.int64)
    held = False
    for kc in range(int(sl[_CL_N])):
        for code in (sl[_CL_FA + kc], sl[_CL_FB + kc]):
            if code == 3.0 or code == 11.0 or code == 12.0 or 28.0 <= code <= 30.0:
                cl_spool = True
            if code == 15.0:
                cl_spool, cl_dir = True, True
            if code == 9.0 or code == 17.0 or code == 18.0 or code == 35.0:
                cl_vdot = True
        for code, slot, tc in ((sl[_CL_FA + kc], _CL_RA + kc, sl[_CL_TA + kc]),
                               (sl[_CL_FB + kc], _CL_RB + kc, sl[_CL_TB + kc])):
            if code == 16.0 or code == 19.0 or 28.0 <= code <= 30.0:
                # (the command lag's one-way parts low-pass the spool as it does)
                rx_idx[rx_n], rx_kind[rx_n], rx_tau[rx_n] = slot, min(code, 28.0), tc
                rx_n += 1
            elif 31.0 <= code <= 34.0:
                rx_idx[rx_n], rx_kind[rx_n], rx_tau[rx_n] = slot, code, tc
                rx_n += 1
                held = True
    return cl_spool, cl_vdot, cl_dir, rx_n, rx_idx, rx_kind, rx_tau, rx_val, rx_ptr, held


@njit(cache=True, error_model="numpy")
def no_closure_plan():
    """:func:`closure_plan` of a slot row without a closure (the pressure-only kernel's,
    which compiles no closure code)."""
    return (False, False, False, 0, np.zeros(2 * CLOSURE_MAX_TERMS, dtype=np.int64),
            np.zeros(2 * CLOSURE_MAX_TERMS), np.zeros(2 * CLOSURE_MAX_TERMS),
            np.zeros(2 * CLOSURE_MAX_TERMS), np.zeros(2 * CLOSURE_MAX_TERMS, dtype=np.int64),
            False)


@njit(cache=True, error_model="numpy")
def command_relaxation_start(t, u, j, t_start, delay, tau):
    """``s_bar`` at ``t_start`` (command unit): the delayed command (held between
    samples; ``j`` the sample in force at ``t_start``) low-passed exactly from
    :data:`RELAXATION_HISTORY` time constants before (or the record's start, at rest
    there). A lagged spool is read as the command it follows (its lag taken as short
    beside ``tau``)."""
    jj = j
    while jj > 0 and t_start - (t[jj] + delay) < RELAXATION_HISTORY * tau:
        jj -= 1
    sbar = u[jj]
    for k in range(jj, j):
        sbar = u[k] + (sbar - u[k]) * math.exp(-(t[k + 1] - t[k]) / tau)
    h = t_start - (t[j] + delay)
    if h > 0.0 and j > jj:
        sbar = u[j] + (sbar - u[j]) * math.exp(-h / tau)
    return sbar


@njit(cache=True, inline="always", error_model="numpy")
def relaxations_mid(sl, n, slot, kind, tau, value, p, rate, q0, q_rate, s0, s_rate, h):
    """Hold each low-pass over a step of ``h`` s at its midpoint value, written into its
    slot of ``sl``: the pressure's from ``p`` Pa at ``rate`` Pa/s, the net port flow's
    from ``q0`` kg/s at ``q_rate`` kg/s^2 (started there when new), the spool's from
    ``s0`` at ``s_rate`` per s."""
    for q in range(n):
        if kind[q] == 16.0:
            sl[slot[q]] = relaxation_mid(value[q], p, rate, h, tau[q])
        elif kind[q] == 28.0:
            sl[slot[q]] = relaxation_mid(value[q], s0, s_rate, h, tau[q])
        elif kind[q] == 19.0:
            if math.isnan(value[q]):
                value[q] = q0
            sl[slot[q]] = relaxation_mid(value[q], q0, q_rate, h, tau[q])


@njit(cache=True, inline="always", error_model="numpy")
def relaxations_accept(n, kind, tau, value, p0, p1, q0, q1, s0, s1, h):
    """Move each low-pass over an accepted step of ``h`` s (the pressure from ``p0`` to
    ``p1`` Pa, the net port flow from ``q0`` to ``q1`` kg/s, the spool from ``s0`` to
    ``s1``, linear between); returns the step's mean rates of the first two (Pa/s,
    kg/s^2)."""
    for q in range(n):
        if kind[q] == 16.0:
            value[q] = relaxation_step(value[q], p0, p1, h, tau[q])
        elif kind[q] == 28.0:
            value[q] = relaxation_step(value[q], s0, s1, h, tau[q])
        elif kind[q] == 19.0:
            value[q] = relaxation_step(value[q], q0, q1, h, tau[q])
    return (p1 - p0) / h, (q1 - q0) / h
