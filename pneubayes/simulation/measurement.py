"""The sensor point of the signal path: what the rig's pressure channel reads.

The simulator integrates the true chamber pressure. When the rig declares a zero-phase
anti-alias filter (:class:`~pneubayes.physics.sensor_filter.PressureFilter` on
:class:`~pneubayes.rig.Rig`), the reading differs from it only at the corners where the
delayed command switches a port and dp/dt jumps. :func:`sensor_reading` adds, for every
such corner at ``tau`` with a jump ``D`` (the ports' eq.-5 terms after minus before the
switch, at the simulated pressure there), ``D * K(t - tau)`` to the samples within the
filter's reach -- :class:`PressureFilter`'s kink response ``K``.

A spool lag or an acoustic line makes the ports' flow into the chamber continuous (no
jump to round), so those parameter sets are read unchanged. With heat transfer the jump
is taken at the supply temperature (the chamber's is not tracked here).
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.rig import Rig
from pneubayes.simulation.rates import rate_terms


def _port_rate(sl, rig, p, spool_V, position_m, supply_Pa):
    r = rate_terms(sl, rig, p, spool_V, position_m, np.zeros_like(p), supply_Pa)
    return r.inlet + r.exhaust


def sensor_reading(pressure_Pa: np.ndarray, slots: np.ndarray, rig: Rig, inputs, starts,
                   length: int) -> np.ndarray:
    """The declared pressure filter's reading of simulated windows, ``(B, W, length)`` Pa.

    ``pressure_Pa`` is the simulator's ``(B, W, length)`` output for the lowered
    ``slots`` ``(B, N_SLOTS)`` on ``inputs`` (:class:`~pneubayes.simulation.Inputs`)
    and windows ``starts``; it is returned unchanged when ``rig.pressure_filter`` is
    None. Each window's first sample is its start pressure (the measured one) and stays
    as it is; NaN rows (failed simulations) stay NaN.
    """
    filt = rig.pressure_filter
    if filt is None:
        return pressure_Pa
    t, u = inputs.time_s, inputs.command_V
    switch = np.nonzero(u[1:] != u[:-1])[0] + 1  # sample j: u[j - 1] -> u[j]
    finite = np.all(np.isfinite(pressure_Pa), axis=(1, 2))
    rows = np.nonzero((slots[:, S["spool_time_constant_s"]] <= 0.0)
                      & (slots[:, S["line_length_m"]] <= 0.0) & finite)[0]
    if switch.size == 0 or rows.size == 0 or length < 2:
        return pressure_Pa
    s_tab, k_tab = filt.kink_response
    reach_lo, reach_hi = s_tab[0], s_tab[-1]
    out = np.array(pressure_Pa, dtype=np.float64, copy=True)
    sl = slots[rows].T[:, :, None]  # (N_SLOTS, b, 1): broadcasts over the corners
    corner_all = t[switch][None, :] + slots[rows, S["command_delay_s"]][:, None]  # (b, k)
    first, last = corner_all.min(axis=0), corner_all.max(axis=0)
    b_index = np.arange(rows.size)[:, None, None]
    for w, s0 in enumerate(np.asarray(starts, dtype=np.int64)):
        tw = t[s0:s0 + length]
        # corners that reach the window's samples 1..length-1
        sel = np.nonzero((last > tw[1] - reach_hi) & (first < tw[-1] - reach_lo))[0]
        if not sel.size:
            continue
        tau = corner_all[:, sel]
        j = switch[sel]
        pw = out[rows, w]  # (b, length), a copy
        # the true pressure at each corner (the window's first sample before its start)
        i1 = np.clip(np.searchsorted(tw, tau), 1, length - 1)
        frac = np.clip((tau - tw[i1 - 1]) / (tw[i1] - tw[i1 - 1]), 0.0, 1.0)
        p = ((1.0 - frac) * np.take_along_axis(pw, i1 - 1, axis=1)
             + frac * np.take_along_axis(pw, i1, axis=1))
        x = np.interp(tau, t, inputs.position_m)
        ps = np.interp(tau, t, inputs.supply_pressure_Pa)
        jump = (_port_rate(sl, rig, p, u[j], x, ps)
                - _port_rate(sl, rig, p, u[j - 1], x, ps))  # (b, k), Pa/s
        # the samples within reach of each corner
        dt_min = float(np.min(np.diff(tw)))
        span = int(np.ceil((reach_hi - reach_lo) / dt_min)) + 2
        base = np.searchsorted(tw, tau + reach_lo)
        idx = base[..., None] + np.arange(span)  # (b, k, span)
        ok = (idx >= 1) & (idx < length)
        idx = np.where(ok, idx, 0)
        k = np.interp(tw[idx] - tau[..., None], s_tab, k_tab, left=0.0, right=0.0)
        np.add.at(pw, (np.broadcast_to(b_index, idx.shape), idx),
                  np.where(ok, k * jump[..., None], 0.0))
        out[rows, w] = pw
    return out
