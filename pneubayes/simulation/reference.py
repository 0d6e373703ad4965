"""Independent reference: the same model integrated by scipy's ``solve_ivp``.

Used by the tests (accuracy, step halving) and the benchmark (speed baseline). It shares
only the lowered slots and some vectorised physics functions with the compiled
integrator. The orifice law (eqs. 2-3), the Gompertz map (eq. 11) and the dead band are
written out again here as scalar formulas; the integration, input handling, the spool
(an ODE state here, closed form there) and a sensor lag's reading (ODE states here,
stepped exactly for a linear pressure there) are written separately. An open-form
closure (effect ``closure``) is evaluated by
:func:`pneubayes.effects.closure_features.evaluate_feature`, not by the compiled
features; a low-pass feature's state (``p_bar``, ``q_bar``) is an ODE state here (at
rest at the start), stepped by splitting there. Slow: thousands of Python calls per
second.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from pneubayes.effects.closure_features import (
    FEATURE_BY_NAME,
    FEATURES,
    LOW_PASS_HISTORIES,
    evaluate_feature,
)
from pneubayes.effects.closure_histories import command_direction
from pneubayes.effects.closure_terms import PORT_FACTOR_LIMITS
from pneubayes.effects.path import JET_FLOW_REF_KG_PER_S, VOLUME_PLAY_COMPLIANCE_SLOTS
from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.model import Model
from pneubayes.physics.cylinder import wall_area_m2
from pneubayes.physics.tube import churchill_fre
from pneubayes.rig import Rig
from pneubayes.simulation.drive import Inputs
from pneubayes.simulation.reading_hinge import (
    hinged_reading,
    hinges_readable,
    unhinged_reading,
)


def _flow(p_up, p_down, alpha, beta, theta, kappa, b_crit=0.0, m_sub=0.0):
    """Eqs. 2-3 as printed (reverse flow: the roles swap, NOTES.md), kg/(s m^2); with a
    port's own critical ratio ``b_crit`` > 0, choked below it and eq. 3's subsonic
    curve stretched over ``[b_crit, 1]``, its share of the choked flow raised to ``2
    m_sub`` (``pneubayes.effects.critical_ratio``)."""
    if p_up < p_down:
        return -_flow(p_down, p_up, alpha, beta, theta, kappa, b_crit, m_sub)
    r = p_down / p_up
    if b_crit > 0.0:
        if r < b_crit:
            return beta * p_up
        # where r sits between b_crit and 1, at the same share between 1/theta and 1
        r = 1.0 - (1.0 - r) * (1.0 - 1.0 / theta) / (1.0 - b_crit)
        g = r ** (2.0 / kappa) - r ** ((kappa + 1.0) / kappa)
        share = alpha * math.sqrt(max(g, 0.0)) / beta  # of the choked flow
        return beta * p_up * share ** (2.0 * (m_sub or 0.5))
    if p_up > theta * p_down:  # choked
        return beta * p_up
    g = r ** (2.0 / kappa) - r ** ((kappa + 1.0) / kappa)
    return alpha * p_up * math.sqrt(g) if g > 0.0 else 0.0


def _restriction_area(drop, k_own, k_other, crack):
    """A restricted direction's area (m^2) at the forward drop ``drop`` (Pa): ``1 /
    k_own``, or where a check valve cracking at ``crack`` passes the wider direction
    beside the narrower one's needle, the needle's below ``crack``, its own above
    ``2 crack`` and a smoothstep between (an unrestricted direction: 1e-3 m^2)."""
    if crack <= 0 or not k_own < k_other:
        return 1.0 / k_own
    wide, needle = (1.0 / k_own if k_own > 0 else 1e-3), 1.0 / k_other
    z = min(max(drop / crack - 1.0, 0.0), 1.0)
    return needle + (wide - needle) * (3.0 * z**2 - 2.0 * z**3)


def _node_pressure(p, p_sup, a_in, a_ex, k_fill, k_vent, crack, law, p_atm):
    """The pressure between the valve's ports and a restriction in series at the port
    (inverse areas ``k_fill`` into, ``k_vent`` out of the chamber; its check valve's
    cracking drop ``crack``, Pa): the root of the node's mass balance by Brent's
    method."""
    def surplus(x):
        area = 0.0 if x == p else _restriction_area(abs(x - p), *own)
        return (a_in * _flow(p_sup, x, *law) - a_ex * _flow(x, p_atm, *law)
                - area * _flow(x, p, *law))

    own = (k_fill, k_vent, crack)
    h0 = surplus(p)
    if h0 < 0:
        own = (k_vent, k_fill, crack)
    if h0 == 0.0 or not (own[0] > 0 or (crack > 0 and own[1] > 0)):
        return p
    lo, hi = (p, max(p_sup, p_atm, p)) if h0 > 0 else (min(p_sup, p_atm, p), p)
    return brentq(surplus, lo, hi, xtol=1e-9, rtol=4 * np.finfo(float).eps)


def _supply_node(p_sup, x, a_in, k, law):
    """The pressure between a restriction of inverse area ``k`` upstream of the valve's
    inlet and the inlet (area ``a_in``, its port at ``x``): the root of the node's mass
    balance by Brent's method (``p_sup`` where nothing flows)."""
    if not (k > 0 and a_in > 0) or p_sup == x:
        return p_sup

    def surplus(n):
        return _flow(p_sup, n, *law) / k - a_in * _flow(n, x, *law)

    return brentq(surplus, min(p_sup, x), max(p_sup, x), xtol=1e-9,
                  rtol=4 * np.finfo(float).eps)


def _gompertz(u, offset, a, b, c, d):
    """Eq. 11, m^2."""
    return offset + a * math.exp(-b * math.exp(-c * (u + d)))


def _switching(u, inlet_open, exhaust_open):
    """An on/off valve's port areas at opening u (clipped to [0, 1]), m^2."""
    f = min(max(u, 0.0), 1.0)
    return inlet_open * f, exhaust_open * (1.0 - f)


def _dead_band(s, halfwidth, rounding):
    """sign(s) phi(|s| - w), the corner rounded by a smoothstep slope over |z| < r."""
    z = abs(s) - halfwidth
    mag = max(z, 0.0)
    if rounding > 0.0 and abs(z) < rounding:
        t = (z + rounding) / (2.0 * rounding)
        mag = 2.0 * rounding * t**3 * (1.0 - 0.5 * t)
    return math.copysign(mag, s) if s != 0.0 else 0.0


def _closure_flow(terms, q_in: float, q_ex: float) -> tuple[float, float]:
    """A closure's mass flow into the chamber and the part of it that leaves at the
    chamber's temperature (kg/s each, the second an outflow) from its terms ``(c,
    name_a, F_a, name_b, F_b)`` at one state, the valve's port flows ``q_in`` (in) and
    ``q_ex`` (out): a term that reads a port's flow (its first) scales that port, the
    port's factor clipped so its flow does not reverse, the change carrying the port's
    enthalpy (``net_flow``'s both); any other adds ``c F_a F_b``, an outflow when
    negative."""
    free, factor, flow = 0.0, {}, {}
    for c, name_a, fa, name_b, fb in terms:
        if name_a in PORT_FACTOR_LIMITS:
            factor[name_a], flow[name_a] = factor.get(name_a, 0.0) + c * fb, fa
        elif name_b in PORT_FACTOR_LIMITS:
            factor[name_b], flow[name_b] = factor.get(name_b, 0.0) + c * fa, fb
        else:
            free += c * fa * fb
    out = max(-free, 0.0)
    # each port's outflow that its factor scales: a reversed inlet, the exhaust, both
    leaving = {"inlet_flow": max(-q_in, 0.0), "exhaust_flow": max(q_ex, 0.0),
               "net_flow": max(-q_in, 0.0) + max(q_ex, 0.0)}
    for name, s in factor.items():
        lo, hi = PORT_FACTOR_LIMITS[name]
        s = min(max(s, lo), hi)
        free += flow[name] * s
        out += (-1.0 if name == "exhaust_flow" else 1.0) * leaving[name] * s
    return free, out


def low_passes(sl) -> list[tuple[float, float]]:
    """The distinct ``(feature code, time constant s)`` of a slot row's live low-pass
    features (``pressure_relaxation``, ``net_flow_lag``, ``command_lag``), in order of
    appearance."""
    # every command lag (and its one-way parts) low-passes the spool: one state per time
    # constant, under command_lag's code
    state = {float(FEATURE_BY_NAME[name].code): float(FEATURE_BY_NAME[
        "command_lag" if key == "spool_history" else name].code)
        for name, key in LOW_PASS_HISTORIES.items()}
    out: list[tuple[float, float]] = []
    for k in range(int(sl[S["closure_terms"]])):
        for side in "ab":
            code = float(sl[S[f"closure_feature_{side}_{k}"]])
            if code not in state:
                continue
            entry = (state[code], float(sl[S[f"closure_threshold_{side}_{k}"]]))
            if entry not in out:
                out.append(entry)
    return out


class _HeldAt:
    """A dead-time feature's area changes over one hold interval (m^2), for
    evaluate_feature: ``{(port, late, dead time s): change}``."""

    def __init__(self, changes):
        self.changes = changes

    def area_change(self, dead_time_s, port, late):
        return self.changes[(port, late, float(dead_time_s))]


def dead_times(sl) -> list[float]:
    """The distinct dead times (s) of a slot row's live dead-time features."""
    out: list[float] = []
    for k in range(int(sl[S["closure_terms"]])):
        for side in "ab":
            if FEATURES[int(sl[S[f"closure_feature_{side}_{k}"]])].dead_time:
                d = float(sl[S[f"closure_threshold_{side}_{k}"]])
                if d not in out:
                    out.append(d)
    return out


def _rhs_factory(sl, rig: Rig, cmd, xa, vdot, ta, seg, sa, sb, cmd_ex=0.0, cdir=0.0,
                 extremes=None):
    g = rig.gas
    kappa, rs, t_s = g.heat_capacity_ratio, g.specific_gas_constant_J_per_kg_K, g.temperature_K
    p_atm = rig.atmospheric_pressure_Pa
    law = (g.alpha_s_per_m, g.beta_s_per_m, g.theta, kappa)
    ins = [sl[S[k]] for k in ("inlet_offset_m2", "inlet_a_m2", "inlet_b", "inlet_c_per_V",
                              "inlet_d_V")]
    exs = [sl[S[k]] for k in ("exhaust_offset_m2", "exhaust_a_m2", "exhaust_b",
                              "exhaust_c_per_V", "exhaust_d_V")]
    tau_s, dead = sl[S["spool_time_constant_s"]], sl[S["deadband_halfwidth_V"]]
    rate_s = sl[S["spool_rate_limit_V_per_s"]]
    tau_dn = sl[S["spool_fall_time_constant_s"]]  # the spool's fall, if its own
    rounding = sl[S["deadband_rounding_V"]]
    lag = sl[S["sensor_time_constant_s"]]  # the reading: the last state
    n_lag = sl[S["sensor_pressure_exponent"]]
    w_r, z_r = sl[S["sensor_natural_frequency_rad_per_s"]], sl[S["sensor_damping"]]
    heat = sl[S["heat_rate_per_s"]]
    h_wall = sl[S["heat_coefficient_W_per_m2_K"]]
    h_jet = sl[S["heat_jet_coefficient_W_per_m2_K"]]  # per g/s of inflow
    coup = sl[S["heat_coupling"]]
    wall_offset = sl[S["heat_wall_offset_K"]]  # the wall above the supply, K
    thermal = coup > 0
    if not thermal:
        heat = h_wall = h_jet = 0.0
    nseg = int(sl[S["line_segments"]]) if sl[S["line_length_m"]] > 0 else 0
    if nseg:
        dia, mu = sl[S["line_diameter_m"]], sl[S["line_viscosity_Pa_s"]]
        area = np.pi / 4 * dia**2
        dx = sl[S["line_length_m"]] / nseg
        v_line = area * sl[S["line_length_m"]]
    else:
        v_line = 0.0

    k_supply = sl[S["supply_restriction_inverse_area_per_m2"]]  # upstream of the inlet
    k_fill = sl[S["restriction_fill_inverse_area_per_m2"]]  # a port's restriction
    k_vent = sl[S["restriction_vent_inverse_area_per_m2"]]
    crack = sl[S["restriction_crack_Pa"]]
    own_ex = sl[S["exhaust_own_command"]] != 0
    tank_v = sl[S["tank_volume_m3"]]
    lung_v = sl[S["lung_volume_m3"]]
    i_tank = 3 + 2 * nseg  # a supply tank's pressure
    i_lung = i_tank + (1 if tank_v > 0 else 0)  # a second compartment's pressure
    i_read = i_lung + (1 if lung_v > 0 else 0)  # a lagged reading (and its rate)
    w_s, z_s = sl[S["spool_natural_frequency_rad_per_s"]], sl[S["spool_damping"]]
    if w_s > 0:  # a second-order spool overrides the first-order lag
        tau_s = 0.0
    n_vt = int(sl[S["volume_table_points"]])
    vt_p = sl[S["volume_table_pressure_Pa_0"]:S["volume_table_pressure_Pa_0"] + n_vt]
    vt_v = sl[S["volume_table_volume_m3_0"]:S["volume_table_volume_m3_0"] + n_vt]
    n_tab = int(sl[S["table_points"]])
    tab_c, tab_i, tab_e = (sl[S[f"table_{k}_0"]:S[f"table_{k}_0"] + n_tab]
                           for k in ("command", "inlet_m2", "exhaust_m2"))
    # an open-form closure's terms: (coefficient, feature a, theta a, feature b, theta b)
    closure = [(sl[S[f"closure_coefficient_{k}"]],
                FEATURES[int(sl[S[f"closure_feature_a_{k}"]])].name,
                sl[S[f"closure_threshold_a_{k}"]],
                FEATURES[int(sl[S[f"closure_feature_b_{k}"]])].name,
                sl[S[f"closure_threshold_b_{k}"]])
               for k in range(int(sl[S["closure_terms"]]))]
    # the low-pass features' states (p_bar, q_bar): one per (signal, time constant),
    # after every other state
    passes = low_passes(sl)
    n_read = (2 if w_r > 0 else 1) if (w_r > 0 or lag > 0) else 0
    i_relax = i_read + n_read + (1 if w_s > 0 else 0)
    code_p = float(FEATURE_BY_NAME["pressure_relaxation"].code)
    code_s = float(FEATURE_BY_NAME["command_lag"].code)

    def valve_areas(s):
        """The valve's port areas at spool ``s`` (a separate exhaust valve's: 0)."""
        ueff = _dead_band(float(s), dead, rounding)
        a_in = _gompertz(ueff, *ins)
        a_ex = 0.0 if own_ex else _gompertz(ueff, *exs)
        s_in, s_ex = _switching(ueff, sl[S["inlet_open_area_m2"]],
                                0.0 if own_ex else sl[S["exhaust_open_area_m2"]])
        if n_tab:  # a tabulated map, linear between its points
            s_in += np.interp(ueff, tab_c, tab_i)
            s_ex += 0.0 if own_ex else np.interp(ueff, tab_c, tab_e)
        return a_in + s_in, a_ex + s_ex

    # the dead-time features' area changes: each window's extreme command against cmd
    held_changes = {}
    for (late, d), ext in (extremes or {}).items():
        now, then = valve_areas(cmd), valve_areas(ext)
        held_changes[("inlet", late, d)] = then[0] - now[0]
        held_changes[("exhaust", late, d)] = then[1] - now[1]
    held_at = _HeldAt(held_changes)

    class _Held:  # a low-pass from the states, for evaluate_feature
        def __init__(self, y, code):
            self.y, self.code = y, code

        def relaxed(self, tau_s):
            return self.y[i_relax + passes.index((self.code, float(tau_s)))]

    def rhs(t, y, net_flow_only=False):
        p, temp, spool = y[:3]
        # the temperature the pressure feels (without a temperature state its row is
        # inert, and a stiff solver's trial values there must not reach the pressure)
        t_felt = t_s + coup * (temp - t_s) if thermal else t_s
        # a second-order spool's velocity: after the reading
        v_spool = y[i_read + n_read] if w_s > 0 else 0.0
        cells, flows_q = y[3:3 + nseg], y[3 + nseg:3 + 2 * nseg]
        p_valve = cells[0] if nseg else p
        s = spool if tau_s > 0 or tau_dn > 0 or w_s > 0 else cmd
        a_in, a_ex = valve_areas(s)
        if own_ex:  # a separate exhaust valve, on its own (undelayed) command
            a_ex = (_gompertz(cmd_ex, *exs)
                    + sl[S["exhaust_open_area_m2"]] * min(max(cmd_ex, 0.0), 1.0))
            if n_tab:
                a_ex += np.interp(_dead_band(float(s), dead, rounding), tab_c, tab_e)
        fr = (t - ta) / seg
        vol = (sl[S["volume_m3"]] - v_line
               + rig.bore_area_m2 * (xa + fr * vdot * seg / rig.bore_area_m2))
        psup = rig.supply_pressure_Pa + sl[S["supply_gain"]] * (
            sa + fr * (sb - sa) - rig.supply_pressure_Pa)
        if tank_v > 0:  # a supply tank: its pressure is the last state
            psup = y[i_tank]
        att = math.exp(-sl[S["flow_attenuation_Pa"]] / p)
        k_lam = max(sl[S["leak_laminar_kg_per_s_Pa2"]]
                    + sl[S["leak_laminar_gradient_kg_per_s_Pa2_m"]]
                    * (vol + v_line - sl[S["volume_m3"]]) / rig.bore_area_m2, 0.0)
        if (k_fill > 0 or k_vent > 0) and not nseg:  # the ports see the node's pressure
            p_valve = _node_pressure(p, psup, a_in, a_ex, k_fill, k_vent, crack, law, p_atm)
        # each mass flow into the chamber (kg/s, negative = out)
        p_in = _supply_node(psup, p_valve, a_in, k_supply, law)
        m_sub = sl[S["port_subsonic_index"]]
        f_in = f_in_raw = _flow(p_in, p_valve, *law, sl[S["inlet_critical_ratio"]], m_sub)
        f_out = f_out_raw = _flow(p_valve, p_atm, *law, sl[S["exhaust_critical_ratio"]],
                                  m_sub)
        net_raw = float(a_in * f_in_raw - a_ex * f_out_raw)  # (a flow lag's signal)
        if net_flow_only:
            return net_raw
        f_leak = _flow(p, p_atm, *law)
        if h_wall > 0 or h_jet > 0:  # orifice outflows at the chamber's temperature; an
            # acoustic line's gas is at the supply's temperature, and so its ports' gas
            if not nseg:
                f_in = f_in * (math.sqrt(t_s / t_felt) if f_in < 0 else 1.0)
                f_out = f_out * (math.sqrt(t_s / t_felt) if f_out > 0 else 1.0)
            f_leak = f_leak * (math.sqrt(t_s / t_felt) if f_leak > 0 else 1.0)
        port = [att * a_in * f_in, -att * a_ex * f_out]
        d_line = []
        if nseg:  # the ports feed the line's first cell; its last flow feeds the chamber
            c_cell = kappa * rs * t_s / (area * dx)
            q_prev, dcells, dq = sum(port), [], []
            for i in range(nseg):
                p_next = cells[i + 1] if i < nseg - 1 else p
                dcells.append(c_cell * (q_prev - flows_q[i]))
                rho = 0.5 * (cells[i] + p_next) / (rs * t_s)
                re = abs(flows_q[i]) * dia / (area * mu)
                link = dx if i < nseg - 1 else 0.5 * dx  # staggered: cell centre to chamber
                dq.append(area / link * (cells[i] - p_next)
                          - churchill_fre(re) * mu * flows_q[i] / (2 * rho * dia**2))
                q_prev = flows_q[i]
            port = [q_prev]
            d_line = dcells + dq
        flows = port + [-sl[S["leak_orifice_area_m2"]] * f_leak,
                        -k_lam * (p * p - p_atm * p_atm)]
        compl = sl[S["compliance_m3_per_Pa"]]  # V grows by C (p - P_atm) + dV(p)
        v_c = vol + compl * (p - p_atm)
        if n_vt:  # a tabulated V(p): np.interp inside, the end segments extended
            k = min(max(int(np.searchsorted(vt_p, p)) - 1, 0), n_vt - 2)
            slope = (vt_v[k + 1] - vt_v[k]) / (vt_p[k + 1] - vt_p[k])
            v_c, compl = v_c + vt_v[k] + slope * (p - vt_p[k]), compl + slope
        m_cl, out_cl = 0.0, 0.0
        if closure:  # its features: the port flows before attenuation and temperature
            signals = {"pressure_Pa": p, "supply_pressure_Pa": psup,
                       "atmospheric_pressure_Pa": p_atm, "spool": s,
                       "inlet_area_m2": a_in, "exhaust_area_m2": a_ex,
                       "inlet_flow_kg_per_s": a_in * f_in_raw,
                       "exhaust_flow_kg_per_s": a_ex * f_out_raw,
                       "inlet_flux_kg_per_s_m2": f_in_raw,
                       "exhaust_flux_kg_per_s_m2": f_out_raw, "volume_m3": v_c,
                       "volume_rate_m3_per_s": vdot, "command_direction": cdir,
                       "pressure_history": _Held(y, code_p),
                       "net_flow_history": _Held(y, float(FEATURE_BY_NAME["net_flow_lag"]
                                                          .code)),
                       "spool_history": _Held(y, code_s), "held_command": held_at}
            m_cl, out_cl = _closure_flow(
                [(c, fa, float(evaluate_feature(fa, signals, ta)), fb,
                  float(evaluate_feature(fb, signals, tb))) for c, fa, ta, fb, tb in closure],
                float(a_in * f_in_raw), float(a_ex * f_out_raw))
        m_lung = 0.0
        if lung_v > 0:  # laminar flow into the second compartment (its pressure: last)
            m_lung = sl[S["lung_conductance_kg_per_s_Pa2"]] * (p * p - y[i_lung] ** 2)
            flows.append(-m_lung)
        mdot = float(sum(flows)) + m_cl
        # enthalpy: inflow at the supply temperature, outflow at the chamber's as the
        # pressure feels it (T_s at coupling 0, where this is eq. 5)
        enthalpy = sum(rs * (t_s if q > 0 else t_felt) * q for q in map(float, flows))
        enthalpy += rs * (t_s * (m_cl + out_cl) - t_felt * out_cl)
        dp = kappa * (enthalpy - p * vdot) / (v_c + kappa * p * compl)
        dtemp = 0.0
        t_hot = t_s + coup * wall_offset  # the wall as the pressure feels it
        if heat > 0:
            dp = dp + p * heat * (t_hot - t_felt) / t_felt
        if h_wall > 0 or h_jet > 0:  # Q = h A_w (T_w - T), wall = end caps + barrel;
            # the forced form's h grows with the inflow
            h = h_wall + h_jet * max(float(port[0]), 0.0) / JET_FLOW_REF_KG_PER_S
            dp = dp + ((kappa - 1.0) * h * float(wall_area_m2(vol, rig.bore_area_m2))
                       * (t_hot - t_felt) / vol)
        if thermal:
            dtemp = temp * (dp / p + vdot / vol - rs * temp * mdot / (p * vol))
        tau_now = tau_dn if tau_dn > 0 and cmd < spool else tau_s
        dspool = (cmd - spool) / tau_now if tau_now > 0 else 0.0
        if rate_s > 0:  # a speed-limited first-order spool
            dspool = min(max(dspool, -rate_s), rate_s)
        d_spool_v = []
        if w_s > 0:
            dspool = v_spool
            d_spool_v = [float(w_s**2 * (cmd - spool) - 2 * z_s * w_s * v_spool)]
        d_tank = []
        if tank_v > 0:  # the tank loses what the inlet draws (polytropic, air at T_s)
            d_tank = [-kappa * rs * t_s * float(a_in * f_in_raw) / tank_v]
        if lung_v > 0:  # eq. 5 in the second, compliant compartment
            pl, cl = y[i_lung], sl[S["lung_compliance_m3_per_Pa"]]
            d_tank = [kappa * rs * t_s * m_lung / (lung_v + cl * (pl - p_atm) + kappa * pl * cl)]
        if w_r > 0:  # the reading and its rate: the last two states
            r, dr = y[i_read], y[i_read + 1]
            d_reading = [float(dr), float(w_r**2 * (p - r) - 2 * z_r * w_r * dr)]
        else:
            # (a pressure-dependent lag: tau (2 P_atm / (p + r))^n, n its exponent)
            tau_r = lag * (2 * p_atm / (p + y[i_read])) ** n_lag if lag > 0 else 0.0
            d_reading = [float(p - y[i_read]) / tau_r] if lag > 0 else []
        d_relax = [float((p if code == code_p else s if code == code_s else net_raw)
                         - y[i_relax + q]) / tau for q, (code, tau) in enumerate(passes)]
        return ([float(dp), float(dtemp), float(dspool)] + [float(d) for d in d_line]
                + d_tank + d_reading + d_spool_v + d_relax)

    return rhs


def _stuck(u, before, band, slip):
    """The commands a sticking valve sees (written apart from
    :func:`pneubayes.simulation.stiction.stuck_command`, which the tests check it
    against): it moves only when the command is a band away, to (1 - slip) band short."""
    out, s = [], float(before)
    for c in map(float, u):
        if c != s and abs(c - s) >= band:
            s = c - math.copysign((1.0 - slip) * band, c - s)
        out.append(s)
    return np.array(out)


def _refuse_moving_walls(sl) -> None:
    """Raise where a parameter set's chamber has a wall with a state of its own (a volume
    play, a loaded wall), which this reference does not solve."""
    if any(sl[S[name]] != 0 for name in VOLUME_PLAY_COMPLIANCE_SLOTS):
        raise ValueError("reference_simulate: a volume play (effect 'volume_play') has a "
                         "state that only moves at its band's edges, which this ODE "
                         "reference does not solve; its independent reference is the "
                         "plant's friction-held wall and Bouc-Wen wall "
                         "(pneubayes.bench.forms.BraidFriction, BoucWenWall; "
                         "tests/test_volume_play.py)")
    if sl[S["loaded_wall_compliance_m3_per_Pa"]] > 0:
        raise ValueError("reference_simulate: a loaded wall (effect 'loaded_wall') is two "
                         "more states, which this ODE reference does not carry; its "
                         "independent reference is the plant's loaded wall "
                         "(pneubayes.bench.forms.LoadedWall; tests/test_loaded_wall.py)")


def reference_simulate(model: Model, params, inputs: Inputs, rig: Rig,
                       initial_pressure_Pa: float, method: str = "Radau", rtol: float = 1e-10,
                       atol: float = 1e-6, return_stats: bool = False,
                       initial_rate_Pa_per_s: float = 0.0):
    """Simulate one parameter set with ``solve_ivp`` on every hold interval separately.

    Break points are the sample times, the delayed-command switch times and, for a
    closure's dead-time feature, where a changed command leaves its window; on each
    interval the command is constant and position and supply are linear, as in the
    compiled integrator (with a sensor lag on every channel, position and supply read
    ahead by its group delay, whose shifted sample times are break points too). A
    supply tank is one more state, integrated with the chamber
    (the compiled integrator couples it by splitting). A sensor lag's reading is the
    last state (a second-order lag's: the last two, the reading and its rate): it
    starts at ``initial_pressure_Pa`` (its rate at ``initial_rate_Pa_per_s``) and the
    chamber at it plus the lag's group delay times ``initial_rate_Pa_per_s``. Returns
    the pressures (the reading, with a sensor lag) ``(N,)`` in Pa (and the rhs count if
    asked). A miscalibrated sensor (effect ``sensor_calibration``) reads P_atm + g (p -
    P_atm) + o: ``initial_pressure_Pa`` and ``initial_rate_Pa_per_s`` are such readings,
    and so is every output. A reading closure's relaxations (effect
    ``reading_closure``) are ODE states that follow that reading from rest; a reading
    play's (effect ``reading_play``) follows it at the samples from rest; lags of the
    command (effect ``reading_command``) add to it, warm from before the first sample;
    hinges (effect ``reading_hinge``) read the whole of it last.
    """
    sl = model.lower(model.as_matrix(params), rig)[0]
    cal_g, curv = 1.0 + sl[S["reading_gain_error"]], sl[S["reading_curvature_Pa"]]
    # the sensor's zero at each sample, o + a t + b (1 - exp(-t / tau)), and its rate
    drift, warm, tau_w = (sl[S[k]] for k in ("reading_drift_Pa_per_s", "reading_warm_up_Pa",
                                              "reading_warm_up_time_constant_s"))
    t_on = np.maximum(inputs.time_s, 0.0)
    cal_o = sl[S["reading_offset_Pa"]] + drift * inputs.time_s + (
        warm * (1.0 - np.exp(-t_on / tau_w)) if warm != 0.0 else 0.0)
    zero_rate = drift + (warm / tau_w * np.exp(-t_on[0] / tau_w)
                         if warm != 0.0 and inputs.time_s[0] > 0.0 else 0.0)
    calibrated = np.any(cal_o != 0.0) or cal_g != 1.0 or curv != 0.0
    p_atm = rig.atmospheric_pressure_Pa
    # lags of the command's magnitude in the reading (effect reading_command), stepped
    # exactly under the held command; the rest of the reading starts r0 less them
    # the reading's hinges read last (effect reading_hinge): the rest starts at H^-1(r0)
    hinges = tuple(a[:1] for a in model.reading_hinges(params))
    initial_pressure_Pa, initial_rate_Pa_per_s = _unhinged_start(
        hinges, initial_pressure_Pa, initial_rate_Pa_per_s)
    commands = np.zeros(inputs.time_s.size)
    for c, tau in zip(*(a[0] for a in model.reading_commands(params))):
        before = inputs.command_before_start
        lag = abs(float(inputs.command_V[0] if before is None else before))
        for k in range(inputs.time_s.size):
            if k:
                a = math.exp(-(inputs.time_s[k] - inputs.time_s[k - 1]) / tau)
                lag = a * lag + (1.0 - a) * abs(float(inputs.command_V[k - 1]))
            commands[k] += c * lag
    initial_pressure_Pa = initial_pressure_Pa - commands[0]
    initial_reading = initial_pressure_Pa
    if calibrated:  # the reading's start -> the chamber's (r = P_atm + g y + k y^2 + o)
        rr = initial_pressure_Pa - p_atm - cal_o[0]
        y0 = rr / cal_g if curv == 0.0 else (
            -cal_g + math.sqrt(cal_g**2 + 4.0 * curv / 1e10 * rr)) / (2.0 * curv / 1e10)
        initial_pressure_Pa = p_atm + y0
        initial_rate_Pa_per_s = (initial_rate_Pa_per_s - zero_rate) / (
            cal_g + 2.0 * curv / 1e10 * y0)
    if sl[S["closure_terms"]] > 0 and (sl[S["wave_length_m"]] > 0
                                        or sl[S["line_length_m"]] > 0):
        raise ValueError("reference_simulate: an open-form closure beside the tube's "
                         "acoustic line or wave line is not simulated (the compiled "
                         "simulator refuses it too)")
    if sl[S["wave_length_m"]] > 0:
        raise ValueError("reference_simulate: the transmission-line tube (tube_delay form "
                         "'wave') is a delay system this ODE reference does not solve; its "
                         "independent reference is the plant's finely lumped acoustic tube "
                         "(pneubayes.bench.plant, tests/test_wave.py)")
    _refuse_moving_walls(sl)
    if sl[S["command_clock_period_s"]] > 0 or sl[S["command_clock_latency_s"]] > 0:
        raise ValueError("reference_simulate: a driver's clock (effect 'command_clock') "
                         "switches the valve between samples, where this reference steps "
                         "from sample to sample; its independent reference is the bench "
                         "plant's driver (pneubayes.bench.forms.ZohDriver, PwmValve; "
                         "tests/test_command_clock.py)")
    flow_gains, flow_features = model.reading_flows(params)
    flow_gains = flow_gains[0]
    if len(flow_features):
        _check_flow_reading(model, params, sl, calibrated, inputs)
    t, u, x, ps = inputs.time_s, inputs.command_V, inputs.position_m, inputs.supply_pressure_Pa
    delay = sl[S["command_delay_s"]]
    nseg = int(sl[S["line_segments"]]) if sl[S["line_length_m"]] > 0 else 0
    # an acoustic line starts at rest at the chamber's pressure, the gas at its wall's
    # temperature (the supply's plus a heat exchange's wall offset)
    y = np.array([initial_pressure_Pa, rig.gas.temperature_K + (
        sl[S["heat_wall_offset_K"]] if sl[S["heat_coupling"]] > 0 else 0.0), 0.0]
                 + [initial_pressure_Pa] * nseg + [0.0] * nseg)
    atols = [atol, atol * 1e-4, 1e-9] + [atol] * nseg
    if nseg:
        area = np.pi / 4 * sl[S["line_diameter_m"]] ** 2
        atols += [atol * area / rig.gas.speed_of_sound_m_per_s] * nseg
    if sl[S["tank_volume_m3"]] > 0:  # a supply tank starts at the supply's first sample
        p_nom = rig.supply_pressure_Pa
        y = np.append(y, p_nom + sl[S["supply_gain"]] * (ps[0] - p_nom))
        atols.append(atol)
    if sl[S["lung_volume_m3"]] > 0:  # a second compartment starts with no flow into it
        y = np.append(y, initial_pressure_Pa)
        atols.append(atol)
    lag = sl[S["sensor_time_constant_s"]]
    w_r, z_r = sl[S["sensor_natural_frequency_rad_per_s"]], sl[S["sensor_damping"]]
    if w_r > 0:  # the reading and its rate start at the given ones, the chamber ahead
        y[0] = initial_pressure_Pa + 2 * z_r / w_r * initial_rate_Pa_per_s
        y = np.append(y, [initial_pressure_Pa, initial_rate_Pa_per_s])
        atols += [atol, atol * w_r]
    elif lag > 0:  # the reading starts at the given pressure, the chamber ahead of it
        lag *= (rig.atmospheric_pressure_Pa / initial_pressure_Pa) ** sl[
            S["sensor_pressure_exponent"]]
        y[0] = initial_pressure_Pa + lag * initial_rate_Pa_per_s
        y = np.append(y, initial_pressure_Pa)
        atols.append(atol)
    ue = inputs.exhaust_command if inputs.exhaust_command is not None else np.zeros(t.size)
    before = inputs.command_before_start
    if sl[S["stiction_band_V"]] > 0:  # a sticking valve sees where it stuck
        u = _stuck(u, u[0] if before is None else before, sl[S["stiction_band_V"]],
                   sl[S["stiction_slip_fraction"]])

    def held(jj):
        """The command held at delayed index jj (before the first sample: the declared
        pre-trigger command, else the first sample's)."""
        return u[0] if jj < 0 and before is None else (before if jj < 0 else u[jj])
    directions = command_direction(u, before)  # (a closure's direction feature)
    j = int(np.searchsorted(t + delay, t[0], side="right") - 1)
    y[2] = held(j)
    if len(flow_features):  # the chamber starts where it reads the start through them
        r0 = float(y[0])
        for _ in range(50):
            y[0] = r0 - _flow_terms(sl, rig, y[2:3], y[0:1], ps[:1], flow_gains,
                                    flow_features)[0]
    out = np.empty(t.size)
    read = (y.size - 2 if w_r > 0 else y.size - 1) if (w_r > 0 or lag > 0) else 0
    w_s = sl[S["spool_natural_frequency_rad_per_s"]]
    if w_s > 0:  # a second-order spool's velocity: at rest at the start
        y = np.append(y, 0.0)
        atols.append(1e-9 * w_s)
    passes = low_passes(sl)  # a low-pass: at rest (p_bar at the chamber's pressure, a
    for code, _ in passes:  # spool's s_bar at the spool, a flow's at the first flow, set
        lag = code == FEATURE_BY_NAME["command_lag"].code  # below)
        y = np.append(y, y[2] if lag else y[0])
        atols.append(1e-9 if lag else atol)
    i_pass = y.size - len(passes)
    flows_pending = any(code == FEATURE_BY_NAME["net_flow_lag"].code for code, _ in passes)
    out[0] = y[read]
    shifted = t + delay
    spools = np.empty(t.size)  # the spool (the held command without a lag) at the samples
    lagged = (sl[S["spool_time_constant_s"]] > 0 or sl[S["spool_fall_time_constant_s"]] > 0
              or w_s > 0)
    spools[0] = y[2]  # (the spool starts at the held command, lag or not)
    # a reading closure's p_bar_k: the last states, following the (calibrated) reading
    n_main = y.size
    gains, taus = (a[0] for a in model.reading_relaxations(params))
    y = np.append(y, [initial_reading] * gains.size)
    atols += [atol] * gains.size
    rel = np.empty((t.size, gains.size))
    rel[0] = y[n_main:]

    def reading(a, yy):
        r = yy[read]
        if not calibrated:
            return r
        o = sl[S["reading_offset_Pa"]] + drift * a + (
            warm * (1.0 - math.exp(-max(a, 0.0) / tau_w)) if warm != 0.0 else 0.0)
        return p_atm + cal_g * (r - p_atm) + curv * ((r - p_atm) / 1e5) ** 2 + o
    nfev = 0
    # position and supply are read at t + adv (a filter on every channel, effect
    # sensor_lag; a late reading: adv < 0), linear between their samples, held after the
    # last and before the first
    adv = sl[S["inputs_advance_s"]]
    early = t - adv

    def measured(a):
        """(x, dx/dt * bore area, segment start, its length, supply at both ends) of the
        input segment holding time ``a + adv``."""
        m = int(np.searchsorted(early, a, side="right") - 1)
        if m < 0:  # (read late, before the first sample: its values, held)
            return x[0], 0.0, a, 1.0, ps[0], ps[0]
        if m + 1 >= t.size:
            return x[-1], 0.0, a, 1.0, ps[-1], ps[-1]
        seg = t[m + 1] - t[m]
        return (x[m], rig.bore_area_m2 * (x[m + 1] - x[m]) / seg, early[m], seg, ps[m],
                ps[m + 1])
    # a dead-time window's extreme changes where a changed value leaves it
    changed = np.concatenate(([False], u[1:] != u[:-1]))
    windows = [(d, shifted + d) for d in dead_times(sl)]
    leaves = np.concatenate([w[changed] for _, w in windows]) if windows else np.zeros(0)

    def extremes(a, jj):
        """Each window's (highest, lowest) command at time ``a`` (``jj`` in force)."""
        out = {}
        for d, w in windows:
            vals = [held(i) for i in range(int(np.searchsorted(w, a, side="right") - 1),
                                           jj + 1)]
            out[("fall", d)], out[("rise", d)] = max(vals), min(vals)
        return out
    for k in range(t.size - 1):
        ta, tb = t[k], t[k + 1]
        cuts = np.union1d(np.union1d(shifted[(shifted > ta) & (shifted < tb)],
                                     early[(early > ta) & (early < tb)]),
                          leaves[(leaves > ta) & (leaves < tb)])
        edges = np.concatenate([[ta], cuts, [tb]])
        for a, b in zip(edges[:-1], edges[1:]):
            jj = int(np.searchsorted(shifted, a, side="right") - 1)
            cmd = held(jj)
            chamber = _rhs_factory(sl, rig, cmd, *measured(a), ue[k],
                                   directions[jj] if jj >= 0 else 0.0, extremes(a, jj))
            if flows_pending:  # a flow lag starts at rest at the first flow
                for q, (code, _) in enumerate(passes):
                    if code == FEATURE_BY_NAME["net_flow_lag"].code:
                        y[i_pass + q] = chamber(a, y[:n_main], net_flow_only=True)
                        atols[i_pass + q] = 1e-12
                flows_pending = False

            def rhs(tt, yy, chamber=chamber):
                return np.concatenate((chamber(tt, yy[:n_main]),
                                       (reading(tt, yy) - yy[n_main:]) / taus))
            sol = solve_ivp(rhs, (a, b), y, method=method, rtol=rtol,
                            atol=atols)
            if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
                raise RuntimeError(f"reference solver failed at t={a:.6f}: {sol.message}")
            nfev += sol.nfev
            y = sol.y[:, -1]
        out[k + 1] = y[read]
        rel[k + 1] = y[n_main:]
        spools[k + 1] = y[2] if lagged else held(
            int(np.searchsorted(shifted, tb, side="right") - 1))
    if calibrated:
        out = p_atm + cal_g * (out - p_atm) + curv * ((out - p_atm) / 1e5) ** 2 + cal_o
    read = out.copy()  # a reading play follows the samples (linear between them)
    out = out + (gains * (read[:, None] - rel)).sum(axis=1)
    for h, w in zip(*(a[0] for a in model.reading_plays(params))):
        y = read[0]
        for k, v in enumerate(read):
            y = min(v + w, max(v - w, y))
            out[k] += h * (v - y)
    out = out + commands
    if len(flow_features):  # terms of the port flows at the samples (effect reading_flow)
        out = out + _flow_terms(sl, rig, spools, out, ps, flow_gains, flow_features)
    if hinges[0].shape[1]:
        out = hinged_reading(out[None], *hinges)[0][0]
    return (out, nfev) if return_stats else out


def _unhinged_start(hinges, reading_Pa: float, rate_Pa_per_s: float) -> tuple[float, float]:
    """The start reading and its rate before the reading's hinges ``(gains, thresholds)``
    (each ``(1, J)``; as they are without one): ``H^-1(r0)`` and the rate over ``H'``."""
    if not hinges[0].shape[1]:
        return reading_Pa, rate_Pa_per_s
    if not hinges_readable(*hinges)[0]:
        raise ValueError("reference_simulate: the reading hinges' map is not increasing "
                         "everywhere (its reading does not tell the pressure)")
    z0 = float(unhinged_reading(np.full((1, 1), reading_Pa), *hinges)[0, 0])
    return z0, rate_Pa_per_s / float(hinged_reading(np.full((1, 1), z0), *hinges)[1][0, 0])


def _check_flow_reading(model, params, sl, calibrated, inputs) -> None:
    """Refuse what the reference does not combine with the port flows' reading terms."""
    other = (model.reading_relaxations(params)[0].size or model.reading_plays(params)[0].size
             or model.reading_commands(params)[0].size
             or model.reading_hinges(params)[0].size)
    if (calibrated or other or sl[S["sensor_time_constant_s"]] > 0
            or sl[S["sensor_natural_frequency_rad_per_s"]] > 0
            or sl[S["exhaust_own_command"]] != 0 or sl[S["table_points"]] > 0
            or sl[S["stiction_band_V"]] > 0 or inputs.command_before_start is not None):
        raise ValueError("reference_simulate: the port flows' terms in the reading (effect "
                         "'reading_flow') are solved here only on the chamber's own reading "
                         "(no sensor lag, calibration or other reading term), one valve's "
                         "maps, a free spool and no pre-trigger command")


def _flow_terms(sl, rig, spools, pressure, supply, gains, features) -> np.ndarray:
    """``sum_k c_k F_k`` (Pa) at the samples from the valve's port flows at the spools
    ``spools`` and chamber pressures ``pressure`` (eqs. 1-3 and 11, written here)."""
    g = rig.gas
    consts = (g.alpha_s_per_m, g.beta_s_per_m, g.theta, g.heat_capacity_ratio)
    ins = tuple(sl[S[f"inlet_{k}"]] for k in ("offset_m2", "a_m2", "b", "c_per_V", "d_V"))
    exs = tuple(sl[S[f"exhaust_{k}"]] for k in ("offset_m2", "a_m2", "b", "c_per_V", "d_V"))
    p_nom, gain = rig.supply_pressure_Pa, sl[S["supply_gain"]]
    out = np.zeros(pressure.size)
    for k, (s, p, p_meas) in enumerate(zip(spools, pressure, supply)):
        ueff = _dead_band(float(s), sl[S["deadband_halfwidth_V"]], sl[S["deadband_rounding_V"]])
        s_in, s_ex = _switching(ueff, sl[S["inlet_open_area_m2"]], sl[S["exhaust_open_area_m2"]])
        a_in, a_ex = _gompertz(ueff, *ins) + s_in, _gompertz(ueff, *exs) + s_ex
        m_sub = sl[S["port_subsonic_index"]]
        q_in = a_in * _flow(p_nom + gain * (p_meas - p_nom), p, *consts,
                            sl[S["inlet_critical_ratio"]], m_sub) * 1e3  # g/s
        q_ex = a_ex * _flow(p, rig.atmospheric_pressure_Pa, *consts,
                            sl[S["exhaust_critical_ratio"]], m_sub) * 1e3
        for c, name in zip(gains, features):
            q = q_in if name.startswith("inlet") else q_ex
            out[k] += c * (q * abs(q) if name.endswith("_square") else q)
    return out
