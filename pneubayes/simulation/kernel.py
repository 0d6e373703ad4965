"""Compiled integrator for the chamber ODE: adaptive exponential Rosenbrock (exprb32).

The chamber pressure obeys a scalar, stiff ODE ``dp/dt = F(t, p)`` (eq. 5) whose
Jacobian ``J = dF/dp`` is known analytically. One step of length h is

    U      = p + h phi1(hJ) F(t, p) + h^2 phi2(hJ) v   (exponential Rosenbrock-Euler)
    D      = F(t + h, U) - F(t, p) - J (U - p) - h v   (nonlinear remainder)
    p_next = U + 2 h phi3(hJ) D                        (exprb32, order 3)

with ``v = dF/dt`` at fixed p (the moving volume, the supply ramp, a moving spool;
without it the method is first order where the inputs change within a step), and
``|2 h phi3(hJ) D|`` the local error estimate. Where the valve switches, the step
restarts at ``max_step_s / 1000`` (a long first step from a port's pressure balance is
accepted on an estimate that misses most of its error). The method is exact for linear
problems, so stiffness (tiny volumes, J ~ -1e8 /s) costs nothing; near equilibrium,
where F has a square-root singularity, a step acts as a damped Newton step.

Inputs follow the recording: the command is held between samples (zero-order hold),
position and supply are linear between samples. A transport delay shifts the held
command, which adds one break point inside some sample intervals; the integrator
stops exactly on every break point. The spool lag (first or second order) is integrated
in closed form under the held command. With
heat transfer (``heat_coupling`` > 0), the chamber temperature is a second state, stepped by
the same method with the full 2 x 2 Jacobian (a diagonal one leaves the method first
order in the p-T coupling). With the tube as an acoustic line, the state is the
chamber's pressure and the line's cells and flows (with heat transfer, and the chamber's
temperature: the line's gas is at the supply's temperature), stepped by the same method
with the full Jacobian (:mod:`pneubayes.simulation.line`). A lagged sensor reading is
stepped in closed form after each accepted step (:mod:`pneubayes.simulation.reading`), a
loaded wall beside the pressure step (:mod:`pneubayes.simulation.loaded_wall`).

Status codes per task: 0 ok, 1 step size underflow, 2 step budget exhausted,
3 non-finite state, 4 an acoustic line not smaller than the dead volume. This module,
:mod:`~pneubayes.simulation.chamber` (the right-hand side),
:mod:`~pneubayes.simulation.thermal` (the (p, T) step),
:mod:`~pneubayes.simulation.line`, :mod:`~pneubayes.simulation.tank`,
:mod:`~pneubayes.simulation.spool`,
:mod:`~pneubayes.simulation.lung` and :mod:`~pneubayes.simulation.reading` are the only
compiled code of the simulator.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit

from pneubayes.compile_cache import first_call, kernel_first_call
from pneubayes.effects.path import (
    LINE_MAX_SEGMENTS,
    SLOT_INDEX,
    TABLE_MAX_POINTS,
    VOLUME_PLAY_COMPLIANCE_SLOTS,
)
from pneubayes.physics.calibration import (
    pressure_behind_reading_scalar,
    reading_slope_scalar,
    reading_zero_rate_scalar,
    reading_zero_scalar,
    sensor_reading_scalar,
)
from pneubayes.physics.valve import gompertz_scalar, switching_scalar, table_scalar
from pneubayes.simulation.chamber import crossed_tables, net_port_flow, rigid_chamber
from pneubayes.simulation.chamber_step import (
    NO_REUSE,
    chamber_step,
    chord_corrected,
    start_rates,
)
from pneubayes.simulation.chord import position_at
from pneubayes.simulation.command_clock import clock_on
from pneubayes.simulation.dense import dense_run, dense_samples
from pneubayes.simulation.held import held_start, held_windows
from pneubayes.simulation.inputs import command_hold, delayed_command, input_segment
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
    S_DENSE,
    S_MAX_STEP,
    S_MAX_STEPS_PER_S,
    S_MIN_STEP,
    S_RTOL,
)
from pneubayes.simulation.line import (
    line_accept,
    line_chamber_rates,
    line_finish,
    line_start,
    line_step,
    line_volume,
    line_workspace,
)
from pneubayes.simulation.loaded_wall import (
    wall_accept,
    wall_chord,
    wall_constants,
    wall_max_step,
    wall_on,
    wall_start,
)
from pneubayes.simulation.lung import lung_step
from pneubayes.simulation.reading import (
    line_reading_deviation,
    reading_lags,
    reading_start,
    reading_step,
)
from pneubayes.simulation.relaxation import (
    closure_plan,
    command_relaxation_start,
    no_closure_plan,
    relaxation_start,
    relaxations_accept,
    relaxations_mid,
)
from pneubayes.simulation.spool import (
    first_order_lag,
    spool_at_end,
    spool_at_start,
    spool_settings,
    spool_step,
)
from pneubayes.simulation.tank import tank_step
from pneubayes.simulation.task_threads import run_chunks
from pneubayes.simulation.thermal import thermal_step
from pneubayes.simulation.volume_play import play_accept, play_on, play_start
from pneubayes.simulation.wave import (
    WAVE_CAPACITY,
    WAVE_CARRY,
    wave_accept,
    wave_chamber_step,
    wave_constants,
    wave_grid,
    wave_grid_step,
    wave_start,
    wave_state,
    wave_switch,
    wave_volume,
    wave_window_end,
    wave_workspace,
)

OK, STEP_UNDERFLOW, STEP_BUDGET, NONFINITE, LINE_VOLUME, NEEDS_GENERAL = 0, 1, 2, 3, 4, 5
WAVE_HISTORY = 6
CALIBRATION = 7
STATUS_TEXT = {OK: "ok", STEP_UNDERFLOW: "step size fell below min_step_s",
               STEP_BUDGET: "more steps in one window than max_steps_per_s allows",
               NONFINITE: "state became non-finite",
               LINE_VOLUME: "the acoustic line's volume is not smaller than the dead volume",
               NEEDS_GENERAL: "a form with a second state or a closure reached the "
                              "pressure-only kernel (an internal error)",
               WAVE_HISTORY: f"more than {WAVE_CAPACITY} entries within one transit time "
                             "of the transmission-line tube (an internal error)",
               CALIBRATION: "the sensor's calibration reads the measured start as no "
                            "pressure > 0 absolute (below vacuum, or beyond a curved "
                            "sensor's turning point)"}
#: Length of the state carried from one window to the next: the chamber temperature,
#: an acoustic line's cell pressures and flows (NaN: start the line at rest) or a
#: transmission-line tube's waves (:func:`~pneubayes.simulation.wave.wave_finish`), a
#: supply tank's pressure (NaN: start at the window's supply) and a second
#: compartment's pressure (NaN: start at the window's initial pressure).
N_CARRY = 3 + max(2 * LINE_MAX_SEGMENTS, WAVE_CARRY)
CARRY_TANK = N_CARRY - 2
CARRY_LUNG = N_CARRY - 1


_IN = SLOT_INDEX["inlet_offset_m2"]
_EX = SLOT_INDEX["exhaust_offset_m2"]
_VOL = SLOT_INDEX["volume_m3"]
_DEAD = SLOT_INDEX["deadband_halfwidth_V"]
_ROUND = SLOT_INDEX["deadband_rounding_V"]
_SUPG = SLOT_INDEX["supply_gain"]
_HCOUP = SLOT_INDEX["heat_coupling"]
_HWOFF = SLOT_INDEX["heat_wall_offset_K"]
_LLEN = SLOT_INDEX["line_length_m"]
_LSEG = SLOT_INDEX["line_segments"]
_WLEN = SLOT_INDEX["wave_length_m"]
_OPEN_IN = SLOT_INDEX["inlet_open_area_m2"]
_OPEN_EX = SLOT_INDEX["exhaust_open_area_m2"]
_OWN_EX = SLOT_INDEX["exhaust_own_command"]
_TANK = SLOT_INDEX["tank_volume_m3"]
_LUNG = SLOT_INDEX["lung_volume_m3"]
_CL_N = SLOT_INDEX["closure_terms"]
_TAB_N = SLOT_INDEX["table_points"]
_TAB_C = SLOT_INDEX["table_command_0"]
_TAB_I = SLOT_INDEX["table_inlet_m2_0"]
_TAB_E = SLOT_INDEX["table_exhaust_m2_0"]
_TAB_MAX = TABLE_MAX_POINTS
_ADVANCE = SLOT_INDEX["inputs_advance_s"]
_CAL_OFFSET = SLOT_INDEX["reading_offset_Pa"]
_CAL_GAIN = SLOT_INDEX["reading_gain_error"]
_CURVATURE = SLOT_INDEX["reading_curvature_Pa"]
_DRIFT = SLOT_INDEX["reading_drift_Pa_per_s"]
_WARM = SLOT_INDEX["reading_warm_up_Pa"]
_WARM_TAU = SLOT_INDEX["reading_warm_up_time_constant_s"]
_SPOOL_W = SLOT_INDEX["spool_natural_frequency_rad_per_s"]
_CLOCK_T = SLOT_INDEX["command_clock_period_s"]


@njit(cache=True, inline="always", error_model="numpy")
def _gompertz_rate(u, a, b, c, d):
    """d(area)/du of eq. 11 (without the offset), m^2/V."""
    inner = math.exp(-c * (u + d))
    return a * math.exp(-b * inner) * b * c * inner


@njit(cache=True, inline="always", error_model="numpy")
def _dead_band(spool, dead, rounding):
    """The opening past the dead band and its slope d/d(spool) (see
    :func:`pneubayes.simulation.rates.dead_band`; corners rounded over ``rounding`` V)."""
    z = abs(spool) - dead
    if rounding > 0.0 and abs(z) < rounding:
        t = (z + rounding) / (2.0 * rounding)
        mag = 2.0 * rounding * t * t * t * (1.0 - 0.5 * t)
        slope = t * t * (3.0 - 2.0 * t)
    elif z > 0.0:
        mag, slope = z, 1.0
    else:
        return 0.0, 0.0
    return (mag if spool > 0.0 else -mag), slope


@njit(cache=True, error_model="numpy")
def _areas(spool, dead, sl):
    """Port areas (eq. 11) for spool position ``spool`` behind a dead band of half-width
    dead; the exhaust's is 0 when it is a separate valve (:func:`_own_exhaust_area`)."""
    u = _dead_band(spool, dead, sl[_ROUND])[0]
    own = sl[_OWN_EX] != 0.0
    a_in = gompertz_scalar(u, sl[_IN], sl[_IN + 1], sl[_IN + 2], sl[_IN + 3], sl[_IN + 4])
    a_ex = 0.0
    if not own:
        a_ex = gompertz_scalar(u, sl[_EX], sl[_EX + 1], sl[_EX + 2], sl[_EX + 3],
                               sl[_EX + 4])
    if sl[_OPEN_IN] != 0.0 or (sl[_OPEN_EX] != 0.0 and not own):
        s_in, s_ex = switching_scalar(u, sl[_OPEN_IN], 0.0 if own else sl[_OPEN_EX])
        a_in += s_in
        a_ex += s_ex
    n = int(sl[_TAB_N])
    if n > 0:  # a tabulated map (its exhaust table is 0 beside a separate exhaust)
        cmds = sl[_TAB_C:_TAB_C + _TAB_MAX]
        a_in += table_scalar(u, cmds, sl[_TAB_I:_TAB_I + _TAB_MAX], n)[0]
        a_ex += table_scalar(u, cmds, sl[_TAB_E:_TAB_E + _TAB_MAX], n)[0]
    return a_in, a_ex


@njit(cache=True, error_model="numpy")
def _held_areas(sl, t, u, j, cmd, delay, tau, t_end, dead, closure):
    """Write each dead-time window's port area change at ``tau`` into its slot (m^2: the
    port's area at the window's extreme command less at ``cmd``, :mod:`.held`) and
    return the stretch's end ``t_end`` cut where a window's extreme may next change."""
    rx_n, rx_idx, rx_kind, rx_tau, rx_val, rx_ptr = closure[3:9]
    t_end = held_windows(t, u, j, delay, tau, t_end, rx_n, rx_kind, rx_tau, rx_val, rx_ptr)
    a_in, a_ex = _areas(cmd, dead, sl)
    for q in range(rx_n):
        if rx_kind[q] >= 31.0:
            h_in, h_ex = _areas(rx_val[q], dead, sl)
            odd = rx_kind[q] == 31.0 or rx_kind[q] == 33.0  # (the inlet's)
            sl[rx_idx[q]] = h_in - a_in if odd else h_ex - a_ex
    return t_end


@njit(cache=True, error_model="numpy")
def _own_exhaust_area(ue, sl):
    """A separately commanded exhaust valve's area at its command ``ue``, m^2: the exhaust
    map (eq. 11) of ue plus the open area times clip(ue, 0, 1); 0 without one."""
    if sl[_OWN_EX] == 0.0:
        return 0.0
    f = 0.0 if ue <= 0.0 else (1.0 if ue >= 1.0 else ue)
    return (gompertz_scalar(ue, sl[_EX], sl[_EX + 1], sl[_EX + 2], sl[_EX + 3], sl[_EX + 4])
            + sl[_OPEN_EX] * f)


@njit(cache=True, error_model="numpy")
def _area_rates(spool, spool_rate, dead, sl):
    """Time derivatives of the two port areas for a spool moving at ``spool_rate`` V/s."""
    u, slope = _dead_band(spool, dead, sl[_ROUND])
    if slope == 0.0:
        return 0.0, 0.0
    spool_rate = spool_rate * slope
    own = sl[_OWN_EX] != 0.0  # a separate exhaust valve does not move with the spool
    r_in = _gompertz_rate(u, sl[_IN + 1], sl[_IN + 2], sl[_IN + 3], sl[_IN + 4])
    r_ex = 0.0 if own else _gompertz_rate(u, sl[_EX + 1], sl[_EX + 2], sl[_EX + 3],
                                          sl[_EX + 4])
    if 0.0 < u < 1.0:  # a switching valve's areas move with its opening
        r_in += sl[_OPEN_IN]
        if not own:
            r_ex -= sl[_OPEN_EX]
    n = int(sl[_TAB_N])
    if n > 0:
        cmds = sl[_TAB_C:_TAB_C + _TAB_MAX]
        r_in += table_scalar(u, cmds, sl[_TAB_I:_TAB_I + _TAB_MAX], n)[1]
        r_ex += table_scalar(u, cmds, sl[_TAB_E:_TAB_E + _TAB_MAX], n)[1]
    return r_in * spool_rate, r_ex * spool_rate


@njit(cache=True, inline="always", error_model="numpy")
def _spool_areas(moving, s_cur, v_cur, s_start, cmd, tau, t_sub, hh, spool_cfg, sl, a_own,
                 a_in, a_ex, s_eff, general):
    """The port areas, their rates and the spool at ``tau`` and ``tau + hh`` of a held
    command's stretch from ``t_sub`` (a moving spool: stepped from ``(s_cur, v_cur)`` in
    the second order, in closed form from ``s_start`` in the first; else the cached
    areas at ``s_eff``; ``spool_cfg`` as :func:`_march` takes it). Returns ``(a_in,
    a_ex, da_in, da_ex, s_at, ds_at, a_in2, a_ex2, s_at2, s2, v2)``, ``(s2, v2)`` the
    second-order spool's state at ``tau + hh`` (a second-order spool: the general kernel
    only, ``general`` not None)."""
    _, tau_s, tau_dn, w_s, z_s, rate_s, spool2, _, dead = spool_cfg
    da_in, da_ex = 0.0, 0.0
    s_at, ds_at = s_eff, 0.0
    s2, v2 = s_eff, v_cur
    if not moving:
        return a_in, a_ex, da_in, da_ex, s_at, ds_at, a_in, a_ex, s_at, s2, v2
    if general is not None and spool2:
        s_at, ds_at = s_cur, v_cur
        s2, v2 = spool_step(s_cur, v_cur, cmd, hh, 0.0, w_s, z_s, 0.0, 0.0)
    else:
        s_at, ds_at = first_order_lag(s_start, cmd, tau - t_sub, tau_s, rate_s, tau_dn)
        s2 = first_order_lag(s_start, cmd, tau + hh - t_sub, tau_s, rate_s, tau_dn)[0]
    a_in, a_ex = _areas(s_at, dead, sl)
    a_ex += a_own
    da_in, da_ex = _area_rates(s_at, ds_at, dead, sl)
    a_in2, a_ex2 = _areas(s2, dead, sl)
    a_ex2 += a_own
    return a_in, a_ex, da_in, da_ex, s_at, ds_at, a_in2, a_ex2, s2, s2, v2


@njit(cache=True, inline="always", error_model="numpy")
def _stretch_areas(s_eff, s_cached, a_in, a_ex, cmd, cmd_cached, lagged, h, err_last, hmax,
                   dead, sl):
    """``(a_in, a_ex, s_cached, h, err_last)`` at a held command's stretch: the port areas
    at the spool ``s_eff``, cached while it holds. Where the valve switched the step
    restarts small (a long first step from a port's balance, where the flow has a
    square-root kink, is accepted on an estimate that misses most of its error); behind
    a lagged spool the areas are continuous: it restarts where the command steps."""
    if s_eff != s_cached:
        a_in, a_ex = _areas(s_eff, dead, sl)
        s_cached = s_eff
        if not lagged or cmd != cmd_cached:
            h = min(h, 1e-3 * hmax)
            err_last = 0.0
    return a_in, a_ex, s_cached, h, err_last


@njit(cache=True, inline="always", error_model="numpy")
def _grown_step(h, hh, err, err_last, crossing, hmax):
    """The next step size after an accepted step of ``hh`` s with error ``err``: grown
    only when it was not cut short by a break point, shrunk when the error asks
    (0.9 / cbrt(err) < 1 iff err > 0.729). Where steps cross samples (dense output) a
    step grows on the larger of its own and its predecessor's error: a curvature
    changing sign gives one small estimate by cancellation, and a step grown 5x on it is
    accepted with an error the estimate misses."""
    if hh >= h or err > 0.729:
        e_g = max(err, err_last) if crossing else err
        fac = 5.0 if e_g < 1e-4 else min(5.0, 0.9 / np.cbrt(e_g))
        h = min(hmax, hh * fac)
    return h


@njit(cache=True, error_model="numpy", _nrt=False)
def _march(sl, cs, sv, t, u, ue, x, ps, i0, length, p0, out, sens, carry, general, forms,
           calibration, spool_cfg, sensor, closure, start, line_state, wave_state, chamber,
           wall):
    """Step one window :func:`_window` prepared (the arguments as it takes them) to its
    end, writing ``out``, ``sens`` and ``carry``; returns its status. The tuples, as
    :func:`_window` builds them: the forms present, the reading's calibration, the
    delayed command and spool, the sensor's lag, a closure's reads and low-passes, the
    start state, a tube's workspaces, the chamber's constants and a loaded wall's
    (``loaded_wall.py``)."""
    rtol, atol_p, atol_t = sv[S_RTOL], sv[S_ATOL_P], sv[S_ATOL_T]
    hmax, hmin = sv[S_MAX_STEP], sv[S_MIN_STEP]
    n, p_atm, kap = t.shape[0], cs[C_P_ATM], cs[C_KAPPA]
    thermal, own_ex, tank, lung, line, wave, plain, shaped, dense, rigid, reading, want_sens = (
        forms)
    calibrated, zero, cal_g, slope0 = calibration
    delay, tau_s, tau_dn, w_s, z_s, rate_s, spool2, lagged, dead = spool_cfg
    lag_r, w_r, z_r, n_r, second = sensor
    cl_spool, cl_vdot, cl_dir, rx_n, rx_idx, rx_kind, rx_tau, rx_val, rx_ptr, held = closure
    k0, t_start, max_steps, r, v_r, p, temp, p_tank, p_lung, s_t0, j, cdir, spool, v_s, m = (
        start)
    nseg, ny, y, y_new, s_vec, prop, line_work = line_state
    w_work, tube, grid, w_near = wave_state
    v0, bore, gain, adv, p_nom, c_tank = chamber
    walled, w_consts, w_state, w_hmax = wall
    w_rate = 0.0  # the last accepted step's mean rate of p (Pa/s), which the wall takes on
    cl_relax, play = rx_n > 0, play_on(sl)
    # the last accepted step's mean rates of p (Pa/s) and of the net port flow
    # (kg/s^2), at which a relaxation's midpoint value takes them on
    rx_rate, rx_qrate, rx_q0 = 0.0, 0.0, 0.0
    s_p0, s_r, s_v = 1.0, 1.0, 0.0  # d(p, reading, its rate)/dp0
    prop_t = (1.0, 0.0, 0.0, 1.0)  # a second state's step propagator (row-major)
    w_switch = (-math.inf, 0.0, 0.0, math.nan, math.nan)  # no switch yet
    a_in2, a_ex2, psup2 = 0.0, 0.0, 0.0
    x0c, x1c = 0.0, 0.0  # a chord step's positions at its ends (dense output), m
    c_c = 0.0  # its coupling (Pa / (m s)); the flows' slope is jf
    qstep = False  # the pressure step's variable is q = p V^n
    sc0, sc1 = 1.0, 1.0  # its scale V^n (1 for p) at the step's ends
    jf = 0.0  # the flows' slope (1/s) over a chord
    h, err_last, steps = hmax, 0.0, 0  # (err_last: the last accepted step's estimate)
    s_cached, cmd_cached, a_in_c, a_ex_c = math.nan, math.nan, 0.0, 0.0
    k_last = i0 + length - 1
    fp, vp, ep = 0.0, 0.0, 0.0  # the last step's rate, its rate of change, its correction
    zp, phi3p = 0.0, 1.0
    fs = NO_REUSE  # first same as last (chamber_step.py)
    c_ok, c_fp, c_jp, c_vp = False, 0.0, 0.0, 0.0
    k = k0
    while k < k_last:
        # the samples this pass integrates to: the next, or with dense output the run
        # over which the supply holds (where the model reads it)
        kn, chord = dense_run(x, ps, k, k_last, gain != 0.0) if dense else (k + 1, False)
        kw = k + 1  # the next sample to read from a step's interpolant (dense output)
        if k == i0 and k0 < i0:  # end of the warm-up: the reading is the measured p0
            lead = p - r
            r = p0
            p = p0 + lead if p0 + lead > 0.0 else p0
            if general is not None and line:
                y[0] = p
            s_p0, s_r, s_v = 1.0, 1.0, 0.0
            fs = NO_REUSE
        tb = t[kn]
        a_own = _own_exhaust_area(ue[k], sl) if own_ex else 0.0
        tau = t[k] if k > k0 else t_start
        while tau < tb:
            # a stretch [tau, t_end) on which the delayed command is constant, and the
            # position and supply linear from (ta, xa / sa)
            j, cdir, cmd, t_end = command_hold(sl, t, u, j, cdir, cl_dir, delay, tau, tb,
                                               kn > k + 1, general)
            m, ta, inv_seg, xa, xb, sa, sb, t_end = input_segment(t, x, ps, m, tau, adv,
                                                                  t_end, kn == k + 1)
            if general is not None and wave and grid[1] < t_end - w_near:
                t_end = grid[1]  # the tube's ends update on their grid
            if general is not None and held:  # a late valve's areas, held over the stretch
                t_end = _held_areas(sl, t, u, j, cmd, delay, tau, t_end, dead, closure)
            vdot = bore * (xb - xa) * inv_seg
            dsup = gain * (sb - sa) * inv_seg
            m_ch = m  # the chord's pointer: the segment holding tau
            spool_a, t_sub = spool, tau
            # port areas are constant on the stretch unless the spool moves; the command
            # is held for many samples, so reuse them while it is unchanged
            moving = lagged and (spool_a != cmd or v_s != 0.0)
            s_eff = spool_a if lagged else cmd
            s_cur, v_cur = spool_a, v_s  # the second-order spool at tau
            a_in_c, a_ex_c, s_cached, h, err_last = _stretch_areas(
                s_eff, s_cached, a_in_c, a_ex_c, cmd, cmd_cached, lagged, h, err_last, hmax,
                dead, sl)
            cmd_cached = cmd
            a_in, a_ex = a_in_c, a_ex_c + a_own
            if general is not None and wave:
                ok, w_switch, t_end = wave_switch(w_work, tube, w_switch, tau, t_end, p, s_p0,
                                                  psup2, a_in, a_ex, w_near, cs)
                if not ok:
                    return WAVE_HISTORY
            while tau < t_end:
                if walled and h > w_hmax:
                    h = w_hmax
                hh = h if h < t_end - tau else t_end - tau
                if t_end - tau - hh < 1e-3 * hh:
                    hh = t_end - tau
                steps += 1
                if steps > max_steps:
                    return STEP_BUDGET
                # the inputs at tau and tau + hh (stage 2)
                fr, fr2 = (tau - ta) * inv_seg, (tau + hh - ta) * inv_seg
                vol, vol2 = v0 + bore * (xa + fr * (xb - xa)), v0 + bore * (xa + fr2 * (xb - xa))
                psup = p_nom + gain * (sa + fr * (sb - sa) - p_nom)
                psup2 = p_nom + gain * (sa + fr2 * (sb - sa) - p_nom)
                (a_in, a_ex, da_in, da_ex, s_at, ds_at, a_in2, a_ex2, s_at2, s2,
                 v2) = _spool_areas(moving, s_cur, v_cur, spool_a, cmd, tau, t_sub, hh,
                                    spool_cfg, sl, a_own, a_in, a_ex, s_eff, general)
                if chord:  # dense output over a moving position: the step reads its chord
                    m_ch, x0c = position_at(t, x, n, m_ch, tau)
                    x1c = position_at(t, x, n, m_ch, tau + hh)[1]
                    vol, vol2 = v0 + bore * x0c, v0 + bore * x1c
                    vdot = bore * (x1c - x0c) / hh
                # the step's volume rate (m^3/s): the position's and a loaded wall's
                vol, vol2, vd = wall_chord(walled, w_state, p, w_rate, hh, vol, vol2, vdot,
                                           p_atm, w_consts, general)
                if general is not None and cl_relax:
                    rx_q0 = net_port_flow(p, a_in, a_ex, psup, cs, sl)
                    relaxations_mid(sl, rx_n, rx_idx, rx_kind, rx_tau, rx_val, p, rx_rate,
                                    rx_q0, rx_qrate, s_at, ds_at, hh)
                err = 10.0
                pn, tn = p, temp
                p_tank_new, p_lung_new = p_tank, p_lung
                zp = 0.0
                dev_r = 0.0  # a first-order reading's departure from the chord's
                if general is not None and line:
                    err = line_step(y, nseg, hh, a_in, a_ex, vol, vd, psup, dsup, da_in,
                                    da_ex, a_in2, a_ex2, vol2, psup2, sl, cs, atol_p,
                                    atol_t, rtol, y_new, prop, line_work)
                    pn = y_new[0]
                    if thermal:
                        tn = y_new[ny - 1]
                    if reading and err < 10.0:
                        dev_r, err = line_reading_deviation(
                            err, p, pn, line_chamber_rates(line_work), hh, r, sensor, p_atm,
                            atol_p, rtol)
                elif general is not None and tank:
                    err, pn, p_tank_new, prop_t = tank_step(p, p_tank, hh, a_in, a_ex, vol,
                                                            vd, da_in, da_ex, a_in2, a_ex2,
                                                            vol2, sl, cs, c_tank, atol_p,
                                                            rtol, s_at, ds_at, s_at2, cdir,
                                                            general)
                elif general is not None and lung:
                    err, pn, p_lung_new, prop_t = lung_step(p, p_lung, hh, a_in, a_ex, vol,
                                                            vd, psup, dsup, da_in, da_ex,
                                                            a_in2, a_ex2, vol2, psup2, sl, cs,
                                                            atol_p, rtol, s_at, ds_at, s_at2,
                                                            cdir, general)
                elif general is not None and wave:
                    err, pn, fp, jp, vp, ep, zp, phi3p, w_gain = wave_chamber_step(
                        p, temp, hh, tau, vol, vd, psup, vol2, psup2, s_at, ds_at, s_at2,
                        cdir, sl, cs, grid, tube, w_work[2][2], ep, atol_p, rtol, general)
                elif general is not None and thermal:
                    err, pn, tn, prop_t, fp, jp, vp = thermal_step(
                        p, temp, hh, a_in, a_ex, vol, vd, psup, dsup, da_in, da_ex, a_in2,
                        a_ex2, vol2, psup2, sl, cs, atol_p, atol_t, rtol, s_at, ds_at, s_at2,
                        cdir, general)
                    zp = hh * jp  # (the pressure's own part: a lagged reading's shape)
                else:
                    fp, jp, vp, fs = start_rates(
                        p, temp, hh, a_in, a_ex, vol, vd, psup, dsup, da_in, da_ex, s_at,
                        ds_at, cdir, sl, cs, fs, m, moving or chord or walled, cl_relax,
                        cl_spool,
                        rigid and gain == 0.0 and not cl_vdot, general)
                    (err, pn, fp, vp, ep, zp, phi3p, qstep, sc0, sc1, ff, jf, c_ok, c_fp,
                     c_jp, c_vp) = chamber_step(p, temp, hh, fp, jp, vp, ep, vol, vd, a_in2,
                                                a_ex2, vol2, psup2, dsup, s_at2, cdir, sl, cs,
                                                kap, rigid, chord, fs[0], atol_p, rtol,
                                                general)
                    if err < 10.0 and chord and m_ch + 1 < n and t[m_ch + 1] < tau + hh:
                        err, pn, c_c = chord_corrected(err, pn, p, t, x, m_ch, tau, hh, x0c,
                                                       x1c, ff, jf, vol, bore, kap, sc0, sc1,
                                                       atol_p, rtol)
                    if not (pn > 0.0 and math.isfinite(pn)):
                        err = 10.0
                if err <= 1.0:
                    fs = ((fs[0], c_fp, c_jp, c_vp, vdot, m, fs[6], fs[7], fs[8]) if c_ok
                          else NO_REUSE)
                    t_prev = tau
                    tau = tau + hh if hh < t_end - tau else t_end
                    if moving and spool2:
                        s_cur, v_cur = s2, v2
                    p_prev, s_prev, p_tank, p_lung = p, s_p0, p_tank_new, p_lung_new
                    p, temp = pn, tn
                    w_state, w_rate = wall_accept(walled, w_state, p_prev, p, tau - t_prev,
                                                  p_atm, w_consts, general)
                    if general is not None and play and play_accept(sl, p_prev, p, p_atm):
                        fs = NO_REUSE  # the table was laid again at a play's turn
                    if general is not None and cl_relax:
                        rx_rate, rx_qrate = relaxations_accept(
                            rx_n, rx_kind, rx_tau, rx_val, p_prev, p, rx_q0,
                            net_port_flow(p, a_in2, a_ex2, psup2, cs, sl), s_at, s_at2,
                            tau - t_prev)
                    # dp/dp0: through the line's propagator, the chamber and the arriving
                    # wave, the (p, second state) propagator, or the pressure step's e^{hJ}
                    if general is not None and line:
                        s_p0 = line_accept(y, y_new, prop, s_vec, want_sens, line_work)
                    elif general is not None and wave:
                        s_p0 = crossed_tables(math.exp(zp) * s_p0 + w_gain, rigid, p_prev, p,
                                              vol2, sl, p_atm, kap)
                        ok, w_switch, grid = wave_accept(w_work, tube, w_switch, grid, t[0],
                                                         tau, p, s_p0, psup2, a_in2, a_ex2,
                                                         w_near, cs)
                        if not ok:
                            return WAVE_HISTORY
                    elif thermal or tank or lung:
                        if want_sens:
                            s_p0, s_t0 = (prop_t[0] * s_p0 + prop_t[1] * s_t0,
                                          prop_t[2] * s_p0 + prop_t[3] * s_t0)
                    elif want_sens:
                        s_p0 = crossed_tables(s_p0 * math.exp(zp) * sc0 / sc1, rigid, p_prev,
                                              p, vol2, sl, p_atm, kap)
                    if kn > k + 1:
                        kw = dense_samples(
                            out, sens, t, x, i0, kw, kn,
                            (t_prev, tau, hh, p_prev, s_prev, sc0, zp, fp, vp, ep, phi3p),
                            (chord, qstep, x0c, x1c, jf, c_c), v0, bore, kap, sl, p_atm,
                            calibrated, zero, cal_g, slope0, want_sens)
                    if reading:
                        r, v_r, s_r, s_v = reading_step(r, v_r, s_r, s_v, p_prev, p, s_prev,
                                                        s_p0, hh, zp, fp, vp, ep, dev_r,
                                                        second, w_r, z_r, lag_r, n_r, p_atm,
                                                        plain, shaped, want_sens)
                    h = _grown_step(h, hh, err, err_last, kn > k + 1, hmax)
                    err_last = err
                else:
                    if not math.isfinite(err):
                        err = 10.0
                    h = hh * max(0.1, 0.9 / np.cbrt(err))
                    if h < hmin:
                        if not (math.isfinite(p) and math.isfinite(temp)):
                            return NONFINITE
                        return STEP_UNDERFLOW
            spool, v_s = spool_at_end(spool2, s_cur, v_cur, spool_a, v_s, cmd, t_end - t_sub,
                                      tau_s, w_s, rate_s, tau_dn)
        if k >= i0:
            _write_sample(out, sens, kn - i0, r if reading else p, s_r if reading else s_p0,
                          t[kn], calibration, p_atm, want_sens)
        k = kn
    carry[0] = temp
    if general is not None and line:
        line_finish(y, carry, nseg)
    if general is not None and wave and not wave_window_end(
            w_work, tube, w_switch, carry, t[i0 + length - 1], p, s_p0, psup2, a_in2, a_ex2,
            w_near, cs):
        return WAVE_HISTORY
    carry[CARRY_TANK] = p_tank if tank else carry[CARRY_TANK]
    carry[CARRY_LUNG] = p_lung if lung else carry[CARRY_LUNG]
    return OK


@njit(cache=True, error_model="numpy")
def _write_sample(out, sens, i, value, s, t_i, calibration, p_atm, want_sens):
    """Write output sample ``i``: the reading of the state ``value`` (Pa; through the
    sensor's calibration at time ``t_i``) and its sensitivity ``s`` to the start."""
    calibrated, zero, cal_g, slope0 = calibration
    out[i] = (sensor_reading_scalar(value, p_atm, reading_zero_scalar(zero, t_i), cal_g)
              if calibrated else value)
    if want_sens:
        sens[i] = s
        if cal_g[1] != 0.0:  # a curved sensor: d(reading)/d(its start)
            sens[i] *= reading_slope_scalar(value, p_atm, cal_g) / slope0


@njit(cache=True, error_model="numpy")
def _window(sl, cs, sv, t, u, ue, x, ps, pm, i0, length, p0, rate0, out, sens, carry,
            general):
    """Integrate one window of ``length`` samples from ``t[i0]`` with p(t[i0]) = p0.

    How each form is stepped (sensor lag and calibration, inputs advance, second-order
    spool, dense output and the q = p V^n step, first same as last, second states, the
    closure) is in ``docs/architecture.md``, "One window (kernel._window)".

    Parameters
    ----------
    sl, cs, sv : float64 vectors
        One parameter set's lowered slots; the rig's and gas's constants; the solver
        settings (``sv[S_DENSE] > 0``: dense output); layouts in ``simulation/layout.py``.
    t, u, ue, x, ps : (N,) float64
        Time (s), command (V, held), a separate exhaust valve's command (held; read with
        slot ``exhaust_own_command``), position (m) and supply (Pa), linear between.
    pm : (N,) float64
        The recorded reading (Pa; NaN: unknown), where a lagged reading's warm-up starts.
    i0, length : int
        The window's first sample and its samples, the start included.
    p0, rate0 : float
        The reading at the start (Pa) and its rate (Pa/s), which starts a lagged sensor's
        chamber at ``p0 + tau * rate0``; ``rate0`` NaN: warm up over 5 settling times of
        command history before the start.
    out, sens : float64 (length,)
        Receive the reading (Pa) and dp(t)/dp0 (``sens`` empty: skipped), the product of
        the accepted steps' ``exp(h J)``.
    carry : float64 (N_CARRY,)
        The unmeasured states at the start, replaced by those at the end: ``carry[0]`` the
        chamber temperature (K), ``carry[1:1 + 2 * LINE_MAX_SEGMENTS]`` a line's cell
        pressures and flows (NaN: at rest at p0), ``carry[CARRY_TANK]`` a supply tank's
        (NaN: the supply) and ``carry[CARRY_LUNG]`` a second compartment's (NaN: p0).
    general : None or True
        None compiles the pressure-only kernel (numba prunes the second-state forms).

    Returns
    -------
    int
        ``OK`` (0), or a failure: ``STEP_UNDERFLOW``, ``STEP_BUDGET``, ``NONFINITE``,
        ``LINE_VOLUME``, ``NEEDS_GENERAL``, ``WAVE_HISTORY`` or ``CALIBRATION``.
    """
    n = t.shape[0]
    # the sensor's calibration: reading = P_atm + g y + k (y / 1 bar)^2 + o(t), y = p - P_atm
    p_atm = cs[C_P_ATM]
    # (its zero o(t) = o + a t + b (1 - exp(-t / tau)) on the recording's clock)
    zero = (sl[_CAL_OFFSET], sl[_DRIFT], sl[_WARM], sl[_WARM_TAU])
    cal_g = (1.0 + sl[_CAL_GAIN], sl[_CURVATURE])  # (g, k)
    calibrated = (zero[0] != 0.0 or cal_g[0] != 1.0 or zero[1] != 0.0 or zero[2] != 0.0
                  or cal_g[1] != 0.0)
    slope0 = 1.0  # d(reading)/dp at the start (a curved sensor's sensitivity ratio)
    p0_read = p0
    if calibrated:
        p0 = pressure_behind_reading_scalar(p0, p_atm, reading_zero_scalar(zero, t[i0]),
                                            cal_g)
        slope0 = reading_slope_scalar(p0, p_atm, cal_g)
        rate0 = (rate0 - reading_zero_rate_scalar(zero, t[i0])) / slope0
        if not p0 > 0.0:
            return CALIBRATION
    # step budget: max_steps_per_s per simulated second, beyond the one step each
    # sample interval takes at least
    max_steps = (length - 1) + int(sv[S_MAX_STEPS_PER_S] * (t[i0 + length - 1] - t[i0]))
    delay, tau_s, tau_dn, w_s, z_s, rate_s, spool2, lagged = spool_settings(sl)
    dead, gain = sl[_DEAD], sl[_SUPG]
    # position and supply are read at t + adv (linear between their samples, held after
    # the last): their sample times, shifted by -adv, are break points of the steps
    adv = sl[_ADVANCE]
    p_nom = cs[C_P_NOM]
    v0, bore = sl[_VOL], cs[C_BORE_AREA]
    thermal = sl[_HCOUP] > 0.0  # the pressure feels the temperature: a state
    own_ex = sl[_OWN_EX] != 0.0
    tank = sl[_TANK] > 0.0
    # a tank's pressure falls by c_tank per kg drawn (polytropic index n, air at T_s)
    c_tank = cs[C_KAPPA] * cs[C_RS] * cs[C_T_SUPPLY] / sl[_TANK] if tank else 0.0
    p_tank = carry[CARRY_TANK]
    if tank and math.isnan(p_tank):
        p_tank = p_nom + gain * (ps[i0] - p_nom)
    lung = sl[_LUNG] > 0.0
    p_lung = carry[CARRY_LUNG]
    lung_from_p0 = lung and math.isnan(p_lung)
    # an open-form closure's reads and low-passes, stepped on the kernel's own copy of
    # the slots
    # (the pressure-only kernel compiles none of it: a closure runs in the general one)
    if general is not None:
        cl_spool, cl_vdot, cl_dir, rx_n, rx_idx, rx_kind, rx_tau, rx_val, rx_ptr, held = (
            closure_plan(sl))
    else:
        if sl[_CL_N] > 0.0:
            return NEEDS_GENERAL
        cl_spool, cl_vdot, cl_dir, rx_n, rx_idx, rx_kind, rx_tau, rx_val, rx_ptr, held = (
            no_closure_plan())
    cl_relax = rx_n > 0
    if general is not None and cl_relax:
        sl = sl.copy()
        for q in range(rx_n):
            if not rx_tau[q] > 0.0:
                return NONFINITE
    if lung_from_p0:
        p_lung = p0
    if general is None and (thermal or tank or lung or sl[_LLEN] > 0.0 or sl[_WLEN] > 0.0
                            or spool2 or clock_on(sl)):
        return NEEDS_GENERAL
    lag_r, w_r, z_r, n_r, second, reading, lead_s, settle_s = reading_lags(sl, p0, p_atm)
    k0, t_start, r, v_r, p = reading_start(t, pm, i0, p0, rate0, reading, lead_s, settle_s,
                                           calibrated, p_atm, zero, cal_g)
    max_steps += i0 - k0
    if general is not None:  # a relaxation's p_bar from the reading's history; a flow's
        for q in range(rx_n):  # low-pass at its first step's flow (at rest)
            rx_val[q] = (relaxation_start(t, pm, k0, rx_tau[q], p, calibrated, p_atm, zero,
                                          cal_g) if rx_kind[q] == 16.0 else math.nan)
    temp = cs[C_T_SUPPLY]
    if thermal:
        temp = carry[0]
        if math.isnan(temp):  # a recording's start: the gas at rest at its wall's
            temp = cs[C_T_SUPPLY] + sl[_HWOFF]
    out[0] = p0_read
    want_sens = sens.shape[0] > 0
    s_t0 = 1.0 if lung_from_p0 else 0.0  # d(second state)/dp0
    if want_sens:
        sens[0] = 1.0
    # acoustic line: state [p, cell pressures, flows] (and T with heat transfer); its
    # volume leaves the chamber's
    nseg = int(sl[_LSEG]) if sl[_LLEN] > 0.0 else 0
    line = nseg > 0
    ny = 1 + 2 * nseg + (1 if line and thermal else 0)
    y, y_new, s_vec = np.empty(ny), np.empty(ny), np.zeros(ny)
    prop = np.empty((ny, ny))
    line_work = line_workspace(ny)
    if general is not None and line:
        v0 = v0 - line_volume(sl)
        if not v0 > 0.0:
            return LINE_VOLUME
        line_start(y, s_vec, p0, carry, nseg, temp)
        y[0] = p
    # transmission-line tube (wave.py): its volume leaves the chamber's; the ends update
    # on a grid anchored at the recording's first sample (a time within w_near of a
    # grid point is on it)
    wave = general is not None and sl[_WLEN] > 0.0
    hist, ring, w_rd, w_row = wave_workspace(wave)
    w_work = (hist, ring, wave_state(sl), w_rd, w_row)
    tube = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1, 1e-4, 0.0, 0.0, 0.0)
    grid = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if general is not None and wave:
        tube = wave_constants(sl, cs)
        v0 = v0 - wave_volume(sl)
        if not v0 > 0.0:
            return LINE_VOLUME
        wave_start(hist, ring, carry, t_start, p, tube[0], tube[6], w_work[2], w_row)
        grid = wave_grid(w_work, tube, t[0], math.floor((t_start - t[0]) / wave_grid_step(
            tube) + 1e-6) + 1.0, t_start)
    w_near = 1e-6 * wave_grid_step(tube)
    # the delayed command's sample (and its direction, read by a closure's code 15),
    # the spool there, and the position/supply segment holding t + adv
    j, cdir = delayed_command(t, u, delay, t_start, cl_dir)
    spool, v_s = u[j], 0.0
    m = k0 if adv >= 0.0 else 0
    while m + 1 < n and t[m + 1] - adv <= t_start:
        m += 1
    if lagged and k0 > 0:
        spool, v_s = spool_at_start(t, u, j, t_start, delay, tau_s, w_s, z_s, rate_s,
                                    tau_dn)
    if general is not None:  # a command lag's s_bar from the command's history
        for q in range(rx_n):
            if rx_kind[q] == 28.0:
                rx_val[q] = command_relaxation_start(t, u, j, t_start, delay, rx_tau[q])
        held_start(t, u, delay, t_start, rx_n, rx_kind, rx_tau, rx_ptr)
    # the pressure is the only state (a lagged reading follows its own exponential
    # over a step, as it does the (p, T) step's pressure part; the other steps start
    # from the chord between their ends)
    plain = not (thermal or tank or lung or line or wave)
    shaped = plain or thermal
    dense = (sv.shape[0] > S_DENSE and sv[S_DENSE] > 0.0 and not reading and not own_ex
             and adv == 0.0 and plain)
    walled = wall_on(sl)
    w_c, w_w, w_z = wall_constants(sl)
    w_x, w_v, w_hmax = 0.0, 0.0, math.inf
    if walled:  # a loaded wall: where the reading's history leaves it, its step bound
        if general is None:
            return NEEDS_GENERAL
        if not (w_w > 0.0 and w_z > 0.0):
            return NONFINITE
        w_x, w_v = wall_start(t, pm, k0, w_w, w_z, p, calibrated, p_atm, zero, cal_g)
        w_hmax = wall_max_step(w_c, w_w, v0, p_nom, cs[C_KAPPA])
        dense = False
    if play_on(sl):  # a volume play lays its table on the kernel's own copy of the slots
        if general is None:
            return NEEDS_GENERAL
        sl = sl.copy()
        play_start(sl, pm, k0, p, p_atm)
    rigid = rigid_chamber(sl)  # no compliance, no volume table: a q = p V^n step
    return _march(
        sl, cs, sv, t, u, ue, x, ps, i0, length, p0, out, sens, carry, general,
        (thermal, own_ex, tank, lung, line, wave, plain, shaped, dense, rigid, reading,
         want_sens),
        (calibrated, zero, cal_g, slope0),
        (delay, tau_s, tau_dn, w_s, z_s, rate_s, spool2, lagged, dead),
        (lag_r, w_r, z_r, n_r, second),
        (cl_spool, cl_vdot, cl_dir, rx_n, rx_idx, rx_kind, rx_tau, rx_val, rx_ptr, held),
        (k0, t_start, max_steps, r, v_r, p, temp, p_tank, p_lung, s_t0, j, cdir, spool, v_s,
         m),
        (nseg, ny, y, y_new, s_vec, prop, line_work), (w_work, tube, grid, w_near),
        (v0, bore, gain, adv, p_nom, c_tank), (walled, (w_c, w_w, w_z), (w_x, w_v), w_hmax))


@njit(cache=True, nogil=True, error_model="numpy")
def _simulate_tasks(first, last, slots, consts, solver, t, u, ue, x, ps, pm, starts, length,
                    p0, rate0, out, sens, status, general, per_task):
    """Tasks ``first..last - 1`` on the calling thread, the GIL released, so several
    threads run disjoint ranges at once (:func:`_run_tasks`). Task ``k`` is parameter set
    ``k // (W / per_task)``, its windows from ``(k % (W / per_task)) * per_task`` on,
    carrying the unmeasured states from window to window. (One compiled function, not a
    loop around a per-task one: each level of calls around the window costs the cold
    compile seconds.)"""
    tasks_per_set = starts.shape[0] // per_task
    for task in range(first, last):
        b = task // tasks_per_set
        w0 = (task % tasks_per_set) * per_task
        carry = _fresh_carry()
        for w in range(w0, w0 + per_task):
            status[b, w] = _window(slots[b], consts, solver, t, u, ue, x, ps, pm, starts[w],
                                   length, p0[w], rate0[b, w], out[b, w], sens[b, w], carry,
                                   general)
            if status[b, w] != OK:
                carry = _fresh_carry()


#: Chunks per thread :func:`_run_tasks` cuts the tasks into: the threads take chunks as
#: they finish, so a thread slowed by another process on its core takes fewer.
CHUNKS_PER_THREAD = 4
#: Samples (windows' lengths summed over the tasks) per thread below which a batch runs
#: on fewer threads: handing a chunk to a thread costs about what simulating a few
#: hundred samples does (``benchmarks/batch_threads.py``).
MIN_SAMPLES_PER_THREAD = 500


def _run_tasks(n_tasks: int, samples_per_task: int, threads: int, args: tuple) -> None:
    """Run tasks ``0..n_tasks - 1`` of :func:`_simulate_tasks` (``args``: its arguments
    after the range; ``samples_per_task``: a task's windows' lengths summed) on up to
    ``threads`` threads (fewer for a short batch: :data:`MIN_SAMPLES_PER_THREAD`), the
    calling one among them, in about ``CHUNKS_PER_THREAD`` chunks per thread taken as
    threads come free (:func:`pneubayes.simulation.task_threads.run_chunks`). Python
    threads around the one compiled loop, not a numba ``prange`` loop: that would be a
    second compiled copy of the whole kernel, which a cold start compiles too."""
    threads = max(1, min(threads, n_tasks,
                         n_tasks * samples_per_task // MIN_SAMPLES_PER_THREAD))
    if threads == 1:
        _simulate_tasks(0, n_tasks, *args)
        return
    size = -(-n_tasks // (threads * CHUNKS_PER_THREAD))
    n_chunks = -(-n_tasks // size)
    run_chunks(lambda i: _simulate_tasks(i * size, min(n_tasks, (i + 1) * size), *args),
               n_chunks, threads)


@njit(cache=True, nogil=True, error_model="numpy")
def _chain_carried(slots, consts, solver, t, u, ue, x, ps, pm, bounds, measured, gain,
                   p_start, carry, out, p_end, status, general):
    """Every parameter set through the chunks ``bounds[c]..bounds[c + 1]`` in order, each
    chunk one window started from the set's own state (:func:`simulate_carried`)."""
    n_out = bounds[-1] - bounds[0] + 1
    longest = 1
    for c in range(bounds.shape[0] - 1):
        longest = max(longest, bounds[c + 1] - bounds[c] + 1)
    tmp = np.empty(longest)
    sens = np.empty(0)
    for b in range(slots.shape[0]):
        p = p_start[b]
        out[b, 0] = p
        for c in range(bounds.shape[0] - 1):
            i0, length = bounds[c], bounds[c + 1] - bounds[c] + 1
            st = _window(slots[b], consts, solver, t, u, ue, x, ps, pm, i0, length, p,
                         math.nan, tmp[:length], sens, carry[b], general)
            if st != OK:
                status[b] = st
                break
            j0 = i0 - bounds[0]
            out[b, j0 + 1:j0 + length] = tmp[1:length]
            p_pred = tmp[length - 1]
            # the next chunk starts from the prediction moved by ``gain`` of its error
            p = p_pred + gain * (measured[bounds[c + 1]] - p_pred)
        if status[b] != OK:
            out[b, :n_out] = math.nan
            p_end[b] = math.nan
        else:
            p_end[b] = out[b, n_out - 1]


def simulate_carried(slots, consts, solver, t, u, ue, x, ps, bounds, measured, gain,
                     p_start, carry, pm=None, general=None):
    """Simulate every parameter set through contiguous chunks, carrying its whole state.

    Chunk ``c`` runs from sample ``bounds[c]`` to ``bounds[c + 1]`` as one window; the
    unmeasured states (``carry``, row per parameter set, updated in place) pass from
    chunk to chunk as contiguous windows pass them, and the pressure each chunk starts
    from is the previous chunk's last prediction moved by ``gain`` of its error against
    ``measured`` there (0: the set's own pressure, an open-loop simulation; 1: the
    measured one, as contiguous windows restart).

    Returns ``(out, p_end, status)``: ``(B, bounds[-1] - bounds[0] + 1)`` predictions
    (column 0 ``p_start``; NaN rows where a set fails), ``(B,)`` the last prediction
    (before any correction) and ``(B,)`` status codes.
    """
    nb = slots.shape[0]
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    out = np.empty((nb, int(bounds[-1] - bounds[0]) + 1))
    p_end = np.empty(nb)
    status = np.zeros(nb, dtype=np.int64)
    hidden = needs_general(slots) if general is None else bool(general)
    if pm is None:
        pm = np.full(t.shape, np.nan)
    with first_call(kernel_first_call("carried", hidden)):
        _chain_carried(slots, consts, solver, t, u, ue, x, ps, pm, bounds, measured,
                       float(gain), p_start, carry, out, p_end, status,
                       True if hidden else None)
    return out, p_end, status


def _simulate(slots, consts, solver, t, u, ue, x, ps, starts, length, p0, rate0, pm,
              with_sensitivity, general):
    """Every (parameter set, window) pair; see :func:`simulate_windows`.

    The compiled variant is chosen here and built on first use: the pressure-only kernel
    unless a parameter set has a second state. The tasks run on numba's thread count
    (``numba.set_num_threads``) of Python threads (:func:`_run_tasks`).
    """
    nb, nw = slots.shape[0], starts.shape[0]
    out = np.empty((nb, nw, length))
    sens = np.empty((nb, nw, length if with_sensitivity else 0))
    status = np.zeros((nb, nw), dtype=np.int64)
    # a state the recording does not measure
    hidden = needs_general(slots) if general is None else bool(general)
    # contiguous windows (each starts on the previous one's last sample) with a hidden
    # state run in order in one task per parameter set, carrying it; else a task each
    chained = nw > 1 and bool(np.all(np.diff(starts) == length - 1))
    per_task = nw if chained and hidden else 1
    if rate0 is None:
        rate0 = np.full((nb, nw), np.nan)
    if pm is None:
        pm = np.full(t.shape, np.nan)
    with first_call(kernel_first_call("simulate", hidden)):
        _run_tasks(nb * (nw // per_task), per_task * length, numba.get_num_threads(),
                   (slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0, rate0,
                    out, sens, status, True if hidden else None, per_task))
    return out, sens, status


def needs_general(slots) -> bool:
    """True when a parameter set (row of ``slots``) has a second state (heat transfer, an
    acoustic line, a transmission-line tube's waves, a supply tank or a second
    compartment), an open-form closure, a restriction at the port or upstream of the
    inlet, a loaded wall, a volume play, a second-order spool or a valve driver's clock
    (whose code the pressure-only kernel leaves out, so that the plain model's first
    call compiles less). The ports' own critical ratios are stepped by both."""
    return bool((np.asarray(slots)[:, GENERAL_SLOTS] > 0.0).any())


#: The slots of the forms with a second state or a closure (:func:`needs_general`), and
#: of the rarer forms the pressure-only kernel leaves out so that the paper's model
#: compiles less on its first call: a second-order spool and a valve driver's clock.
GENERAL_SLOTS = np.array([_HCOUP, _LLEN, _WLEN, _TANK, _LUNG, _CL_N,
                          _SPOOL_W, _CLOCK_T] + [
    SLOT_INDEX[name] for name in VOLUME_PLAY_COMPLIANCE_SLOTS] + [
    SLOT_INDEX["loaded_wall_compliance_m3_per_Pa"],
    SLOT_INDEX["restriction_fill_inverse_area_per_m2"],
    SLOT_INDEX["restriction_vent_inverse_area_per_m2"],
    SLOT_INDEX["supply_restriction_inverse_area_per_m2"]])


@njit(cache=True, error_model="numpy")
def _fresh_carry():
    """Unmeasured states at a recording's start, all NaN: the gas at its wall's
    temperature (the supply's plus ``heat_wall_offset_K``), a line at rest, a tank at the
    window's supply, a second compartment at the first window's p0."""
    return np.full(N_CARRY, np.nan)


def simulate_windows(slots, consts, solver, t, u, ue, x, ps, starts, length, p0, rate0=None,
                     pm=None, general=None):
    """Simulate every (parameter set, window) pair.

    The chamber temperature (a state only with heat transfer) starts at its wall's (the
    supply's plus ``heat_wall_offset_K``) in the first window, an acoustic line at rest
    at the chamber's pressure; when every window starts on the previous one's last
    sample, each later window starts from the temperature, line and tank state the
    previous one ended with.

    Parameters
    ----------
    slots : (B, N_SLOTS) float64      lowered parameters (see effects.path)
    consts, solver : float64 vectors  rig/gas constants and solver settings (layouts above)
    t, u, x, ps : (N,) float64        time (s), command (V), position (m), supply (Pa)
    ue : (N,) float64                 a separate exhaust valve's command (its unit)
    starts : (W,) int64               first sample of each window
    length : int                      samples per window (output includes the start)
    p0 : (W,) float64                 initial pressure (the reading) of each window (Pa)
    rate0 : (B, W) float64 or None    the reading's rate at each start (Pa/s; NaN or
                                      None: warm up over the command history), read
                                      only with a sensor lag
    pm : (N,) float64 or None         the recorded reading (Pa; NaN or None: unknown),
                                      where a lagged reading's warm-up starts
    general : bool or None            whether a parameter set has a second state
                                      (None: :func:`needs_general` of ``slots``)

    Returns
    -------
    out : (B, W, length) float64 pressures (Pa); status : (B, W) int64
    """
    out, _, status = _simulate(slots, consts, solver, t, u, ue, x, ps, starts, length, p0,
                               rate0, pm, False, general)
    return out, status


def simulate_windows_sensitivity(slots, consts, solver, t, u, ue, x, ps, starts, length, p0,
                                 rate0=None, pm=None, general=None):
    """:func:`simulate_windows` plus dp(t)/dp0 per sample: ``(out, sens, status)``."""
    return _simulate(slots, consts, solver, t, u, ue, x, ps, starts, length, p0, rate0, pm,
                     True, general)
