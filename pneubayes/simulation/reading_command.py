"""The reading's lags of the command (effect ``reading_command``), added to simulated
windows.

A model with :class:`~pneubayes.effects.reading_command.ReadingCommand` reads each
window's pressure ``p`` as ``r = p + sum_k c_k l_k``, ``tau_k dl_k/dt = |u| - l_k``, u
the recorded command held between samples (so each lag steps exactly:
``l(t_n+1) = a l(t_n) + (1 - a) |u_n|``, ``a = exp(-(t_n+1 - t_n) / tau)``). Each lag runs
over the whole recording from its steady value under the command held before it (the
inputs' ``command_before_start``, else the first sample's), so a window started
mid-recording finds it warm; :func:`command_offsets` gives ``sum_k c_k l_k`` at every
window's samples. The simulator starts each window's chamber at the pressure that reads
its first reading, ``p0 = r0 - sum_k c_k l_k(start)``, and adds the offsets to what the
kernel and the reading's other maps (:mod:`pneubayes.simulation.reading_closure`) give.
"""

from __future__ import annotations

import numpy as np

from pneubayes.simulation.reading_closure import UNIFORM_RTOL, _recursion


def command_lag(time_s, command, tau_s: float, before=None) -> np.ndarray:
    """The first-order lag of ``|command|`` (held between the samples ``time_s``, s)
    with time constant ``tau_s`` (s, > 0) at every sample, from its steady value under
    ``before`` (the command held before the first sample; None: the first sample's)."""
    t = np.asarray(time_s, dtype=np.float64)
    d = np.abs(np.asarray(command, dtype=np.float64))
    if not (np.isfinite(tau_s) and tau_s > 0.0):
        raise ValueError(f"command_lag: the time constant must be finite and > 0, got "
                         f"{tau_s!r}")
    out = np.empty_like(d)
    out[0] = d[0] if before is None else abs(float(before))
    if d.size < 2:
        return out
    a = np.exp(-np.diff(t) / tau_s)
    if np.all(np.abs(a - a[0]) <= UNIFORM_RTOL * a[0]):
        from scipy.signal import lfilter  # (here: see closure_histories.py)
        out[1:] = lfilter([1.0 - a[0]], [1.0, -a[0]], d[:-1], zi=[a[0] * out[0]])[0]
        return out
    row = out[None].copy()
    _recursion(a[None], ((1.0 - a) * d[:-1])[None], row)
    return row[0]


def command_offsets(inputs, starts, length: int, gains, time_constants_s) -> np.ndarray:
    """``sum_k c_k l_k`` (Pa) at the ``length`` samples of each window from ``starts``:
    ``(B, W, length)`` for ``gains`` (Pa per command unit) and ``time_constants_s`` (s),
    each ``(B, K)``; zeros without a term."""
    g = np.asarray(gains, dtype=np.float64)
    tau = np.asarray(time_constants_s, dtype=np.float64)
    if g.ndim != 2 or g.shape != tau.shape:
        raise ValueError(f"command_offsets: gains and time_constants_s must both be (B, K), "
                         f"got {g.shape} and {tau.shape}")
    idx = np.asarray(starts, dtype=np.int64)[:, None] + np.arange(length)
    out = np.zeros((g.shape[0], *idx.shape))
    lags: dict[float, np.ndarray] = {}  # (a batch shares its time constants mostly)
    for b in range(g.shape[0]):
        for k in range(g.shape[1]):
            if g[b, k] == 0.0:
                continue
            key = float(tau[b, k])
            if key not in lags:
                lags[key] = command_lag(inputs.time_s, inputs.command_V, key,
                                        inputs.command_before_start)[idx]
            out[b] += g[b, k] * lags[key]
    return out
