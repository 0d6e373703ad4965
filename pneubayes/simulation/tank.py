"""The step of models with a supply tank: exprb32 on the state (p, P_tank).

A finite tank (slot ``tank_volume_m3``; :mod:`pneubayes.rigcard.supply_tank`) makes the
supply pressure a second state, drained by what the inlet draws,
``dP_tank/dt = -n Rs T a_in f(P_tank, p) / V_tank`` (eqs. 1-3 upstream of the port). The
chamber and the tank exchange air through the port, a stiff mode near pressure balance
(both sides' slopes are those of the port's square-root flow), so the two are stepped
together with the full 2 x 2 Jacobian, as the (p, T) step of
:mod:`pneubayes.simulation.thermal`; an explicit tank update is first order there.
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.physics.orifice import flow_slopes, flow_terms
from pneubayes.simulation.chamber import chamber_rhs
from pneubayes.simulation.layout import C_ALPHA, C_BETA, C_KAPPA, C_T_SUPPLY, C_THETA
from pneubayes.simulation.thermal import exprb2_correct, exprb2_predict


@njit(cache=True, error_model="numpy")
def tank_rhs(p, pt, a_in, cs, c_tank, dp_floor, need_j, da_in):
    """The tank's ``(dP_t/dt, d/dp, d/dP_t, explicit d/dt)``; c_tank = n Rs T / V_t.

    ``dp_floor`` (Pa) is the secant floor of the port's square-root slope; it must be the
    chamber's (:func:`chamber_rhs` uses ``|dp/dt| h``) so that the two Jacobians keep
    ``V p + V_t P_t`` (the air the port exchanges) conserved near pressure balance."""
    f, sg, dg, r, rev = flow_terms(pt, p, cs[C_ALPHA], cs[C_BETA], cs[C_THETA], cs[C_KAPPA])
    ft = -c_tank * a_in * f
    if not need_j:
        return ft, 0.0, 0.0, 0.0
    d_up, d_down = flow_slopes(pt, p, sg, dg, r, rev, cs[C_ALPHA], cs[C_BETA], cs[C_KAPPA],
                               dp_floor)
    return ft, -c_tank * a_in * d_down, -c_tank * a_in * d_up, -c_tank * f * da_in


@njit(cache=True, error_model="numpy")
def tank_step(p, pt, hh, a_in, a_ex, vol, vdot, da_in, da_ex, a_in2, a_ex2, vol2, sl, cs,
              c_tank, atol_p, rtol, spool, dspool, spool2, cdir, general):
    """One exprb32 step of (p, P_tank) with the full 2 x 2 Jacobian; ``spool`` (moving at
    ``dspool``) and ``spool2`` the spool at the step's start and end, ``cdir`` the
    command's direction (a closure's features), ``general`` the general kernel's flag
    (``chamber_rhs``'s ``with_closure``).
    A closure's flow does not draw from the tank.

    Returns ``(err, p_new, P_tank_new, exp(h J))``, the propagator row-major; ``err`` <= 1
    accepts the step. The chamber's d(dp/dt)/dP_tank is the rate of its explicit time
    derivative per unit supply ramp (:func:`chamber_rhs` is linear in the ramp).
    """
    temp = cs[C_T_SUPPLY]
    fp, jpp, _, _, vp, _, _, _ = chamber_rhs(p, temp, a_in, a_ex, vol, vdot, pt, sl, cs, hh,
                                             True, 0.0, da_in, da_ex, spool, dspool, cdir, general)
    vp_ramp = chamber_rhs(p, temp, a_in, a_ex, vol, vdot, pt, sl, cs, hh, True, 1.0, da_in,
                          da_ex, spool, dspool, cdir, general)[4]
    jpt = vp_ramp - vp
    ft, jtp, jtt, vt = tank_rhs(p, pt, a_in, cs, c_tank, abs(fp) * hh, True, da_in)
    up, ut, f3, prop = exprb2_predict(p, pt, hh, fp, ft, jpp, jpt, jtp, jtt, vp, vt)
    if not (up > 0.0 and math.isfinite(up) and ut > 0.0 and math.isfinite(ut)):
        return 10.0, p, pt, prop
    fp2 = chamber_rhs(up, temp, a_in2, a_ex2, vol2, vdot, ut, sl, cs, hh, False, 0.0, 0.0,
                      0.0, spool2, 0.0, cdir, general)[0]
    ft2 = tank_rhs(up, ut, a_in2, cs, c_tank, 0.0, False, 0.0)[0]
    err, pn, tn = exprb2_correct(p, pt, up, ut, hh, f3, fp, ft, fp2, ft2, jpp, jpt, jtp, jtt,
                                 vp, vt, atol_p, atol_p, rtol)
    return err, pn, tn, prop
