"""One exponential Rosenbrock step of the chamber pressure alone (the pressure-only form).

The step is the exprb32 of :mod:`pneubayes.simulation.kernel` on eq. 5 with the
pressure as the only state. Two refinements live here:

* **first same as last**: the rate, slope and time derivative at the last accepted
  step's end (from its second stage, moved to its corrected end to first order) start
  the next step while the inputs they depend on hold (the same port areas, spool and
  input segment; in a rigid chamber a new chord of the position is folded in exactly);
* **the q step**: over a chord of a moving position in a rigid chamber where the
  compression outpaces the flows' relaxation (``|J_f| < n |dV/dt| / V``), the step is
  taken in ``q = p V^n``, which the compression leaves alone (``dq/dt = V^n F_f``, F_f
  the flows' part of dp/dt and J_f its slope), so a closed chamber is exact; elsewhere
  in p. A step that crosses samples of the position is corrected for the chord's effect
  on the flows to first order (:mod:`pneubayes.simulation.chord`), and that
  correction's size, weighted by ``CHORD_ERROR_WEIGHT``, enters its error estimate.
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.simulation.chamber import chamber_rhs
from pneubayes.simulation.chord import chord_coupling, chord_response
from pneubayes.simulation.layout import C_KAPPA
from pneubayes.simulation.phi import phi123

# The weight of the chord correction's size in a crossing step's error estimate (the
# step's error is the larger of its own estimate and this times the correction, both
# against the tolerance). 0.3 ran 20-25 % faster on a moving piston at errors up to
# 1.7 x larger (benchmarks/README.md).
CHORD_ERROR_WEIGHT = 1.0
#: The first-same-as-last cache of :func:`start_rates` when it holds nothing.
NO_REUSE = (False, 0.0, 0.0, 0.0, 0.0, -1, 0.0, 0.0, 0.0)


@njit(cache=True, inline="always", error_model="numpy")
def start_rates(p, temp, hh, a_in, a_ex, vol, vdot, psup, dsup, da_in, da_ex, s_at, ds_at,
                cdir, sl, cs, fs, m, varying, relaxing, reads_spool, any_segment, general):
    """``(F, J, dF/dt, fs)`` at the step's start and the first-same-as-last cache.

    ``fs`` = ``(ok, F, J, dF/dt, vdot, m, a_in, a_ex, spool)``: the last accepted step's
    end values and the inputs they hold for (input segment ``m``, or any with
    ``any_segment``: a rigid chamber on the nominal supply, its volume rate read by no
    closure), reused where they match (a new chord ``vdot`` m^3/s of a rigid chamber's
    volume folded in exactly), else eq. 5's right-hand side
    (:func:`~pneubayes.simulation.chamber.chamber_rhs`). ``varying``: the inputs move
    within the step (a moving spool, a chord), so nothing is reused or cached;
    ``relaxing``: a closure's low-pass moves, so nothing is reused; ``reads_spool``: a
    closure reads the spool; ``general`` None: the pressure-only kernel (no closure).
    """
    ok, fs_fp, fs_jp, fs_vp, fs_vdot, fs_m, fs_ain, fs_aex, fs_s = fs
    if (ok and not relaxing and not varying and a_in == fs_ain and a_ex == fs_aex
            and (not reads_spool or s_at == fs_s) and (fs_m == m or any_segment)):
        fp, jp, vp = fs_fp, fs_jp, fs_vp
        if vdot != fs_vdot:  # a new chord of the position (rigid)
            kap = cs[C_KAPPA]
            iv = 1.0 / vol
            xv = vp + fp * fs_vdot * iv
            fp -= kap * iv * p * (vdot - fs_vdot)
            jp -= kap * iv * (vdot - fs_vdot)
            vp = xv - fp * vdot * iv
    else:
        fp, jp, _, _, vp, _, _, _ = chamber_rhs(p, temp, a_in, a_ex, vol, vdot, psup, sl, cs,
                                                hh, True, dsup, da_in, da_ex, s_at, ds_at,
                                                cdir, general)
    if varying:
        return fp, jp, vp, (False, fs_fp, fs_jp, fs_vp, fs_vdot, fs_m, fs_ain, fs_aex, fs_s)
    return fp, jp, vp, (True, fp, jp, vp, vdot, m, a_in, a_ex, s_at)


@njit(cache=True, inline="always", error_model="numpy")
def chamber_step(p, temp, hh, fp, jp, vp, ep, vol, vdot, a_in2, a_ex2, vol2, psup2, dsup,
                 s_at2, cdir, sl, cs, kap, rigid, chord, fsal, atol_p, rtol, general):
    """One exprb32 step of ``hh`` s from ``p`` Pa with start rates ``(fp, jp, vp)``.

    ``vol``/``vol2`` and ``a_in2``, ``a_ex2``, ``psup2``, ``s_at2`` are the volume and
    the second stage's inputs; ``chord``: the position moves over a step that crosses
    samples; ``fsal``: the start rates will be reused, so the second stage takes its
    slope too. ``ep`` is returned unchanged where the step fails. ``general`` as
    :func:`start_rates` takes it.

    Returns ``(err, pn, fp, vp, ep, zp, phi3p, qstep, sc0, sc1, ff, jf, c_ok, c_fp,
    c_jp, c_vp)``: the error against the tolerance (10: failed), the end pressure, the
    rate and its time derivative as stepped (of q with a q step, whose scale V^n at the
    ends is sc0, sc1), the correction, ``h J``, phi_3(h J), the flows' rate and slope,
    and the end's rates for the next step (``c_ok``).
    """
    err, pn = 10.0, p
    c_ok, c_fp, c_jp, c_vp = False, 0.0, 0.0, 0.0
    qstep, rv, ff, jf = False, 0.0, 0.0, 0.0
    if chord:
        rv = vdot / vol
        ff, jf = fp + kap * p * rv, jp + kap * rv
        qstep = rigid and abs(jf) < kap * abs(rv)
    if qstep:
        sc0 = math.exp(kap * math.log(vol))
        sc1 = math.exp(kap * math.log(vol2))
        vp = sc0 * (vp + kap * rv * (ff - p * (rv + jf)))  # d(dq/dt)/dt
        fp = sc0 * ff  # dq/dt
        zp = hh * jf
        phi1p, phi2p, phi3p = phi123(zp)
        uq = p * sc0 + hh * (phi1p * fp + hh * phi2p * vp)
        up = uq / sc1
        if up > 0.0 and math.isfinite(up):
            fp2 = chamber_rhs(up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh, False,
                              0.0, 0.0, 0.0, s_at2, 0.0, cdir, general)[0]
            ep = 2.0 * hh * phi3p * (sc1 * (fp2 + kap * up * vdot / vol2)
                                     - fp - jf * (uq - p * sc0) - hh * vp)
            pn = (uq + ep) / sc1
            err = abs(ep) / sc1 / (atol_p + rtol * max(abs(p), abs(pn)))
    else:  # (written apart: the scale's arithmetic would slow every step)
        sc0, sc1 = 1.0, 1.0
        zp = hh * jp
        phi1p, phi2p, phi3p = phi123(zp)
        up = p + hh * (phi1p * fp + hh * phi2p * vp)
        if up > 0.0 and math.isfinite(up):
            if fsal:
                fp2, jp2, _, _, vp2, _, _, _ = chamber_rhs(
                    up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh, True, dsup, 0.0,
                    0.0, s_at2, 0.0, cdir, general)
            else:
                fp2 = chamber_rhs(up, temp, a_in2, a_ex2, vol2, vdot, psup2, sl, cs, hh,
                                  False, 0.0, 0.0, 0.0, s_at2, 0.0, cdir, general)[0]
            ep = 2.0 * hh * phi3p * (fp2 - fp - jp * (up - p) - hh * vp)
            pn = up + ep
            err = abs(ep) / (atol_p + rtol * max(abs(p), abs(pn)))
            if fsal:
                c_ok, c_fp, c_jp = True, fp2 + jp2 * ep, jp2
                c_vp = vp2
                if vdot != 0.0:
                    c_vp -= jp2 * ep * vdot / vol2
    return (err, pn, fp, vp, ep, zp, phi3p, qstep, sc0, sc1, ff, jf, c_ok, c_fp, c_jp,
            c_vp)


@njit(cache=True, error_model="numpy", _nrt=False)
def chord_corrected(err, pn, p, t, x, m_ch, tau, hh, x0c, x1c, ff, jf, vol, bore, kap, sc0,
                    sc1, atol_p, rtol):
    """``(err, pn, c_c)``: a step over a chord that crossed a sample of the position
    (``t[m_ch + 1] < tau + hh``), its end corrected for the chord's effect on the flows
    to first order and that correction's size in its error; ``c_c`` the coupling
    (Pa / (m s))."""
    c_c = chord_coupling(p, ff, jf, vol, bore, kap)
    dpe = c_c * chord_response(t, x, m_ch, tau, tau + hh, x0c, x1c, jf) * sc0 / sc1
    pn -= dpe
    err = max(err, CHORD_ERROR_WEIGHT * abs(dpe) / (atol_p + rtol * max(abs(p), abs(pn))))
    return err, pn, c_c
