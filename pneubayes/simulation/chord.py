"""Dense output over a moving piston: a step reads the chord of the position across the
samples it crosses (one dV/dt), and the pressure is corrected for the difference.

The position is linear between its samples, so it has a kink at every sample; a step
that crosses samples on the chord integrates a slightly different volume. With
q = p V^n, dq/dt = n Rs T mdot V^(n-1) does not see the volume's path but through the
flows; to first order in the volume's departure dV = A_bore (chord - position),
d(dq)/dt = J_f dq + V^n (-n p J_f + (n - 1) F) dV / V (F and J_f: the flows' part of
dp/dt and its slope), and dp = dq / V^n - n p dV / V. So a crossed sample is moved to its
own volume adiabatically (:func:`off_chord`) less the flows' response so far, and the
step's end by that response (:func:`chord_coupling`, :func:`chord_response`); a step
taken in q itself (the kernel's rigid chamber where the compression outpaces the flows)
reads a sample's pressure as q / V^n at the sample's own volume instead of
:func:`off_chord`'s second-order move. Used by :func:`pneubayes.simulation.kernel` with
``SolverConfig.dense_output``.
"""

from __future__ import annotations

from numba import njit

from pneubayes.simulation.chamber import compliant_volume
from pneubayes.simulation.phi import phi123


@njit(cache=True, inline="always", error_model="numpy")
def position_at(t, x, n, m, tq):
    """The index of the sample segment holding time ``tq`` (s), searched forward from
    ``m``, and the position there (m): linear between samples, held after the last."""
    while m + 1 < n and t[m + 1] <= tq:
        m += 1
    if m + 1 < n:
        return m, x[m] + (tq - t[m]) / (t[m + 1] - t[m]) * (x[m + 1] - x[m])
    return m, x[m]


@njit(cache=True, inline="always", error_model="numpy")
def response_weights(jf, dt):
    """``(e, a, b)``: over an interval of ``dt`` s on which the departure d is linear
    from d0 to d1, w(end) = e w(start) + a d0 + b (d1 - d0) for
    w = integral of exp(jf (t - s)) d(s) ds (e = exp(jf dt), a = dt phi_1, b = dt phi_2)."""
    z = jf * dt
    f1, f2, _ = phi123(z)
    return 1.0 + z * f1, dt * f1, dt * f2


@njit(cache=True, inline="always", error_model="numpy")
def chord_response(t, x, m0, t0, t1, x0, x1, jf):
    """The integral over [t0, t1] of exp(jf (t1 - s)) (chord - position)(s) ds, m s: the
    chord runs from x0 at t0 to x1 at t1, the position is linear between samples (those
    after index ``m0``, the segment holding t0, and before t1 are its kinks), each piece
    in closed form (:func:`response_weights`, once per distinct sample spacing)."""
    slope = (x1 - x0) / (t1 - t0)
    acc, tp, dp = 0.0, t0, 0.0
    dt_c, e_c, a_c, b_c = -1.0, 0.0, 0.0, 0.0
    i = m0 + 1
    while True:
        if i < t.shape[0] and t[i] < t1:
            tn = t[i]
            dn = x0 + (tn - t0) * slope - x[i]
        else:
            tn, dn = t1, 0.0
        dt = tn - tp
        if dt != dt_c:
            dt_c = dt
            e_c, a_c, b_c = response_weights(jf, dt)
        acc = e_c * acc + a_c * dp + b_c * (dn - dp)
        if tn >= t1:
            return acc
        tp, dp = tn, dn
        i += 1


@njit(cache=True, inline="always", error_model="numpy")
def chord_coupling(p, ff, jf, vol, bore, kappa):
    """The coupling c (Pa per m s) with which the pressure at a step's end moves by c
    times :func:`chord_response` (with ``jf``), from the step's start: pressure ``p`` Pa,
    the flows' part of dp/dt ``ff`` (Pa/s) and its slope ``jf`` (1/s), volume ``vol``
    m^3, bore area ``bore`` m^2, polytropic index ``kappa``."""
    return (-kappa * p * jf + (kappa - 1.0) * ff) * bore / vol


@njit(cache=True, inline="always", error_model="numpy")
def off_chord(p_chord, dev_m, vol, bore, kappa, sl, p_atm):
    """A sample's pressure, Pa, from the step's interpolant on the position's chord
    (``dev_m``: the chord minus the sample's position, m), moved adiabatically to the
    sample's volume ``vol`` (m^3, before compliance): p (1 + r)^n to second order in
    r = A_bore dev / (V + n p C) (a step of 20 ms across an accelerating piston moves
    the volume by ~1 %: the first order alone leaves ~50 Pa)."""
    v, c = compliant_volume(p_chord, vol, sl, p_atm)
    r = bore * dev_m / (v + kappa * p_chord * c)
    return p_chord * (1.0 + kappa * r * (1.0 + 0.5 * (kappa - 1.0) * r))
