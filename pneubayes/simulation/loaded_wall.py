"""Compiled parts of the loaded wall (effect ``loaded_wall``): a chamber wall that carries
a load, a mass on a spring driven by the gauge pressure.

The wall's state is its displacement ``x`` in pascals (the gauge pressure it would be
at rest under) and its rate ``v`` (Pa/s)::

    x'' + 2 z w x' + w^2 x = w^2 (p - P_atm),    V = V_0 + C x.

Over one step the kernel holds the pressure moving at the last accepted step's mean rate,
advances the wall exactly under it (:func:`wall_advance`) and gives the chamber step the
volume linear between the wall's ends (so ``dV/dt = C (x_end - x) / h``, as a piston's
chord); after the step is accepted it advances the wall exactly under the pressure linear
between the step's ends. The splitting's error is second order in ``h w``; the step is
bounded by :func:`wall_max_step`. A window starts the wall where the recorded reading's
history before it leaves it (:func:`wall_start`), as a relaxation's low-pass starts.
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import SLOT_INDEX
from pneubayes.simulation.relaxation import recorded_pressure

_LW_C = SLOT_INDEX["loaded_wall_compliance_m3_per_Pa"]
_LW_F = SLOT_INDEX["loaded_wall_frequency_Hz"]
_LW_Z = SLOT_INDEX["loaded_wall_damping_ratio"]

#: How far back, in the wall's slowest time constants, its start reads the reading's
#: history (the start's weight there is e^-6).
WALL_HISTORY = 6.0
#: Most samples of that history stepped, evenly strided (a one-step prediction at every
#: sample must not walk seconds of history each); before them the wall starts at rest
#: under the first pressure read.
WALL_HISTORY_POINTS = 512
#: The stride's longest time as a share of the wall's natural period (a ring read through
#: a coarser stride would alias): where the history needs more, it is cut shorter.
WALL_HISTORY_STRIDE_PERIODS = 0.05
#: The step's bound as a share of the coupled wall's period over 2 pi (``h w_c``).
WALL_STEP_SHARE = 0.2


@njit(cache=True, error_model="numpy")
def wall_on(sl) -> bool:
    """Whether a parameter set carries a loaded wall (a compliance that is not 0)."""
    return sl[_LW_C] > 0.0


@njit(cache=True, error_model="numpy")
def wall_constants(sl):
    """``(C m^3/Pa, w rad/s, z)`` of a parameter set's wall."""
    return sl[_LW_C], 2.0 * math.pi * sl[_LW_F], sl[_LW_Z]


@njit(cache=True, error_model="numpy")
def _free_motion(h, w, z):
    """``(E (C + a S), E S, E (C - a S))``: the free wall's propagator terms over ``h``
    s (``a = z w``, ``E = e^{-a h}``, ``C`` and ``S`` the cosine and the sine over its
    frequency, hyperbolic where it is overdamped)."""
    a = z * w
    q = w * w - a * a
    if abs(q) * h * h < 1e-6:  # near critical damping: the series
        e = math.exp(-a * h)
        c = 1.0 - 0.5 * q * h * h
        s = h * (1.0 - q * h * h / 6.0)
        return e * (c + a * s), e * s, e * (c - a * s)
    if q > 0.0:
        r = math.sqrt(q)
        e = math.exp(-a * h)
        c, s = e * math.cos(r * h), e * math.sin(r * h) / r
    else:  # overdamped: r < a, so both exponentials decay
        r = math.sqrt(-q)
        up, down = math.exp((r - a) * h), math.exp(-(r + a) * h)
        c, s = 0.5 * (up + down), 0.5 * (up - down) / r
    return c + a * s, s, c - a * s


@njit(cache=True, error_model="numpy")
def wall_advance(x, v, y0, y1, h, w, z):
    """The wall's ``(x Pa, v Pa/s)`` after ``h`` s from ``(x, v)`` under a gauge pressure
    linear from ``y0`` to ``y1`` (Pa) over the step, exactly; unchanged for ``h`` <= 0."""
    if not h > 0.0:
        return x, v
    s = (y1 - y0) / h
    # about the forced motion x_p(t) = y(t) - 2 z s / w, v_p = s
    lag = 2.0 * z * s / w
    e0, f0 = x - (y0 - lag), v - s
    k1, k2, k3 = _free_motion(h, w, z)
    e1 = k1 * e0 + k2 * f0
    f1 = -w * w * k2 * e0 + k3 * f0
    return y1 - lag + e1, s + f1


@njit(cache=True, error_model="numpy")
def wall_slowest_time_s(w, z):
    """The free wall's slowest decay time (s): ``1 / (z w)`` underdamped, the slow
    root's inverse overdamped."""
    if z < 1.0:
        return 1.0 / (z * w)
    a = z * w
    return 1.0 / (a - math.sqrt(a * a - w * w)) if a * a > w * w else 1.0 / a


@njit(cache=True, error_model="numpy")
def wall_max_step(c, w, volume_m3, p_nom, kap):
    """The step's bound (s): :data:`WALL_STEP_SHARE` over the wall's frequency stiffened
    by the gas it compresses, ``w sqrt(1 + n p_s C / V)``."""
    stiff = 1.0 + kap * p_nom * c / volume_m3 if volume_m3 > 0.0 else 1.0
    return WALL_STEP_SHARE / (w * math.sqrt(stiff))


@njit(cache=True, error_model="numpy")
def wall_start(t, pm, k, w, z, p_start, calibrated, p_atm, zero, cal_g):
    """The wall's ``(x, v)`` at sample ``k``: stepped exactly over the recorded reading
    ``pm`` (the chamber pressures behind a miscalibrated sensor's readings when
    ``calibrated``), linear between its finite samples, from :data:`WALL_HISTORY` of its
    slowest time constants before ``t[k]`` (at most :data:`WALL_HISTORY_POINTS` samples,
    strided no coarser than :data:`WALL_HISTORY_STRIDE_PERIODS` of its period), at rest
    under the first pressure read; at rest under ``p_start`` (Pa) where no sample there is
    finite."""
    span = WALL_HISTORY * wall_slowest_time_s(w, z)
    dt = t[k] - t[k - 1] if k > 0 else 0.0
    most = 1 if not dt > 0.0 else max(1, int(WALL_HISTORY_STRIDE_PERIODS * 2.0 * math.pi
                                              / (w * dt)))
    j, j_min = k, max(0, k - WALL_HISTORY_POINTS * most)
    while j > j_min and t[k] - t[j - 1] <= span:
        j -= 1
    stride = max(1, -(-(k - j) // WALL_HISTORY_POINTS))
    j = k - ((k - j) // stride) * stride
    x, v = math.nan, 0.0
    y_prev, t_prev = 0.0, 0.0
    for i in range(j, k + 1, stride):
        y = recorded_pressure(t, pm, i, calibrated, p_atm, zero, cal_g) - p_atm
        if math.isnan(y):
            continue
        if math.isnan(x):
            x = y
        else:
            x, v = wall_advance(x, v, y_prev, y, t[i] - t_prev, w, z)
        y_prev, t_prev = y, t[i]
    if math.isnan(x):
        return p_start - p_atm, 0.0
    return x, v


@njit(cache=True, error_model="numpy")
def wall_chord(walled, wall_state, p, rate, hh, vol, vol2, vdot, p_atm, wall, general):
    """A step's ``(vol, vol2, vdot)`` with the wall's volume laid on (unchanged without
    one): the wall ``wall_state = (x, v)`` advanced over ``hh`` s under the pressure
    ``p`` (Pa) moving at ``rate`` (Pa/s), its volume linear between the step's ends;
    ``wall`` = ``(C, w, z)``. The general kernel's only (``general`` not None; the
    pressure-only kernel compiles none of it)."""
    if general is None or not walled:
        return vol, vol2, vdot
    c, w, z = wall
    x = wall_state[0]
    x_end = wall_advance(x, wall_state[1], p - p_atm, p + rate * hh - p_atm, hh, w, z)[0]
    return vol + c * x, vol2 + c * x_end, vdot + c * (x_end - x) / hh


@njit(cache=True, error_model="numpy")
def wall_accept(walled, wall_state, p_prev, p, h, p_atm, wall, general):
    """The wall's ``(x, v)`` and the pressure's mean rate (Pa/s) after an accepted step
    of ``h`` s from ``p_prev`` to ``p`` (Pa), the pressure linear over it (the general
    kernel's only, as :func:`wall_chord`)."""
    if general is None or not walled:
        return wall_state, 0.0
    x, v = wall_advance(wall_state[0], wall_state[1], p_prev - p_atm, p - p_atm, h, wall[1],
                        wall[2])
    return (x, v), (p - p_prev) / h if h > 0.0 else 0.0
