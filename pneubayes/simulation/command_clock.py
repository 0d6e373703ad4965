"""Compiled part of the driver's clock (effect ``command_clock``): a valve that takes the
command only at the ticks of its driver's clock.

With period ``T`` and phase ``phi`` the driver's ticks fall at ``(phi + k) T`` on the
recording's clock (its ``time_s``); at each tick it takes the command sample held there
and, ``L`` later (latency), drives the valve with it: holding it over the period, or
(pulse-width modulation) at the full command ``+-U`` of its sign for ``min(|u| / U, 1)``
of the period less a trim, the pulse starting a share (its alignment) of the period's
shut time after the tick, and shut (0) for the rest. The chamber sees the valve a
transport delay later still; the kernel reads the latency with that delay
(:func:`~pneubayes.simulation.spool.spool_settings`), so with no clock (period 0) it is a
pure delay of the command. :func:`clocked_hold` is the kernel's held command under the
clock: what the valve takes from ``tau`` and when it next changes.
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import SLOT_INDEX

_T = SLOT_INDEX["command_clock_period_s"]
_PHASE = SLOT_INDEX["command_clock_phase"]
_PWM = SLOT_INDEX["command_clock_pwm"]
_FULL = SLOT_INDEX["command_clock_full_command_V"]
_TRIM = SLOT_INDEX["command_clock_pulse_trim_s"]
_ALIGN = SLOT_INDEX["command_clock_pulse_alignment"]
#: A hold shorter than this share of the period is taken as its end (rounding at a tick).
TICK_TOLERANCE = 1e-9


@njit(cache=True, inline="always", error_model="numpy")
def clock_on(sl) -> bool:
    """Whether a parameter set's valve takes the command on a driver's clock."""
    return sl[_T] > 0.0


@njit(cache=True, error_model="numpy")
def clocked_hold(sl, t, u, j, delay, tau, tb):
    """``(j, command, t_end)`` under the driver's clock: the command the valve holds from
    ``tau`` (s, the chamber's time; ``delay`` s the driver's latency and the transport
    delay after the valve, as :func:`~pneubayes.simulation.spool.spool_settings` gives
    it), the
    index ``j`` of the sample the driver took, and where the held value next changes
    before ``tb`` (else ``tb``)."""
    period, trim = sl[_T], sl[_TRIM]
    s = tau - delay  # the driver's time
    k = math.floor(s / period - sl[_PHASE])
    tick = (sl[_PHASE] + k) * period
    if tick + period - s <= TICK_TOLERANCE * period:  # at the next tick, to rounding
        tick += period
    n = t.shape[0]
    while j > 0 and t[j] > tick:  # the sample held at the tick (j moves either way)
        j -= 1
    while j + 1 < n and t[j + 1] <= tick:
        j += 1
    cmd, end = u[j], tick + period
    if sl[_PWM] != 0.0:
        full = sl[_FULL]
        duty = min(abs(cmd) / full, 1.0)
        on = period if duty >= 1.0 else min(duty * period - trim, period)
        lead = sl[_ALIGN] * (1.0 - duty) * period  # the driver's pulse starts
        tol = TICK_TOLERANCE * period
        if cmd == 0.0 or on <= 0.0 or s >= tick + lead + on - tol:
            cmd = 0.0
        elif s < tick + lead - tol:  # shut until the pulse starts
            cmd, end = 0.0, tick + lead
        else:
            cmd, end = math.copysign(full, cmd), tick + lead + on
    t_end = end + delay
    return j, cmd, t_end if t_end < tb else tb
