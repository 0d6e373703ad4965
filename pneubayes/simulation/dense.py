"""Dense output: a step runs over the samples that repeat the command and the supply,
and the samples it crosses are read from its interpolant (``SolverConfig.dense_output``;
:mod:`pneubayes.simulation.kernel`).

The interpolant is the exponential step's own solution,
``p(s) = p_a + s phi_1(s J) F + s^2 phi_2(s J) v`` plus the correction as
``(s / h)^3 phi_3(s J) / phi_3(h J)`` of it; over a moving position a crossed sample is
moved from the chord to its own position (:mod:`pneubayes.simulation.chord`).
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.physics.calibration import (
    reading_slope_scalar,
    reading_zero_scalar,
    sensor_reading_scalar,
)
from pneubayes.simulation.chord import off_chord, response_weights
from pneubayes.simulation.phi import phi123


@njit(cache=True, inline="always", error_model="numpy")
def dense_run(x, ps, k, k_last, reads_supply):
    """``(kn, chord)``: with dense output, the last sample of the run from ``k`` over
    which the supply holds (where the model reads it) and whether the position moves
    over it (a step reads the position's chord there)."""
    kn = k + 1
    chord = False
    while (kn < k_last
           and (not reads_supply or (ps[kn] == ps[k] and ps[kn + 1] == ps[k]))):
        kn += 1
    if kn > k + 1:
        for i in range(k + 1, kn + 1):
            if x[i] != x[k]:
                chord = True
                break
    return kn, chord


@njit(cache=True, error_model="numpy", _nrt=False)
def dense_samples(out, sens, t, x, i0, kw, kn, step, chord_step, v0, bore, kap, sl, p_atm,
                  calibrated, zero, cal_g, slope0, want_sens):
    """Write the readings (and dp/dp0) of the samples ``kw..kn - 1`` before the end of an
    accepted step that it crossed, read from its interpolant; returns the next sample to
    read.

    ``step`` is ``(t_prev, tau, h, p_prev, s_prev, sc0, zp, fp, vp, ep, phi3p)``: its
    start and end (s), length, start pressure and dp/dp0, its scale V^n (a q step; else
    1), h J, rate, rate's time derivative, correction and phi_3(h J). ``chord_step`` is
    ``(chord, qstep, x0c, x1c, jf, c_c)``: over a chord of the position (``x0c``, ``x1c``
    m at its ends) a sample is read at its own position, not the chord's: adiabatically,
    less the flows' response to the chord so far (slope ``jf``, coupling ``c_c``), or as
    q / V^n at its own volume after a q step. ``calibrated``, ``zero`` (``(o, a, b, tau)``
    of :func:`~pneubayes.physics.calibration.reading_zero_scalar`), ``cal_g`` (``(g, k)``)
    and ``slope0`` (d(reading)/dp at the window's start): the reading's calibration.
    """
    t_prev, tau, hh, p_prev, s_prev, sc0, zp, fp, vp, ep, phi3p = step
    chord, qstep, x0c, x1c, jf, c_c = chord_step
    w_r, t_r, d_r, dt_r = 0.0, t_prev, 0.0, -1.0
    e_r, a_r, b_r = 0.0, 0.0, 0.0
    while kw < kn and t[kw] < tau:
        th = (t[kw] - t_prev) / hh
        q1, q2, q3 = phi123(th * zp)
        value = (p_prev * sc0 + th * hh * (q1 * fp + th * hh * q2 * vp)
                 + th * th * th * q3 / phi3p * ep)
        sc_k = 1.0
        if chord:
            dev = x0c + th * (x1c - x0c) - x[kw]
            dt = t[kw] - t_r
            if dt != dt_r:  # uniform sampling: once per step
                dt_r = dt
                e_r, a_r, b_r = response_weights(jf, dt)
            w_r = e_r * w_r + a_r * d_r + b_r * (dev - d_r)
            t_r, d_r = t[kw], dev
            if qstep:  # q at the sample's own volume
                sc_k = math.exp(kap * math.log(v0 + bore * x[kw]))
                value = (value - c_c * sc0 * w_r) / sc_k
            else:
                value = (off_chord(value, dev, v0 + bore * x[kw], bore, kap, sl, p_atm)
                         - c_c * w_r)
        out[kw - i0] = (sensor_reading_scalar(value, p_atm, reading_zero_scalar(
            zero, t[kw]), cal_g) if calibrated
                        else value)
        if want_sens:
            sens[kw - i0] = s_prev * math.exp(th * zp) * sc0 / sc_k
            if cal_g[1] != 0.0:  # a curved sensor: d(reading)/d(its start)
                sens[kw - i0] *= reading_slope_scalar(value, p_atm, cal_g) / slope0
        kw += 1
    return kw
