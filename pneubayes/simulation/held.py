"""A closure's dead-time windows in the compiled kernel (the features ``*_late_fall``
and ``*_late_rise`` of :mod:`pneubayes.effects.closure_features`, whose numpy twin is
:class:`~pneubayes.effects.closure_histories.HeldCommand`).

At a time t a window of d s covers the delayed command over ``[t - d, t]``: the samples
from the one in force at ``t - d`` (the window's pointer) to the one in force at t. Its
extreme changes only where the command does (``t_i + delay``) or where a value leaves
the window (``t_i + delay + d`` for a change at sample i): the kernel ends its command
stretches at both, so the feature is constant over each.
"""

from __future__ import annotations

from numba import njit

from pneubayes.simulation.inputs import delayed_command


@njit(cache=True, error_model="numpy")
def held_start(t, u, delay, t_start, n, kind, dead, pointer):
    """Each window's pointer at ``t_start``: the command sample in force at ``t_start -
    dead`` (entries of ``kind`` 31-34 among the closure's ``n``; ``dead`` in s)."""
    for q in range(n):
        if kind[q] >= 31.0:
            pointer[q] = delayed_command(t, u, delay + dead[q], t_start, False)[0]


@njit(cache=True, error_model="numpy")
def held_windows(t, u, j, delay, tau, t_end, n, kind, dead, value, pointer):
    """Move each window to ``tau`` (s; ``j`` the command sample in force there), write
    its extreme into ``value`` (the highest command for kinds 31 and 32, a valve late
    after falls; the lowest for 33 and 34) and return ``t_end`` cut at the first time
    before it that a changed value leaves a window."""
    nt = t.shape[0]
    for q in range(n):
        if kind[q] < 31.0:
            continue
        d = dead[q]
        jo = pointer[q]
        while jo + 1 < nt and t[jo + 1] + delay + d <= tau:
            jo += 1
        pointer[q] = jo
        fall = kind[q] < 33.0
        ext = u[j]
        for i in range(jo, j):
            if (u[i] > ext) if fall else (u[i] < ext):
                ext = u[i]
        value[q] = ext
        i = jo + 1  # the value before sample i leaves at t_i + delay + d
        while i < nt and t[i] + delay + d < t_end:
            if u[i] != u[i - 1]:
                t_end = t[i] + delay + d
                break
            i += 1
    return t_end
