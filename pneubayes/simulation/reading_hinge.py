"""The reading's hinges (effect ``reading_hinge``), applied to simulated windows.

A model with :class:`~pneubayes.effects.reading_hinge.ReadingHinge` reads each window
through ``H(z) = z + sum_j c_j max(0, z - theta_j)``, ``z`` the reading every other term
gives (:mod:`pneubayes.simulation.reading_closure`, ``reading_command``,
``reading_flow``): the reading's last map. ``H`` is piecewise linear with slope 1 below
the lowest knee and ``1 + sum of the gains of the knees below`` above each; a parameter
set whose slope is not positive on every piece has a reading that does not tell the
pressure (:func:`hinges_readable`) and fails as a set.

A window starts from a measured reading ``r0``: the rest of the reading starts at
``z0 = H^-1(r0)`` (:func:`unhinged_reading`, exact on the piece ``r0`` lies on), and the
start sensitivity of the reading is ``H'(z) dz/dz0 / H'(z0)``.
"""

from __future__ import annotations

import numpy as np


def _per_set(a, ndim: int) -> np.ndarray:
    """A ``(B,)`` column of per-set values shaped to broadcast against ``(B, ...)``."""
    return np.asarray(a, dtype=np.float64).reshape((-1,) + (1,) * (ndim - 1))


def hinges_readable(gains, thresholds_Pa) -> np.ndarray:
    """``(B,)`` bool: whether each parameter set's map is increasing on every piece
    (``1 + the gains of the knees at or below each knee > 0``)."""
    g = np.asarray(gains, dtype=np.float64)
    th = np.asarray(thresholds_Pa, dtype=np.float64)
    if g.ndim != 2 or g.shape != th.shape:
        raise ValueError(f"reading hinges: gains and thresholds_Pa must both be (B, J), got "
                         f"{g.shape} and {th.shape}")
    if not g.shape[1]:
        return np.ones(g.shape[0], dtype=bool)
    order = np.argsort(th, axis=1)
    slopes = 1.0 + np.cumsum(np.take_along_axis(g, order, axis=1), axis=1)
    return np.all(slopes > 0.0, axis=1) & np.all(np.isfinite(th), axis=1)


def hinged_reading(z_Pa, gains, thresholds_Pa) -> tuple[np.ndarray, np.ndarray]:
    """``(H(z), H'(z))`` of ``z_Pa`` ``(B, ...)`` (Pa) for each set's ``gains`` (-) and
    ``thresholds_Pa`` (Pa absolute), each ``(B, J)``; H' is the slope on the piece ``z``
    lies on (above a knee at the knee itself)."""
    z = np.asarray(z_Pa, dtype=np.float64)
    g = np.asarray(gains, dtype=np.float64)
    th = np.asarray(thresholds_Pa, dtype=np.float64)
    out, slope = z.copy(), np.ones_like(z)
    for j in range(g.shape[1]):
        c, t = _per_set(g[:, j], z.ndim), _per_set(th[:, j], z.ndim)
        above = z >= t
        out += c * np.where(above, z - t, 0.0)
        slope += np.where(above, c, 0.0)
    return out, slope


def unhinged_reading(r_Pa, gains, thresholds_Pa) -> np.ndarray:
    """``H^-1(r)`` (Pa) of the readings ``r_Pa`` ``(B, ...)`` for each set's ``gains``
    and ``thresholds_Pa``, each ``(B, J)`` (a set whose map is not increasing
    everywhere, :func:`hinges_readable`: NaN)."""
    r = np.asarray(r_Pa, dtype=np.float64)
    g = np.asarray(gains, dtype=np.float64)
    th = np.asarray(thresholds_Pa, dtype=np.float64)
    z = r.copy()
    if not g.shape[1]:
        return z
    order = np.argsort(th, axis=1)
    th_s = np.take_along_axis(th, order, axis=1)
    slopes = 1.0 + np.cumsum(np.take_along_axis(g, order, axis=1), axis=1)
    knees = hinged_reading(th_s, g, th)[0]  # H at each knee, (B, J)
    for k in range(th_s.shape[1]):  # the highest knee below the reading sets its piece
        t, h, s = (_per_set(a[:, k], r.ndim) for a in (th_s, knees, slopes))
        z = np.where(r >= h, t + (r - h) / s, z)
    bad = ~hinges_readable(g, th)
    if bad.any():
        z[bad] = np.nan
    return z
