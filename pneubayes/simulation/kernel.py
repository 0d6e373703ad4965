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
heat transfer on (either form), the chamber temperature is a second state, stepped by
the same method with the full 2 x 2 Jacobian (a diagonal one leaves the method first
order in the p-T coupling). With the tube as an acoustic line, the state is the
chamber's pressure and the line's cells and flows (with heat transfer, and the chamber's
temperature: the line's gas is at the supply's temperature), stepped by the same method
with the full Jacobian (:mod:`pneubayes.simulation.line`). A lagged sensor reading is
stepped in closed form after each accepted step (:mod:`pneubayes.simulation.reading`).

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
from numba import njit, prange

from pneubayes.effects.path import (
    CLOSURE_MAX_TERMS,
    LINE_MAX_SEGMENTS,
    SLOT_INDEX,
    TABLE_MAX_POINTS,
)
from pneubayes.physics.calibration import (
    pressure_behind_reading_scalar,
    sensor_reading_scalar,
)
from pneubayes.physics.valve import gompertz_scalar, switching_scalar, table_scalar
from pneubayes.simulation.chamber import chamber_rhs, net_port_flow, rigid_chamber
from pneubayes.simulation.chord import (
    chord_coupling,
    chord_response,
    off_chord,
    position_at,
    response_weights,
)
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
from pneubayes.simulation.lung import lung_step
from pneubayes.simulation.phi import phi123
from pneubayes.simulation.reading import (
    first_order_exponential_sensitivity,
    first_order_exponential_step,
    first_order_hermite_deviation,
    first_order_step,
    pressure_dependent_step,
    pressure_lag,
    second_order_curvature,
    second_order_exponential_deviation,
    second_order_step,
)
from pneubayes.simulation.relaxation import (
    relaxation_mid,
    relaxation_start,
    relaxation_step,
)
from pneubayes.simulation.spool import first_order_lag, spool_settle_s, spool_step
from pneubayes.simulation.tank import tank_step
from pneubayes.simulation.thermal import thermal_step
from pneubayes.simulation.wave import (
    WAVE_CAPACITY,
    WAVE_CARRY,
    wave_arriving,
    wave_constants,
    wave_ends,
    wave_finish,
    wave_gain,
    wave_grid_step,
    wave_newest_time,
    wave_ramped,
    wave_resistance,
    wave_start,
    wave_volume,
    wave_workspace,
)

OK, STEP_UNDERFLOW, STEP_BUDGET, NONFINITE, LINE_VOLUME, NEEDS_GENERAL = 0, 1, 2, 3, 4, 5
WAVE_HISTORY = 6
CALIBRATION = 7
STATUS_TEXT = {OK: "ok", STEP_UNDERFLOW: "step size fell below min_step_s",
               STEP_BUDGET: "more steps in one window than max_steps_per_s allows",
               NONFINITE: "state became non-finite",
               LINE_VOLUME: "the acoustic line's volume is not smaller than the dead volume",
               NEEDS_GENERAL: "a form with a second state reached the pressure-only kernel "
                              "(an internal error)",
               WAVE_HISTORY: f"more than {WAVE_CAPACITY} entries within one transit time "
                             "of the transmission-line tube (an internal error)",
               CALIBRATION: "the sensor's calibration reads the measured start as a "
                            "pressure <= 0 absolute"}
#: Length of the state carried from one window to the next: the chamber temperature,
#: an acoustic line's cell pressures and flows (NaN: start the line at rest) or a
#: transmission-line tube's waves (:func:`~pneubayes.simulation.wave.wave_finish`), a
#: supply tank's pressure (NaN: start at the window's supply) and a second
#: compartment's pressure (NaN: start at the window's initial pressure).
N_CARRY = 3 + max(2 * LINE_MAX_SEGMENTS, WAVE_CARRY)
CARRY_TANK = N_CARRY - 2
CARRY_LUNG = N_CARRY - 1


# The weight of the chord correction's size in a crossing step's error estimate (the
# step's error is the larger of its own estimate and this times the correction, both
# against the tolerance). 0.3 ran 20-25 % faster on a moving piston at errors up to
# 1.7 x larger (benchmarks/README.md).
CHORD_ERROR_WEIGHT = 1.0
_IN = SLOT_INDEX["inlet_offset_m2"]
_EX = SLOT_INDEX["exhaust_offset_m2"]
_VOL = SLOT_INDEX["volume_m3"]
_DELAY = SLOT_INDEX["command_delay_s"]
_SPOOL = SLOT_INDEX["spool_time_constant_s"]
_SPOOL_RATE = SLOT_INDEX["spool_rate_limit_V_per_s"]
_SPOOL_FALL = SLOT_INDEX["spool_fall_time_constant_s"]
_SPOOL_W = SLOT_INDEX["spool_natural_frequency_rad_per_s"]
_SPOOL_Z = SLOT_INDEX["spool_damping"]
_DEAD = SLOT_INDEX["deadband_halfwidth_V"]
_ROUND = SLOT_INDEX["deadband_rounding_V"]
_SUPG = SLOT_INDEX["supply_gain"]
_HEAT = SLOT_INDEX["heat_rate_per_s"]
_HCONV = SLOT_INDEX["heat_coefficient_W_per_m2_K"]
_LLEN = SLOT_INDEX["line_length_m"]
_LSEG = SLOT_INDEX["line_segments"]
_WLEN = SLOT_INDEX["wave_length_m"]
_WSEG = SLOT_INDEX["wave_segments"]
_OPEN_IN = SLOT_INDEX["inlet_open_area_m2"]
_OPEN_EX = SLOT_INDEX["exhaust_open_area_m2"]
_OWN_EX = SLOT_INDEX["exhaust_own_command"]
_TANK = SLOT_INDEX["tank_volume_m3"]
_LUNG = SLOT_INDEX["lung_volume_m3"]
_TAB_N = SLOT_INDEX["table_points"]
_TAB_C = SLOT_INDEX["table_command_0"]
_TAB_I = SLOT_INDEX["table_inlet_m2_0"]
_TAB_E = SLOT_INDEX["table_exhaust_m2_0"]
_TAB_MAX = TABLE_MAX_POINTS
_SENSOR = SLOT_INDEX["sensor_time_constant_s"]
_SENSOR_W = SLOT_INDEX["sensor_natural_frequency_rad_per_s"]
_SENSOR_Z = SLOT_INDEX["sensor_damping"]
_SENSOR_N = SLOT_INDEX["sensor_pressure_exponent"]
_ADVANCE = SLOT_INDEX["inputs_advance_s"]
_CAL_OFFSET = SLOT_INDEX["reading_offset_Pa"]
_CAL_GAIN = SLOT_INDEX["reading_gain_error"]
_CL_N = SLOT_INDEX["closure_terms"]
_CL_FA = SLOT_INDEX["closure_feature_a_0"]
_CL_FB = SLOT_INDEX["closure_feature_b_0"]
_CL_TA = SLOT_INDEX["closure_threshold_a_0"]
_CL_TB = SLOT_INDEX["closure_threshold_b_0"]
_CL_RA = SLOT_INDEX["closure_relaxed_a_0"]
_CL_RB = SLOT_INDEX["closure_relaxed_b_0"]
_CL_MAX = CLOSURE_MAX_TERMS


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
    rtol, atol_p, atol_t = sv[S_RTOL], sv[S_ATOL_P], sv[S_ATOL_T]
    hmax, hmin = sv[S_MAX_STEP], sv[S_MIN_STEP]
    n = t.shape[0]
    # the sensor's calibration: reading = P_atm + cal_g (p - P_atm) + cal_o
    p_atm = cs[C_P_ATM]
    cal_o, cal_g = sl[_CAL_OFFSET], 1.0 + sl[_CAL_GAIN]
    calibrated = cal_o != 0.0 or cal_g != 1.0
    p0_read = p0
    if calibrated:
        p0 = pressure_behind_reading_scalar(p0, p_atm, cal_o, cal_g)
        rate0 = rate0 / cal_g
        if not p0 > 0.0:
            return CALIBRATION
    # step budget: max_steps_per_s per simulated second, beyond the one step each
    # sample interval takes at least
    max_steps = (length - 1) + int(sv[S_MAX_STEPS_PER_S] * (t[i0 + length - 1] - t[i0]))
    delay, tau_s, dead = sl[_DELAY], sl[_SPOOL], sl[_DEAD]
    w_s, z_s = sl[_SPOOL_W], sl[_SPOOL_Z]
    tau_dn = sl[_SPOOL_FALL]  # the first-order spool's fall, if its own
    spool2 = w_s > 0.0  # a second-order spool (overrides the first-order lag)
    if spool2:
        tau_s = tau_dn = 0.0
    rate_s = sl[_SPOOL_RATE] if tau_s > 0.0 else 0.0  # the first-order spool's speed limit
    lagged = tau_s > 0.0 or tau_dn > 0.0 or spool2
    gain = sl[_SUPG]
    # position and supply are read at t + adv (linear between their samples, held after
    # the last): their sample times, shifted by -adv, are break points of the steps
    adv = sl[_ADVANCE]
    p_nom = cs[C_P_NOM]
    v0, bore = sl[_VOL], cs[C_BORE_AREA]
    thermal = sl[_HEAT] > 0.0 or sl[_HCONV] > 0.0
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
    # an open-form closure: whether a term reads the spool (codes 3, 11, 12) or the
    # command's direction (code 15; both change only with the command), or the volume
    # rate (code 9; a volume hinge's rate, codes 17 and 18), which the reuse of a step's
    # end below must respect
    cl_spool, cl_vdot, cl_dir = False, False, False
    # and its low-passes (code 16 the pressure's, 19 the net port flow's): each one's
    # slot, signal (its code), time constant and value, which the kernel steps
    # (relaxation.py) on its own copy of the slots
    rx_n = 0
    rx_idx = np.zeros(2 * _CL_MAX, dtype=np.int64)
    rx_kind = np.zeros(2 * _CL_MAX)
    rx_tau = np.zeros(2 * _CL_MAX)
    rx_val = np.zeros(2 * _CL_MAX)
    for kc in range(int(sl[_CL_N])):
        for code in (sl[_CL_FA + kc], sl[_CL_FB + kc]):
            if code == 3.0 or code == 11.0 or code == 12.0:
                cl_spool = True
            if code == 15.0:
                cl_spool, cl_dir = True, True
            if code == 9.0 or code == 17.0 or code == 18.0:
                cl_vdot = True
        for code, slot, tc in ((sl[_CL_FA + kc], _CL_RA + kc, sl[_CL_TA + kc]),
                               (sl[_CL_FB + kc], _CL_RB + kc, sl[_CL_TB + kc])):
            if code == 16.0 or code == 19.0:
                rx_idx[rx_n], rx_kind[rx_n], rx_tau[rx_n] = slot, code, tc
                rx_n += 1
    cl_relax = rx_n > 0
    # the last accepted step's mean rates of p (Pa/s) and of the net port flow (kg/s^2),
    # at which a step's midpoint value takes them on; the net flow at a step's start
    rx_rate, rx_qrate, rx_q0 = 0.0, 0.0, 0.0
    if cl_relax:
        sl = sl.copy()
        for q in range(rx_n):
            if not rx_tau[q] > 0.0:
                return NONFINITE
    if lung_from_p0:
        p_lung = p0
    if general is None and (thermal or tank or lung or sl[_LLEN] > 0.0 or sl[_WLEN] > 0.0):
        return NEEDS_GENERAL
    lag_r = sl[_SENSOR]
    w_r, z_r = sl[_SENSOR_W], sl[_SENSOR_Z]
    second = w_r > 0.0
    reading = lag_r > 0.0 or second
    # a first-order lag whose time constant depends on the pressure (lag_r at the
    # atmosphere; reading.pressure_dependent_step steps it over substeps)
    n_r = sl[_SENSOR_N] if (lag_r > 0.0 and not second) else 0.0
    lag_0 = pressure_lag(lag_r, n_r, p0, p0, p_atm) if n_r != 0.0 else lag_r
    # the reading's lead at DC (its group delay) and the time its transient takes
    lead_s = 2.0 * z_r / w_r if second else lag_0
    settle_s = max(lead_s, 1.0 / (z_r * w_r)) if second else max(lag_r, lag_0)
    r = p0
    v_r = 0.0  # the reading's rate (second order)
    p = p0
    # a lagged reading with no rate given: warm up over 5 time constants of the command
    # history before the start, then keep the chamber's lead on the reading
    k0 = i0
    t_start = t[i0]  # the integration's start: the window's, or its warm-up's
    if reading and math.isnan(rate0):
        while k0 > 0 and t[i0] - t[k0] < 5.0 * settle_s:
            k0 -= 1
        t_start = t[k0]
        if k0 < i0 and math.isfinite(pm[k0]):  # from the recorded reading there
            r = (pressure_behind_reading_scalar(pm[k0], p_atm, cal_o, cal_g) if calibrated
                 else pm[k0])
            p = r
        # a gap before the warm-up's first sample longer than the warm-up (a triggered
        # recording's pre-trigger command, held from 10 s back): start 5 settling times
        # before the window, not at the gap's start (a tube's wave grid would step
        # through all of it)
        if k0 < i0 and t[k0 + 1] - t[k0] > 5.0 * settle_s:
            t_start = t[i0] - 5.0 * settle_s
    elif reading:
        v_r = rate0
        if p0 + lead_s * rate0 > 0.0:
            p = p0 + lead_s * rate0
    max_steps += i0 - k0
    for q in range(rx_n):  # a relaxation's p_bar from the reading's history; a flow's
        # low-pass at its first step's flow (at rest)
        rx_val[q] = (relaxation_start(t, pm, k0, rx_tau[q], p, calibrated, p_atm, cal_o,
                                      cal_g) if rx_kind[q] == 16.0 else math.nan)
    temp = carry[0] if thermal else cs[C_T_SUPPLY]
    out[0] = p0_read
    want_sens = sens.shape[0] > 0
    s_p0, s_t0 = 1.0, 0.0  # d(p, T)/dp0 (T: or the tank's or second compartment's p)
    s_r, s_v = 1.0, 0.0  # d(reading, its rate)/dp0
    if lung_from_p0:
        s_t0 = 1.0
    prop_t = (1.0, 0.0, 0.0, 1.0)  # a thermal step's propagator (row-major)
    if want_sens:
        sens[0] = 1.0
    # acoustic line: state [p, cell pressures, flows] (and T with heat transfer); its
    # volume leaves the chamber's
    nseg = int(sl[_LSEG]) if sl[_LLEN] > 0.0 else 0
    line = nseg > 0
    ny = 1 + 2 * nseg + (1 if line and thermal else 0)
    y = np.empty(ny)
    y_new = np.empty(ny)
    s_vec = np.zeros(ny)
    prop = np.empty((ny, ny))
    line_work = line_workspace(ny)
    if general is not None and line:
        v0 = v0 - line_volume(sl)
        if not v0 > 0.0:
            return LINE_VOLUME
        line_start(y, s_vec, p0, carry, nseg, temp)
        y[0] = p
    # transmission-line tube: the history of its waves (wave.py); its volume leaves the
    # chamber's and a step never exceeds an element's transit time
    wave = general is not None and sl[_WLEN] > 0.0
    hist, ring, w_rd, w_row = wave_workspace(wave)
    w_state = np.zeros(2 + max(int(sl[_WSEG]), 1))  # [q_a, p_v, q_c, junction flows]
    w_t, w_z, w_area, w_len, w_dia, w_mu, w_k = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1
    if general is not None and wave:
        w_t, w_z, w_area, w_len, w_dia, w_mu, w_k = wave_constants(sl, cs)
        v0 = v0 - wave_volume(sl)
        if not v0 > 0.0:
            return LINE_VOLUME
        wave_start(hist, ring, carry, t_start, p, w_t, w_k, w_state, w_row)
    # the junctions and ends update on a grid anchored at the recording's first sample
    # (every window of it shares the grid; grid point w_n is w_grid); a time within
    # w_near of a grid point is on it
    w_dt = wave_grid_step(w_t)
    w_near = 1e-6 * w_dt
    w_n = math.floor((t_start - t[0]) / w_dt + 1e-6) + 1.0
    w_grid = t[0] + w_dt * w_n
    # the chamber's forcing, the valve's wave arriving A_K(t - tau) (and its dA/dp0),
    # linear between its reads at the ends of the grid interval [w_ta, w_grid]
    w_ta, w_a0, w_s0, w_a1, w_s1 = t_start, 0.0, 0.0, 0.0, 0.0
    if general is not None and wave:
        w_a0, w_s0 = wave_arriving(hist, ring, t_start - w_t, w_k)
        w_a1, w_s1 = wave_arriving(hist, ring, w_grid - w_t, w_k)
    # a switch of the port areas reaches the valve end as a ramp over one grid step
    # from the areas (w_oin, w_oex) at w_sw; (w_lin, w_lex): the areas at the last step's
    # end (NaN before the first)
    w_sw, w_oin, w_oex = -math.inf, 0.0, 0.0
    w_lin, w_lex = math.nan, math.nan
    a_in2, a_ex2, psup2 = 0.0, 0.0, 0.0
    x0c, x1c = 0.0, 0.0  # a chord step's positions at its ends (dense output), m
    c_c = 0.0  # its coupling (Pa / (m s)); the flows' slope is jf
    # Delayed-command pointer: index j of the sample held at time t - delay, the last
    # j >= 1 with t[j] + delay <= t_start (else 0), by bisection: a one-step window at
    # every sample would otherwise scan the recording from its start each time
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if t[mid] + delay <= t_start:
            lo = mid + 1
        else:
            hi = mid
    j = lo - 1 if lo > 1 else 0
    # the delayed command's direction (a closure's code 15): the sign of its last change
    # up to j, found by scanning back, then tracked as j moves on
    cdir = 0.0
    if cl_dir:
        jj = j
        while jj > 0 and u[jj] == u[jj - 1]:
            jj -= 1
        if jj > 0:
            cdir = 1.0 if u[jj] > u[jj - 1] else -1.0
    spool = u[j]  # steady spool at the start of the recording
    v_s = 0.0  # its velocity (second order), V/s
    # Input pointer: index m of the position/supply segment that holds time t + adv
    # (from the window's start: an advance >= 0 reads no earlier sample)
    m = k0 if adv >= 0.0 else 0
    while m + 1 < n and t[m + 1] - adv <= t_start:
        m += 1
    if lagged and k0 > 0:
        # mid-recording: the spool state follows from the command history (in closed
        # form over the held samples of up to 20 settling times before t_start)
        # (a speed-limited spool also ramps across the commands' span there first)
        jj = j
        settle = spool_settle_s(max(tau_s, tau_dn), w_s, z_s)
        u_lo, u_hi = u[j], u[j]
        while jj > 0 and t_start - (t[jj] + delay) < 20.0 * settle + (
                (u_hi - u_lo) / rate_s if rate_s > 0.0 else 0.0):
            jj -= 1
            u_lo, u_hi = min(u_lo, u[jj]), max(u_hi, u[jj])
        spool = u[jj]
        for k in range(jj, j):
            spool, v_s = spool_step(spool, v_s, u[k], t[k + 1] - t[k], tau_s, w_s, z_s,
                                    rate_s, tau_dn)
        spool, v_s = spool_step(spool, v_s, u[j], t_start - (t[j] + delay), tau_s, w_s,
                                z_s, rate_s, tau_dn)
    # dense output: steps cross the samples where the position and supply hold
    # the pressure is the only state (its step's rate, slope and correction describe it)
    plain = not (thermal or tank or lung or line or wave)
    # a lagged reading follows the pressure's own exponential over a step (the (p, T)
    # step's pressure part); the other steps start from the chord between their ends
    shaped = plain or thermal
    dense = (sv.shape[0] > S_DENSE and sv[S_DENSE] > 0.0 and not reading and not own_ex
             and adv == 0.0 and plain)
    # a rigid chamber (no compliance, no volume table) may step q = p V^n over a chord
    rigid = rigid_chamber(sl)
    kap = cs[C_KAPPA]
    qstep = False  # the pressure step's variable is q = p V^n
    sc0, sc1 = 1.0, 1.0  # its scale V^n (1 for p) at the step's ends
    rv, ff, jf = 0.0, 0.0, 0.0  # dV/dt / V (1/s), the flows' dp/dt (Pa/s) and slope (1/s)
    h = hmax
    err_last = 0.0  # the last accepted step's error estimate
    steps = 0
    s_cached = math.nan
    cmd_cached = math.nan
    a_in_c, a_ex_c = 0.0, 0.0
    k_last = i0 + length - 1
    fp, vp, ep = 0.0, 0.0, 0.0  # the last step's rate, its rate of change, its correction
    # first same as last: the rate, slope and time derivative at the last accepted step's
    # end (from its second stage, moved to its corrected end to first order), reused as
    # the next step's start while the inputs they depend on hold
    fs_ok, fs_fp, fs_jp, fs_vp, fs_vdot, fs_m = False, 0.0, 0.0, 0.0, 0.0, -1
    fs_ain, fs_aex = 0.0, 0.0  # the port areas it was evaluated with, m^2
    fs_s = 0.0  # and the spool (read with a closure's spool term)
    c_ok, c_fp, c_jp, c_vp = False, 0.0, 0.0, 0.0
    k = k0
    while k < k_last:
        # the samples this pass integrates to: the next, or with dense output the last
        # of the run over which the supply holds (only where the model reads it: a gain
        # of zero holds it at the nominal); a moving position is read on chords
        kn = k + 1
        chord = False  # the position moves over a pass that crosses samples
        if dense:
            while (kn < k_last
                   and (gain == 0.0 or (ps[kn] == ps[k] and ps[kn + 1] == ps[k]))):
                kn += 1
            if kn > k + 1:
                for i in range(k + 1, kn + 1):
                    if x[i] != x[k]:
                        chord = True
                        break
        kw = k + 1  # the next sample to read from a step's interpolant (dense output)
        if k == i0 and k0 < i0:  # end of the warm-up: the reading is the measured p0
            lead = p - r
            r = p0
            p = p0 + lead if p0 + lead > 0.0 else p0
            if general is not None and line:
                y[0] = p
            s_p0, s_r, s_v = 1.0, 1.0, 0.0
            fs_ok = False
        tb = t[kn]
        a_own = _own_exhaust_area(ue[k], sl) if own_ex else 0.0
        tau = t[k] if k > k0 else t_start
        while tau < tb:
            # Sub-interval [tau, t_end) on which the delayed command is constant.
            while j + 1 < n and t[j + 1] + delay <= tau:
                j += 1
                if cl_dir and u[j] != u[j - 1]:
                    cdir = 1.0 if u[j] > u[j - 1] else -1.0
            cmd = u[j]
            t_end = tb
            jn = j + 1  # the next break of the delayed command
            if kn > k + 1:  # dense output: past the samples that repeat the command
                while jn < n and u[jn] == cmd and t[jn] + delay < tb:
                    jn += 1
            if jn < n and t[jn] + delay < tb:
                t_end = t[jn] + delay
            # position and supply: linear from (ta, xa / sa) on the sub-interval
            while m + 1 < n and t[m + 1] - adv <= tau:
                m += 1
            if m + 1 < n:
                ta = t[m] - adv
                inv_seg = 1.0 / (t[m + 1] - t[m])
                xa, xb, sa, sb = x[m], x[m + 1], ps[m], ps[m + 1]
                if t[m + 1] - adv < t_end and kn == k + 1:
                    t_end = t[m + 1] - adv
            else:  # read past the last sample: its values, held
                ta, inv_seg = tau, 0.0
                xa, xb, sa, sb = x[m], x[m], ps[m], ps[m]
            if general is not None and wave and w_grid < t_end - w_near:
                t_end = w_grid  # the tube's ends update on their grid
            vdot = bore * (xb - xa) * inv_seg
            dsup = gain * (sb - sa) * inv_seg
            m_ch = m  # the chord's pointer: the segment holding tau
            spool_a, t_sub = spool, tau
            # Port areas are constant on the sub-interval unless the spool moves; the
            # command is held for many samples, so reuse them while it is unchanged.
            moving = lagged and (spool_a != cmd or v_s != 0.0)
            s_eff = spool_a if lagged else cmd
            s_cur, v_cur = spool_a, v_s  # the second-order spool at tau
            if s_eff != s_cached:
                a_in_c, a_ex_c = _areas(s_eff, dead, sl)
                s_cached = s_eff
                # the valve switched: restart small (the error estimate of a long first
                # step from a port's balance, where the flow has a square-root kink,
                # misses most of its error) and let the controller grow it 5x a step.
                # Behind a lagged spool the areas are continuous: restart where the
                # command steps, not at every sample while the spool glides
                if not lagged or cmd != cmd_cached:
                    h = min(h, 1e-3 * hmax)
                    err_last = 0.0
            cmd_cached = cmd
            a_in, a_ex = a_in_c, a_ex_c + a_own
            if general is not None and wave:
                if (not math.isnan(w_lin) and abs(a_in - w_lin) + abs(a_ex - w_lex)
                        > 1e-9 * (a_in + a_ex + w_lin + w_lex)):
                    # the ports switch at tau: the valve end's entry there with the areas
                    # before, then a ramp to the new ones over a grid step
                    o_in, o_ex = wave_ramped(tau, w_lin, w_lex, w_sw, w_dt, w_oin, w_oex)
                    if wave_newest_time(hist, ring) < tau - w_near:
                        if not wave_ends(hist, ring, tau, w_t, w_z, w_k, p, s_p0, psup2,
                                         o_in, o_ex, cs, w_area, w_len, w_dia, w_mu,
                                         w_state, w_rd, w_row):
                            return WAVE_HISTORY
                    w_sw, w_oin, w_oex = tau, o_in, o_ex
                    w_lin, w_lex = a_in, a_ex
                if tau < w_sw + w_dt - w_near and w_sw + w_dt < t_end - w_near:
                    t_end = w_sw + w_dt  # the ramp's end: an entry there
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
                # the spool (before the dead band) and its rate at tau, and at tau + hh
                s_at, ds_at = s_eff, 0.0
                if moving and spool2:
                    a_in, a_ex = _areas(s_cur, dead, sl)
                    a_ex += a_own
                    da_in, da_ex = _area_rates(s_cur, v_cur, dead, sl)
                    s_at, ds_at = s_cur, v_cur
                elif moving:
                    s_now, ds_now = first_order_lag(spool_a, cmd, tau - t_sub, tau_s, rate_s,
                                                     tau_dn)
                    a_in, a_ex = _areas(s_now, dead, sl)
                    a_ex += a_own
                    da_in, da_ex = _area_rates(s_now, ds_now, dead, sl)
                    s_at, ds_at = s_now, ds_now
                # inputs at tau + hh (stage 2)
                fr2 = (tau + hh - ta) * inv_seg
                vol2 = v0 + bore * (xa + fr2 * (xb - xa))
                psup2 = p_nom + gain * (sa + fr2 * (sb - sa) - p_nom)
                if chord:
                    # dense output over a moving position: the step reads the chord of
                    # the position across the samples it crosses
                    m_ch, x0c = position_at(t, x, n, m_ch, tau)
                    x1c = position_at(t, x, n, m_ch, tau + hh)[1]
                    vol = v0 + bore * x0c
                    vol2 = v0 + bore * x1c
                    vdot = bore * (x1c - x0c) / hh
                if moving:
                    if spool2:
                        s2, v2 = spool_step(s_cur, v_cur, cmd, hh, 0.0, w_s, z_s, 0.0,
                                            0.0)
                    else:
                        s2 = first_order_lag(spool_a, cmd, tau + hh - t_sub, tau_s, rate_s,
                                             tau_dn)[0]
                    a_in2, a_ex2 = _areas(s2, dead, sl)
                    a_ex2 += a_own
                    s_at2 = s2
                else:
                    a_in2, a_ex2 = a_in, a_ex
                    s_at2 = s_at
                if cl_relax:  # each low-pass held over the step at its midpoint value
                    rx_q0 = net_port_flow(p, a_in, a_ex, psup, cs)
                    for q in range(rx_n):
                        if rx_kind[q] == 16.0:
                            sl[rx_idx[q]] = relaxation_mid(rx_val[q], p, rx_rate, hh,
                                                           rx_tau[q])
                        else:
                            if math.isnan(rx_val[q]):
                                rx_val[q] = rx_q0
                            sl[rx_idx[q]] = relaxation_mid(rx_val[q], rx_q0, rx_qrate, hh,
                                                           rx_tau[q])
                err = 10.0
                pn, tn = p, temp
                p_tank_new = p_tank
                p_lung_new = p_lung
                zp = 0.0
                dev_r = 0.0  # a first-order reading's departure from the chord's
                if general is not None and line:
                    err = line_step(y, nseg, hh, a_in, a_ex, vol, vdot, psup, dsup, da_in,
                                    da_ex, a_in2, a_ex2, vol2, psup2, sl, cs, atol_p,
                                    atol_t, rtol, y_new, prop, line_work)
                    pn = y_new[0]
                    if thermal:
                        tn = y_new[ny - 1]
                    if reading and err < 10.0:
                        # the chamber rings with the line within a step: a first-order
                        # reading over the cubic through the step's ends and their rates
                        # (the end's at the uncorrected stage); its departure from the
                        # chord's reading enters the error estimate (for the second-order
                        # lag that of a first-order lag of its group delay, which its
                        # chord reading does not correct)
                        rate_a, rate_b = line_chamber_rates(line_work)
                        dev_r = first_order_hermite_deviation(
                            p, pn, hh * rate_a, hh * rate_b, hh,
                            2.0 * z_r / w_r if second else (
                                pressure_lag(lag_r, n_r, p, r, p_atm) if n_r != 0.0
                                else lag_r))
                        err = max(err, abs(dev_r) / (atol_p + rtol * max(abs(p), abs(pn))))
                elif general is not None and tank:
                    err, pn, p_tank_new, prop_t = tank_step(p, p_tank, hh, a_in, a_ex, vol,
                                                            vdot, da_in, da_ex, a_in2, a_ex2,
                                                            vol2, sl, cs, c_tank, atol_p,
                                                            rtol, s_at, ds_at, s_at2, cdir)
                elif general is not None and lung:
                    err, pn, p_lung_new, prop_t = lung_step(p, p_lung, hh, a_in, a_ex, vol,
                                                            vdot, psup, dsup, da_in, da_ex,
                                                            a_in2, a_ex2, vol2, psup2, sl, cs,
                                                            atol_p, rtol, s_at, ds_at, s_at2,
                                                            cdir)
                elif general is not None and wave:
                    # the chamber end: the valve's wave arriving, A_K(t - tau), linear
                    # over the grid interval the step lies in, drives the inflow
                    # (A_K - p) / (Z + r/2) of eq. 5
                    w_inv = 1.0 / (w_grid - w_ta)
                    wb0 = w_a0 + (w_a1 - w_a0) * (tau - w_ta) * w_inv
                    wb1 = w_a0 + (w_a1 - w_a0) * (tau + hh - w_ta) * w_inv
                    swb0 = w_s0 + (w_s1 - w_s0) * (tau - w_ta) * w_inv
                    swb1 = w_s0 + (w_s1 - w_s0) * (tau + hh - w_ta) * w_inv
                    zc = w_z + 0.5 * wave_resistance(w_state[2], p, cs, w_area, w_len,
                                                     w_dia, w_mu)
                    fp, jp, _, _, vp, _, _, _ = chamber_rhs(p, temp, 0.0, 0.0, vol, vdot,
                                                            psup, sl, cs, hh, True, 0.0, 0.0,
                                                            0.0, s_at, ds_at, cdir)
                    gw = wave_gain(p, vol, sl, cs) / zc
                    fp += gw * (wb0 - p)
                    jp -= gw
                    vp += gw * (wb1 - wb0) / hh
                    zp = hh * jp
                    phi1p, phi2p, phi3p = phi123(zp)
                    up = p + hh * (phi1p * fp + hh * phi2p * vp)
                    if up > 0.0 and math.isfinite(up):
                        fp2 = (chamber_rhs(up, temp, 0.0, 0.0, vol2, vdot, psup2, sl, cs, hh,
                                           False, 0.0, 0.0, 0.0, s_at2, 0.0, cdir)[0]
                               + wave_gain(up, vol2, sl, cs) / zc * (wb1 - up))
                        ep = 2.0 * hh * phi3p * (fp2 - fp - jp * (up - p) - hh * vp)
                        pn = up + ep
                        err = abs(ep) / (atol_p + rtol * max(abs(p), abs(pn)))
                        if not (pn > 0.0 and math.isfinite(pn)):
                            err = 10.0
                elif general is not None and thermal:
                    err, pn, tn, prop_t, fp, jp, vp = thermal_step(
                        p, temp, hh, a_in, a_ex, vol, vdot, psup, dsup, da_in, da_ex, a_in2,
                        a_ex2, vol2, psup2, sl, cs, atol_p, atol_t, rtol, s_at, ds_at, s_at2,
                        cdir)
                    zp = hh * jp  # (the pressure's own part: a lagged reading's shape)
                else:
                    c_ok = False
                    if (fs_ok and not cl_relax and not moving and not chord
                            and a_in == fs_ain and a_ex == fs_aex
                            and (not cl_spool or s_at == fs_s)
                            and (fs_m == m or (rigid and gain == 0.0 and not cl_vdot))):
                        fp, jp, vp = fs_fp, fs_jp, fs_vp
                        if vdot != fs_vdot:  # a new chord of the position (rigid)
                            iv = 1.0 / vol
                            xv = vp + fp * fs_vdot * iv
                            fp -= kap * iv * p * (vdot - fs_vdot)
                            jp -= kap * iv * (vdot - fs_vdot)
                            vp = xv - fp * vdot * iv
                    else:
                        fp, jp, _, _, vp, _, _, _ = chamber_rhs(p, temp, a_in, a_ex, vol,
                                                                vdot, psup, sl, cs, hh, True,
                                                                dsup, da_in, da_ex, s_at,
                                                                ds_at, cdir)
                    if not moving and not chord:
                        fs_ok, fs_fp, fs_jp, fs_vp, fs_vdot, fs_m = True, fp, jp, vp, vdot, m
                        fs_ain, fs_aex, fs_s = a_in, a_ex, s_at
                    else:
                        fs_ok = False
                    # over a chord in a rigid chamber where the compression outpaces
                    # the flows' relaxation (|J_f| < n |dV/dt| / V), the step is taken in
                    # q = p V^n (scale sc = V^n at its ends), which the compression
                    # leaves alone: dq/dt = V^n F_f (F_f: the flows' part of dp/dt, J_f
                    # its slope), so a closed chamber is exact; elsewhere in p (sc = 1)
                    qstep = False
                    if chord:
                        rv = vdot / vol
                        ff, jf = fp + kap * p * rv, jp + kap * rv
                        qstep = rigid and abs(jf) < kap * abs(rv)
                    if qstep:
                        sc0 = math.exp(kap * math.log(vol))
                        sc1 = math.exp(kap * math.log(vol2))
                        vp = sc0 * (vp + kap * rv * (ff - p * (rv + jf)))  # d(dq/dt)/dt
                        fp = sc0 * ff  # dq/dt
                        zp = hh * jf
                        phi1p, phi2p, phi3p = phi123(zp)
                        uq = p * sc0 + hh * (phi1p * fp + hh * phi2p * vp)
                        up = uq / sc1
                        if up > 0.0 and math.isfinite(up):
                            fp2 = chamber_rhs(up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl,
                                              cs, hh, False, 0.0, 0.0, 0.0, s_at2, 0.0,
                                              cdir)[0]
                            ep = 2.0 * hh * phi3p * (sc1 * (fp2 + kap * up * vdot / vol2)
                                                     - fp - jf * (uq - p * sc0) - hh * vp)
                            pn = (uq + ep) / sc1
                            err = abs(ep) / sc1 / (atol_p + rtol * max(abs(p), abs(pn)))
                    else:  # (written apart: the scale's arithmetic would slow every step)
                        sc0, sc1 = 1.0, 1.0
                        zp = hh * jp
                        phi1p, phi2p, phi3p = phi123(zp)
                        up = p + hh * (phi1p * fp + hh * phi2p * vp)
                        if up > 0.0 and math.isfinite(up):
                            if fs_ok:
                                fp2, jp2, _, _, vp2, _, _, _ = chamber_rhs(
                                    up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh,
                                    True, dsup, 0.0, 0.0, s_at2, 0.0, cdir)
                            else:
                                fp2 = chamber_rhs(up, temp, a_in2, a_ex2, vol2, vdot, psup2,
                                                  sl, cs, hh, False, 0.0, 0.0, 0.0, s_at2,
                                                  0.0, cdir)[0]
                            ep = 2.0 * hh * phi3p * (fp2 - fp - jp * (up - p) - hh * vp)
                            pn = up + ep
                            err = abs(ep) / (atol_p + rtol * max(abs(p), abs(pn)))
                            if fs_ok:
                                c_ok, c_fp, c_jp = True, fp2 + jp2 * ep, jp2
                                c_vp = vp2
                                if vdot != 0.0:
                                    c_vp -= jp2 * ep * vdot / vol2
                    if err < 10.0 and chord and m_ch + 1 < n and t[m_ch + 1] < tau + hh:
                        # the chord's effect on the flows, corrected to first order at the
                        # step's end; its size, weighted by CHORD_ERROR_WEIGHT, also
                        # enters the error estimate
                        c_c = chord_coupling(p, ff, jf, vol, bore, kap)
                        dpe = c_c * chord_response(t, x, m_ch, tau, tau + hh, x0c, x1c,
                                                   jf) * sc0 / sc1
                        pn -= dpe
                        err = max(err, CHORD_ERROR_WEIGHT * abs(dpe)
                                  / (atol_p + rtol * max(abs(p), abs(pn))))
                    if not (pn > 0.0 and math.isfinite(pn)):
                        err = 10.0
                if err <= 1.0:
                    if c_ok:
                        fs_fp, fs_jp, fs_vp, fs_vdot, fs_m = c_fp, c_jp, c_vp, vdot, m
                    else:
                        fs_ok = False
                    t_prev = tau
                    tau = tau + hh if hh < t_end - tau else t_end
                    if moving and spool2:
                        s_cur, v_cur = s2, v2
                    p_prev, s_prev = p, s_p0
                    p_tank = p_tank_new
                    p_lung = p_lung_new
                    p, temp = pn, tn
                    if cl_relax:
                        q1 = net_port_flow(p, a_in2, a_ex2, psup2, cs)
                        for q in range(rx_n):
                            if rx_kind[q] == 16.0:
                                rx_val[q] = relaxation_step(rx_val[q], p_prev, p,
                                                            tau - t_prev, rx_tau[q])
                            else:
                                rx_val[q] = relaxation_step(rx_val[q], rx_q0, q1,
                                                            tau - t_prev, rx_tau[q])
                        rx_rate = (p - p_prev) / (tau - t_prev)
                        rx_qrate = (q1 - rx_q0) / (tau - t_prev)
                    if general is not None and line:
                        s_p0 = line_accept(y, y_new, prop, s_vec, want_sens, line_work)
                    elif general is not None and wave:
                        # dp/dp0 through the chamber and the arriving wave's dA/dp0
                        s_p0 = (math.exp(zp) * s_p0
                                + hh * phi1p * gw * 0.5 * (swb0 + swb1))
                        w_lin, w_lex = a_in2, a_ex2
                        on_grid = tau >= w_grid - w_near
                        if on_grid or abs(tau - w_sw - w_dt) <= w_near:
                            # a grid point or a ramp's end: the ends send their waves
                            v_in, v_ex = wave_ramped(tau, a_in2, a_ex2, w_sw, w_dt, w_oin,
                                                     w_oex)
                            if not wave_ends(hist, ring, tau, w_t, w_z, w_k, p, s_p0,
                                             psup2, v_in, v_ex, cs, w_area, w_len, w_dia,
                                             w_mu, w_state, w_rd, w_row):
                                return WAVE_HISTORY
                        if on_grid:
                            w_n += 1.0
                            w_ta, w_grid = tau, t[0] + w_dt * w_n
                            w_a0, w_s0 = wave_arriving(hist, ring, tau - w_t, w_k)
                            w_a1, w_s1 = wave_arriving(hist, ring, w_grid - w_t, w_k)
                    elif thermal or tank or lung:
                        if want_sens:  # (dp, dT or the second p)/dp0 through the propagator
                            s_p0, s_t0 = (prop_t[0] * s_p0 + prop_t[1] * s_t0,
                                          prop_t[2] * s_p0 + prop_t[3] * s_t0)
                    elif want_sens:
                        s_p0 *= math.exp(zp) * sc0 / sc1
                    if kn > k + 1:
                        # dense output: the samples this step crossed, from its interpolant
                        w_r, t_r, d_r, dt_r = 0.0, t_prev, 0.0, -1.0
                        e_r, a_r, b_r = 0.0, 0.0, 0.0
                        while kw < kn and t[kw] < tau:
                            th = (t[kw] - t_prev) / hh
                            q1, q2, q3 = phi123(th * zp)
                            value = (p_prev * sc0 + th * hh * (q1 * fp + th * hh * q2 * vp)
                                     + th * th * th * q3 / phi3p * ep)
                            sc_k = 1.0
                            if chord:
                                # the sample's position, not the chord's: adiabatically,
                                # less the flows' response to the chord so far
                                dev = x0c + th * (x1c - x0c) - x[kw]
                                dt = t[kw] - t_r
                                if dt != dt_r:  # uniform sampling: once per step
                                    dt_r = dt
                                    e_r, a_r, b_r = response_weights(jf, dt)
                                w_r = e_r * w_r + a_r * d_r + b_r * (dev - d_r)
                                t_r, d_r = t[kw], dev
                                if qstep:  # q at the sample's own volume
                                    sc_k = math.exp(kap * math.log(v0 + bore * x[kw]))
                                    value = (value - c_c * sc0 * w_r) / sc_k
                                else:
                                    value = (off_chord(value, dev, v0 + bore * x[kw], bore,
                                                       kap, sl, p_atm)
                                             - c_c * w_r)
                            out[kw - i0] = (sensor_reading_scalar(value, p_atm, cal_o, cal_g)
                                            if calibrated else value)
                            if want_sens:
                                sens[kw - i0] = s_prev * math.exp(th * zp) * sc0 / sc_k
                            kw += 1
                    # the reading over the step: over the pressure step's own solution
                    # (exponential, not linear; dp/dp0 = e^{sJ} times its start's); for
                    # the (p, T) step over the pressure's own exponential part (rate,
                    # slope J_pp, time derivative) with the rest of its change as a ramp,
                    # its sensitivity over the chord; for the other steps over the chord
                    if second:
                        r, v_r = second_order_step(r, v_r, p_prev, p, hh, w_r, z_r)
                        if shaped:
                            d_r, d_v = second_order_curvature(zp, fp, vp, hh, w_r, z_r)
                            r, v_r = r + d_r, v_r + d_v
                        if want_sens:
                            s_r, s_v = second_order_step(s_r, s_v, s_prev, s_p0, hh, w_r, z_r)
                            if plain:
                                d_r, d_v = second_order_exponential_deviation(s_prev, zp, hh,
                                                                              w_r, z_r)
                                s_r, s_v = s_r + d_r, s_v + d_v
                    elif reading:
                        r_a, s_a = r, s_r
                        tau_r = lag_r
                        if plain or shaped:
                            rest = ep
                            if not plain:  # the (p, T) step: the rest of its change a ramp
                                q1, q2, _ = phi123(zp)
                                rest = p - (p_prev + hh * (q1 * fp + hh * q2 * vp))
                            if n_r != 0.0:  # a time constant that moves with the pressure
                                r, tau_r = pressure_dependent_step(r_a, p_prev, hh, lag_r, n_r,
                                                                   p_atm, zp, fp, vp, rest)
                            else:
                                r = first_order_exponential_step(r_a, p_prev, hh, lag_r, zp, fp,
                                                                 vp, rest)
                        elif n_r != 0.0:
                            r, tau_r = pressure_dependent_step(r_a, p_prev, hh, lag_r, n_r,
                                                               p_atm, 0.0, (p - p_prev) / hh,
                                                               0.0, 0.0)
                            r += dev_r
                        else:
                            r = first_order_step(r_a, p_prev, p, hh, lag_r) + dev_r
                        if want_sens:
                            if plain:
                                s_r = first_order_exponential_sensitivity(s_a, s_prev, hh, tau_r,
                                                                          zp)
                            else:
                                s_r = first_order_step(s_a, s_prev, s_p0, hh, tau_r)
                            if n_r != 0.0:  # the time constant moves with p and r:
                                # + n (p - r) / (tau (p + r)) (s_p + s_r), at the middle
                                p_m, r_m = 0.5 * (p_prev + p), 0.5 * (r_a + r)
                                s_r += hh * n_r * (p_m - r_m) / (tau_r * max(
                                    p_m + r_m, 1e-3 * p_atm)) * 0.5 * (s_prev + s_p0 + s_a
                                                                      + s_r)
                    # grow the step only when it was not cut short by a break point;
                    # shrink it when the error asks (0.9 / cbrt(err) < 1 iff err > 0.729)
                    if hh >= h or err > 0.729:
                        # where steps cross samples (dense output) a step grows on the
                        # larger of its own and its predecessor's error: a curvature
                        # changing sign gives one small estimate by cancellation, and a
                        # step grown 5x on it is accepted with an error the estimate misses
                        e_g = max(err, err_last) if kn > k + 1 else err
                        fac = 5.0 if e_g < 1e-4 else min(5.0, 0.9 / np.cbrt(e_g))
                        h = min(hmax, hh * fac)
                    err_last = err
                else:
                    if not math.isfinite(err):
                        err = 10.0
                    h = hh * max(0.1, 0.9 / np.cbrt(err))
                    if h < hmin:
                        if not (math.isfinite(p) and math.isfinite(temp)):
                            return NONFINITE
                        return STEP_UNDERFLOW
            # spool position at the end of the sub-interval (closed form)
            if spool2:
                spool, v_s = s_cur, v_cur
                # settled to rounding: the areas stay cached until the command moves
                if (abs(spool - cmd) <= 1e-12 * (1.0 + abs(cmd))
                        and abs(v_s) <= 1e-12 * w_s * (1.0 + abs(cmd))):
                    spool, v_s = cmd, 0.0
            elif tau_s > 0.0 or tau_dn > 0.0:
                spool = spool_step(spool_a, 0.0, cmd, t_end - t_sub, tau_s, 0.0, 0.0,
                                   rate_s, tau_dn)[0]
            else:
                spool = cmd
        if k >= i0:
            value = r if reading else p
            out[kn - i0] = (sensor_reading_scalar(value, p_atm, cal_o, cal_g) if calibrated
                            else value)
            if want_sens:
                sens[kn - i0] = s_r if reading else s_p0
        k = kn
    carry[0] = temp
    if general is not None and line:
        line_finish(y, carry, nseg)
    if general is not None and wave:
        # the state at the window's end (off the grid in general): the ends' waves
        # there, then the last transit time of every wave
        t_last = t[i0 + length - 1]
        if wave_newest_time(hist, ring) < t_last - w_near:
            v_in, v_ex = wave_ramped(t_last, a_in2, a_ex2, w_sw, w_dt, w_oin, w_oex)
            if not wave_ends(hist, ring, t_last, w_t, w_z, w_k, p, s_p0, psup2, v_in, v_ex,
                             cs, w_area, w_len, w_dia, w_mu, w_state, w_rd, w_row):
                return WAVE_HISTORY
        wave_finish(hist, ring, carry, t_last, w_t, w_k, w_state, w_rd)
    if tank:
        carry[CARRY_TANK] = p_tank
    if lung:
        carry[CARRY_LUNG] = p_lung
    return OK


@njit(cache=True, error_model="numpy")
def _task(task, per_task, slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0,
          rate0, out, sens, status, general):
    """One task: parameter set ``task // (W / per_task)``, its windows from
    ``(task % (W / per_task)) * per_task`` on, carrying the unmeasured states."""
    tasks_per_set = starts.shape[0] // per_task
    b = task // tasks_per_set
    w0 = (task % tasks_per_set) * per_task
    carry = _fresh_carry(consts)
    for w in range(w0, w0 + per_task):
        status[b, w] = _window(slots[b], consts, solver, t, u, ue, x, ps, pm, starts[w], length,
                               p0[w], rate0[b, w], out[b, w], sens[b, w], carry, general)
        if status[b, w] != OK:
            carry = _fresh_carry(consts)


@njit(cache=True, nogil=True, error_model="numpy")
def _simulate_serial(slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0, rate0,
                     out, sens, status, general, per_task):
    """Every (parameter set, window) pair on the calling thread (the GIL released: calls
    from several Python threads run at once,
    :meth:`pneubayes.inference.windows.WindowSet.simulate`)."""
    for task in range(slots.shape[0] * (starts.shape[0] // per_task)):
        _task(task, per_task, slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0,
              rate0, out, sens, status, general)


@njit(cache=True, parallel=True, error_model="numpy")
def _simulate_parallel(slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0,
                       rate0, out, sens, status, general, per_task):
    """Every (parameter set, window) pair, tasks spread over numba's threads."""
    for task in prange(slots.shape[0] * (starts.shape[0] // per_task)):
        _task(task, per_task, slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0,
              rate0, out, sens, status, general)


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
    _chain_carried(slots, consts, solver, t, u, ue, x, ps, pm, bounds, measured,
                   float(gain), p_start, carry, out, p_end, status,
                   True if hidden else None)
    return out, p_end, status


def _simulate(slots, consts, solver, t, u, ue, x, ps, starts, length, p0, rate0, pm,
              with_sensitivity, general):
    """Every (parameter set, window) pair; see :func:`simulate_windows`.

    Compiled variants are chosen here and built on first use: the pressure-only kernel
    unless a parameter set has a second state, and the multi-threaded loop only when
    numba has more than one thread and there is more than one task.
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
    run = _simulate_serial
    if nb * nw > 1 and numba.get_num_threads() > 1:
        run = _simulate_parallel
    if rate0 is None:
        rate0 = np.full((nb, nw), np.nan)
    if pm is None:
        pm = np.full(t.shape, np.nan)
    run(slots, consts, solver, t, u, ue, x, ps, pm, starts, length, p0, rate0, out, sens,
        status, True if hidden else None, per_task)
    return out, sens, status


def needs_general(slots) -> bool:
    """True when a parameter set (row of ``slots``) has a second state: heat transfer, an
    acoustic line, a transmission-line tube's waves, a supply tank or a second
    compartment."""
    return bool((np.asarray(slots)[:, GENERAL_SLOTS] > 0.0).any())


#: The slots of the forms with a second state (:func:`needs_general`).
GENERAL_SLOTS = np.array([_HEAT, _HCONV, _LLEN, _WLEN, _TANK, _LUNG])


@njit(cache=True, error_model="numpy")
def _fresh_carry(consts):
    """Unmeasured states at a recording's start: supply temperature, line at rest, a
    tank at the window's supply, a second compartment at the first window's p0."""
    carry = np.full(N_CARRY, np.nan)
    carry[0] = consts[C_T_SUPPLY]
    return carry


def simulate_windows(slots, consts, solver, t, u, ue, x, ps, starts, length, p0, rate0=None,
                     pm=None, general=None):
    """Simulate every (parameter set, window) pair.

    The chamber temperature (a state only with heat transfer) starts at the supply's in
    the first window, an acoustic line at rest at the chamber's pressure; when every
    window starts on the previous one's last sample, each later window starts from the
    temperature, line and tank state the previous one ended with.

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
