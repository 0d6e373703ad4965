"""The recorded inputs as the compiled kernel reads them (:mod:`pneubayes.simulation.kernel`).

The command is held between samples (zero-order hold) and read ``command_delay_s``
late; the position and supply are linear between samples and read ``inputs_advance_s``
early (late where it is negative: before the first sample they hold its values). A step
never crosses a break of either, except with dense output, where a step runs over the
samples that repeat the command and the supply
(:func:`pneubayes.simulation.dense.dense_run`). A driver's clock
(:mod:`pneubayes.simulation.command_clock`) takes the command at its ticks instead.
"""

from __future__ import annotations

from numba import njit

from pneubayes.simulation.command_clock import clock_on, clocked_hold


@njit(cache=True, error_model="numpy")
def delayed_command(t, u, delay, t_start, track_direction):
    """``(j, direction)``: the index of the command sample held at ``t_start - delay``
    (the last ``j >= 1`` with ``t[j] + delay <= t_start``, else 0; by bisection: a one-step
    window at every sample would otherwise scan the recording from its start each time)
    and, with ``track_direction``, the sign of the command's last change up to it
    (+1, -1; 0: none)."""
    n = t.shape[0]
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if t[mid] + delay <= t_start:
            lo = mid + 1
        else:
            hi = mid
    j = lo - 1 if lo > 1 else 0
    cdir = 0.0
    if track_direction:
        jj = j
        while jj > 0 and u[jj] == u[jj - 1]:
            jj -= 1
        if jj > 0:
            cdir = 1.0 if u[jj] > u[jj - 1] else -1.0
    return j, cdir


@njit(cache=True, inline="always", error_model="numpy")
def command_hold(sl, t, u, j, cdir, track_direction, delay, tau, tb, crossing, general):
    """``(j, direction, command, t_end)``: the delayed command held from ``tau`` (its
    index ``j`` moved on, the direction tracked) and where it next changes before ``tb``
    (else ``tb``); ``crossing`` (dense output): past the samples that repeat it. Where
    the slots ``sl`` carry a driver's clock, as it takes the command
    (:func:`~pneubayes.simulation.command_clock.clocked_hold`; direction untracked; the
    general kernel only, ``general`` not None)."""
    if general is not None and clock_on(sl):
        j, cmd, t_end = clocked_hold(sl, t, u, j, delay, tau, tb)
        return j, cdir, cmd, t_end
    n = t.shape[0]
    while j + 1 < n and t[j + 1] + delay <= tau:
        j += 1
        if track_direction and u[j] != u[j - 1]:
            cdir = 1.0 if u[j] > u[j - 1] else -1.0
    cmd = u[j]
    t_end = tb
    jn = j + 1  # the next break of the delayed command
    if crossing:
        while jn < n and u[jn] == cmd and t[jn] + delay < tb:
            jn += 1
    if jn < n and t[jn] + delay < tb:
        t_end = t[jn] + delay
    return j, cdir, cmd, t_end


@njit(cache=True, inline="always", error_model="numpy")
def input_segment(t, x, ps, m, tau, adv, t_end, single):
    """``(m, ta, inv_seg, xa, xb, sa, sb, t_end)``: the segment ``m`` of the position and
    supply that holds ``tau + adv``, its start ``ta`` (s, shifted by ``-adv``), ``1 / its
    length`` (0 past the last sample, whose values are held) and end values; ``t_end``
    cut at the segment's end when the pass steps one sample (``single``)."""
    n = t.shape[0]
    while m + 1 < n and t[m + 1] - adv <= tau:
        m += 1
    if m == 0 and tau < t[0] - adv:  # read before the first sample (read late): its values,
        if t[0] - adv < t_end:  # held, until the first sample is reached
            t_end = t[0] - adv
        return m, tau, 0.0, x[0], x[0], ps[0], ps[0], t_end
    if m + 1 < n:
        ta = t[m] - adv
        inv_seg = 1.0 / (t[m + 1] - t[m])
        xa, xb, sa, sb = x[m], x[m + 1], ps[m], ps[m + 1]
        if t[m + 1] - adv < t_end and single:
            t_end = t[m + 1] - adv
    else:  # read past the last sample: its values, held
        ta, inv_seg = tau, 0.0
        xa, xb, sa, sb = x[m], x[m], ps[m], ps[m]
    return m, ta, inv_seg, xa, xb, sa, sb, t_end
