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

from pneubayes.simulation.reading import second_order_step


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
