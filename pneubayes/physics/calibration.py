"""A pressure sensor's calibration: the reading of a zero offset and a gain error.

A sensor with zero offset o (its reading at atmospheric pressure, less P_atm) and gain g
records ``r = P_atm + g (p - P_atm) + o`` for the chamber pressure p (Pa, absolute). The
two maps below are each other's inverse; they take scalars or arrays, and their
``_scalar`` forms are the compiled simulator's (effect ``sensor_calibration``).
"""

from __future__ import annotations

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
