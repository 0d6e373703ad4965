"""The reading's relaxations (effect ``reading_closure``), applied to simulated windows.

The kernel integrates the chamber; a model with
:class:`~pneubayes.effects.reading_closure.ReadingClosure` reads each window's pressure
``p`` as ``r = p + sum_k g_k (p - p_bar_k)``, ``tau_k dp_bar_k/dt = p - p_bar_k``.
:func:`relaxed_reading` steps ``p_bar`` exactly for ``p`` linear between samples (as
:func:`~pneubayes.effects.closure_histories.first_order_low_pass` does for one series).

A window starts from a measured reading ``r0``, and ``p_bar_k`` is then partway through
its relaxation. Where the inputs carry the recorded reading
(:class:`~pneubayes.simulation.Inputs` ``reading_Pa``), each ``p_bar_k`` starts at that
reading's low-pass at the window's start (from rest at the recording's first sample:
:func:`history_low_pass`), and the chamber at the pressure that reads ``r0`` there,
``p0 = (r0 + sum_k g_k p_bar_k) / (1 + sum_k g_k)`` (:func:`start_state`). The kernel
simulates each window from the parameter sets' mean ``p0`` (exactly for one set);
:func:`read_windows` moves each set to its own to first order with the kernel's start
sensitivity dp/dp0. Without the recorded reading, every ``p_bar_k`` starts at rest.
:func:`start_state` and :func:`read_windows` also take a model's plays of the reading
(:mod:`pneubayes.simulation.reading_play`), whose gains join the sums above.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pneubayes.effects.closure_histories import first_order_low_pass
from pneubayes.simulation.reading_play import (
    history_at_starts,
    history_play,
    played_reading,
)


def _low_pass_rows(time_s: np.ndarray, values: np.ndarray, tau_s: float,
                   start=None) -> np.ndarray:
    """Each row's first-order low-pass (``(W, L)`` of ``(W, L)`` series at the times
    ``time_s``, ``(W, L)`` s), from ``start`` (``(W,)``; None: at rest at its first
    value)."""
    h = np.diff(time_s, axis=-1)
    a = np.exp(-h / tau_s)
    s = (values[:, 1:] - values[:, :-1]) / np.where(h > 0, h, 1.0)
    b = values[:, 1:] - s * tau_s - a * (values[:, :-1] - s * tau_s)
    out = np.empty_like(values)
    out[:, 0] = values[:, 0] if start is None else start
    if not h.size:
        return out
    # uniform sampling (to rounding: a grid built as k * dt differs in its last bits):
    # one linear filter along the rows
    if np.all(np.abs(a - a.flat[0]) <= UNIFORM_RTOL * a.flat[0]):
        from scipy.signal import lfilter  # (here: see closure_histories.py)
        out[:, 1:] = lfilter([1.0], [1.0, -a.flat[0]], b, axis=-1,
                             zi=a.flat[0] * out[:, :1])[0]
        return out
    _recursion(np.ascontiguousarray(a), np.ascontiguousarray(b), out)
    return out


#: Sample intervals whose decay factors agree to this share count as one (uniform).
UNIFORM_RTOL = 1e-9


@njit(cache=True, error_model="numpy")
def _recursion(a, b, out):
    """``out[:, k + 1] = a[:, k] out[:, k] + b[:, k]`` along each row (from ``out[:, 0]``)."""
    for i in range(out.shape[0]):
        y = out[i, 0]
        for k in range(a.shape[1]):
            y = a[i, k] * y + b[i, k]
            out[i, k + 1] = y


def relaxed_reading(time_s, pressure_Pa, gains, time_constants_s,
                    start_Pa=None) -> np.ndarray:
    """The reading ``p + sum_k g_k (p - p_bar_k)`` of simulated windows.

    Parameters
    ----------
    time_s : (W, L) array
        Each window's sample times, s.
    pressure_Pa : (B, W, L) array
        The chamber pressure (or any series the map is applied to, e.g. dp/dp0).
    gains, time_constants_s : (B, K) arrays
        Each parameter set's gains (-) and time constants (s, > 0).
    start_Pa : (B, K, W) array or None
        Each ``p_bar_k`` at each window's start; None: at rest (the window's first
        sample).

    Returns
    -------
    (B, W, L) array
        The reading (a failed simulation's NaN rows stay as they are).
    """
    t = np.asarray(time_s, dtype=np.float64)
    p = np.asarray(pressure_Pa, dtype=np.float64)
    g = np.asarray(gains, dtype=np.float64)
    tau = np.asarray(time_constants_s, dtype=np.float64)
    if p.ndim != 3 or t.shape != p.shape[1:]:
        raise ValueError(f"relaxed_reading: pressure_Pa must be (B, W, L) and time_s (W, L), "
                         f"got {p.shape} and {t.shape}")
    if g.shape != tau.shape or g.ndim != 2 or g.shape[0] != p.shape[0]:
        raise ValueError(f"relaxed_reading: gains and time_constants_s must both be (B, K) "
                         f"with B = {p.shape[0]}, got {g.shape} and {tau.shape}")
    if start_Pa is not None and np.shape(start_Pa) != (*g.shape, p.shape[1]):
        raise ValueError(f"relaxed_reading: start_Pa must be (B, K, W) = "
                         f"{(*g.shape, p.shape[1])}, got {np.shape(start_Pa)}")
    out = p.copy()
    for b in range(p.shape[0]):
        if not np.all(np.isfinite(p[b])):
            continue  # (a failed simulation's rows stay as they are)
        for k in range(g.shape[1]):
            if g[b, k] == 0.0:
                continue
            if not (np.isfinite(tau[b, k]) and tau[b, k] > 0.0):
                raise ValueError(f"relaxed_reading: time constant {k} of parameter set {b} "
                                 f"must be finite and > 0, got {tau[b, k]!r}")
            start = None if start_Pa is None else start_Pa[b, k]
            out[b] += g[b, k] * (p[b] - _low_pass_rows(t, p[b], float(tau[b, k]), start))
    return out


def history_low_pass(time_s, reading_Pa, time_constants_s, starts) -> np.ndarray:
    """The recorded reading's first-order low-pass at the samples ``starts``, from rest at
    the first sample of the stretch of finite readings each start lies in, for each time
    constant: ``(B, K, W)`` for ``time_constants_s`` ``(B, K)`` (NaN where the reading at
    a start is not finite)."""
    t = np.asarray(time_s, dtype=np.float64)
    r = np.asarray(reading_Pa, dtype=np.float64)
    return history_at_starts(r, time_constants_s, starts,
                             lambda a, b, tau: first_order_low_pass(t[a:b], r[a:b], tau))


def reading_start(gains, bar_start_Pa, reading0_Pa) -> np.ndarray:
    """The chamber pressure ``(r0 + sum_k g_k p_bar_k) / (1 + sum_k g_k)`` that reads
    ``reading0_Pa`` (``(W,)``) when each ``p_bar_k`` is at ``bar_start_Pa``
    (``(B, K, W)``); ``(B, W)`` Pa."""
    g = np.asarray(gains, dtype=np.float64)[:, :, None]
    return (reading0_Pa + np.sum(g * bar_start_Pa, axis=1)) / (1.0 + np.sum(g, axis=1))


def start_state(gains, time_constants_s, inputs, starts, reading0_Pa, plays=None):
    """``(p0, p_bar0, y0)``: the chamber's start ``(B, W)``, each relaxation's ``(B, K,
    W)`` and each play's ``(B, J, W)`` (:mod:`pneubayes.simulation.reading_play`;
    ``plays``: ``(gains, half-widths Pa)``, each ``(B, J)``, or None) for windows
    starting at the samples ``starts`` from the readings ``reading0_Pa`` (``(W,)``, or
    each parameter set's ``(B, W)``), Pa.
    With the inputs' recorded reading, ``p_bar_k`` is its low-pass with time constant
    ``tau_k (1 + G)`` and ``y_j`` its play of half-width ``w_j (1 + G)``, ``G`` the sum
    of every gain (exact for one term alone: with ``p = (r + g p_bar) / (1 + g)``, ``tau
    dp_bar/dt = p - p_bar`` is ``tau (1 + g) dp_bar/dt = r - p_bar``; for two, to second
    order in the gains), at rest where it has no finite sample; without it, every
    ``p_bar_k`` and ``y_j`` at the start reading."""
    g = np.asarray(gains, dtype=np.float64)
    h, w = ((np.zeros((g.shape[0], 0)), np.ones((g.shape[0], 0))) if plays is None
            else (np.asarray(a, dtype=np.float64) for a in plays))
    total = np.sum(g, axis=1) + np.sum(h, axis=1)
    if np.any(1.0 + total <= 0.0):
        raise ValueError("reading closure: the gains must sum to more than -1 (a reading "
                         "that still moves with the pressure at once), got "
                         f"{total.min():.3g}")
    r0 = np.asarray(reading0_Pa, dtype=np.float64)
    r0 = np.broadcast_to(r0, (g.shape[0], r0.shape[-1]))  # (W,) or each set's (B, W)
    bar0 = np.broadcast_to(r0[:, None, :], (*g.shape, r0.shape[1])).copy()
    y0 = np.broadcast_to(r0[:, None, :], (*h.shape, r0.shape[1])).copy()
    if inputs.reading_Pa is not None:
        stretch = (1.0 + total)[:, None]
        if g.shape[1]:
            warm = history_low_pass(inputs.time_s, inputs.reading_Pa,
                                    np.asarray(time_constants_s, np.float64) * stretch, starts)
            bar0 = np.where(np.isfinite(warm), warm, bar0)
        if h.shape[1]:
            played = history_play(inputs.reading_Pa, w * stretch, starts)
            y0 = np.where(np.isfinite(played), played, y0)
    return (reading_start(np.concatenate([g, h], axis=1),
                          np.concatenate([bar0, y0], axis=1), r0), bar0, y0)


def read_windows(gains, time_constants_s, inputs, starts, pressure_Pa, sensitivity,
                 kernel_start_Pa, start_Pa, bar_start_Pa, plays=None, play_start_Pa=None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's windows ``(B, W, L)`` (``pressure_Pa``, simulated from
    ``kernel_start_Pa`` ``(W,)``, and ``sensitivity``, dp/dp0) moved to each parameter
    set's own chamber start ``start_Pa`` ``(B, W)`` to first order, and read through the
    relaxations (``gains``, ``time_constants_s``: ``(B, K)``) from ``bar_start_Pa`` and
    the plays (``plays``: ``(gains, half-widths)``, ``(B, J)``, or None) from
    ``play_start_Pa`` (:func:`start_state`): the reading and its sensitivity to the
    window's start reading."""
    g = np.asarray(gains, dtype=np.float64)
    starts = np.asarray(starts, dtype=np.int64)
    t = np.asarray(inputs.time_s, dtype=np.float64)[
        starts[:, None] + np.arange(pressure_Pa.shape[-1])]
    p = pressure_Pa + sensitivity * (start_Pa - kernel_start_Pa[None])[:, :, None]
    reading = relaxed_reading(t, p, g, time_constants_s, bar_start_Pa)
    # d reading / d r0: the chamber's start moves by 1 / (1 + sum of gains), the
    # relaxations' and plays' starts do not
    sens = relaxed_reading(t, sensitivity, g, time_constants_s, np.zeros_like(bar_start_Pa))
    total = np.sum(g, axis=1)
    if plays is not None and np.shape(plays[0])[1]:
        part, slope = played_reading(p, sensitivity, *plays, play_start_Pa)
        reading, sens = reading + part, sens + slope
        total = total + np.sum(plays[0], axis=1)
    return reading, sens / (1.0 + total)[:, None, None]
