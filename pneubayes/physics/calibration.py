"""A pressure sensor's calibration: the reading of a zero offset and a gain error.

A sensor with zero offset o (its reading at atmospheric pressure, less P_atm) and gain g
records ``r = P_atm + g (p - P_atm) + o`` for the chamber pressure p (Pa, absolute), and
with a curvature k (effect ``sensor_nonlinearity``) ``+ k ((p - P_atm) / 1 bar)^2``. The
two maps below are each other's inverse; they take scalars or arrays, and their
``_scalar`` forms (the gain as ``(g, k)``) are the compiled simulator's (effect
``sensor_calibration``).

A zero that drifts (effect ``sensor_drift``) is ``o(t) = o + a t + b (1 - exp(-t /
tau))`` on the recording's clock (its ``time_s``; the warm-up held at 0 before t = 0):
:func:`reading_zero_Pa`, whose value at a sample's time is the ``o`` of the maps there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: The pressure scale of a reading's curvature: k (y / CURVATURE_SCALE_PA)^2, y gauge (Pa).
CURVATURE_SCALE_PA = 1e5


def sensor_reading_Pa(pressure_Pa, atmospheric_Pa, offset_Pa, gain, curvature_Pa=0.0):
    """What the sensor records for the chamber pressure: P_atm + g y + k (y / 1 bar)^2
    + o, y = p - P_atm (Pa)."""
    y = pressure_Pa - atmospheric_Pa
    return atmospheric_Pa + gain * y + curvature_Pa * (y / CURVATURE_SCALE_PA) ** 2 + offset_Pa


def pressure_behind_reading_Pa(reading_Pa, atmospheric_Pa, offset_Pa, gain, curvature_Pa=0.0):
    """The chamber pressure a reading stands for (Pa): P_atm + (r - P_atm - o) / g, or
    with a curvature k the root of k (y / 1 bar)^2 + g y = r - P_atm - o continuous with
    it (NaN where the reading is beyond the curve's turning point)."""
    rr = reading_Pa - atmospheric_Pa - offset_Pa
    if np.all(np.asarray(curvature_Pa) == 0.0):
        return atmospheric_Pa + rr / gain
    c = curvature_Pa / CURVATURE_SCALE_PA**2
    disc = gain**2 + 4.0 * c * rr
    with np.errstate(invalid="ignore"):
        return atmospheric_Pa + np.where(disc >= 0.0, 2.0 * rr / (gain + np.sqrt(
            np.maximum(disc, 0.0))), np.nan)


@njit(cache=True, error_model="numpy")
def sensor_reading_scalar(pressure_Pa, atmospheric_Pa, offset_Pa, gain):
    """:func:`sensor_reading_Pa` for one pressure, ``gain`` = ``(g, k)``."""
    y = pressure_Pa - atmospheric_Pa
    g, k = gain
    return atmospheric_Pa + g * y + k * (y / CURVATURE_SCALE_PA) ** 2 + offset_Pa


@njit(cache=True, error_model="numpy")
def pressure_behind_reading_scalar(reading_Pa, atmospheric_Pa, offset_Pa, gain):
    """:func:`pressure_behind_reading_Pa` for one reading, ``gain`` = ``(g, k)``."""
    rr = reading_Pa - atmospheric_Pa - offset_Pa
    g, k = gain
    if k == 0.0:
        return atmospheric_Pa + rr / g
    disc = g * g + 4.0 * k / CURVATURE_SCALE_PA**2 * rr
    if not disc >= 0.0:
        return math.nan
    return atmospheric_Pa + 2.0 * rr / (g + math.sqrt(disc))


@njit(cache=True, error_model="numpy")
def reading_slope_scalar(pressure_Pa, atmospheric_Pa, gain):
    """d(reading)/dp at one pressure, ``gain`` = ``(g, k)``: g + 2 k y / (1 bar)^2."""
    g, k = gain
    return g + 2.0 * k * (pressure_Pa - atmospheric_Pa) / CURVATURE_SCALE_PA**2


def reading_zero_Pa(time_s, offset_Pa, rate_Pa_per_s, warm_up_Pa, warm_up_time_constant_s):
    """The sensor's zero at ``time_s`` (s, the recording's clock), Pa: ``o + a t + b (1 -
    exp(-max(t, 0) / tau))``; ``b`` 0 ignores ``tau``."""
    t = np.asarray(time_s, dtype=np.float64)
    zero = offset_Pa + rate_Pa_per_s * t
    warm = np.asarray(warm_up_Pa, dtype=np.float64)
    if np.any(warm != 0.0):
        tau = np.where(warm != 0.0, warm_up_time_constant_s, 1.0)
        zero = zero - warm * np.expm1(-np.maximum(t, 0.0) / tau)
    return zero


@njit(cache=True, error_model="numpy")
def reading_zero_scalar(zero, t):
    """:func:`reading_zero_Pa` at one time ``t`` (s) for ``zero = (o, a, b, tau)``."""
    o, a, b, tau = zero
    if b != 0.0:
        return o + a * t - b * math.expm1(-max(t, 0.0) / tau)
    return o + a * t


@njit(cache=True, error_model="numpy")
def reading_zero_rate_scalar(zero, t):
    """The zero's rate do/dt at time ``t`` (Pa/s) for ``zero = (o, a, b, tau)``."""
    _, a, b, tau = zero
    if b != 0.0 and t > 0.0:
        return a + b / tau * math.exp(-t / tau)
    return a
