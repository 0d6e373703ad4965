"""The step of heat-transfer models: exprb32 on the state (p, T) with its full Jacobian.

With wall heat exchange the chamber temperature is a second state. Stepping it with a
diagonal Jacobian leaves the exponential method first order in the p-T coupling (the
outflow's enthalpy and the wall term make dp/dt depend on T, and dT/dt on p); here the
phi-functions of the full 2 x 2 ``h J`` are taken in one pass (:func:`phi0123_2x2`).
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.simulation.chamber import chamber_rhs
from pneubayes.simulation.phi import phi0123_2x2


@njit(cache=True, error_model="numpy")
def exprb2_predict(p, q, hh, fp, fq, jpp, jpq, jqp, jqq, vp, vq):
    """Stage 1 of exprb32 for a positive 2-state ``(p, q)`` with slopes ``fp, fq``,
    Jacobian ``J`` and explicit time derivatives ``vp, vq``; the phi-functions are taken
    of the balanced ``S^-1 h J S``, ``S = diag(p, q)`` (:func:`phi0123_2x2`).

    Returns ``(up, uq, f3, prop)``: the exponential Rosenbrock-Euler state, phi_3 of the
    balanced matrix (for :func:`exprb2_correct`) and ``exp(h J)`` row-major."""
    r = q / p
    f0, f1, f2, f3 = phi0123_2x2((hh * jpp, hh * jpq * r, hh * jqp / r, hh * jqq))
    prop = (f0[0], f0[1] / r, f0[2] * r, f0[3])
    w1p, w1q = hh * fp / p, hh * fq / q
    w2p, w2q = hh * hh * vp / p, hh * hh * vq / q
    up = p + p * (f1[0] * w1p + f1[1] * w1q + f2[0] * w2p + f2[1] * w2q)
    uq = q + q * (f1[2] * w1p + f1[3] * w1q + f2[2] * w2p + f2[3] * w2q)
    return up, uq, f3, prop


@njit(cache=True, error_model="numpy")
def exprb2_correct(p, q, up, uq, hh, f3, fp, fq, fp2, fq2, jpp, jpq, jqp, jqq, vp, vq,
                   atol_p, atol_q, rtol):
    """Stage 2 of exprb32 from the slopes ``fp2, fq2`` at ``(up, uq)``: the nonlinear
    remainder through ``2 h phi_3``. Returns ``(err, p_new, q_new)``; ``err`` <= 1
    accepts the step (10 where the new state is not positive and finite)."""
    dp, dq = up - p, uq - q
    w3p = 2.0 * hh * (fp2 - fp - jpp * dp - jpq * dq - hh * vp) / p
    w3q = 2.0 * hh * (fq2 - fq - jqp * dp - jqq * dq - hh * vq) / q
    ep = p * (f3[0] * w3p + f3[1] * w3q)
    eq = q * (f3[2] * w3p + f3[3] * w3q)
    pn, qn = up + ep, uq + eq
    if not (pn > 0.0 and math.isfinite(pn) and qn > 0.0 and math.isfinite(qn)):
        return 10.0, p, q
    err = max(abs(ep) / (atol_p + rtol * max(abs(p), abs(pn))),
              abs(eq) / (atol_q + rtol * max(q, qn)))
    return err, pn, qn


@njit(cache=True, error_model="numpy")
def thermal_step(p, temp, hh, a_in, a_ex, vol, vdot, psup, dsup, da_in, da_ex, a_in2, a_ex2,
                 vol2, psup2, sl, cs, atol_p, atol_t, rtol, spool, dspool, spool2, cdir,
                 general):
    """One exprb32 step of the state (p, T) with its full 2 x 2 Jacobian
    (:func:`exprb2_predict`, :func:`exprb2_correct`). ``spool`` (moving at ``dspool``)
    and ``spool2`` are the spool's position at the step's start and end, ``cdir`` the
    command's direction (a closure's features,
    :func:`~pneubayes.simulation.chamber.chamber_rhs`), ``general`` the general kernel's
    flag (its ``with_closure``).

    Returns ``(err, p_new, T_new, exp(h J), f_p, J_pp, v_p)``: the propagator as a
    row-major 4-tuple (``err`` <= 1 accepts the step), then the pressure's rate, its slope
    in the pressure and its explicit time derivative at the start (Pa/s, 1/s, Pa/s^2),
    from which a lagged reading takes the pressure's shape within the step.
    """
    fp, jpp, ft, jtt, vp, jpt, jtp, vt = chamber_rhs(p, temp, a_in, a_ex, vol, vdot, psup,
                                                     sl, cs, hh, True, dsup, da_in, da_ex,
                                                     spool, dspool, cdir, general)
    up, ut, f3, prop = exprb2_predict(p, temp, hh, fp, ft, jpp, jpt, jtp, jtt, vp, vt)
    if not (up > 0.0 and math.isfinite(up) and ut > 0.0 and math.isfinite(ut)):
        return 10.0, p, temp, prop, fp, jpp, vp
    fp2, _, ft2, _, _, _, _, _ = chamber_rhs(up, ut, a_in2, a_ex2, vol2, vdot, psup2, sl,
                                             cs, hh, False, 0.0, 0.0, 0.0, spool2, 0.0, cdir,
                                             general)
    err, pn, tn = exprb2_correct(p, temp, up, ut, hh, f3, fp, ft, fp2, ft2, jpp, jpt, jtp,
                                 jtt, vp, vt, atol_p, atol_t, rtol)
    return err, pn, tn, prop, fp, jpp, vp
