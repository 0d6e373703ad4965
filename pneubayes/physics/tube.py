"""Friction in the valve-chamber tube: the Darcy factor of a smooth pipe.

The momentum balance of a tube segment of length dx and section A carrying mass flow q
(Richer & Hurmuzlu 2000, lumped) is ``dq/dt = A / dx (p_i - p_{i+1}) - f Re mu q /
(2 rho D^2)``; ``f Re`` is 64 in laminar flow (Poiseuille) and grows with Re once the
flow turns turbulent. The 2-mm tubes of the paper carry 1 g/s at Re ~ 3e4, so the
turbulent branch matters. A fast-changing flow also meets Zielke's unsteady wall shear,
whose memory turbulence shortens (:func:`vardy_brown_cutoff`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def churchill_fre(re):
    """Darcy friction factor times Reynolds number for a smooth tube (Churchill 1977).

    ``f = 8 ((8/Re)^12 + (A + B)^-1.5)^(1/12)``, A = (2.457 ln(1 / (7/Re)^0.9))^16,
    B = (37530 / Re)^16; returned as ``f Re`` (64 in laminar flow), smooth in Re.
    Below Re = 1000 the turbulent correction is below 2e-14 of 64, and 64 is returned
    (the transmission-line tube, at every junction every 0.1 ms, and the lumped line
    evaluate :func:`churchill_fre_table` instead).
    """
    if re < 1000.0:
        return 64.0
    a = (2.457 * 0.9 * math.log(re / 7.0)) ** 16
    b = (37530.0 / re) ** 16
    return 8.0 * (8.0**12 + re**12 * (a + b) ** -1.5) ** (1.0 / 12.0)


@njit(cache=True, error_model="numpy")
def churchill_fre_slope(re):
    """``d ln(f Re) / d ln Re`` of :func:`churchill_fre` (0 laminar, ~0.75 turbulent)."""
    if re < 1000.0:
        return 0.0
    step = 1e-4
    return (math.log(churchill_fre(re * math.exp(step)))
            - math.log(churchill_fre(re * math.exp(-step)))) / (2.0 * step)


#: Points of the table :func:`churchill_fre_table` interpolates, evenly spaced in ln Re
#: from ``CHURCHILL_TABLE_RE`` [0] to [1].
CHURCHILL_TABLE_POINTS = 4096
CHURCHILL_TABLE_RE = (1000.0, 1.0e8)


def _churchill_fre_array(re: np.ndarray) -> np.ndarray:
    """:func:`churchill_fre` of an array of Reynolds numbers >= 1000 (NumPy)."""
    a = (2.457 * 0.9 * np.log(re / 7.0)) ** 16
    b = (37530.0 / re) ** 16
    return 8.0 * (8.0**12 + re**12 * (a + b) ** -1.5) ** (1.0 / 12.0)


_LN_RE0 = math.log(CHURCHILL_TABLE_RE[0])
_LN_STEP = (math.log(CHURCHILL_TABLE_RE[1]) - _LN_RE0) / (CHURCHILL_TABLE_POINTS - 1)
_LN_RE = _LN_RE0 + _LN_STEP * np.arange(CHURCHILL_TABLE_POINTS)
_FRE_TABLE = _churchill_fre_array(np.exp(_LN_RE))
# slopes per table step (d fRe / d ln Re x the step), by central differences of 1e-6
_FRE_SLOPE = (_churchill_fre_array(np.exp(_LN_RE + 1e-6))
              - _churchill_fre_array(np.exp(_LN_RE - 1e-6))) / 2e-6 * _LN_STEP


@njit(cache=True, error_model="numpy")
def _table_cell(re):
    """The table interval of ``re`` (>= 1000): its first point and the position in it."""
    x = (math.log(re) - _LN_RE0) / _LN_STEP
    i = int(x)
    return i, x - i


@njit(cache=True, error_model="numpy")
def _table_value(i, t):
    """The cubic Hermite of the table at position ``t`` in interval ``i``."""
    t2 = t * t
    t3 = t2 * t
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * _FRE_TABLE[i] + (t3 - 2.0 * t2 + t) * _FRE_SLOPE[i]
            + (3.0 * t2 - 2.0 * t3) * _FRE_TABLE[i + 1] + (t3 - t2) * _FRE_SLOPE[i + 1])


@njit(cache=True, error_model="numpy")
def churchill_fre_table(re):
    """:func:`churchill_fre` interpolated from a table of ``CHURCHILL_TABLE_POINTS``
    values and slopes, evenly spaced in ln Re (cubic Hermite; the formula itself beyond
    the table; relative error below 1e-8, ``tests/test_physics.py``): one logarithm in
    place of a logarithm and three powers, several times cheaper where the flow is
    turbulent. 64 in laminar flow (Re < 1000), as the formula."""
    if re < 1000.0:
        return 64.0
    i, t = _table_cell(re)
    if i >= CHURCHILL_TABLE_POINTS - 1:
        return churchill_fre(re)
    return _table_value(i, t)


@njit(cache=True, error_model="numpy")
def churchill_fre_and_slope_table(re):
    """``(f Re, d ln(f Re) / d ln Re)`` from the table of :func:`churchill_fre_table`:
    the value and the cubic's derivative over it (:func:`churchill_fre_slope` within
    1e-5; the formulas themselves beyond the table; ``(64, 0)`` in laminar flow)."""
    if re < 1000.0:
        return 64.0, 0.0
    i, t = _table_cell(re)
    if i >= CHURCHILL_TABLE_POINTS - 1:
        return churchill_fre(re), churchill_fre_slope(re)
    value = _table_value(i, t)
    d_dt = ((6.0 * t * t - 6.0 * t) * (_FRE_TABLE[i] - _FRE_TABLE[i + 1])
            + (3.0 * t * t - 4.0 * t + 1.0) * _FRE_SLOPE[i]
            + (3.0 * t * t - 2.0 * t) * _FRE_SLOPE[i + 1])
    return value, d_dt / (_LN_STEP * value)


@njit(cache=True, error_model="numpy")
def vardy_brown_cutoff(re):
    """Vardy and Brown's (2003) smooth-pipe turbulent cut-off B* of Zielke's unsteady
    friction weighting function (W_turb = W_lam exp(-B* t'), t' = nu t / R^2):
    ``Re^k / 12.86``, ``k = log10(15.29 / Re^0.0567)``, faded in over Re 2000-4000 by a
    C1 smoothstep (0 in laminar flow)."""
    if re <= 2000.0:
        return 0.0
    k = math.log10(15.29 / re ** 0.0567)
    z = (re - 2000.0) / 2000.0
    return re ** k / 12.86 * (1.0 if z >= 1.0 else z * z * (3.0 - 2.0 * z))
