"""A closure's relaxed pressure ``p_bar`` in the compiled kernel (feature
``pressure_relaxation`` of :mod:`pneubayes.effects.closure_features`).

``tau dp_bar/dt = p - p_bar``. The kernel starts ``p_bar`` from the recorded reading's
history before the window (:func:`relaxation_start`, the same low-pass the open-form
search applies to the measured pressure), holds it over a step at its value half-way
through with the pressure held (:func:`relaxation_mid`: the step's error is second order
in ``h / tau``), and after an accepted step moves it exactly for a pressure linear
between the step's ends (:func:`relaxation_step`).
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.physics.calibration import pressure_behind_reading_scalar

#: How far back, in time constants, the reading's history starts ``p_bar`` (its weight
#: there is e^-5, under 1 %).
RELAXATION_HISTORY = 5.0
#: Most samples of that history read (evenly strided when it holds more).
HISTORY_POINTS = 256


@njit(cache=True, error_model="numpy")
def relaxation_step(pbar, p0, p1, h, tau):
    """``p_bar`` after ``h`` s (Pa) from ``pbar`` for a pressure linear from ``p0`` to
    ``p1`` (Pa) over the step; unchanged for ``h`` <= 0."""
    if not h > 0.0:
        return pbar
    s = (p1 - p0) / h
    return p1 - s * tau + (pbar - p0 + s * tau) * math.exp(-h / tau)


@njit(cache=True, error_model="numpy")
def relaxation_mid(pbar, p, rate, h, tau):
    """``p_bar`` half-way through a step of ``h`` s, the pressure moving from ``p`` (Pa)
    at ``rate`` (Pa/s; the kernel gives the last accepted step's)."""
    return relaxation_step(pbar, p, p + 0.5 * h * rate, 0.5 * h, tau)


@njit(cache=True, error_model="numpy")
def relaxation_start(t, pm, k, tau, p_start, calibrated, p_atm, cal_o, cal_g):
    """``p_bar`` at sample ``k`` (Pa): the recorded reading ``pm`` (chamber pressures
    behind a miscalibrated sensor's readings when ``calibrated``) low-passed from
    :data:`RELAXATION_HISTORY` time constants before ``t[k]`` (or the record's start;
    at most :data:`HISTORY_POINTS` samples of it, strided), non-finite samples skipped;
    ``p_start`` where no sample there is finite."""
    j = k
    while j > 0 and t[k] - t[j - 1] <= RELAXATION_HISTORY * tau:
        j -= 1
    # at most HISTORY_POINTS samples of it, evenly strided (the reading linear between
    # them: a slow low-pass barely sees the difference), so that a one-step prediction
    # at every sample does not walk seconds of history each
    stride = max(1, (k - j) // HISTORY_POINTS)
    j = k - ((k - j) // stride) * stride
    pbar = math.nan
    p_prev = math.nan
    t_prev = 0.0
    for i in range(j, k + 1, stride):
        v = pm[i]
        if not math.isfinite(v):
            continue
        if calibrated:
            v = pressure_behind_reading_scalar(v, p_atm, cal_o, cal_g)
        if math.isnan(pbar):
            pbar = v
        else:
            pbar = relaxation_step(pbar, p_prev, v, t[i] - t_prev, tau)
        p_prev, t_prev = v, t[i]
    return p_start if math.isnan(pbar) else pbar
