"""High-fidelity plant: the thin-port chamber plus realistic forms of the effects.

Written independently of the compiled simulator (:mod:`pneubayes.simulation.kernel`):
the right-hand side below is its own code (it reuses only the scalar orifice law of
eqs. 1-3, the Gompertz map of eq. 11 and the tube's friction correlation from
:mod:`pneubayes.physics`), and it is integrated by scipy's ``solve_ivp`` (Radau or
LSODA) with explicit tolerances.

State: chamber pressure p (eq. 5 with the volume ``V = V_dead + A_bore x(t)``), and
what the forms and effects add (:mod:`pneubayes.bench.forms` documents each form's
equations; the ``L_I*`` constants index them). A sticking spool (SpoolStiction) changes
the command the valve sees; a late release (ReleaseDelay), a PWM driver (PwmValve) and
a sampling driver (ZohDriver) when and what it takes (one of them at a time); the bench
applies the reading-side forms (its :mod:`~pneubayes.bench.forms.reading`, with the
inlet's flow the plant returns) to the plant's output. The other
out-of-catalogue forms act in the same right-hand side; at zero strength each leaves it
as it was.

Catalogue effects may be planted beside the forms: the plant reads their lowered
signal-path slots (:mod:`pneubayes.effects.path`) with the meanings the model gives
them (dead band, first-order spool, supply gain, command delay and flow attenuation,
orifice and laminar leaks, heat exchange), so with no forms the plant and the compiled
simulator solve the same equations and a test checks they agree. A form replaces its
catalogue effect; planting both is an error.

Inputs: the command is held between samples (zero-order hold), as in the recording.
Position and supply are interpolated by a C2 cubic spline through the samples, not
linearly as in the models: the plant is the truth, whose piston moves smoothly, and a
smooth right-hand side between command switches keeps the adaptive solver's error
control valid (with linear inputs dV/dt jumps at every sample, which LSODA and Radau
step over blindly: a closed chamber's p V^1.4 then drifts by up to 1e-3). At the
samples both interpolations agree; between them they differ by about dt^2 x''/8 (1e-9 m
for the bench's motions at 10 kHz). The integration restarts where the (delayed)
command switches; between switches the solver steps across sample times freely and
``t_eval`` gives the samples.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from pneubayes.bench.forms import (
    AcousticTube,
    ArmatureDeadTime,
    BladderVolume,
    BoucWenWall,
    BraidFriction,
    ClearanceLeak,
    CreepingWall,
    EndCushion,
    EnergisedSealLeak,
    ExhaustCheckValve,
    ExhaustSilencer,
    GasAccumulator,
    InletFlowForce,
    InletFlowLimiter,
    Iso6358Ports,
    LipSealLeak,
    LoadedWall,
    LowReynoldsPorts,
    MeterOutThrottle,
    PilotFedSpool,
    PilotInletValve,
    PistonSealBypass,
    PlantForm,
    PressureHeldSolenoid,
    PwmValve,
    QuickExhaustValve,
    RegulatorDroop,
    ReleaseDelay,
    ReliefValve,
    RoundedDeadzone,
    ScoredBarrelLeak,
    SealSpeedLeak,
    SeatLeak,
    SecondOrderSpool,
    SpoolHysteresis,
    SpoolLandLeak,
    SpoolSlewLimit,
    SpoolStiction,
    SpoolUnderlap,
    SpringReturnSpool,
    SupplyHose,
    WallHeatTransfer,
    WarmingCoil,
    ZohDriver,
    check_forms,
)
from pneubayes.effects import Effect
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.errors import SimulationError
from pneubayes.physics.orifice import flow_terms
from pneubayes.physics.tube import churchill_fre, vardy_brown_cutoff
from pneubayes.physics.valve import gompertz_scalar
from pneubayes.rig import Rig
from pneubayes.simulation.drive import Inputs

# ---------------------------------------------------------------- constant layout
(K_KAPPA, K_RS, K_TS, K_ALPHA, K_BETA, K_THETA, K_PATM, K_PNOM, K_ABORE, K_BORE) = range(10)
K_IN, K_EX, K_VDEAD = 10, 15, 20
(K_TAU, K_DEAD, K_GAIN, K_ATT, K_LEAKO, K_LEAKL, K_HEAT) = range(21, 28)
K_ROUND, K_WN, K_ZETA = 28, 29, 30
K_CL_C, K_CL_L0, K_CL_SLOPE = 31, 32, 33
K_DROOP, K_DROOP_TAU = 34, 35
K_TUBE_A, K_TUBE_DX, K_TUBE_D, K_TUBE_MU = 36, 37, 38, 39
K_H, K_TWALL = 40, 41
# out-of-catalogue forms (all 0: absent)
K_BL_DV, K_BL_PS = 42, 43
K_HY_B, K_HY_TAU = 44, 45
K_RV_P, K_RV_K = 46, 47
K_FF = 48
K_LS_P, K_LS_K = 49, 50
# the second blind set's forms (all 0: absent)
K_SI_V, K_SI_RL, K_SI_RT = 51, 52, 53
K_SB_A, K_SB_X1, K_SB_X2, K_SB_E = 54, 55, 56, 57
K_CW_C, K_CW_TAU = 58, 59
K_PI_D, K_PI_W = 60, 61
K_ISO_B, K_ISO_M = 62, 63  # (Iso6358Ports: b 0 is the thin port's law)
# the third blind set's forms (all 0: absent)
K_SL_R, K_SL_TAU = 64, 65
K_UL_A, K_UL_W = 66, 67
K_MO_N, K_MO_C, K_MO_P, K_MO_V = 68, 69, 70, 71
# the fourth blind set's forms (all 0: absent; SpoolStiction and SensorBow act on the
# command and on the reading, outside the right-hand side)
K_SH_A, K_SH_V = 72, 73
K_RE_C, K_RE_MU = 74, 75
# the fifth blind set's forms (all 0: absent; CapillarySensorPort and
# LaggingPositionSensor act on the readings, outside the right-hand side)
K_SR_UP, K_SR_DN = 76, 77
K_WC_K, K_WC_TAU, K_WC_MIN, K_WC_SPAN = 78, 79, 80, 81
# the sixth blind set's forms (all 0: absent; ReleaseDelay acts on the command's
# switching times, outside the right-hand side)
K_XC_P, K_SE_A, K_SE_D, K_FL_M = 82, 83, 84, 85
# the seventh blind set's forms (all 0: absent; SensorZeroDrift acts on the reading,
# outside the right-hand side)
K_PB_K, K_PB_A, K_PB_V = 86, 87, 88
K_ES_K, K_ES_P = 89, 90
K_EC_L, K_EC_N, K_EC_E = 91, 92, 93
# the eighth blind set's forms (all 0: absent; SensorThermalShock acts on the reading,
# outside the right-hand side)
K_QE_A, K_QE_P, K_QE_B, K_QE_V = 94, 95, 96, 97
K_GA_V, K_GA_P, K_GA_N = 98, 99, 100
K_LL_K, K_LL_S = 101, 102
# the ninth blind set's forms (all 0: absent; PwmValve and ZohDriver act on the
# command's switching, SensorHysteresis on the reading, outside the right-hand side)
K_SS_K, K_SS_V = 103, 104
# the tenth blind set's forms (all 0: absent; SolenoidGroundShift and InletJetAtSensor
# act on the reading, outside the right-hand side)
K_BF_C, K_BF_W = 105, 106
K_PH_TAU, K_PH_K = 107, 108
# the eleventh set's form
K_BW_CE, K_BW_VH, K_BW_Z, K_BW_N = 109, 110, 111, 112
# the twelfth set's form
K_LW_C, K_LW_W, K_LW_Z = 113, 114, 115
# an AcousticTube's unsteady friction (0: quasi-steady only)
K_TUBE_UF = 116
# a WallHeatTransfer's forced convection by the inflow's jet
K_HJ, K_HJ_Q = 117, 118
# the fourteenth set's form (0: absent)
K_PF_K, K_PF_Q0, K_PF_TAU = 119, 120, 121
N_K = 122
#: Below this drop (Pa) a MeterOutThrottle's flow, and a QuickExhaustValve's passage's,
#: is laminar (linear in the drop).
MO_LAMINAR_DROP_PA = 1000.0
# Integer layout: modes and state indices (-1 = absent). Spool modes: 0 none, 1 first
# order, 2 second order, 3 slew-limited (SpoolSlewLimit), 4 spring return
# (SpringReturnSpool), 5 held by the inlet's drop (PressureHeldSolenoid).
(L_SPOOL, L_IS, L_ISV, L_DZ_ROUND, L_HEAT, L_IT, L_DROOP, L_ID, L_CLEAR, L_NSEG, L_ITP,
 L_ITQ, L_N, L_IH, L_IM, L_IC, L_IF, L_IHS, L_IW, L_IB, L_IQ, L_IBF, L_IBW, L_ILW,
 L_ITY, L_IPF) = range(26)
N_L = 26


#: Schohl's (2003) five exponentials of Zielke's (1968) laminar weighting function,
#: W(t') ~ sum m_k exp(-n_k t'), t' = nu t / R^2 (the model's wave tube uses Trikha's
#: three: another approximation of the same function).
UNSTEADY_M = np.array([1.051, 2.358, 9.021, 29.47, 79.55])
UNSTEADY_N = np.array([26.65, 100.0, 669.0, 6497.0, 57990.0])


@njit(cache=True)
def _pilot_fed(s, y, dy, L, P):
    """The spool ``s`` less a :class:`PilotFedSpool`'s shift, its pilot's rate written to
    ``dy`` (``s`` itself where there is none)."""
    if L[L_IPF] < 0:
        return s
    q = y[L[L_IPF]]
    dy[L[L_IPF]] = (y[0] - P[K_PATM] - q) / P[K_PF_TAU]
    return s - P[K_PF_K] * max(q - P[K_PF_Q0], 0.0) / 1e5


@njit(cache=True)
def unsteady_friction_rates(y, dy, iy, dq, rho, re, area, dia, mu, weight):
    """A tube link's mass-flow rate ``dq`` (kg/s^2) less ``weight`` times Zielke's
    unsteady wall shear over its length, ``4 pi mu sum y_k`` per unit length, and the
    rates of its five states ``y[iy:iy + 5]`` (m/s): ``y_k' = -(n_k + B*) nu / R^2 y_k +
    m_k dV/dt``, V = q / (rho A) the mean velocity (:data:`UNSTEADY_M`,
    :func:`vardy_brown_cutoff`). Returns the link's rate."""
    total = 0.0
    for k in range(5):
        total += y[iy + k]
    dq = dq - weight * 4.0 * math.pi * mu * total
    dv = dq / (rho * area)
    rate = mu / rho * 4.0 / (dia * dia)
    cut = vardy_brown_cutoff(re)
    for k in range(5):
        dy[iy + k] = -(UNSTEADY_N[k] + cut) * rate * y[iy + k] + UNSTEADY_M[k] * dv
    return dq


@njit(cache=True)
def smoothstep(z):
    """C1 ramp: 0 for z <= 0, 3 z^2 - 2 z^3 on (0, 1), 1 for z >= 1."""
    if z <= 0.0:
        return 0.0
    if z >= 1.0:
        return 1.0
    return z * z * (3.0 - 2.0 * z)


@njit(cache=True)
def forchheimer_flow(drop, r_lin, r_quad):
    """Signed m solving ``drop = r_lin m + r_quad m |m|`` (kg/s), the stable root."""
    d = abs(drop)
    if d == 0.0:
        return 0.0
    m = 2.0 * d / (r_lin + math.sqrt(r_lin * r_lin + 4.0 * r_quad * d))
    return m if drop > 0.0 else -m


@njit(cache=True)
def rounded_deadband(s, halfwidth, rounding):
    """Dead band with C1 quadratic corners (:class:`RoundedDeadzone`), V.

    ``sign(s) phi(|s| - w)``, phi(z) = 0 (z <= -r), (z + r)^2 / (4r) (|z| < r), z (z >= r);
    ``rounding = 0`` is the hard dead band ``sign(s) max(|s| - w, 0)``.
    """
    z = abs(s) - halfwidth
    if rounding > 0.0 and abs(z) < rounding:
        mag = (z + rounding) * (z + rounding) / (4.0 * rounding)
    else:
        mag = z if z > 0.0 else 0.0
    return mag if s >= 0.0 else -mag


@njit(cache=True)
def iso6358_flow(p_up, p_down, beta, b, m):
    """ISO 6358 flow per unit sonic area (kg/(s m^2)): ``beta p_up`` choked (ratio <= b),
    times ``(1 - ((r - b) / (1 - b))^2)^m`` above; reversed flow swaps the ends
    (:class:`~pneubayes.bench.forms.Iso6358Ports`)."""
    sign = 1.0
    if p_down > p_up:
        p_up, p_down, sign = p_down, p_up, -1.0
    r = p_down / p_up
    if r <= b:
        return sign * beta * p_up
    z = (r - b) / (1.0 - b)
    return sign * beta * p_up * max(1.0 - z * z, 0.0) ** m


@njit(cache=True)
def low_reynolds_flow(m0, area, re_c, mu):
    """A port's flow ``m0 Re / (Re + Re_c)`` (kg/s) at Reynolds number ``Re = 4 |m0| /
    (pi mu d)``, ``d = sqrt(4 area / pi)`` (:class:`~pneubayes.bench.forms.LowReynoldsPorts`)."""
    if re_c <= 0.0 or area <= 0.0 or m0 == 0.0:
        return m0
    q_c = re_c * math.pi * mu * math.sqrt(4.0 * area / math.pi) / 4.0  # m0 at Re = Re_c
    return m0 * abs(m0) / (abs(m0) + q_c)


@njit(cache=True)
def laminar_tail_flux(p_from, p_to, P):
    """Signed flow per unit area (kg/(s m^2)) from ``p_from`` to ``p_to`` (Pa) through a
    passage: eqs. 1-3 from the higher side, linear in the drop below
    ``MO_LAMINAR_DROP_PA`` (laminar; the orifice law's slope is infinite at no drop)."""
    drop = p_from - p_to
    up, sign = (p_from, 1.0) if drop >= 0.0 else (p_to, -1.0)
    return sign * flow_terms(up, up - max(abs(drop), MO_LAMINAR_DROP_PA), P[K_ALPHA],
                             P[K_BETA], P[K_THETA], P[K_KAPPA])[0] * min(
        abs(drop) / MO_LAMINAR_DROP_PA, 1.0)


@njit(cache=True)
def quick_exhaust_flows(p, pv, P, hot):
    """A QuickExhaustValve's flows (kg/s): from its line (at ``pv``) into the chamber
    (at ``p``) through the passage, and from the chamber to the atmosphere through its
    exhaust (:class:`~pneubayes.bench.forms.QuickExhaustValve`); ``hot`` is
    sqrt(T_s / T) for chamber gas that leaves at the chamber's temperature T (else 1).
    The passage follows :func:`laminar_tail_flux`."""
    w = smoothstep((p - pv) / P[K_QE_B])
    f_lc = laminar_tail_flux(pv, p, P)
    if f_lc < 0.0:
        f_lc *= hot
    f_q = flow_terms(p, P[K_PATM], P[K_ALPHA], P[K_BETA], P[K_THETA], P[K_KAPPA])[0]
    if f_q > 0.0:
        f_q *= hot
    return P[K_QE_P] * (1.0 - w) * f_lc, P[K_QE_A] * w * f_q


@njit(cache=True)
def _wall_heat_flow(P, vol, temp, inflow):
    """A WallHeatTransfer's heat flow into the gas, W: ``h A_w (T_w - T)`` on the end caps
    and barrel of a cylinder holding ``vol``, h raised by the inflow's jet (kg/s) while
    the chamber fills."""
    a_wall = 2.0 * P[K_ABORE] + math.pi * P[K_BORE] * vol / P[K_ABORE]
    h_wall = P[K_H]
    if P[K_HJ] > 0.0 and inflow > 0.0:
        h_wall += P[K_HJ] * (inflow / P[K_HJ_Q]) ** 0.8
    return h_wall * a_wall * (P[K_TWALL] - temp)


@njit(cache=True)
def _leaks_out(p, x, xdot, y, dy, P, L, heat, temp):
    """The chamber's leaks (kg/s, out) at pressure ``p`` and piston position ``x`` (m,
    moving at ``xdot`` m/s): the catalogue's orifice and laminar leaks and the
    out-of-catalogue seals and valves; a worn piston seal's other chamber's rate goes
    into ``dy``."""
    kappa, rs, ts, p_atm = P[K_KAPPA], P[K_RS], P[K_TS], P[K_PATM]
    alpha, beta, theta = P[K_ALPHA], P[K_BETA], P[K_THETA]
    f_l = flow_terms(p, p_atm, alpha, beta, theta, kappa)[0] if P[K_LEAKO] > 0.0 else 0.0
    if heat == 2 and f_l > 0.0:
        f_l *= math.sqrt(ts / temp)
    k_lam = P[K_LEAKL]
    if L[L_CLEAR] == 1:
        k_lam += P[K_CL_C] / (P[K_CL_L0] + P[K_CL_SLOPE] * x)
    leak = P[K_LEAKO] * f_l + k_lam * (p * p - p_atm * p_atm)
    if p > P[K_RV_P] and P[K_RV_K] > 0.0:  # relief valve
        leak += P[K_RV_K] * (p - P[K_RV_P]) ** 1.5
    if p > P[K_LS_P] and P[K_LS_K] > 0.0:  # lip seal lifted
        leak += P[K_LS_K] * (p - P[K_LS_P]) ** 2
    if P[K_SB_A] > 0.0:  # the seal over a scored section of the barrel
        win = (smoothstep((x - P[K_SB_X1]) / P[K_SB_E] + 0.5)
               * smoothstep((P[K_SB_X2] - x) / P[K_SB_E] + 0.5))
        if win > 0.0:
            f_s = flow_terms(p, p_atm, alpha, beta, theta, kappa)[0]
            if heat == 2 and f_s > 0.0:
                f_s *= math.sqrt(ts / temp)
            leak += P[K_SB_A] * win * f_s
    if L[L_IB] >= 0:  # a worn piston seal into the other chamber, which breathes out
        p_b = y[L[L_IB]]
        m_s = P[K_PB_K] * (p * p - p_b * p_b)
        f_v = flow_terms(p_b, p_atm, alpha, beta, theta, kappa)[0]
        v_b = P[K_PB_V] - P[K_ABORE] * x
        dy[L[L_IB]] = kappa * (rs * ts * (m_s - P[K_PB_A] * f_v)
                               + p_b * P[K_ABORE] * xdot) / v_b
        leak += m_s
    if P[K_ES_K] > 0.0:  # a pressure-energised seal: its gap closes as p rises
        g_e = max(p - p_atm, -0.5 * P[K_ES_P])
        leak += P[K_ES_K] * (p * p - p_atm * p_atm) / (1.0 + g_e / P[K_ES_P]) ** 3
    if P[K_SS_K] > 0.0:  # a seal whose film thickens with the piston's speed
        leak += P[K_SS_K] * (abs(xdot) / P[K_SS_V]) ** 1.5 * (p * p - p_atm * p_atm)
    return leak


@njit(cache=True)
def _rhs_into(t, y, u, P, L, tt, xx, ss, dy):
    """Right-hand side of the plant into ``dy``; returns the supply a sensor reads, Pa
    (at the valve's inlet; with a SupplyHose at the regulator, upstream of it), and the
    mass flow through the valve's inlet port, kg/s.

    ``u`` is the held command (V); ``xx`` and ``ss`` are the cubic-spline coefficients
    (ascending powers of t - tt[k], one row per sample interval k) of the position (m)
    and the upstream supply (Pa).
    """
    n = tt.shape[0]
    k = np.searchsorted(tt, t, side="right") - 1
    k = min(max(k, 0), n - 2)
    tau = t - tt[k]
    x = xx[k, 0] + tau * (xx[k, 1] + tau * (xx[k, 2] + tau * xx[k, 3]))
    xdot = xx[k, 1] + tau * (2.0 * xx[k, 2] + tau * 3.0 * xx[k, 3])
    sup_in = ss[k, 0] + tau * (ss[k, 1] + tau * (ss[k, 2] + tau * ss[k, 3]))
    kappa, rs, ts, p_atm = P[K_KAPPA], P[K_RS], P[K_TS], P[K_PATM]
    alpha, beta, theta = P[K_ALPHA], P[K_BETA], P[K_THETA]
    for i in range(y.shape[0]):
        dy[i] = 0.0
    if L[L_IW] >= 0:  # a warming coil: less current for the same command
        heat_w = y[L[L_IW]]
        drive = (u - P[K_WC_MIN]) / P[K_WC_SPAN]
        rise = 1.0 + P[K_WC_K] * heat_w
        dy[L[L_IW]] = (drive * drive / rise - heat_w) / P[K_WC_TAU]
        u = P[K_WC_MIN] + (u - P[K_WC_MIN]) / rise
    # command -> spool
    mode = L[L_SPOOL]
    if mode == 0:
        s = u
    elif mode == 1:
        s = y[L[L_IS]]
        dy[L[L_IS]] = (u - s) / P[K_TAU]
    elif mode == 2:
        s = y[L[L_IS]]
        v = y[L[L_ISV]]
        wn = P[K_WN]
        dy[L[L_IS]] = v
        dy[L[L_ISV]] = wn * wn * (u - s) - 2.0 * P[K_ZETA] * wn * v
    elif mode == 3:  # a rate-limited spool (SpoolSlewLimit)
        s = y[L[L_IS]]
        r = P[K_SL_R]
        dy[L[L_IS]] = r * math.tanh((u - s) / (P[K_SL_TAU] * r))
    elif mode == 4:  # a spring-returned spool (SpringReturnSpool): up and down apart
        s = y[L[L_IS]]
        dy[L[L_IS]] = (u - s) / (P[K_SR_UP] if u > s else P[K_SR_DN])
    else:  # held by the inlet's drop (PressureHeldSolenoid): its rate once pv is known
        s = y[L[L_IS]]
    if L[L_IH] >= 0:  # spool play (SpoolHysteresis): held inside the band
        sh = y[L[L_IH]]
        band = P[K_HY_B]
        if s > sh + band:
            dy[L[L_IH]] = (s - band - sh) / P[K_HY_TAU]
        elif s < sh - band:
            dy[L[L_IH]] = (s + band - sh) / P[K_HY_TAU]
        s = sh
    s = _pilot_fed(s, y, dy, L, P)  # a spool pushed back by its pilot (PilotFedSpool)
    ue = rounded_deadband(s, P[K_DEAD], P[K_ROUND] if L[L_DZ_ROUND] == 1 else 0.0)
    a_in = gompertz_scalar(ue, P[K_IN], P[K_IN + 1], P[K_IN + 2], P[K_IN + 3], P[K_IN + 4])
    a_ex = gompertz_scalar(ue, P[K_EX], P[K_EX + 1], P[K_EX + 2], P[K_EX + 3], P[K_EX + 4])
    if P[K_UL_A] > 0.0:  # an underlapped spool: both ports open a little at the null
        a_u = P[K_UL_A] * (1.0 - smoothstep(abs(s) / P[K_UL_W]))
        a_in += a_u
        a_ex += a_u
    # supply at the valve inlet
    p_up = P[K_PNOM] + P[K_GAIN] * (sup_in - P[K_PNOM])
    if L[L_DROOP] == 1:
        p_up -= y[L[L_ID]]
    p_sensed = p_up
    if L[L_IHS] >= 0:  # a supply hose: the valve sees the hose, the sensor the regulator
        p_up = y[L[L_IHS]]
    p = y[0]
    heat = L[L_HEAT]
    temp = y[L[L_IT]] if heat > 0 else ts
    nseg = L[L_NSEG]
    pv = y[L[L_ITP]] if nseg > 0 else p
    if L[L_IF] >= 0:  # a meter-out throttle's fitting between the valve and the chamber
        pv = y[L[L_IF]]
    if L[L_IQ] >= 0:  # a quick-exhaust valve's line between the valve and the chamber
        pv = y[L[L_IQ]]
    if mode == 5:  # the armature held by the drop across the inlet opens slower
        slow = 1.0 + P[K_PH_K] * max(p_up - pv, 0.0) / p_atm if u > s else 1.0
        dy[L[L_IS]] = (u - s) / (P[K_PH_TAU] * slow)
    if P[K_FF] > 0.0:  # flow forces close the inlet with the drop across it
        a_in = a_in / (1.0 + P[K_FF] * max(p_up - pv, 0.0) / p_atm)
    if P[K_PI_D] > 0.0:  # a pilot-operated inlet shuts below its minimum drop
        a_in = a_in * smoothstep((abs(p_up - pv) - P[K_PI_D]) / P[K_PI_W] + 0.5)
    # the exhaust port discharges into a silencer's body, else to the atmosphere (past
    # an exhaust check valve: against its cracking pressure)
    p_exd = y[L[L_IM]] if L[L_IM] >= 0 else p_atm + P[K_XC_P]
    # port flows (eqs. 1-3); a hot or cold chamber gas scales them by sqrt(T_s / T)
    if P[K_ISO_B] > 0.0:
        f_in = iso6358_flow(p_up, pv, beta, P[K_ISO_B], P[K_ISO_M])
        f_ex = iso6358_flow(pv, p_exd, beta, P[K_ISO_B], P[K_ISO_M])
    else:
        f_in = flow_terms(p_up, pv, alpha, beta, theta, kappa)[0]
        f_ex = flow_terms(pv, p_exd, alpha, beta, theta, kappa)[0]
    # (a fitting or a QEV's line holds supply-temperature gas)
    hot = heat == 2 and nseg == 0 and L[L_IF] < 0 and L[L_IQ] < 0
    if hot and f_in < 0.0:
        f_in *= math.sqrt(ts / temp)
    if hot and f_ex > 0.0:
        f_ex *= math.sqrt(ts / temp)
    if P[K_XC_P] > 0.0 and f_ex < 0.0:  # the exhaust's check valve lets nothing in
        f_ex = 0.0
    m_in = a_in * f_in
    m_ex = a_ex * f_ex
    if P[K_LL_K] > 0.0:  # laminar leaks across the spool's lands, longer as a port closes
        m_in += P[K_LL_K] * (p_up * p_up - pv * pv) / (1.0 + max(0.0, -s) / P[K_LL_S])
        m_ex += P[K_LL_K] * (pv * pv - p_exd * p_exd) / (1.0 + max(0.0, s) / P[K_LL_S])
    if P[K_RE_C] > 0.0:  # viscous losses at low Reynolds numbers
        m_in = low_reynolds_flow(m_in, a_in, P[K_RE_C], P[K_RE_MU])
        m_ex = low_reynolds_flow(m_ex, a_ex, P[K_RE_C], P[K_RE_MU])
    if P[K_EC_N] > 0.0:  # an end cushion throttles what leaves the chamber near x = 0
        w = smoothstep((P[K_EC_L] - x) / P[K_EC_E] + 0.5)
        if w > 0.0:
            a_n = P[K_EC_N]
            if m_ex > 0.0:
                m_ex *= 1.0 - w + w * a_n / math.sqrt(a_ex * a_ex + a_n * a_n)
            if m_in < 0.0:
                m_in *= 1.0 - w + w * a_n / math.sqrt(a_in * a_in + a_n * a_n)
    if P[K_FL_M] > 0.0:  # a flow limiter at the inlet
        m_in = P[K_FL_M] * math.tanh(m_in / P[K_FL_M])
    if P[K_SE_A] > 0.0:  # a worn seat: supply air past the inlet, incompressible law
        drop = p_up - pv
        rho = (p_up if drop >= 0.0 else pv) / (rs * ts)
        d0 = P[K_SE_D]
        mag = math.sqrt(2.0 * rho * max(abs(drop), d0))
        m_in += P[K_SE_A] * mag * (drop / d0 if abs(drop) < d0 else math.copysign(1.0, drop))
    m_inlet = m_in
    if L[L_IHS] >= 0:  # the hose refills through its restriction, the inlet draws it
        f_r = flow_terms(p_sensed, p_up, alpha, beta, theta, kappa)[0]
        dy[L[L_IHS]] = kappa * rs * ts / P[K_SH_V] * (P[K_SH_A] * f_r - m_in)
    if L[L_DROOP] == 1:
        dy[L[L_ID]] = (P[K_DROOP] * m_in - y[L[L_ID]]) / P[K_DROOP_TAU]
    if L[L_IM] >= 0:  # silencer body: the port's flow in, the porous element's out
        m_out = forchheimer_flow(p_exd - p_atm, P[K_SI_RL], P[K_SI_RT])
        dy[L[L_IM]] = kappa * rs * ts / P[K_SI_V] * (m_ex - m_out)
    att = math.exp(-P[K_ATT] / p) if P[K_ATT] > 0.0 else 1.0
    # enthalpy bookkeeping for the energy equation: sum(T_src * mdot_into_chamber)
    if nseg > 0:
        area, dx, dia, mu = P[K_TUBE_A], P[K_TUBE_DX], P[K_TUBE_D], P[K_TUBE_MU]
        itp, itq = L[L_ITP], L[L_ITQ]
        c_cell = kappa * rs * ts / (area * dx)
        q_prev = att * (m_in - m_ex)
        for i in range(nseg):
            p_i = y[itp + i]
            p_next = y[itp + i + 1] if i < nseg - 1 else p
            q = y[itq + i]
            dy[itp + i] = c_cell * (q_prev - q)
            rho = 0.5 * (p_i + p_next) / (rs * ts)
            re = abs(q) * dia / (area * mu)
            link = dx if i < nseg - 1 else 0.5 * dx  # staggered: cell centre to chamber
            dq = (area / link * (p_i - p_next)
                  - churchill_fre(re) * mu * q / (2.0 * rho * dia * dia))
            if L[L_ITY] >= 0:  # Zielke's unsteady wall shear (AcousticTube)
                dq = unsteady_friction_rates(y, dy, L[L_ITY] + 5 * i, dq, rho, re, area,
                                             dia, mu, P[K_TUBE_UF])
            dy[itq + i] = dq
            q_prev = q
        inflow = q_prev
        h_in = inflow * (ts if inflow > 0.0 else temp)
    elif L[L_IF] >= 0:  # the fitting fills from the valve, the chamber from the fitting
        drop = pv - p
        area = P[K_MO_N] + P[K_MO_C] * smoothstep((drop - P[K_MO_P]) / P[K_MO_P] + 0.5)
        f = laminar_tail_flux(pv, p, P)  # (chamber gas leaving at its own temperature)
        if drop < 0.0 and heat == 2:
            f *= math.sqrt(ts / temp)
        inflow = area * f
        dy[L[L_IF]] = kappa * rs * ts / P[K_MO_V] * (att * (m_in - m_ex) - inflow)
        h_in = inflow * (ts if inflow > 0.0 else temp)
    elif L[L_IQ] >= 0:  # the QEV: the line feeds the chamber, or the chamber vents itself
        m_lc, m_q = quick_exhaust_flows(p, pv, P, math.sqrt(ts / temp) if heat == 2 else 1.0)
        dy[L[L_IQ]] = kappa * rs * ts / P[K_QE_V] * (att * (m_in - m_ex) - m_lc)
        inflow = m_lc - m_q
        h_in = m_lc * (ts if m_lc > 0.0 else temp) - m_q * (temp if m_q > 0.0 else ts)
    else:
        inflow = att * (m_in - m_ex)
        h_in = att * (m_in * (ts if m_in > 0.0 else temp) - m_ex * (temp if m_ex > 0.0 else ts))
    leak = _leaks_out(p, x, xdot, y, dy, P, L, heat, temp)  # to the atmosphere
    mdot = inflow - leak
    # chamber (eq. 5, or the energy equation)
    vol = P[K_VDEAD] + P[K_ABORE] * x
    vdot = P[K_ABORE] * xdot
    dvdp = 0.0
    if L[L_IC] >= 0:  # a creeping wall: its volume lags the pressure
        v_c = y[L[L_IC]]
        dvc = (P[K_CW_C] * (p - p_atm) - v_c) / P[K_CW_TAU]
        dy[L[L_IC]] = dvc
        vol += v_c
        vdot += dvc
    if P[K_BL_DV] > 0.0:  # compliant bladder: V grows with gauge pressure
        g = (p - p_atm) / P[K_BL_PS]
        if g >= 0.0:
            e = math.exp(-g)
            vol += P[K_BL_DV] * (1.0 - e)
            dvdp = P[K_BL_DV] * e / P[K_BL_PS]
        else:  # below atmosphere it collapses onto its seat: 4x stiffer, C1 at 0
            den = 1.0 - 4.0 * g
            vol += P[K_BL_DV] * g / den
            dvdp = P[K_BL_DV] / (P[K_BL_PS] * den * den)
    if P[K_GA_V] > 0.0 and p > P[K_GA_P]:  # an accumulator's gas, compressed
        r_ga = (P[K_GA_P] / p) ** (1.0 / P[K_GA_N])
        vol, dvdp = vol + P[K_GA_V] * (1.0 - r_ga), dvdp + P[K_GA_V] * r_ga / (P[K_GA_N] * p)
    if L[L_IBF] >= 0:  # a friction-held wall: its give, held inside the band
        vol += P[K_BF_C] * y[L[L_IBF]]
    if L[L_IBW] >= 0:  # a Bouc-Wen wall: elastic, and its hysteretic part z
        vol += P[K_BW_CE] * (p - p_atm) + P[K_BW_VH] * y[L[L_IBW]] / P[K_BW_Z]
    if L[L_ILW] >= 0:  # a loaded wall: its give and the give's rate (states)
        vol += y[L[L_ILW]]
        vdot += y[L[L_ILW] + 1]
    # inflow at its source's temperature, outflow at the chamber's (T = T_s without a
    # temperature state, where this is eq. 5)
    enth = h_in - leak * (temp if leak > 0.0 else ts)
    if heat == 2:
        q_heat = _wall_heat_flow(P, vol, temp, inflow)
        dp = kappa / vol * (rs * enth - p * vdot) + (kappa - 1.0) * q_heat / vol
    else:
        dp = kappa / vol * (rs * enth - p * vdot)
        if heat == 1:
            dp += p * P[K_HEAT] * (P[K_TWALL] - temp) / temp
    slide = 0.0
    if L[L_IBF] >= 0:  # the wall slides with the pressure once past its band
        lead = (p - p_atm - y[L[L_IBF]]) * (1.0 if dp > 0.0 else -1.0)
        band = P[K_BF_W]
        if dp != 0.0 and lead > 0.0:
            slide = smoothstep((lead - band) / (0.1 * band) + 0.5)
        dvdp += P[K_BF_C] * slide
    gate = 1.0
    if L[L_IBW] >= 0:  # z's rate per dp/dt: slowed only while pushed towards its memory
        z = y[L[L_IBW]]
        if z * dp > 0.0:
            gate = 1.0 - (abs(z) / P[K_BW_Z]) ** P[K_BW_N]
        dvdp += P[K_BW_CE] + P[K_BW_VH] * gate / P[K_BW_Z]
    if dvdp > 0.0:  # dV/dt = A dx/dt + dV/dp dp/dt, solved for dp/dt
        dp = dp / (1.0 + kappa * p * dvdp / vol)
        vdot += dvdp * dp
    dy[0] = dp
    if L[L_IBF] >= 0:
        dy[L[L_IBF]] = slide * dp
    if L[L_IBW] >= 0:
        dy[L[L_IBW]] = gate * dp
    if L[L_ILW] >= 0:  # the give's mass on its spring, driven by the gauge pressure
        w = P[K_LW_W]
        dy[L[L_ILW]] = y[L[L_ILW] + 1]
        dy[L[L_ILW] + 1] = (w * w * (P[K_LW_C] * (p - p_atm) - y[L[L_ILW]])
                            - 2.0 * P[K_LW_Z] * w * y[L[L_ILW] + 1])
    if heat > 0:
        dy[L[L_IT]] = temp * (dp / p + vdot / vol - rs * temp * mdot / (p * vol))
    return p_sensed, m_inlet


@njit(cache=True)
def _rhs(t, y, u, P, L, tt, xx, ss):
    dy = np.empty_like(y)
    _rhs_into(t, y, u, P, L, tt, xx, ss, dy)
    return dy


@njit(cache=True)
def _jac(t, y, u, P, L, tt, xx, ss, scale):
    """Forward-difference Jacobian, column j stepped by 1e-7 max(|y_j|, scale_j)."""
    n = y.shape[0]
    f0 = np.empty(n)
    f1 = np.empty(n)
    _rhs_into(t, y, u, P, L, tt, xx, ss, f0)
    jac = np.empty((n, n))
    yy = y.copy()
    for j in range(n):
        h = 1e-7 * max(abs(y[j]), scale[j])
        yy[j] = y[j] + h
        _rhs_into(t, yy, u, P, L, tt, xx, ss, f1)
        yy[j] = y[j]
        for i in range(n):
            jac[i, j] = (f1[i] - f0[i]) / h
    return jac


@njit(cache=True)
def _sensor_traces(ts_out, ys, us, P, L, tt, xx, ss):
    """``(supply Pa, inlet flow kg/s)``: the valve-inlet supply and the inlet port's mass
    flow at each output time from the states ``ys`` (N, n) under the held commands
    ``us`` (N,)."""
    supply = np.empty(ts_out.shape[0])
    inflow = np.empty(ts_out.shape[0])
    dy = np.empty(ys.shape[1])
    for i in range(ts_out.shape[0]):
        supply[i], inflow[i] = _rhs_into(ts_out[i], ys[i], us[i], P, L, tt, xx, ss, dy)
    return supply, inflow


# ---------------------------------------------------------------- Python interface
_METHODS = ("Radau", "LSODA", "BDF")


@dataclass(frozen=True)
class PlantConfig:
    """Integration settings of the plant (no hidden defaults; saved with each result).

    Parameters
    ----------
    method : str
        ``solve_ivp`` method: "Radau", "BDF" or "LSODA".
    rtol : float
        Relative tolerance.
    atol_Pa : float
        Absolute tolerance on pressures (chamber, tube cells, regulator droop), Pa. The
        tube's mass flows get the flow of an acoustic wave of that amplitude,
        ``atol_Pa A / c`` (kg/s).
    atol_K : float
        Absolute tolerance on the chamber temperature, K.
    atol_V : float
        Absolute tolerance on the spool position, V (its velocity: ``atol_V`` times the
        spool's natural angular frequency, V/s).
    max_step_s : float
        Largest step, s.
    """

    method: str
    rtol: float
    atol_Pa: float
    atol_K: float
    atol_V: float
    max_step_s: float

    def __post_init__(self):
        if self.method not in _METHODS:
            raise ValueError(f"PlantConfig.method must be one of {_METHODS}, "
                             f"got {self.method!r}")
        for name in ("rtol", "atol_Pa", "atol_K", "atol_V", "max_step_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v > 0):
                raise ValueError(f"PlantConfig.{name} must be a finite number > 0, got {v!r}")

    @classmethod
    def reference(cls) -> "PlantConfig":
        """The bench's preset: LSODA, rtol 1e-8, 0.01 Pa.

        Measured on 1-s moving-piston recordings (AIR37, valve1, 10 kHz inputs) with
        each default form and all six together: within 0.25 Pa of Radau at rtol 1e-10.
        Cost on one core: about 0.02 s per second of recording without a tube, 0.2 s
        with the 1 m AcousticTube (its waves need steps of ~20 us).
        """
        return cls(method="LSODA", rtol=1e-8, atol_Pa=0.01, atol_K=1e-5, atol_V=1e-7,
                   max_step_s=0.005)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class PlantTrajectory:
    """Plant output on the input sample times.

    ``pressure_Pa`` (N,) chamber pressure, ``supply_at_valve_Pa`` (N,) the absolute
    supply at the valve inlet (what a supply sensor there reads; with a SupplyHose the
    regulator's, where its sensor sits),
    ``chamber_temperature_K`` (N,) or None without a temperature state; ``stats`` holds
    the solver's counts (``nfev``, ``njev``, ``spans``); ``inlet_flow_kg_per_s`` (N,)
    the mass flow through the valve's inlet port (at the command held at each sample).
    """

    time_s: np.ndarray
    pressure_Pa: np.ndarray
    supply_at_valve_Pa: np.ndarray
    chamber_temperature_K: np.ndarray | None
    config: PlantConfig
    forms: tuple[PlantForm, ...]
    stats: dict
    inlet_flow_kg_per_s: np.ndarray | None = None


@dataclass(frozen=True)
class _Setup:
    P: np.ndarray
    L: np.ndarray
    y0_extra: dict
    atol: np.ndarray
    scale: np.ndarray
    delay_s: float
    #: the catalogue's sticking valve as the bench's own form (None: a free valve)
    stiction: "SpoolStiction | None" = None


def _lower_catalogue(params: Mapping[str, float], effects: Sequence[Effect], rig: Rig):
    from pneubayes.model import Model  # model imports effects only; no cycle at run time

    model = Model(effects)
    vec = model.vector(params)  # ParameterError names missing / unknown names
    model.check_bounds(vec)
    return model.lower(vec, rig)[0]


def _out_of_catalogue_constants(P, L, by: dict, rig: Rig, inputs: Inputs) -> None:
    """Write the out-of-catalogue forms of ``by`` (form class -> form) into the
    constants ``P`` and the layout ``L`` (in place), refusing the pairs the plant
    cannot hold."""
    if BladderVolume in by:
        f = by[BladderVolume]
        P[K_BL_DV], P[K_BL_PS] = f.dV_max_m3, f.pressure_scale_Pa
    if ReliefValve in by:
        f = by[ReliefValve]
        P[K_RV_P], P[K_RV_K] = f.crack_pressure_Pa, f.flow_coefficient_kg_per_s_Pa1p5
    if InletFlowForce in by:
        P[K_FF] = by[InletFlowForce].flow_force_coefficient
    if LipSealLeak in by:
        f = by[LipSealLeak]
        P[K_LS_P], P[K_LS_K] = f.seal_pressure_Pa, f.conductance_kg_per_s_Pa2
    silencer = by.get(ExhaustSilencer)
    if silencer is not None and silencer.back_pressure_Pa > 0:
        P[K_SI_V] = silencer.volume_m3
        P[K_SI_RL], P[K_SI_RT] = silencer.resistances
    if ScoredBarrelLeak in by:
        f = by[ScoredBarrelLeak]
        P[K_SB_A], P[K_SB_X1], P[K_SB_X2], P[K_SB_E] = (f.area_m2, f.start_m, f.end_m,
                                                          f.edge_m)
    creep = by.get(CreepingWall)
    if creep is not None and creep.compliance_m3_per_Pa > 0:
        P[K_CW_C], P[K_CW_TAU] = creep.compliance_m3_per_Pa, creep.time_constant_s
    if PilotInletValve in by:
        f = by[PilotInletValve]
        if f.min_pressure_difference_Pa > 0:
            P[K_PI_D] = f.min_pressure_difference_Pa
            P[K_PI_W] = f.transition_fraction * f.min_pressure_difference_Pa
    if Iso6358Ports in by:
        P[K_ISO_B], P[K_ISO_M] = (by[Iso6358Ports].critical_pressure_ratio,
                                  by[Iso6358Ports].subsonic_index)
    slew = by.get(SpoolSlewLimit)
    if slew is not None and slew.slew_rate_V_per_s > 0:
        if L[L_SPOOL] != 0:
            raise ValueError("plant: SpoolSlewLimit is the spool's stage; it cannot be "
                             "planted beside a spool_lag effect or a SecondOrderSpool")
        P[K_SL_R], P[K_SL_TAU], L[L_SPOOL] = slew.slew_rate_V_per_s, slew.time_constant_s, 3
    spring = by.get(SpringReturnSpool)
    if spring is not None and spring.rise_time_constant_s > 0:
        if L[L_SPOOL] != 0:
            raise ValueError("plant: SpringReturnSpool is the spool's stage; it cannot be "
                             "planted beside a spool_lag effect, a SecondOrderSpool or a "
                             "SpoolSlewLimit")
        P[K_SR_UP], P[K_SR_DN] = spring.rise_time_constant_s, spring.fall_time_constant_s
        L[L_SPOOL] = 4
    check = by.get(ExhaustCheckValve)
    if check is not None:
        if silencer is not None and silencer.back_pressure_Pa > 0:
            raise ValueError("plant: an ExhaustCheckValve cannot be planted beside an "
                             "ExhaustSilencer (both sit on the exhaust port)")
        P[K_XC_P] = check.crack_pressure_Pa
    seat = by.get(SeatLeak)
    if seat is not None and seat.area_m2 > 0:
        P[K_SE_A], P[K_SE_D] = seat.area_m2, seat.laminar_drop_Pa
    limiter = by.get(InletFlowLimiter)
    if limiter is not None:
        P[K_FL_M] = limiter.max_flow_kg_per_s
    bypass = by.get(PistonSealBypass)
    if bypass is not None and bypass.conductance_kg_per_s_Pa2 > 0:
        v_b = bypass.opposite_volume_m3 - rig.bore_area_m2 * float(inputs.position_m.max())
        if not v_b > 0:
            raise ValueError(f"PistonSealBypass: the other chamber's volume {v_b} m^3 at the "
                             f"largest position is not > 0 (opposite_volume_m3 "
                             f"{bypass.opposite_volume_m3})")
        P[K_PB_K], P[K_PB_A] = bypass.conductance_kg_per_s_Pa2, bypass.vent_area_m2
        P[K_PB_V] = bypass.opposite_volume_m3
    energised = by.get(EnergisedSealLeak)
    if energised is not None:
        P[K_ES_K], P[K_ES_P] = (energised.conductance_kg_per_s_Pa2,
                                energised.energising_pressure_Pa)
    cushion = by.get(EndCushion)
    if cushion is not None and cushion.needle_area_m2 > 0:
        if AcousticTube in by or MeterOutThrottle in by:
            raise ValueError("plant: an EndCushion cannot be planted beside an AcousticTube "
                             "or a MeterOutThrottle (the port's flows reach the chamber "
                             "through them)")
        P[K_EC_L], P[K_EC_N], P[K_EC_E] = (cushion.length_m, cushion.needle_area_m2,
                                           cushion.edge_m)
    qev = by.get(QuickExhaustValve)
    if qev is not None and qev.exhaust_area_m2 > 0:
        if AcousticTube in by or MeterOutThrottle in by or EndCushion in by:
            raise ValueError("plant: a QuickExhaustValve cannot be planted beside an "
                             "AcousticTube, a MeterOutThrottle or an EndCushion (they sit "
                             "on the same port)")
        P[K_QE_A], P[K_QE_P] = qev.exhaust_area_m2, qev.passage_area_m2
        P[K_QE_B], P[K_QE_V] = qev.switch_band_Pa, qev.line_volume_m3
    acc = by.get(GasAccumulator)
    if acc is not None and acc.volume_m3 > 0:
        P[K_GA_V], P[K_GA_P], P[K_GA_N] = acc.volume_m3, acc.precharge_Pa, acc.polytropic_index
    lands = by.get(SpoolLandLeak)
    if lands is not None and lands.conductance_kg_per_s_Pa2 > 0:
        P[K_LL_K], P[K_LL_S] = lands.conductance_kg_per_s_Pa2, lands.overlap_scale_V
    film = by.get(SealSpeedLeak)
    if film is not None and film.conductance_kg_per_s_Pa2 > 0:
        P[K_SS_K], P[K_SS_V] = film.conductance_kg_per_s_Pa2, film.reference_speed_m_per_s
    wall = by.get(BraidFriction)
    if wall is not None and wall.compliance_m3_per_Pa > 0:
        P[K_BF_C], P[K_BF_W] = wall.compliance_m3_per_Pa, wall.friction_band_Pa
    bw = by.get(BoucWenWall)
    if bw is not None and (bw.elastic_compliance_m3_per_Pa > 0 or bw.loop_volume_m3 > 0):
        P[K_BW_CE], P[K_BW_VH] = bw.elastic_compliance_m3_per_Pa, bw.loop_volume_m3
        P[K_BW_Z], P[K_BW_N] = bw.memory_Pa, bw.exponent
    loaded = by.get(LoadedWall)
    if loaded is not None and loaded.compliance_m3_per_Pa > 0:
        P[K_LW_C], P[K_LW_Z] = loaded.compliance_m3_per_Pa, loaded.damping_ratio
        P[K_LW_W] = 2.0 * math.pi * loaded.natural_frequency_Hz
    held = by.get(PressureHeldSolenoid)
    if held is not None and held.time_constant_s > 0:
        if L[L_SPOOL] != 0:
            raise ValueError("plant: PressureHeldSolenoid is the spool's stage; it cannot "
                             "be planted beside a spool_lag effect or another spool form")
        P[K_PH_TAU], P[K_PH_K], L[L_SPOOL] = held.time_constant_s, held.slowing_per_atm, 5
    coil = by.get(WarmingCoil)
    if coil is not None and coil.resistance_rise > 0:
        P[K_WC_K], P[K_WC_TAU] = coil.resistance_rise, coil.time_constant_s
        P[K_WC_MIN], P[K_WC_SPAN] = coil.command_min_V, coil.command_span_V
    under = by.get(SpoolUnderlap)
    if under is not None and under.area_m2 > 0:
        P[K_UL_A], P[K_UL_W] = under.area_m2, under.width_V
    throttle = by.get(MeterOutThrottle)
    if throttle is not None and throttle.needle_area_m2 > 0:
        if AcousticTube in by:
            raise ValueError("plant: a MeterOutThrottle cannot be planted beside an "
                             "AcousticTube (both sit between the valve and the chamber)")
        P[K_MO_N], P[K_MO_C] = throttle.needle_area_m2, throttle.check_area_m2
        P[K_MO_P], P[K_MO_V] = throttle.crack_pressure_Pa, throttle.volume_m3
    hose = by.get(SupplyHose)
    if hose is not None and hose.restriction_area_m2 > 0:
        P[K_SH_A], P[K_SH_V] = hose.restriction_area_m2, hose.volume_m3
    viscous = by.get(LowReynoldsPorts)
    if viscous is not None and viscous.critical_reynolds > 0:
        P[K_RE_C], P[K_RE_MU] = viscous.critical_reynolds, viscous.air_viscosity_Pa_s
    hyst = by.get(SpoolHysteresis)
    if hyst is not None and hyst.half_band_V > 0:
        P[K_HY_B], P[K_HY_TAU] = hyst.half_band_V, hyst.time_constant_s
    pilot = by.get(PilotFedSpool)
    if pilot is not None and pilot.feedback_V_per_bar > 0:
        P[K_PF_K], P[K_PF_Q0] = pilot.feedback_V_per_bar, pilot.preload_Pa
        P[K_PF_TAU] = pilot.pilot_time_constant_s


def _setup(params, effects, forms, rig: Rig, inputs: Inputs, cfg: PlantConfig) -> _Setup:
    sl = _lower_catalogue(params, effects, rig)
    if sl[SLOT_INDEX["leak_laminar_gradient_kg_per_s_Pa2_m"]] != 0.0:
        raise ValueError("plant: a catalogue leak graded along the stroke is not simulated "
                         "here; plant a ClearanceLeak form with a seal_length_slope instead")
    if sl[SLOT_INDEX["deadband_rounding_V"]] != 0.0:
        raise ValueError("plant: the catalogue's rounded valve_deadzone is not simulated "
                         "here; plant a RoundedDeadzone form instead")
    if sl[SLOT_INDEX["heat_coefficient_W_per_m2_K"]] != 0.0:
        raise ValueError("plant: the catalogue's convective heat_transfer is not simulated "
                         "here; plant a WallHeatTransfer form instead")
    coupling = float(sl[SLOT_INDEX["heat_coupling"]])
    if coupling not in (0.0, 1.0):
        raise ValueError(f"plant: the catalogue heat_transfer's partial coupling "
                         f"({coupling:g}) is not simulated here: the plant's chamber feels "
                         "its whole temperature (1) or none (0)")
    if sl[SLOT_INDEX["spool_rate_limit_V_per_s"]] != 0.0:
        raise ValueError("plant: the catalogue's speed-limited spool_lag is not simulated "
                         "here; plant a SpoolSlewLimit form instead")
    fall = float(sl[SLOT_INDEX["spool_fall_time_constant_s"]])
    if fall > 0.0 and not sl[SLOT_INDEX["spool_time_constant_s"]] > 0.0:
        raise ValueError("plant: the catalogue's asymmetric spool_lag needs a rise time "
                         "constant > 0 beside its fall's")
    stiction = None
    band = float(sl[SLOT_INDEX["stiction_band_V"]])
    if band > 0.0:  # the catalogue's sticking valve, stepped by the bench's own form
        if any(isinstance(f, SpoolStiction) for f in forms):
            raise ValueError("plant: valve_stiction and a SpoolStiction form both make the "
                             "valve stick; plant one of them")
        slip = float(sl[SLOT_INDEX["stiction_slip_fraction"]])
        stiction = SpoolStiction(breakaway_V=band, stop_V=(1.0 - slip) * band)
    g = rig.gas
    P = np.zeros(N_K)
    P[K_KAPPA], P[K_RS], P[K_TS] = (g.heat_capacity_ratio, g.specific_gas_constant_J_per_kg_K,
                                    g.temperature_K)
    P[K_ALPHA], P[K_BETA], P[K_THETA] = g.alpha_s_per_m, g.beta_s_per_m, g.theta
    P[K_PATM], P[K_PNOM] = rig.atmospheric_pressure_Pa, rig.supply_pressure_Pa
    P[K_ABORE], P[K_BORE] = rig.bore_area_m2, rig.bore_m
    for i, name in enumerate(("inlet_offset_m2", "inlet_a_m2", "inlet_b", "inlet_c_per_V",
                              "inlet_d_V")):
        P[K_IN + i] = sl[SLOT_INDEX[name]]
        P[K_EX + i] = sl[SLOT_INDEX[name.replace("inlet", "exhaust")]]
    P[K_VDEAD] = sl[SLOT_INDEX["volume_m3"]]
    for k, slot in ((K_TAU, "spool_time_constant_s"), (K_DEAD, "deadband_halfwidth_V"),
                    (K_GAIN, "supply_gain"), (K_ATT, "flow_attenuation_Pa"),
                    (K_LEAKO, "leak_orifice_area_m2"), (K_LEAKL, "leak_laminar_kg_per_s_Pa2"),
                    (K_HEAT, "heat_rate_per_s")):
        P[k] = sl[SLOT_INDEX[slot]]
    L = np.full(N_L, -1, dtype=np.int64)
    L[[L_SPOOL, L_DZ_ROUND, L_HEAT, L_DROOP, L_CLEAR, L_NSEG]] = 0
    L[L_SPOOL] = 1 if P[K_TAU] > 0 else 0
    if sl[SLOT_INDEX["spool_natural_frequency_rad_per_s"]] > 0:  # the catalogue's 2nd order
        P[K_WN], P[K_ZETA] = (sl[SLOT_INDEX["spool_natural_frequency_rad_per_s"]],
                              sl[SLOT_INDEX["spool_damping"]])
        L[L_SPOOL] = 2
    if fall > 0.0:  # the catalogue's asymmetric spool, stepped as the plant's own
        P[K_SR_UP], P[K_SR_DN], L[L_SPOOL] = P[K_TAU], fall, 4
    L[L_HEAT] = 1 if coupling > 0 else 0
    # the catalogue's wall: at the supply's temperature plus its offset
    P[K_TWALL] = g.temperature_K + float(sl[SLOT_INDEX["heat_wall_offset_K"]])
    by = {type(f): f for f in forms}
    if RoundedDeadzone in by:
        f = by[RoundedDeadzone]
        P[K_DEAD], P[K_ROUND], L[L_DZ_ROUND] = f.halfwidth_V, f.rounding_V, 1
    if SecondOrderSpool in by:
        f = by[SecondOrderSpool]
        P[K_WN], P[K_ZETA], L[L_SPOOL] = 2 * math.pi * f.natural_frequency_Hz, f.damping, 2
    if WallHeatTransfer in by:
        f = by[WallHeatTransfer]
        P[K_H], L[L_HEAT] = f.h_W_per_m2_K, 2
        P[K_HJ], P[K_HJ_Q] = f.jet_h_W_per_m2_K, f.jet_flow_kg_per_s
        P[K_TWALL] = g.temperature_K if f.wall_temperature_K is None else f.wall_temperature_K
    if ClearanceLeak in by:
        f = by[ClearanceLeak]
        lo, hi = float(inputs.position_m.min()), float(inputs.position_m.max())
        for xpos in (lo, hi):
            if not f.seal_length_at(xpos) > 0:
                raise ValueError(f"ClearanceLeak: seal length {f.seal_length_at(xpos)} m at "
                                 f"position {xpos} m is not > 0 (seal_length_slope "
                                 f"{f.seal_length_slope})")
        d = rig.bore_m if f.seal_diameter_m is None else f.seal_diameter_m
        P[K_CL_C] = math.pi * d * f.gap_m**3 / (24.0 * f.air_viscosity_Pa_s * P[K_RS] * P[K_TS])
        P[K_CL_L0], P[K_CL_SLOPE], L[L_CLEAR] = f.seal_length_m, f.seal_length_slope, 1
    if RegulatorDroop in by:
        f = by[RegulatorDroop]
        P[K_DROOP], P[K_DROOP_TAU] = 1000.0 * f.droop_Pa_per_g_per_s, f.time_constant_s
        L[L_DROOP] = 1
    _out_of_catalogue_constants(P, L, by, rig, inputs)
    tube = by.get(AcousticTube)
    if tube is not None:
        P[K_TUBE_A], P[K_TUBE_DX] = tube.area_m2, tube.length_m / tube.segments
        P[K_TUBE_D], P[K_TUBE_MU] = tube.diameter_m, tube.air_viscosity_Pa_s
        P[K_TUBE_UF] = tube.unsteady_friction
        L[L_NSEG] = tube.segments
    # (a bladder's volume at atmosphere is 0; it only grows above)
    vmin = P[K_VDEAD] + P[K_ABORE] * float(inputs.position_m.min())
    if not vmin > 0:
        raise ValueError(f"chamber volume {vmin} m^3 at the smallest position is not > 0 "
                         f"(dead_volume_m3 {P[K_VDEAD]})")
    # state layout and per-state tolerances / Jacobian scales
    atol, scale, extra = [cfg.atol_Pa], [1e5], {}
    n = 1
    if L[L_HEAT] > 0:
        L[L_IT] = n
        n += 1
        t0 = P[K_TWALL]  # the gas at rest at its wall's temperature
        extra[L_IT] = t0
        atol.append(cfg.atol_K)
        scale.append(300.0)
    if L[L_SPOOL] > 0:
        L[L_IS] = n
        n += 1
        atol.append(cfg.atol_V)
        scale.append(1.0)
        if L[L_SPOOL] == 2:
            L[L_ISV] = n
            n += 1
            atol.append(cfg.atol_V * P[K_WN])
            scale.append(P[K_WN])
    if L[L_DROOP] == 1:
        L[L_ID] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e4)
        extra[L_ID] = 0.0
    if tube is not None:
        c = g.speed_of_sound_m_per_s
        L[L_ITP] = n
        L[L_ITQ] = n + tube.segments
        n += 2 * tube.segments
        atol += [cfg.atol_Pa] * tube.segments + [cfg.atol_Pa * tube.area_m2 / c] * tube.segments
        scale += [1e5] * tube.segments + [1e5 * tube.area_m2 / c] * tube.segments
        if tube.unsteady_friction > 0:  # the links' shear states: velocities, m/s
            L[L_ITY] = n
            n += 5 * tube.segments
            rho_c = rig.atmospheric_pressure_Pa / (g.specific_gas_constant_J_per_kg_K
                                                 * g.temperature_K) * c
            atol += [cfg.atol_Pa / rho_c] * (5 * tube.segments)
            scale += [1e5 / rho_c] * (5 * tube.segments)
    if P[K_HY_B] > 0:
        L[L_IH] = n
        n += 1
        atol.append(cfg.atol_V)
        scale.append(1.0)
    if P[K_SI_V] > 0:  # the silencer body's pressure, from the atmosphere
        L[L_IM] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
        extra[L_IM] = rig.atmospheric_pressure_Pa
    if P[K_CW_C] > 0:  # the creeping wall's volume, m^3: atol_Pa's share of the chamber
        L[L_IC] = n
        n += 1
        atol.append(cfg.atol_Pa * vmin / 1e6)
        scale.append(vmin)
    if P[K_MO_N] > 0:  # the throttle's fitting pressure
        L[L_IF] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
    if P[K_SH_A] > 0:  # the supply hose's pressure, from the regulator's at the start
        L[L_IHS] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
        extra[L_IHS] = P[K_PNOM] + P[K_GAIN] * (float(inputs.supply_pressure_Pa[0]) - P[K_PNOM])
    if P[K_WC_K] > 0:  # the coil's heat, from cold
        L[L_IW] = n
        n += 1
        atol.append(cfg.atol_V)
        scale.append(1.0)
        extra[L_IW] = 0.0
    if P[K_PB_K] > 0:  # the other chamber's pressure, from the atmosphere
        L[L_IB] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
        extra[L_IB] = rig.atmospheric_pressure_Pa
    if P[K_QE_A] > 0:  # the QEV's line pressure
        L[L_IQ] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
    if P[K_BF_C] > 0:  # the friction-held wall's gauge pressure, Pa
        L[L_IBF] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
    if P[K_BW_Z] > 0:  # the Bouc-Wen wall's hysteretic part z, Pa (starts at 0)
        L[L_IBW] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
    if P[K_LW_C] > 0:  # a loaded wall's give (m^3) and its rate (m^3/s): at rest
        L[L_ILW] = n
        n += 2
        v_scale = P[K_LW_C] * 1e5
        atol += [cfg.atol_Pa * P[K_LW_C], cfg.atol_Pa * P[K_LW_C] * P[K_LW_W]]
        scale += [v_scale, v_scale * P[K_LW_W]]
    if P[K_PF_K] > 0:  # the pilot chamber's gauge pressure, Pa
        L[L_IPF] = n
        n += 1
        atol.append(cfg.atol_Pa)
        scale.append(1e5)
    L[L_N] = n
    return _Setup(P, L, extra, np.array(atol), np.array(scale),
                  float(sl[SLOT_INDEX["command_delay_s"]]), stiction)


def _spline_rows(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """C2 cubic spline through the samples: rows ``(c0, c1, c2, c3)`` per interval."""
    if np.all(v == v[0]):
        rows = np.zeros((t.size - 1, 4))
        rows[:, 0] = v[0]
        return rows
    c = CubicSpline(t, v).c  # (4, N - 1), highest power first
    return np.ascontiguousarray(c[::-1].T)


def _initial_state(su: _Setup, p0: float, u0: float) -> np.ndarray:
    L = su.L
    y = np.zeros(int(L[L_N]))
    y[0] = p0
    for idx, v in su.y0_extra.items():
        y[L[idx]] = v
    if L[L_SPOOL] > 0:
        y[L[L_IS]] = u0  # at rest at the first (delayed) command
    if L[L_IH] >= 0:
        y[L[L_IH]] = u0  # the play's output starts at the first command
    if L[L_IF] >= 0:
        y[L[L_IF]] = p0  # the throttle's fitting at the chamber's pressure
    if L[L_IQ] >= 0:
        y[L[L_IQ]] = p0  # the QEV's line at the chamber's pressure
    if L[L_IBF] >= 0:
        y[L[L_IBF]] = p0 - su.P[K_PATM]  # the wall stuck where the pressure starts
    if L[L_IC] >= 0:  # the creeping wall in equilibrium with the initial pressure
        y[L[L_IC]] = su.P[K_CW_C] * (p0 - su.P[K_PATM])
    if L[L_ILW] >= 0:  # the loaded wall at rest at its static give (its rate 0)
        y[L[L_ILW]] = su.P[K_LW_C] * (p0 - su.P[K_PATM])
    if L[L_IPF] >= 0:  # the pilot at the chamber's gauge pressure
        y[L[L_IPF]] = p0 - su.P[K_PATM]
    if L[L_NSEG] > 0:
        y[L[L_ITP]:L[L_ITP] + L[L_NSEG]] = p0  # tube at rest at the chamber's pressure
    return y


#: The forms that decide when (and with what value) the valve takes the command: each
#: has ``switches(time_s, command, shared_delay_s)`` and ``acts`` (False at zero strength).
_DRIVERS = (ReleaseDelay, PwmValve, ZohDriver, ArmatureDeadTime)


def simulate_plant(params: Mapping[str, float], forms: Sequence[PlantForm], inputs: Inputs,
                   rig: Rig, initial_pressure_Pa: float, config: PlantConfig,
                   effects: Sequence[Effect] = ()) -> PlantTrajectory:
    """Simulate the high-fidelity plant on ``inputs``.

    Parameters
    ----------
    params : mapping
        Parameters of ``Model(effects)``: the thin-port base (Gompertz maps, chamber
        ``dead_volume_m3`` *without* any AcousticTube, whose cells hold its volume) and
        the catalogue effects planted beside the forms.
    forms : sequence of PlantForm
        Realistic effect forms (:mod:`pneubayes.bench.forms`), each catalogue effect at
        most once among forms and ``effects``.
    inputs : Inputs
        Command (held), position and upstream supply (linear between samples).
    rig : Rig
        Bore, atmosphere, nominal supply and gas.
    initial_pressure_Pa : float
        Absolute chamber (and tube) pressure at ``inputs.time_s[0]``, Pa.
    config : PlantConfig
        Solver and tolerances.
    effects : sequence of Effect
        Catalogue effects planted as the model defines them.
    """
    if not isinstance(config, PlantConfig):
        raise TypeError(f"config must be a PlantConfig (e.g. PlantConfig.reference()), got "
                        f"{type(config).__name__}")
    if not isinstance(inputs, Inputs):
        raise TypeError(f"inputs must be pneubayes.simulation.Inputs, got "
                        f"{type(inputs).__name__}")
    if not isinstance(rig, Rig):
        raise TypeError(f"rig must be a pneubayes.rig.Rig, got {type(rig).__name__}")
    p0 = float(initial_pressure_Pa)
    if not (math.isfinite(p0) and p0 > 0):
        raise ValueError(f"initial_pressure_Pa must be finite and > 0 (absolute), got "
                         f"{initial_pressure_Pa!r}")
    effects = tuple(effects)
    forms = check_forms(forms, [e.name for e in effects])
    su = _setup(params, effects, forms, rig, inputs, config)
    t, u = inputs.time_s, inputs.command_V
    stiction = su.stiction or next((f for f in forms if isinstance(f, SpoolStiction)), None)
    if stiction is not None and stiction.breakaway_V > 0:  # the valve sees where it sticks
        u = np.asarray(stiction.targets(u), dtype=np.float64)
    xx, ss = _spline_rows(t, inputs.position_m), _spline_rows(t, inputs.supply_pressure_Pa)
    delay = su.delay_s
    drivers = [f for f in forms if isinstance(f, _DRIVERS)]
    if len(drivers) > 1:
        raise ValueError(f"plant: {[type(f).__name__ for f in drivers]} each decide when "
                         "the valve takes the command; plant one of them")
    release = drivers[0] if drivers else None
    if release is not None and release.acts:  # when the valve takes the command
        kw = {}
        if release.reads_supply:  # the supply where a change reaches the valve
            supply = np.asarray(inputs.supply_pressure_Pa, dtype=np.float64)
            kw["supply_gauge_at"] = lambda tau: float(
                np.interp(tau, t, supply)) - rig.atmospheric_pressure_Pa
        sw_t, sw_u = release.switches(t, u, delay, **kw)

        def command_at(tau):
            return float(sw_u[int(np.searchsorted(sw_t, tau, side="right")) - 1])

        cuts = sw_t[1:]
    else:
        shifted = t + delay

        def command_at(tau):
            return float(u[max(int(np.searchsorted(shifted, tau, side="right")) - 1, 0)])

        change = np.nonzero(np.diff(u) != 0)[0] + 1
        cuts = shifted[change]
    cuts = cuts[(cuts > t[0]) & (cuts < t[-1])]
    edges = np.unique(np.concatenate([[t[0]], cuts, [t[-1]]]))
    y = _initial_state(su, p0, command_at(t[0]))
    ys = np.empty((t.size, y.size))
    ys[0] = y
    P, L, scale = su.P, su.L, su.scale
    nfev = njev = 0
    start = time.perf_counter()
    for a, b in zip(edges[:-1], edges[1:]):
        cmd = command_at(a)
        i0 = int(np.searchsorted(t, a, side="right"))
        i1 = int(np.searchsorted(t, b, side="right"))  # samples i0..i1-1 lie in (a, b]
        t_eval = t[i0:i1]
        at_sample = t_eval.size > 0 and t_eval[-1] == b
        if not at_sample:
            t_eval = np.append(t_eval, b)

        def fun(tau, yy, cmd=cmd):
            return _rhs(tau, yy, cmd, P, L, t, xx, ss)

        def jac(tau, yy, cmd=cmd):
            return _jac(tau, yy, cmd, P, L, t, xx, ss, scale)

        sol = solve_ivp(fun, (a, b), y, method=config.method, t_eval=t_eval, jac=jac,
                        rtol=config.rtol, atol=su.atol, max_step=config.max_step_s)
        if sol.status != 0 or not np.all(np.isfinite(sol.y)):
            raise SimulationError(f"plant: {config.method} failed between t={a:.6f} s and "
                                  f"{b:.6f} s ({sol.message}); forms "
                                  f"{[type(f).__name__ for f in forms]}")
        nfev += sol.nfev
        njev += sol.njev
        got = sol.y.T
        ys[i0:i1] = got if at_sample else got[:-1]
        y = got[-1].copy()
    elapsed = time.perf_counter() - start
    held = np.array([command_at(tau) for tau in t])
    supply, inflow = _sensor_traces(t, ys, held, P, L, t, xx, ss)
    temp = ys[:, L[L_IT]].copy() if L[L_HEAT] > 0 else None
    return PlantTrajectory(t.copy(), ys[:, 0].copy(), supply, temp, config, forms,
                           {"nfev": int(nfev), "njev": int(njev), "spans": int(edges.size - 1),
                            "seconds": elapsed}, inflow)
