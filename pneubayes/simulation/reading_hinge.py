"""The reading's hinges (effect ``reading_hinge``), applied to simulated windows.

A model with :class:`~pneubayes.effects.reading_hinge.ReadingHinge` reads each window
through ``H(z) = z + sum_j c_j h_j(z)``, ``z`` the reading every other term gives
(:mod:`pneubayes.simulation.reading_closure`, ``reading_command``, ``reading_flow``):
the reading's last map. A knee above, ``h_j = max(0, z - theta_j)``, bends the reading
above its threshold; a knee below, ``h_j = min(0, z - theta_j)``, bends it below (a
floor). The functions here take a knee below as its threshold negated (``-theta_j``: a
pressure is positive, so the sign is free to say the side). ``H`` is piecewise linear,
its slope on each piece ``1 +`` the gains of the knees above that it lies above and of
the knees below that it lies below; a parameter set whose slope is not positive on every
piece has a reading that does not tell the pressure (:func:`hinges_readable`) and fails
as a set.

A window starts from a measured reading ``r0``: the rest of the reading starts at
``z0 = H^-1(r0)`` (:func:`unhinged_reading`, exact on the piece ``r0`` lies on), and the
start sensitivity of the reading is ``H'(z) dz/dz0 / H'(z0)``.
"""

from __future__ import annotations

import numpy as np


def _per_set(a, ndim: int) -> np.ndarray:
    """A ``(B,)`` column of per-set values shaped to broadcast against ``(B, ...)``."""
    return np.asarray(a, dtype=np.float64).reshape((-1,) + (1,) * (ndim - 1))


def _piece_slopes(g, th) -> tuple[np.ndarray, np.ndarray]:
    """``(knees, slopes)``: each set's knees sorted (Pa, ``(B, J)``) and the map's slope
    on the ``J + 1`` pieces they bound, lowest first (``(B, J + 1)``)."""
    order = np.argsort(np.abs(th), axis=1)
    th_s = np.take_along_axis(th, order, axis=1)
    g_s = np.take_along_axis(g, order, axis=1)
    up = np.where(th_s >= 0.0, g_s, 0.0)  # knees above: their gain above them
    down = np.where(th_s < 0.0, g_s, 0.0)  # knees below: their gain below them
    zero = np.zeros((g.shape[0], 1))
    slopes = (1.0 + np.concatenate([zero, np.cumsum(up, axis=1)], axis=1)
              + np.concatenate([np.cumsum(down[:, ::-1], axis=1)[:, ::-1], zero], axis=1))
    return np.abs(th_s), slopes


def hinges_readable(gains, thresholds_Pa) -> np.ndarray:
    """``(B,)`` bool: whether each parameter set's map is increasing on every piece
    (a knee below as its threshold negated)."""
    g = np.asarray(gains, dtype=np.float64)
    th = np.asarray(thresholds_Pa, dtype=np.float64)
    if g.ndim != 2 or g.shape != th.shape:
        raise ValueError(f"reading hinges: gains and thresholds_Pa must both be (B, J), got "
                         f"{g.shape} and {th.shape}")
    if not g.shape[1]:
        return np.ones(g.shape[0], dtype=bool)
    slopes = _piece_slopes(g, th)[1]
    return np.all(slopes > 0.0, axis=1) & np.all(np.isfinite(th), axis=1)


def hinged_reading(z_Pa, gains, thresholds_Pa) -> tuple[np.ndarray, np.ndarray]:
    """``(H(z), H'(z))`` of ``z_Pa`` ``(B, ...)`` (Pa) for each set's ``gains`` (-) and
    ``thresholds_Pa`` (Pa absolute; a knee below negated), each ``(B, J)``; H' is the
    slope on the piece ``z`` lies on (above a knee at the knee itself)."""
    z = np.asarray(z_Pa, dtype=np.float64)
    g = np.asarray(gains, dtype=np.float64)
    th = np.asarray(thresholds_Pa, dtype=np.float64)
    out, slope = z.copy(), np.ones_like(z)
    for j in range(g.shape[1]):
        c, t = _per_set(g[:, j], z.ndim), _per_set(th[:, j], z.ndim)
        bent = np.where(t >= 0.0, z >= t, z < -t)  # the side of the knee it bends
        out += c * np.where(bent, z - np.abs(t), 0.0)
        slope += np.where(bent, c, 0.0)
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
    th_s, slopes = _piece_slopes(g, th)
    knees = hinged_reading(th_s, g, th)[0]  # H at each knee, (B, J)
    t, h, s = (_per_set(a[:, 0], r.ndim) for a in (th_s, knees, slopes))
    z = t + (r - h) / s  # below every knee: the lowest piece
    for k in range(th_s.shape[1]):  # the highest knee below the reading sets its piece
        t, h, s = (_per_set(a[:, k], r.ndim) for a in (th_s, knees, slopes[:, 1:]))
        z = np.where(r >= h, t + (r - h) / s, z)
    bad = ~hinges_readable(g, th)
    if bad.any():
        z[bad] = np.nan
    return z
