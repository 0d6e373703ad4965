"""A pressure sensor's calibration: the reading of a zero offset and a gain error.

A sensor with zero offset o (its reading at atmospheric pressure, less P_atm) and gain g
records ``r = P_atm + g (p - P_atm) + o`` for the chamber pressure p (Pa, absolute). The
two maps below are each other's inverse; they take scalars or arrays, and their
``_scalar`` forms are the compiled simulator's (effect ``sensor_calibration``).

A zero that drifts (effect ``sensor_drift``) is ``o(t) = o + a t + b (1 - exp(-t /
tau))`` on the recording's clock (its ``time_s``; the warm-up held at 0 before t = 0):
:func:`reading_zero_Pa`, whose value at a sample's time is the ``o`` of the maps there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


def sensor_reading_Pa(pressure_Pa, atmospheric_Pa, offset_Pa, gain):
    """What the sensor records for the chamber pressure: P_atm + g (p - P_atm) + o (Pa)."""
    return atmospheric_Pa + gain * (pressure_Pa - atmospheric_Pa) + offset_Pa


def pressure_behind_reading_Pa(reading_Pa, atmospheric_Pa, offset_Pa, gain):
    """The chamber pressure a reading stands for: P_atm + (r - P_atm - o) / g (Pa)."""
    return atmospheric_Pa + (reading_Pa - atmospheric_Pa - offset_Pa) / gain


sensor_reading_scalar = njit(cache=True, inline="always", error_model="numpy")(
    sensor_reading_Pa)
pressure_behind_reading_scalar = njit(cache=True, inline="always", error_model="numpy")(
    pressure_behind_reading_Pa)


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


@njit(cache=True, inline="always", error_model="numpy")
def reading_zero_scalar(zero, t):
    """:func:`reading_zero_Pa` at one time ``t`` (s) for ``zero = (o, a, b, tau)``."""
    o, a, b, tau = zero
    if b != 0.0:
        return o + a * t - b * math.expm1(-max(t, 0.0) / tau)
    return o + a * t


@njit(cache=True, inline="always", error_model="numpy")
def reading_zero_rate_scalar(zero, t):
    """The zero's rate do/dt at time ``t`` (Pa/s) for ``zero = (o, a, b, tau)``."""
    _, a, b, tau = zero
    if b != 0.0 and t > 0.0:
        return a + b / tau * math.exp(-t / tau)
    return a
