"""The spool's state under a held command (effect ``spool_lag``), in closed form.

First order ``ds/dt = (u - s) / tau``, with a speed limit ``ds/dt = clip((u - s) / tau,
-r, r)`` (a ramp at r until ``|u - s| = r tau``, then the lag) or with its own time
constant ``tau_down`` while the command is below the spool (a spool that falls slower
or faster than it rises: under a held command the spool never crosses it, so the time
constant is the one at the hold's start), or second order
``s'' = w^2 (u - s) - 2 z w s'``
(position and velocity; exact through :func:`pneubayes.simulation.reading.second_order_step`
with a constant input). The compiled kernel (:mod:`pneubayes.simulation.kernel`) steps
the spool with these and warms it up over the command history before a window.
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import SLOT_INDEX
from pneubayes.simulation.reading import second_order_step

_DELAY = SLOT_INDEX["command_delay_s"]
_CLOCK_LATENCY = SLOT_INDEX["command_clock_latency_s"]
_SPOOL = SLOT_INDEX["spool_time_constant_s"]
_SPOOL_RATE = SLOT_INDEX["spool_rate_limit_V_per_s"]
_SPOOL_FALL = SLOT_INDEX["spool_fall_time_constant_s"]
_SPOOL_W = SLOT_INDEX["spool_natural_frequency_rad_per_s"]
_SPOOL_Z = SLOT_INDEX["spool_damping"]


@njit(cache=True, error_model="numpy")
def spool_step(s, v, cmd, h, tau, w, z, rate, tau_down):
    """``(position V, velocity V/s)`` of the spool after ``h`` s under the held command
    ``cmd`` V: second order when ``w`` > 0, else first order when ``tau`` or
    ``tau_down`` > 0 (velocity 0; speed-limited at ``rate`` V/s when ``rate`` > 0, falling
    with ``tau_down`` when it is > 0: :func:`first_order_lag`), else unchanged;
    unchanged for ``h`` <= 0."""
    if not h > 0.0:
        return s, v
    if w > 0.0:
        return second_order_step(s, v, cmd, cmd, h, w, z)
    if tau > 0.0 or tau_down > 0.0:
        return first_order_lag(s, cmd, h, tau, rate, tau_down)[0], 0.0
    return s, v


@njit(cache=True, inline="always", error_model="numpy")
def first_order_lag(s, cmd, h, tau, rate, tau_down):
    """``(position, rate)`` of the first-order spool ``ds/dt = (cmd - s) / tau`` after
    ``h`` s from ``s`` (V, V/s), speed-limited at ``rate`` V/s when ``rate`` > 0
    (``ds/dt = clip((cmd - s) / tau, -rate, rate)``: a ramp at ``rate`` while
    ``|cmd - s| > rate tau``, the exponential lag after); with ``tau_down`` > 0 the time
    constant is ``tau_down`` when ``cmd < s`` (``s`` the spool at the hold's start). A
    time constant of 0 in the spool's direction jumps onto the command."""
    if tau_down > 0.0 and cmd < s:
        tau = tau_down
    if not tau > 0.0:
        return cmd, 0.0
    if rate > 0.0:
        e = cmd - s
        excess = abs(e) - rate * tau
        if excess > 0.0:
            sg = 1.0 if e > 0.0 else -1.0
            t_ramp = excess / rate
            if h <= t_ramp:
                return s + sg * rate * h, sg * rate
            s = cmd - sg * rate * tau
            h -= t_ramp
    s1 = cmd + (s - cmd) * math.exp(-h / tau)
    return s1, (cmd - s1) / tau


@njit(cache=True, inline="always", error_model="numpy")
def spool_settle_s(tau, w, z):
    """Time constant of the spool's slowest mode (s): ``tau`` for the first order (the
    larger of its rise's and fall's);
    1 / (z w) for the second at z <= 1, (z + sqrt(z^2 - 1)) / w above it."""
    if not w > 0.0:
        return tau
    if z <= 1.0:
        return 1.0 / (z * w)
    return (z + math.sqrt(z * z - 1.0)) / w


@njit(cache=True, inline="always", error_model="numpy")
def spool_settings(sl):
    """``(delay s, tau s, tau_down s, w rad/s, z, rate V/s, second_order, lagged)`` of
    one parameter set's lowered slots (the delay: the command's transport delay and a
    valve driver's latency, :mod:`pneubayes.simulation.command_clock`): a second-order
    spool (``w`` > 0) overrides the first-order lag (its ``tau`` and ``tau_down`` read
    as 0), whose speed limit applies only with a rise time constant."""
    delay, tau_s = sl[_DELAY] + sl[_CLOCK_LATENCY], sl[_SPOOL]
    w_s, z_s = sl[_SPOOL_W], sl[_SPOOL_Z]
    tau_dn = sl[_SPOOL_FALL]  # the first-order spool's fall, if its own
    spool2 = w_s > 0.0
    if spool2:
        tau_s = tau_dn = 0.0
    rate_s = sl[_SPOOL_RATE] if tau_s > 0.0 else 0.0
    lagged = tau_s > 0.0 or tau_dn > 0.0 or spool2
    return delay, tau_s, tau_dn, w_s, z_s, rate_s, spool2, lagged


@njit(cache=True, error_model="numpy")
def spool_at_start(t, u, j, t_start, delay, tau, w, z, rate, tau_down):
    """``(position V, velocity V/s)`` of a lagged spool at ``t_start`` mid-recording
    (``j``: the delayed command's sample there), in closed form over the held samples of
    up to 20 settling times before it (a speed-limited spool also ramps across the
    commands' span there first)."""
    jj = j
    settle = spool_settle_s(max(tau, tau_down), w, z)
    u_lo, u_hi = u[j], u[j]
    while jj > 0 and t_start - (t[jj] + delay) < 20.0 * settle + (
            (u_hi - u_lo) / rate if rate > 0.0 else 0.0):
        jj -= 1
        u_lo, u_hi = min(u_lo, u[jj]), max(u_hi, u[jj])
    spool, v_s = u[jj], 0.0
    for k in range(jj, j):
        spool, v_s = spool_step(spool, v_s, u[k], t[k + 1] - t[k], tau, w, z, rate, tau_down)
    return spool_step(spool, v_s, u[j], t_start - (t[j] + delay), tau, w, z, rate, tau_down)


@njit(cache=True, inline="always", error_model="numpy")
def spool_at_end(second_order, s_cur, v_cur, s_start, v_s, cmd, h, tau, w, rate, tau_down):
    """``(position, velocity)`` of the spool after a held command's ``h`` s: the second
    order's stepped state ``(s_cur, v_cur)`` (snapped onto the command once settled to
    rounding, so the areas stay cached until it moves), the first order's closed form
    from ``s_start``, or the command itself."""
    if second_order:
        spool, v_s = s_cur, v_cur
        if (abs(spool - cmd) <= 1e-12 * (1.0 + abs(cmd))
                and abs(v_s) <= 1e-12 * w * (1.0 + abs(cmd))):
            spool, v_s = cmd, 0.0
        return spool, v_s
    if tau > 0.0 or tau_down > 0.0:
        return spool_step(s_start, 0.0, cmd, h, tau, 0.0, 0.0, rate, tau_down)[0], v_s
    return cmd, v_s
