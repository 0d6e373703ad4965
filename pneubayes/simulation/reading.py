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

from pneubayes.simulation.phi import phi123


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
