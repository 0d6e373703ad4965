"""The reading's plays (effect ``reading_play``), applied to simulated windows.

A play (backlash) operator of half-width ``w`` follows its input ``p`` only once it
has moved ``w`` away: ``y = min(p + w, max(p - w, y_prev))``. For ``p`` linear between
samples the operator at the samples is exactly this recursion (it is rate-independent:
a monotone stretch moves it to its end's clip). A model with
:class:`~pneubayes.effects.reading_play.ReadingPlay` reads each window's pressure as
``r = p + sum_j h_j (p - y_j)``.

A window starts from a measured reading ``r0``. Where the inputs carry the recorded
reading, each ``y_j`` starts at that reading's play of half-width ``w_j (1 + H)``
(``H = sum h``; exact for one play alone: with ``p = (r + h y) / (1 + h)`` the play
moves exactly when ``|r - y| > w (1 + h)``), from rest at the first finite sample of
its stretch; without it, at ``r0``. The chamber starts at the pressure that reads
``r0``: ``p0 = (r0 + sum_j h_j y_j) / (1 + H)`` (the relaxations' gains join ``H``
and their ``p_bar`` the sum, :func:`pneubayes.simulation.reading_closure.start_state`).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def play_series(values, width, y0):
    """The play of half-width ``width`` of the 1-D ``values`` from ``y0``."""
    out = np.empty_like(values)
    y = y0
    for k in range(values.size):
        v = values[k]
        if y < v - width:
            y = v - width
        elif y > v + width:
            y = v + width
        out[k] = y
    return out


@njit(cache=True, error_model="numpy")
def _play_rows(v, s, width, y0, out, dout):
    """:func:`play_rows`' recursion, row by row into ``out`` and ``dout``."""
    for i in range(v.shape[0]):
        y, dy = y0[i], 0.0
        for k in range(v.shape[1]):
            if y < v[i, k] - width:
                y, dy = v[i, k] - width, s[i, k]
            elif y > v[i, k] + width:
                y, dy = v[i, k] + width, s[i, k]
            out[i, k], dout[i, k] = y, dy


def play_rows(values, sensitivity, width_Pa: float, start_Pa):
    """Each row's play and its slope in the window's start pressure.

    Parameters
    ----------
    values : (W, L) array
        The series played (Pa).
    sensitivity : (W, L) array
        d values / d p0 (-): the play's slope follows it while the play moves and keeps
        its value while it rests.
    width_Pa : float
        The half-width (Pa, > 0).
    start_Pa : (W,) array
        Each row's play before its first sample (a fixed value: slope 0 until moved).

    Returns
    -------
    (y, dy) : two (W, L) arrays
    """
    v = np.ascontiguousarray(values, dtype=np.float64)
    s = np.ascontiguousarray(np.broadcast_to(sensitivity, v.shape), dtype=np.float64)
    y0 = np.ascontiguousarray(np.broadcast_to(start_Pa, v.shape[:1]), dtype=np.float64)
    out, dout = np.empty_like(v), np.empty_like(v)
    _play_rows(v, s, float(width_Pa), y0, out, dout)
    return out, dout


def history_at_starts(reading_Pa, parameters, starts, follow) -> np.ndarray:
    """A map of the recorded reading (``follow(first, end, value)``: its series over the
    stretch ``[first, end)`` of finite readings, from rest at ``first``, for the
    parameter ``value``) at the samples ``starts``, for each of ``parameters``: ``(B, K,
    W)`` for ``(B, K)`` (NaN where the reading at a start is not finite; each distinct
    value walked once)."""
    par = np.asarray(parameters, dtype=np.float64)
    starts = np.asarray(starts, dtype=np.int64)
    r = np.asarray(reading_Pa, dtype=np.float64)
    edges = np.diff(np.concatenate(([0], np.isfinite(r).astype(np.int8), [0])))
    firsts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = np.empty((*par.shape, starts.size))
    memo: dict[float, np.ndarray] = {}
    for idx in np.ndindex(par.shape):
        v = float(par[idx])
        if v not in memo:
            y = np.full(r.shape, np.nan)
            for a, b in zip(firsts, ends):
                y[a:b] = follow(a, b, v)
            memo[v] = y[starts]
        out[idx] = memo[v]
    return out


def history_play(reading_Pa, widths_Pa, starts) -> np.ndarray:
    """The recorded reading's play at the samples ``starts``, from rest at the first
    sample of the stretch of finite readings each start lies in, for each half-width:
    ``(B, J, W)`` for ``widths_Pa`` ``(B, J)`` (NaN where the reading at a start is not
    finite; a play does not depend on the times, only on the samples' order)."""
    r = np.asarray(reading_Pa, dtype=np.float64)
    return history_at_starts(r, widths_Pa, starts,
                             lambda a, b, w: play_series(r[a:b], w, r[a]))


def played_reading(pressure_Pa, sensitivity, gains, widths_Pa, start_Pa):
    """The plays' part of the reading, ``sum_j h_j (p - y_j)``, and its slope in the
    start pressure, ``sum_j h_j (dp/dp0 - dy_j/dp0)``, of simulated windows.

    Parameters
    ----------
    pressure_Pa, sensitivity : (B, W, L) arrays
        The chamber pressure (Pa) and its start sensitivity (-).
    gains, widths_Pa : (B, J) arrays
        Each parameter set's gains (-) and half-widths (Pa, > 0).
    start_Pa : (B, J, W) array
        Each play at each window's start.

    Returns
    -------
    (part, slope) : two (B, W, L) arrays (a failed simulation's rows: zero)
    """
    p = np.asarray(pressure_Pa, dtype=np.float64)
    s = np.asarray(sensitivity, dtype=np.float64)
    h = np.asarray(gains, dtype=np.float64)
    w = np.asarray(widths_Pa, dtype=np.float64)
    part, slope = np.zeros_like(p), np.zeros_like(p)
    for b in range(p.shape[0]):
        if not np.all(np.isfinite(p[b])):
            continue
        for j in range(h.shape[1]):
            if h[b, j] == 0.0:
                continue
            if not (np.isfinite(w[b, j]) and w[b, j] > 0.0):
                raise ValueError(f"played_reading: half-width {j} of parameter set {b} "
                                 f"must be finite and > 0 Pa, got {w[b, j]!r}")
            y, dy = play_rows(p[b], s[b], float(w[b, j]), start_Pa[b, j])
            part[b] += h[b, j] * (p[b] - y)
            slope[b] += h[b, j] * (s[b] - dy)
    return part, slope
