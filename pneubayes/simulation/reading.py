"""A lagged pressure reading, stepped exactly beside the chamber (effect ``sensor_lag``).

Over an accepted step of ``h`` s the integrator knows the chamber pressure at both ends
and takes it as linear in between; both lags below are then integrated in closed form,
so the reading adds no error and no step-size limit of its own. The compiled kernel
(:mod:`pneubayes.simulation.kernel`) calls these once per accepted step (and again for
the start sensitivity, which obeys the same linear filter).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always", error_model="numpy")
def first_order_step(r, pa, pb, h, tau):
    """The reading dr/dt = (p - r) / tau after a step of ``h`` s on which p goes
    linearly from ``pa`` to ``pb``: r a + (1 - a) pa + c (pb - pa), a = e^-z, z = h /
    tau, c = 1 - (1 - a) / z (its series for small z, where the difference cancels)."""
    z = h / tau
    a = math.exp(-z)
    if z < 1e-3:
        c = z * (0.5 - z * (1.0 / 6.0 - z / 24.0))
    else:
        c = 1.0 + math.expm1(-z) / z
    return a * r + (1.0 - a) * pa + c * (pb - pa)


@njit(cache=True, error_model="numpy")
def second_order_step(r, v, pa, pb, h, w, z):
    """``(r, v)`` of the reading r'' = w^2 (p - r) - 2 z w r' after a step of ``h`` s on
    which p goes linearly from ``pa`` to ``pb``: exact. The ramp's tracking solution
    r = p - m D (D = 2 z / w, the filter's group delay at DC), v = m, plus the
    homogeneous deviation from it, propagated by exp(A h) = (c + z w s) I + s A."""
    m = (pb - pa) / h
    lead = 2.0 * z / w
    er, ev = r - (pa - m * lead), v - m
    mu = -z * w
    q2 = (z * z - 1.0) * w * w
    if abs(q2) * h * h < 1e-8:  # near critical damping: the series
        e = math.exp(mu * h)
        c, s = e * (1.0 + 0.5 * q2 * h * h), e * h * (1.0 + q2 * h * h / 6.0)
    elif q2 > 0.0:  # overdamped: two real poles (the slow one without cancellation)
        q = math.sqrt(q2)
        slow = -w / (z + math.sqrt(z * z - 1.0))
        e1, e2 = math.exp(slow * h), math.exp((mu - q) * h)
        c, s = 0.5 * (e1 + e2), 0.5 * (e1 - e2) / q
    else:
        wd = math.sqrt(-q2)
        e = math.exp(mu * h)
        c, s = e * math.cos(wd * h), e * math.sin(wd * h) / wd
    er2 = (c + z * w * s) * er + s * ev
    ev2 = -w * w * s * er + (c - z * w * s) * ev
    return pb - m * lead + er2, m + ev2
