"""A lagged pressure reading, stepped exactly beside the chamber (effect ``sensor_lag``).

Over an accepted step of ``h`` s the integrator knows the chamber pressure at both ends;
:func:`first_order_step` and :func:`second_order_step` integrate both lags in closed form
for a pressure linear in between. Within a pressure step the chamber follows the
exponential step's own solution, p(s) = p_a + s phi_1(s J) f + s^2 phi_2(s J) v (its
correction taken as a ramp), which is far from linear where the step is much longer
than the chamber's time constant (a 1e-7 m^3 chamber: the reading erred 0.5-0.6 kPa
on a 1-s random-step trajectory, at any tolerance, with the linear form):
:func:`first_order_exponential_step` integrates the first-order lag over that solution
exactly (the phi functions of the triangular 2 x 2 system of chamber and reading, whose
lower-left entries are divided differences of the scalar ones), and
:func:`second_order_curvature` adds the second-order lag's response to the solution's
departure from linear. Over the acoustic line's steps, where the chamber rings with
the line within a step, :func:`first_order_hermite_deviation` corrects the first-order
reading for the cubic through the step's ends and their rates, and its size enters the
step's error estimate. The compiled kernel (:mod:`pneubayes.simulation.kernel`) calls
these once per accepted step (and again for the start sensitivity, which obeys the
same linear filter, with dp/dp0 = e^{sJ} times its value at the step's start).
"""
from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import SLOT_INDEX
from pneubayes.physics.calibration import pressure_behind_reading_scalar, reading_zero_scalar
from pneubayes.simulation.phi import phi123

_SENSOR = SLOT_INDEX["sensor_time_constant_s"]
_SENSOR_W = SLOT_INDEX["sensor_natural_frequency_rad_per_s"]
_SENSOR_Z = SLOT_INDEX["sensor_damping"]
_SENSOR_N = SLOT_INDEX["sensor_pressure_exponent"]


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


#: 4-point Gauss-Legendre nodes and weights on [0, 1]
_GL_S = (0.0694318442029737, 0.3300094782075719, 0.6699905217924281, 0.9305681557970263)
_GL_W = (0.1739274225687269, 0.3260725774312731, 0.3260725774312731, 0.1739274225687269)


@njit(cache=True, error_model="numpy")
def first_order_hermite_deviation(pa, pb, da, db, h, tau):
    """The first-order reading's change over a step of ``h`` s when p follows the cubic
    Hermite path through ``pa``, ``pb`` with end slopes ``da / h``, ``db / h`` (Pa/s;
    ``da``, ``db`` in Pa) instead of the chord (:func:`first_order_step`): the lag's
    response to c(s) = s (1 - s) (A (1 - s) + B s), A = da - (pb - pa), B = (pb - pa) -
    db. With l = tau / h: c - l c' + l^2 c'' - l^3 c''' at s = 1 less its value at 0
    times e^(-1/l) (closed form, l < 2), else 4-point Gauss-Legendre quadrature of
    the integral of e^(-(1 - s) / l) c(s) / l over s (where the closed form cancels)."""
    chord = pb - pa
    ca, cb = da - chord, chord - db
    lam = tau / h
    if lam < 2.0:
        end = lam * cb + lam * lam * (2.0 * ca - 4.0 * cb) - 6.0 * lam ** 3 * (ca - cb)
        start = -lam * ca + 2.0 * lam * lam * (cb - 2.0 * ca) - 6.0 * lam ** 3 * (ca - cb)
        return end - start * math.exp(-1.0 / lam)
    out = 0.0
    for i in range(4):
        si = _GL_S[i]
        out += _GL_W[i] * math.exp(-(1.0 - si) / lam) * si * (1.0 - si) * (
            ca * (1.0 - si) + cb * si)
    return out / lam


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


@njit(cache=True, error_model="numpy")
def phi12_divided(z, w):
    """The divided differences ``phi_k[z, w] = (phi_k(z) - phi_k(w)) / (z - w)``, k = 1, 2:
    directly where |z - w| >= 1e-5 (the difference's rounding, about 2e-16 |phi_k| / |z -
    w|, stays below 1e-10 of a term whose size is the step's pressure change), else the
    derivatives at the midpoint, phi_1' = phi_1 - phi_2 and phi_2' = phi_2 - 2 phi_3
    (from phi_k(z) = int_0^1 e^{(1-s) z} s^{k-1} / (k-1)! ds; error O((z - w)^2))."""
    d = z - w
    if abs(d) >= 1e-5:
        a1, a2, _ = phi123(z)
        b1, b2, _ = phi123(w)
        inv = 1.0 / d
        return (a1 - b1) * inv, (a2 - b2) * inv
    q1, q2, q3 = phi123(0.5 * (z + w))
    return q1 - q2, q2 - 2.0 * q3


@njit(cache=True, error_model="numpy")
def first_order_exponential_step(r, pa, h, tau, z, f, v, e):
    """The reading dr/dt = (p - r) / tau after an exponential step of ``h`` s from p =
    ``pa`` (Pa) with rate ``f`` (Pa/s), slope J = z / h (1/s) and explicit time
    derivative ``v`` (Pa/s^2): p(s) = pa + s phi_1(s J) f + s^2 phi_2(s J) v, plus the
    correction ``e`` (Pa) as a ramp. With x = h / tau and a = e^-x, exactly
    ``a r + (1 - a) pa + h x (phi_1[z, -x] f + h phi_2[z, -x] v) + c e``, c the ramp's
    weight of :func:`first_order_step` (the step of the system (p, r), whose matrix h [[J,
    0], [1 / tau, -1 / tau]] has these divided differences below its diagonal)."""
    x = h / tau
    d1, d2 = phi12_divided(z, -x)
    return first_order_step(r, pa, pa + e, h, tau) + h * x * (d1 * f + h * d2 * v)


@njit(cache=True, error_model="numpy")
def first_order_exponential_sensitivity(s_r, s_a, h, tau, z):
    """The first-order reading's start sensitivity after a step of ``h`` s over which the
    chamber's is ``s_a e^{s J}`` (J = z / h): ``e^-x s_r + s_a x (e^z - e^-x) / (z + x)``,
    x = h / tau, the divided difference as e^max phi_1(min - max)."""
    x = h / tau
    hi, lo = (z, -x) if z >= -x else (-x, z)
    return math.exp(-x) * s_r + s_a * x * math.exp(hi) * phi123(lo - hi)[0]


@njit(cache=True, error_model="numpy")
def second_order_exponential_deviation(c2, z, h, w, zeta):
    """``(dr, dv)``: the second-order reading's response, from rest, over ``h`` s to
    ``c2 (e^{s J} - 1 - s (e^{h J} - 1) / h)`` (J = z / h; an exponential less its
    chord): the particular solution c2 H e^{s J}, H = w^2 / (J^2 + 2 zeta w J + w^2),
    with its start's homogeneous part and the ramp by :func:`second_order_step`. Zero
    where H is singular (J at a pole of an overdamped lag), the chord's answer."""
    jj = z / h
    den = jj * jj + 2.0 * zeta * w * jj + w * w
    if abs(den) < 1e-9 * w * w:
        return 0.0, 0.0
    big = w * w / den * c2
    ez = math.exp(z)
    r, v = second_order_step(-big, -jj * big, -c2, -c2 * ez, h, w, zeta)
    return r + big * ez, v + jj * big * ez


@njit(cache=True, error_model="numpy")
def second_order_curvature(z, f, v, h, w, zeta):
    """``(dr, dv)`` to add to :func:`second_order_step`'s reading after an exponential
    step (``z``, ``f``, ``v`` as in :func:`first_order_exponential_step`): the lag's
    response to the step's solution less its chord, c2 (e^{sJ} - 1 - s (e^{hJ} - 1) / h)
    with c2 = (f + v / J) / J; for |z| < 1e-4, where c2 cancels, its quadratic part
    b s (s - h), b = (J f + v) / 2 (the cubic's share is below 1e-4 of it)."""
    if abs(z) >= 1e-4:
        jj = z / h
        return second_order_exponential_deviation((f + v / jj) / jj, z, h, w, zeta)
    b = 0.5 * (z / h * f + v)
    r, vv = second_order_step(b * (2.0 - 8.0 * zeta * zeta) / (w * w), b * 4.0 * zeta / w,
                              0.0, -b * h * h, h, w, zeta)
    return (r + b * (h * h - 4.0 * zeta * h / w + (8.0 * zeta * zeta - 2.0) / (w * w)),
            vv + b * (2.0 * h - 4.0 * zeta / w))


@njit(cache=True, inline="always", error_model="numpy")
def pressure_lag(tau_a, n, p, r, p_atm):
    """The pressure-dependent lag's time constant (s), ``tau_a (2 P_atm / (p + r))^n``
    for a chamber at ``p`` read as ``r`` (Pa): a cavity fed through a laminar passage
    (n = 1) fills as fast as the mean pressure drives the flow. The sum is held at no
    less than 1e-3 P_atm (a pressure that is not absolute)."""
    return tau_a * math.exp(n * math.log(2.0 * p_atm / max(p + r, 1e-3 * p_atm)))


@njit(cache=True, error_model="numpy")
def pressure_dependent_step(r, pa, h, tau_a, n, p_atm, z, f, v, e):
    """``(r, tau)``: the reading dr/dt = (p - r) / :func:`pressure_lag` after a step of
    ``h`` s over the exponential path of :func:`first_order_exponential_step` (``z``,
    ``f``, ``v``, ``e`` as there; a chord is z = 0, f its slope, v = e = 0), and the
    step's effective time constant (the harmonic mean of its ends'). The step is cut into
    substeps of at most half the lag (at most 32), each stepped exactly over its piece of
    the path at the harmonic mean of the time constants at its start and at its end (the
    end's reading predicted as an exponential approach to the end's pressure)."""
    q1, q2, _ = phi123(z)
    pb = pa + h * (q1 * f + h * q2 * v) + e
    t_a = pressure_lag(tau_a, n, pa, r, p_atm)
    m = min(32, 1 + int(2.0 * h / min(t_a, pressure_lag(tau_a, n, pb, pb, p_atm))))
    hs = h / m
    jj = z / h
    zs = hs * jj
    e_i = e * hs / h
    k1, k2, _ = phi123(zs)
    p_i, f_i = pa, f
    for _ in range(m):
        t0 = pressure_lag(tau_a, n, p_i, r, p_atm)
        p_e = p_i + hs * (k1 * f_i + hs * k2 * v) + e_i
        r_e = p_e + (r - p_e) * math.exp(-hs / t0)
        t1 = pressure_lag(tau_a, n, p_e, r_e, p_atm)
        r = first_order_exponential_step(r, p_i, hs, 2.0 / (1.0 / t0 + 1.0 / t1), zs, f_i, v,
                                         e_i)
        # the path's rate at the substep's end: e^{hs J} f_i + hs phi_1(hs J) v
        p_i, f_i = p_e, (1.0 + zs * k1) * f_i + hs * k1 * v
    t_end = pressure_lag(tau_a, n, pb, r, p_atm)
    return r, 2.0 / (1.0 / t_a + 1.0 / t_end)


@njit(cache=True, inline="always", error_model="numpy")
def reading_lags(sl, p0, p_atm):
    """``(tau s, w rad/s, z, n, second_order, lagged, lead s, settle s)`` of the sensor
    in one parameter set's lowered slots: a first-order lag ``tau`` (at the atmosphere;
    its time constant moving with the pressure by exponent ``n``) or a second-order one
    (``w`` > 0); the reading's lead at DC (its group delay) and the time its transient
    takes, at the window's start pressure ``p0`` Pa."""
    lag_r = sl[_SENSOR]
    w_r, z_r = sl[_SENSOR_W], sl[_SENSOR_Z]
    second = w_r > 0.0
    reading = lag_r > 0.0 or second
    n_r = sl[_SENSOR_N] if (lag_r > 0.0 and not second) else 0.0
    lag_0 = pressure_lag(lag_r, n_r, p0, p0, p_atm) if n_r != 0.0 else lag_r
    lead_s = 2.0 * z_r / w_r if second else lag_0
    settle_s = max(lead_s, 1.0 / (z_r * w_r)) if second else max(lag_r, lag_0)
    return lag_r, w_r, z_r, n_r, second, reading, lead_s, settle_s


@njit(cache=True, error_model="numpy")
def reading_start(t, pm, i0, p0, rate0, lagged, lead_s, settle_s, calibrated, p_atm,
                  zero, cal_g):
    """``(k0, t_start, r, v_r, p)``: where a window's integration starts and the reading,
    its rate and the chamber pressure there.

    A lagged reading with no rate given (``rate0`` NaN) warms up over 5 settling times of
    the command history before the window (from the recorded reading ``pm`` there when
    known; after a gap longer than the warm-up, a triggered recording's pre-trigger hold,
    5 settling times before the window, not at the gap's start); with a rate, the chamber
    leads the reading by ``lead_s`` times it.
    """
    r, v_r, p = p0, 0.0, p0
    k0 = i0
    t_start = t[i0]
    if lagged and math.isnan(rate0):
        while k0 > 0 and t[i0] - t[k0] < 5.0 * settle_s:
            k0 -= 1
        t_start = t[k0]
        if k0 < i0 and math.isfinite(pm[k0]):  # from the recorded reading there
            r = (pressure_behind_reading_scalar(pm[k0], p_atm, reading_zero_scalar(
                zero, t[k0]), cal_g) if calibrated
                 else pm[k0])
            p = r
        if k0 < i0 and t[k0 + 1] - t[k0] > 5.0 * settle_s:
            t_start = t[i0] - 5.0 * settle_s
    elif lagged:
        v_r = rate0
        if p0 + lead_s * rate0 > 0.0:
            p = p0 + lead_s * rate0
    return k0, t_start, r, v_r, p


@njit(cache=True, inline="always", error_model="numpy")
def line_reading_deviation(err, p, pn, rates, h, r, sensor, p_atm, atol_p, rtol):
    """``(deviation Pa, err)``: over an acoustic line's step, where the chamber rings with
    the line, a first-order reading over the cubic through the step's ends and their
    ``rates`` (Pa/s; :func:`first_order_hermite_deviation`; the second-order lag as a
    first-order lag of its group delay, which its chord reading does not correct), and
    the step's error with that deviation against the tolerance. ``sensor`` is ``(tau,
    w, z, n, second_order)`` as :func:`reading_lags` gives them."""
    lag_r, w_r, z_r, n_r, second = sensor
    dev_r = first_order_hermite_deviation(
        p, pn, h * rates[0], h * rates[1], h,
        2.0 * z_r / w_r if second else (
            pressure_lag(lag_r, n_r, p, r, p_atm) if n_r != 0.0 else lag_r))
    return dev_r, max(err, abs(dev_r) / (atol_p + rtol * max(abs(p), abs(pn))))


@njit(cache=True, error_model="numpy", _nrt=False)
def reading_step(r, v_r, s_r, s_v, p_prev, p, s_prev, s_p0, h, zp, fp, vp, ep, dev_r, second,
                 w_r, z_r, lag_r, n_r, p_atm, plain, shaped, want_sens):
    """``(r, v_r, s_r, s_v)``: the lagged reading, its rate and their sensitivities to the
    window's start after an accepted step of ``h`` s from ``p_prev`` to ``p`` Pa.

    Over the pressure step's own solution (exponential, not linear; dp/dp0 = e^{sJ} times
    its start's: ``plain``); for the (p, T) step over the pressure's own exponential part
    (rate ``fp``, slope ``zp / h``, time derivative ``vp``) with the rest of its change as
    a ramp and its sensitivity over the chord (``shaped``); for the other steps over the
    chord, plus an acoustic line's deviation ``dev_r``.
    """
    if second:
        r, v_r = second_order_step(r, v_r, p_prev, p, h, w_r, z_r)
        if shaped:
            d_r, d_v = second_order_curvature(zp, fp, vp, h, w_r, z_r)
            r, v_r = r + d_r, v_r + d_v
        if want_sens:
            s_r, s_v = second_order_step(s_r, s_v, s_prev, s_p0, h, w_r, z_r)
            if plain:
                d_r, d_v = second_order_exponential_deviation(s_prev, zp, h, w_r, z_r)
                s_r, s_v = s_r + d_r, s_v + d_v
        return r, v_r, s_r, s_v
    r_a, s_a = r, s_r
    tau_r = lag_r
    if plain or shaped:
        rest = ep
        if not plain:  # the (p, T) step: the rest of its change a ramp
            q1, q2, _ = phi123(zp)
            rest = p - (p_prev + h * (q1 * fp + h * q2 * vp))
        if n_r != 0.0:  # a time constant that moves with the pressure
            r, tau_r = pressure_dependent_step(r_a, p_prev, h, lag_r, n_r, p_atm, zp, fp, vp,
                                               rest)
        else:
            r = first_order_exponential_step(r_a, p_prev, h, lag_r, zp, fp, vp, rest)
    elif n_r != 0.0:
        r, tau_r = pressure_dependent_step(r_a, p_prev, h, lag_r, n_r, p_atm, 0.0,
                                           (p - p_prev) / h, 0.0, 0.0)
        r += dev_r
    else:
        r = first_order_step(r_a, p_prev, p, h, lag_r) + dev_r
    if want_sens:
        if plain:
            s_r = first_order_exponential_sensitivity(s_a, s_prev, h, tau_r, zp)
        else:
            s_r = first_order_step(s_a, s_prev, s_p0, h, tau_r)
        if n_r != 0.0:  # the time constant moves with p and r:
            # + n (p - r) / (tau (p + r)) (s_p + s_r), at the middle
            p_m, r_m = 0.5 * (p_prev + p), 0.5 * (r_a + r)
            s_r += h * n_r * (p_m - r_m) / (tau_r * max(
                p_m + r_m, 1e-3 * p_atm)) * 0.5 * (s_prev + s_p0 + s_a + s_r)
    return r, v_r, s_r, s_v
