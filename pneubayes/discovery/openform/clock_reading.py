"""Reading a clock the recording does not carry from when things happen: the valve
driver's ticks behind the command changes' takes, and a pulse-width modulator's ripple
in the residual (the steps of
:class:`~pneubayes.discovery.openform.command_clock.CommandClockSearch`).

Over a 20-s recording a clock's period must be known to about a part in 10^5 for its
ticks to stay in phase, so the period is read where the times are most in phase on a
fine frequency grid (:func:`clock_in_phase`), from each change's take as the current
model sees it (:func:`change_takes`) or as the measured pressure shows it
(:func:`change_onsets`), or from the residual's spectral lines (:func:`ripple_periods`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Frequencies whose phase factors one pass of :func:`phase_sums` advances by a
#: recurrence from one computed exactly (its rounding grows with the pass's length).
PHASE_BLOCK = 2048


@njit(cache=True)
def phase_sums(first_hz, step_hz, count, times_s, weights):
    """``|sum_k w_k exp(2 pi i f_m t_k)|`` at the ``count`` frequencies ``f_m = first_hz +
    m step_hz`` (Hz) for times ``times_s`` (s) and weights ``weights``: ``(count,)``.

    Each time's phase factor is computed exactly at a block's first frequency and
    advanced by the factor of one step through the block (:data:`PHASE_BLOCK`
    frequencies), so a grid of M frequencies costs M multiplications per time instead of
    M complex exponentials; over a block the recurrence's relative error stays under
    about ``PHASE_BLOCK`` x 1e-16."""
    out = np.empty(count)
    acc = np.empty(PHASE_BLOCK, dtype=np.complex128)
    two_pi = 2.0 * math.pi
    for a in range(0, count, PHASE_BLOCK):
        nb = min(PHASE_BLOCK, count - a)
        acc[:nb] = 0.0
        f_a = first_hz + a * step_hz
        for k in range(times_s.shape[0]):
            t = times_s[k]
            e = weights[k] * complex(math.cos(two_pi * f_a * t), math.sin(two_pi * f_a * t))
            z = complex(math.cos(two_pi * step_hz * t), math.sin(two_pi * step_hz * t))
            for m in range(nb):
                acc[m] += e
                e *= z
        for m in range(nb):
            out[a + m] = abs(acc[m])
    return out


def change_takes(changes, measured, resid, waits, after):
    """Each command change's take: ``(C, 2)`` of (its time plus its best wait, the wait)
    in s, and its weight (the share of the change's residual the wait removes), for the
    changes a wait improves. ``changes`` is ``(window, sample, time_s)`` of each command
    change (:meth:`~pneubayes.discovery.openform.command_clock.CommandClockProblem.changes`),
    ``measured`` the windows' pressure ``(W, L)`` (Pa), ``resid`` the residuals ``(waits, W,
    L - 1)`` at each of ``waits`` (s); ``after`` the samples after a change judged. A
    change's simulated departure from the sample before it is
    scaled to fit the measured one's (least squares, per wait): its timing is judged, not
    the size a model whose valve maps the wait has bent gives it."""
    win, k, tc = changes
    took, weight = [], []
    n = resid.shape[2]
    for i in range(win.size):
        if k[i] < 2:
            continue
        nxt = k[(win == win[i]) & (k > k[i])]
        end = min(int(k[i] + after), int(nxt.min()) if nxt.size else n + 1, n + 1)
        y = measured[win[i], k[i]:end] - measured[win[i], k[i] - 1]
        sim = resid[:, win[i], k[i] - 2:end - 1] + measured[None, win[i], k[i] - 1:end]
        x = sim[:, 1:] - sim[:, :1]  # (residual j is window sample j + 1)
        xx = np.sum(x * x, axis=1)
        scale = np.where(xx > 0.0, np.sum(x * y, axis=1) / np.where(xx > 0.0, xx, 1.0), 0.0)
        sse = np.sum((y - scale[:, None] * x) ** 2, axis=1)
        if not np.all(np.isfinite(sse)) or sse[0] <= 0.0:
            continue
        j = int(np.argmin(sse))
        gain = 1.0 - sse[j] / sse[0]
        if j > 0 and gain > 0.0:
            wait = waits[j]
            if j + 1 < waits.size:  # between the grid's waits: the parabola's vertex
                curv = sse[j - 1] - 2.0 * sse[j] + sse[j + 1]
                if curv > 0.0:
                    wait += 0.5 * (waits[1] - waits[0]) * (sse[j - 1] - sse[j + 1]) / curv
            took.append((tc[i] + wait, wait))
            weight.append(gain)
    return np.array(took).reshape(-1, 2), np.array(weight)


def change_onsets(changes, measured, most, dt):
    """Each command change's onset in the measured pressure: ``(C, 2)`` of (the time
    the pressure leaves the line it followed before the change, back-extrapolated along
    its first departure; its wait after the change) in s, and weights (1), for the
    changes whose pressure departs by six noise deviations within ``most`` samples;
    ``changes`` and ``measured`` as :func:`change_takes` takes them, ``dt`` the sample
    interval (s)."""
    win, k, tc = changes
    d = np.diff(measured, axis=1)
    sigma = float(np.median(np.abs(d - np.median(d)))) / 0.6745 / np.sqrt(2.0)
    level = 6.0 * max(sigma, 1.0)
    n, out = measured.shape[1], []
    for w, i, t0 in zip(win, k, tc):
        if i < 6 or i + most + 4 >= n:
            continue
        x = np.arange(-6, most + 4)
        a, b = np.polyfit(x[:6], measured[w, i - 6:i], 1)
        dev = np.abs(measured[w, i - 6:i + most + 4] - (a * x + b))[6:]
        over = np.flatnonzero((dev[:-2] > level) & (dev[1:-1] > level) & (dev[2:] > level))
        if not over.size or over[0] == 0:
            continue
        m = int(over[0])
        slope = (dev[m + 2] - dev[m]) / 2.0  # Pa per sample, along the departure
        if not slope > 0.0:
            continue
        onset = t0 + dt * max(m - dev[m] / slope, 0.0)
        out.append((onset, onset - t0))
    return np.array(out).reshape(-1, 2), np.ones(len(out))


def clock_in_phase(times, weight, shortest, longest, duration, changes=None,
                   max_change_coherence=0.5):
    """``(period s, offset s, coherence, p)``: the period at which ``times`` are most in
    phase (weighted; frequencies every 0.02 / ``duration``, the best sharpened 40 times
    finer), the longest among those within 5 % of the best (a tick pattern is in phase at
    its period's fractions too), where in the period the ticks fall, and the chance that
    times without a clock are as much in phase at some frequency of the grid (Rayleigh's
    ``exp(-N R^2)`` over the grid's frequencies, ``N`` the weights' effective count).

    Frequencies at which the command's ``changes`` themselves (s) are in phase beyond
    ``max_change_coherence`` x the ``times``' coherence are not read (a driver's ticks put
    the takes in phase, not the changes): a command logged every 10 ms changes only on
    that grid, so its changes taken after a fixed delay are in phase at 10 ms, its
    fractions and the sides of their peaks without any driver. No frequency left:
    ``(nan, nan, 0, 1)``."""
    step = 0.02 / max(duration, 1.0)
    freqs = np.arange(1.0 / longest, 1.0 / shortest + step, step)
    w = weight / np.sum(weight)

    times = np.ascontiguousarray(times, dtype=np.float64)

    def in_phase(t, wt):
        return phase_sums(float(freqs[0]), step, freqs.size, t,
                          np.ascontiguousarray(wt, dtype=np.float64))

    coh = in_phase(times, w)
    if changes is not None and np.size(changes):
        c = np.asarray(changes, dtype=np.float64)
        own = in_phase(c, np.full(c.size, 1.0 / c.size))
        coh = np.where(own > max_change_coherence * coh, 0.0, coh)
    if not np.any(coh > 0.0):
        return float("nan"), float("nan"), 0.0, 1.0
    j = int(np.argmax(coh))
    for m in (6, 5, 4, 3, 2):  # the fundamental of the best, if as much in phase
        i = int(np.argmin(np.abs(freqs - freqs[j] / m)))
        if freqs[j] / m >= freqs[0] and coh[i] >= 0.95 * coh[j]:
            j = i
            break
    fine = np.linspace(freqs[j] - step, freqs[j] + step, 81)  # between the grid's steps
    f = fine[int(np.argmax(np.abs(np.exp(2j * np.pi * np.outer(fine, times)) @ w)))]
    angle = float(np.angle(np.exp(2j * np.pi * f * times) @ w))
    n_eff = float(np.sum(weight) ** 2 / np.sum(weight**2))
    p = min(1.0, freqs.size * float(np.exp(-n_eff * coh[j] ** 2)))
    return 1.0 / f, (angle / (2.0 * np.pi) % 1.0) / f, float(coh[j]), p


def ripple_periods(times, resid, dt, shortest, longest, duration, lines=2):
    """Candidate periods (s) of a ripple locked to a clock in the residual ``resid`` (Pa,
    at ``times`` s, both ``(W, L - 1)``): the ``lines`` strongest lines of the windows'
    mean power spectrum between the periods' bounds (each over the spectrum's running
    median), each sharpened on the whole record (where the windows' ripples add in
    phase, frequencies every 0.02 / ``duration``), and its periods' multiples up to six
    (a line may be the ripple's harmonic)."""
    r = np.where(np.isfinite(resid), resid, 0.0)
    r = r - np.mean(r, axis=1, keepdims=True)
    power = np.mean(np.abs(np.fft.rfft(r, axis=1)) ** 2, axis=0)
    freqs = np.fft.rfftfreq(r.shape[1], dt)
    band = np.flatnonzero((freqs >= 1.0 / longest) & (freqs <= 1.0 / shortest))
    if band.size < 5:
        return []
    half = 8
    base = np.array([np.median(power[max(0, i - half):i + half + 1]) for i in band])
    score = power[band] / np.maximum(base, np.finfo(float).tiny)
    out, taken = [], []
    for i in np.argsort(score)[::-1]:
        f0 = freqs[band[i]]
        if any(abs(f0 - f) < 2.0 * (freqs[1] - freqs[0]) for f in taken):
            continue
        taken.append(f0)
        width = 2.0 * (freqs[1] - freqs[0])
        fine = np.arange(f0 - width, f0 + width, 0.02 / max(duration, 1.0))
        amp = [abs(np.sum(r * np.exp(2j * np.pi * g * times))) for g in fine]
        f = fine[int(np.argmax(amp))]
        out += [float(m / f) for m in range(1, 7) if f / m >= 1.0 / longest]
        if len(taken) == lines:
            break
    return out


def ticks_centred(change_times_s, period_s, phase, latency_s, latency_bounds_s):
    """``(phase, latency_s)`` with the driver's ticks moved to the middle of the span in
    which every command change of ``change_times_s`` (s, on the recording's clock) is
    still taken at the same tick, the latency moved the other way (the valve switches
    when it did, within ``latency_bounds_s``).

    The windows fix when the valve switches (the ticks plus the latency) sharply, but
    where between the changes the ticks fall only as far as no change crosses one: a
    fit leaves the ticks anywhere in that span, and a change of new data that falls
    between the fitted ticks and the true ones is taken a period early or late. The
    middle is the split the data support most widely. No changes (or no period): as
    given."""
    t = np.asarray(change_times_s, dtype=np.float64)
    if not period_s > 0.0 or not t.size:
        return phase, latency_s
    # each change's lead on the tick that takes it: ticks later by up to
    # period - max(lead) keep every take, earlier by up to min(lead)
    lead = (phase * period_s - t) % period_s
    shift = 0.5 * (period_s - float(np.max(lead)) - float(np.min(lead)))
    lo, hi = latency_bounds_s
    shift = float(np.clip(shift, latency_s - hi, latency_s - lo))
    return float((phase + shift / period_s) % 1.0), float(latency_s - shift)


__all__ = ["change_onsets", "change_takes", "clock_in_phase", "ripple_periods",
           "ticks_centred"]
