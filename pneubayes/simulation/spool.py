"""The spool's state under a held command (effect ``spool_lag``), in closed form.

First order ``ds/dt = (u - s) / tau``, or second order ``s'' = w^2 (u - s) - 2 z w s'``
(position and velocity; exact through :func:`pneubayes.simulation.reading.second_order_step`
with a constant input). The compiled kernel (:mod:`pneubayes.simulation.kernel`) steps
the spool with these and warms it up over the command history before a window.
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.simulation.reading import second_order_step


@njit(cache=True, error_model="numpy")
def spool_step(s, v, cmd, h, tau, w, z):
    """``(position V, velocity V/s)`` of the spool after ``h`` s under the held command
    ``cmd`` V: second order when ``w`` > 0, else first order when ``tau`` > 0 (velocity
    0), else unchanged; unchanged for ``h`` <= 0."""
    if not h > 0.0:
        return s, v
    if w > 0.0:
        return second_order_step(s, v, cmd, cmd, h, w, z)
    if tau > 0.0:
        return cmd + (s - cmd) * math.exp(-h / tau), 0.0
    return s, v


@njit(cache=True, inline="always", error_model="numpy")
def spool_settle_s(tau, w, z):
    """Time constant of the spool's slowest mode (s): ``tau`` for the first order;
    1 / (z w) for the second at z <= 1, (z + sqrt(z^2 - 1)) / w above it."""
    if not w > 0.0:
        return tau
    if z <= 1.0:
        return 1.0 / (z * w)
    return (z + math.sqrt(z * z - 1.0)) / w
