"""The sensor point of the signal path: what the rig's pressure channel reads.

The simulator integrates the true chamber pressure. When the rig declares a zero-phase
anti-alias filter (:class:`~pneubayes.physics.sensor_filter.PressureFilter` on
:class:`~pneubayes.rig.Rig`), the reading differs from it only at the corners where the
delayed command switches a port and dp/dt jumps. :func:`sensor_reading` adds, for every
such corner at ``tau`` with a jump ``D`` (the ports' eq.-5 terms after minus before the
switch, at the simulated pressure there), ``D * K(t - tau)`` to the samples within the
filter's reach -- :class:`PressureFilter`'s kink response ``K``.

A spool lag or an acoustic line makes the ports' flow into the chamber continuous (no
jump to round), so those parameter sets are read unchanged; so is a reading that
already lags the chamber (effect ``sensor_lag``), which rounds every corner itself.
With heat transfer the jump is taken at the supply temperature (the chamber's is not
tracked here). A miscalibrated sensor (effect ``sensor_calibration``) reads the jump
through its gain, at the chamber pressure behind the reading.

A window starts from a measured reading. A corner within the filter's reach of the start
(±2.7 ms at 1 kHz) is already in that reading and is counted again near the start: in
about 3 % of 2-s windows at the bench's step rate, tens of Pa for a few ms. One-step
predictions, which start at every sample, leave the sensor term out for this reason
(:mod:`pneubayes.discovery.one_step`).
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.command_clock import command_delay_s
from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.physics.calibration import (
    CURVATURE_SCALE_PA,
    pressure_behind_reading_Pa,
    reading_zero_Pa,
)
from pneubayes.rig import Rig
from pneubayes.simulation.rates import rate_terms


def _port_rate(sl, rig, p, spool_V, position_m, supply_Pa, exhaust_command):
    # (the ports' terms only)
    r = rate_terms(sl, rig, p, spool_V, position_m, np.zeros_like(p), supply_Pa,
                   exhaust_command, include_closure=False)
    return r.inlet + r.exhaust


def sensor_reading(pressure_Pa: np.ndarray, slots: np.ndarray, rig: Rig, inputs, starts,
                   length: int) -> tuple[np.ndarray, np.ndarray]:
    """The declared pressure filter's reading of simulated windows, ``(B, W, length)`` Pa,
    and the parameter sets (row indices) whose reading failed.

    ``pressure_Pa`` is the simulator's ``(B, W, length)`` output for the lowered
    ``slots`` ``(B, N_SLOTS)`` on ``inputs`` (:class:`~pneubayes.simulation.Inputs`)
    and windows ``starts``; it is returned unchanged when ``rig.pressure_filter`` is
    None. Each window's first sample is its start pressure (the measured one) and stays
    as it is; NaN rows (failed simulations) stay NaN, and a parameter set whose reading
    at a corner stands for no chamber pressure (beyond a curved sensor's turning point)
    becomes one: those are the rows returned.
    """
    filt = rig.pressure_filter
    none = np.zeros(0, dtype=np.int64)
    if filt is None:
        return pressure_Pa, none
    t, u = inputs.time_s, inputs.command_V
    switch = np.nonzero(u[1:] != u[:-1])[0] + 1  # sample j: u[j - 1] -> u[j]
    finite = np.all(np.isfinite(pressure_Pa), axis=(1, 2))
    rows = np.nonzero((slots[:, S["spool_time_constant_s"]] <= 0.0)
                      & (slots[:, S["command_clock_period_s"]] <= 0.0)
                      & (slots[:, S["spool_fall_time_constant_s"]] <= 0.0)
                      & (slots[:, S["spool_natural_frequency_rad_per_s"]] <= 0.0)
                      & (slots[:, S["line_length_m"]] <= 0.0)
                      & (slots[:, S["sensor_time_constant_s"]] <= 0.0)
                      & (slots[:, S["sensor_natural_frequency_rad_per_s"]] <= 0.0)
                      & finite)[0]
    if switch.size == 0 or rows.size == 0 or length < 2:
        return pressure_Pa, none
    s_tab, k_tab = filt.kink_response
    reach_lo, reach_hi = s_tab[0], s_tab[-1]
    starts = np.asarray(starts, dtype=np.int64)
    out = np.array(pressure_Pa, dtype=np.float64, copy=True)
    delay = command_delay_s(slots[rows])
    t_switch = t[switch]
    # (window, switch) pairs whose corner, for some row, reaches samples 1..length-1
    t_first, t_last = t[starts + 1], t[starts + length - 1]
    k_lo = np.searchsorted(t_switch + delay.max(), t_first - reach_hi, side="right")
    k_hi = np.searchsorted(t_switch + delay.min(), t_last - reach_lo, side="left")
    count = np.maximum(k_hi - k_lo, 0)
    if not count.sum():
        return pressure_Pa, none
    w = np.repeat(np.arange(starts.size), count)  # (P,)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + k_lo[w]
    j = switch[k]
    s0 = starts[w]
    tau = t_switch[k][None, :] + delay[:, None]  # (b, P), s
    # the true pressure at each corner, interpolated in its window (the window's first
    # sample for a corner before the start, its last for one after the end)
    g = np.clip(np.searchsorted(t, tau), s0 + 1, s0 + length - 1)  # global sample index
    frac = np.clip((tau - t[g - 1]) / (t[g] - t[g - 1]), 0.0, 1.0)
    b_idx = np.arange(rows.size)[:, None]
    p = ((1.0 - frac) * out[rows[b_idx], w, g - 1 - s0]
         + frac * out[rows[b_idx], w, g - s0])
    # a miscalibrated sensor (effect sensor_calibration): the chamber's pressure behind
    # the reading, and the jump read through the sensor's gain
    cal_o = reading_zero_Pa(tau, *(slots[rows, S[k]][:, None] for k in (
        "reading_offset_Pa", "reading_drift_Pa_per_s", "reading_warm_up_Pa",
        "reading_warm_up_time_constant_s")))
    cal_g = 1.0 + slots[rows, S["reading_gain_error"]][:, None]
    curv = slots[rows, S["reading_curvature_Pa"]][:, None]
    p = pressure_behind_reading_Pa(p, rig.atmospheric_pressure_Pa, cal_o, cal_g, curv)
    # a reading beyond a curved sensor's turning point stands for no pressure: that
    # parameter set fails, as a simulation that fails does (its rows become NaN)
    unread = ~np.all(np.isfinite(p) & (p > 0.0), axis=1)  # (b,)
    p = np.where(unread[:, None], rig.atmospheric_pressure_Pa, p)
    # the sensor's slope there (g, and a curved sensor's 2 k y / (1 bar)^2)
    slope = cal_g + 2.0 * curv * (p - rig.atmospheric_pressure_Pa) / CURVATURE_SCALE_PA**2
    x = np.interp(tau, t, inputs.position_m)
    ps = np.interp(tau, t, inputs.supply_pressure_Pa)
    sl = slots[rows].T[:, :, None]  # (N_SLOTS, b, 1): broadcasts over the corners
    # the valve command's corners (a separate exhaust valve's command held as at j)
    ue = inputs.exhaust_command
    ue_j = None if ue is None else np.broadcast_to(ue[j], p.shape)
    jump = slope * (_port_rate(sl, rig, p, u[j], x, ps, ue_j)
                    - _port_rate(sl, rig, p, u[j - 1], x, ps, ue_j))  # (b, P), Pa/s
    # the samples within the filter's reach of each corner
    dt_min = float(np.min(np.diff(t)))
    span = int(np.ceil((reach_hi - reach_lo) / dt_min)) + 2
    first = np.searchsorted(t, tau + reach_lo)
    idx = first[..., None] + np.arange(span)  # (b, P, span), global sample index
    ok = (idx >= (s0 + 1)[:, None]) & (idx < (s0 + length)[:, None])
    idx = np.where(ok, idx, (s0 + 1)[:, None])
    kr = np.interp(t[idx] - tau[..., None], s_tab, k_tab, left=0.0, right=0.0)
    shape = idx.shape
    np.add.at(out, (np.broadcast_to(rows[:, None, None], shape),
                    np.broadcast_to(w[None, :, None], shape), idx - s0[:, None]),
              np.where(ok, kr * jump[..., None], 0.0))
    out[rows[unread]] = np.nan
    return out, rows[unread]
