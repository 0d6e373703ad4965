"""The step of models with a second compartment behind a resistance: exprb32 on (p, p_L).

A two-compartment chamber (slot ``lung_volume_m3`` > 0; rig card chamber kind
``two_compartment``, :mod:`pneubayes.rigcard.chamber_two_compartment`): the measured
compartment (the circuit at the sensor; eq. 5 with the chamber's volume) feeds a
compliant compartment (a test lung, a bellows behind a hose) through a laminar
resistance. The mass flow from the measured compartment into the second is
``m_L = k (p^2 - p_L^2)`` (isothermal compressible laminar flow, the form of the
laminar leak), and the second compartment's pressure follows eq. 5 with a compliant
volume ``V_L = V_L0 + C_L (p_L - P_atm)``:

    dp_L/dt = n Rs T m_L / (V_L + n p_L C_L).

Where the flow through the resistance is large the measured pressure leads the second
compartment's by ``R`` times the flow: the jump of the measured pressure when a valve
opens or shuts that a single chamber cannot make. The two are stepped together with the
full 2 x 2 Jacobian (the coupling is stiff when the measured compartment is small).
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import SLOT_INDEX
from pneubayes.simulation.chamber import chamber_rhs, compliant_volume
from pneubayes.simulation.layout import C_KAPPA, C_P_ATM, C_RS, C_T_SUPPLY
from pneubayes.simulation.thermal import exprb2_correct, exprb2_predict

_LUNG_V = SLOT_INDEX["lung_volume_m3"]
_LUNG_C = SLOT_INDEX["lung_compliance_m3_per_Pa"]
_LUNG_K = SLOT_INDEX["lung_conductance_kg_per_s_Pa2"]


@njit(cache=True, error_model="numpy")
def lung_terms(p, pl, vol, vdot, sl, cs, need_j):
    """The coupling's ``(f_p, f_L, J_pp, J_pL, J_Lp, J_LL, v_p)``: the measured
    compartment's extra dp/dt (Pa/s) from the flow into the second, the second's dp_L/dt,
    their Jacobian entries and the explicit time derivative of f_p (the measured
    compartment's volume moving at ``vdot``). ``vol`` is the measured compartment's
    volume before its own compliance (as :func:`chamber_rhs` takes it)."""
    kappa, p_atm = cs[C_KAPPA], cs[C_P_ATM]
    rs_t = cs[C_RS] * cs[C_T_SUPPLY]
    k = sl[_LUNG_K]
    m = k * (p * p - pl * pl)
    vc, compl = compliant_volume(p, vol, sl, p_atm)
    den = vc + kappa * p * compl
    cl = sl[_LUNG_C]
    den_l = sl[_LUNG_V] + cl * (pl - p_atm) + kappa * pl * cl
    fp = -kappa * rs_t * m / den
    fl = kappa * rs_t * m / den_l
    if not need_j:
        return fp, fl, 0.0, 0.0, 0.0, 0.0, 0.0
    jpp = -kappa * rs_t * 2.0 * k * p / den - fp * compl * (1.0 + kappa) / den
    jpl = kappa * rs_t * 2.0 * k * pl / den
    jlp = kappa * rs_t * 2.0 * k * p / den_l
    jll = -kappa * rs_t * 2.0 * k * pl / den_l - fl * cl * (1.0 + kappa) / den_l
    vp = -fp * vdot / den
    return fp, fl, jpp, jpl, jlp, jll, vp


@njit(cache=True, error_model="numpy")
def lung_step(p, pl, hh, a_in, a_ex, vol, vdot, psup, dsup, da_in, da_ex, a_in2, a_ex2,
              vol2, psup2, sl, cs, atol_p, rtol, spool, dspool, spool2, cdir, general):
    """One exprb32 step of (p, p_L) with the full 2 x 2 Jacobian; ``spool`` (moving at
    ``dspool``) and ``spool2`` the spool at the step's start and end, ``cdir`` the
    command's direction (a closure's features), ``general`` the general kernel's flag
    (``chamber_rhs``'s ``with_closure``).

    Returns ``(err, p_new, p_L_new, exp(h J))``, the propagator row-major; ``err`` <= 1
    accepts the step."""
    temp = cs[C_T_SUPPLY]
    fc, jc, _, _, vc, _, _, _ = chamber_rhs(p, temp, a_in, a_ex, vol, vdot, psup, sl, cs, hh,
                                            True, dsup, da_in, da_ex, spool, dspool, cdir, general)
    fa, fl, ja, jpl, jlp, jll, va = lung_terms(p, pl, vol, vdot, sl, cs, True)
    fp, jpp, vp = fc + fa, jc + ja, vc + va
    up, ul, f3, prop = exprb2_predict(p, pl, hh, fp, fl, jpp, jpl, jlp, jll, vp, 0.0)
    if not (up > 0.0 and math.isfinite(up) and ul > 0.0 and math.isfinite(ul)):
        return 10.0, p, pl, prop
    fa2, fl2, _, _, _, _, _ = lung_terms(up, ul, vol2, vdot, sl, cs, False)
    fp2 = chamber_rhs(up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh, False, 0.0, 0.0,
                      0.0, spool2, 0.0, cdir, general)[0] + fa2
    err, pn, ln = exprb2_correct(p, pl, up, ul, hh, f3, fp, fl, fp2, fl2, jpp, jpl, jlp, jll,
                                 vp, 0.0, atol_p, atol_p, rtol)
    return err, pn, ln, prop
