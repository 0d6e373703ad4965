"""The model's pressure rate at a *given* state, vectorised over samples.

The simulator integrates dp/dt along its own trajectory; discovery needs the model's
dp/dt at the *measured* pressure (the equation error of section VI-B) with inputs that
may be modified (a delayed or filtered command, a dead band, the measured supply), and
the sensor point (:mod:`pneubayes.simulation.measurement`) the jump of dp/dt where a
port switches. This
is eq. 5 with the port flows of eqs. 1-4 and 9, composed from the lowered slots of any
model (:mod:`pneubayes.effects.path`) -- except the temperature state of
``heat_transfer``, which needs a trajectory: here T is the supply temperature.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.effects.closure_features import (
    DEAD_TIME_FEATURES,
    FEATURE_BY_NAME,
    FEATURES,
    LOW_PASS_HISTORIES,
    evaluate_feature,
)
from pneubayes.effects.closure_histories import HeldCommand
from pneubayes.effects.closure_terms import combine_terms
from pneubayes.effects.path import CLOSURE_MAX_TERMS, TABLE_MAX_POINTS
from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.physics.orifice import flow_function
from pneubayes.physics.valve import gompertz_area, switching_areas
from pneubayes.rig import Rig
from pneubayes.simulation.layout import rig_constants
from pneubayes.simulation.restriction import node_pressures
from pneubayes.simulation.supply_restriction import supply_nodes

_PORT = ("offset_m2", "a_m2", "b", "c_per_V", "d_V")


def dead_band(spool_V, halfwidth_V, rounding_V):
    """``sign(s) phi(|s| - w)`` (paper Fig. 4), V: phi(z) = max(z, 0) for the hard dead
    band (``rounding_V`` r = 0); with r > 0 the corner ``|z| < r`` is rounded so that the
    slope phi' rises as the smoothstep ``3 t^2 - 2 t^3``, t = (z + r) / (2 r), and
    ``phi(z) = 2 r (t^3 - t^4 / 2)``: C2, equal to the hard band for ``|z| >= r``."""
    s = np.asarray(spool_V, dtype=np.float64)
    r = np.asarray(rounding_V, dtype=np.float64)
    z = np.abs(s) - halfwidth_V
    mag = np.maximum(z, 0.0)
    if np.any(r > 0.0):  # (broadcasts over slot rows: r may be an array)
        rr = np.where(r > 0.0, r, 1.0)
        t = np.clip((z + rr) / (2.0 * rr), 0.0, 1.0)
        mag = np.where((r > 0.0) & (np.abs(z) < r), 2.0 * rr * t**3 * (1.0 - 0.5 * t), mag)
    return np.sign(s) * mag


@dataclass(frozen=True)
class RateTerms:
    """dp/dt contributions, Pa/s, at each sample (arrays of one shape).

    ``inlet`` and ``exhaust`` are the valve ports' terms (attenuation included),
    ``leak`` the cylinder leak's, ``volume`` the -n p dV/dt / V term, ``closure`` an
    open-form closure's (effect ``closure``; zeros without one); ``total`` their sum.
    ``inlet_choked`` / ``exhaust_choked`` flag choked ports (eq. 2).
    """

    inlet: np.ndarray
    exhaust: np.ndarray
    leak: np.ndarray
    volume: np.ndarray
    closure: np.ndarray
    inlet_choked: np.ndarray
    exhaust_choked: np.ndarray

    @property
    def total(self) -> np.ndarray:
        return self.inlet + self.exhaust + self.leak + self.volume + self.closure


def _closure_feature_values(code, threshold, signals: dict) -> np.ndarray:
    """Feature values for feature codes ``code`` (slot values, which may differ per slot
    row) with hinge thresholds ``threshold`` on ``signals``."""
    code = np.asarray(code, dtype=np.float64)
    out = 0.0
    for c in np.unique(code):
        value = evaluate_feature(FEATURES[int(c)].name, signals, threshold)
        out = np.where(code == c, value, out)
    return out


def _reads_feature(slots: np.ndarray, name: str) -> bool:
    """Whether a live closure term reads feature ``name``."""
    code = float(FEATURE_BY_NAME[name].code)
    n = np.asarray(slots[S["closure_terms"]])
    return any(bool(np.any((k < n) & (np.asarray(slots[S[f"closure_feature_{s}_{k}"]])
                                      == code)))
               for k in range(CLOSURE_MAX_TERMS) for s in "ab")


def closure_mass_flow(slots: np.ndarray, signals: dict) -> np.ndarray:
    """An open-form closure's mass flow into the chamber, ``sum_k c_k F_a F_b`` (kg/s),
    from the lowered ``slots`` (slots ``closure_*``; ``slots`` may carry trailing
    dimensions that broadcast against the signals) on ``signals``
    (:data:`pneubayes.effects.closure_features.SIGNALS`); zeros without a closure."""
    sl = np.asarray(slots, dtype=np.float64)
    n = sl[S["closure_terms"]]
    terms = []
    for k in range(CLOSURE_MAX_TERMS):
        live = k < n
        if not np.any(live):
            break
        code_a = sl[S[f"closure_feature_a_{k}"]]
        code_b = sl[S[f"closure_feature_b_{k}"]]
        fa = _closure_feature_values(code_a, sl[S[f"closure_threshold_a_{k}"]], signals)
        fb = _closure_feature_values(code_b, sl[S[f"closure_threshold_b_{k}"]], signals)
        terms.append((np.where(live, sl[S[f"closure_coefficient_{k}"]], 0.0), code_a, fa,
                      code_b, fb))
    shape = np.broadcast_shapes(np.shape(signals["pressure_Pa"]), np.shape(n))
    return np.broadcast_to(combine_terms(terms), shape).copy() if terms else np.zeros(shape)


def port_pressure(slots: np.ndarray, rig: Rig, pressure_Pa, supply_Pa, inlet_area_m2,
                  exhaust_area_m2):
    """The pressure (Pa) the valve's ports see at chamber pressures ``pressure_Pa``: a
    port restriction's node in series where the slot row (or rows, broadcast as the
    other arguments) has one (:func:`pneubayes.simulation.restriction.node_pressures`),
    else the chamber's own."""
    k_fill = slots[S["restriction_fill_inverse_area_per_m2"]]
    k_vent = slots[S["restriction_vent_inverse_area_per_m2"]]
    if not (np.any(k_fill > 0.0) or np.any(k_vent > 0.0)):
        return pressure_Pa
    return node_pressures(pressure_Pa, supply_Pa, inlet_area_m2, exhaust_area_m2, k_fill,
                          k_vent, slots[S["restriction_crack_Pa"]], rig_constants(rig))


def port_laws(slots: np.ndarray) -> tuple:
    """The valve's ports' own flow law in a slot row (or rows): ``(inlet critical ratio,
    exhaust critical ratio, subsonic index)``, 0 for eq. 3's (effect ``critical_ratio``;
    :func:`pneubayes.physics.orifice.flow_function`'s arguments)."""
    return (slots[S["inlet_critical_ratio"]], slots[S["exhaust_critical_ratio"]],
            slots[S["port_subsonic_index"]])


def inlet_supply(slots: np.ndarray, rig: Rig, supply_Pa, port_Pa, inlet_area_m2):
    """The pressure (Pa) the valve's inlet is fed at: a supply restriction's node where
    the slot row (or rows, broadcast as the other arguments) has one
    (:func:`pneubayes.simulation.supply_restriction.supply_nodes`), else the supply;
    ``port_Pa`` the pressure the ports see (:func:`port_pressure`)."""
    k = slots[S["supply_restriction_inverse_area_per_m2"]]
    if not np.any(k > 0.0):
        return supply_Pa
    return supply_nodes(supply_Pa, port_Pa, inlet_area_m2, k, rig_constants(rig))


def port_areas(slots: np.ndarray, spool_V, exhaust_command=None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Inlet and exhaust areas (m^2) for one slot row at spool positions ``spool_V`` (in
    the command's unit): the dead band, the Gompertz maps (eq. 11) and a switching
    valve's opening, as the compiled simulator computes them. A separately commanded
    exhaust valve (slot ``exhaust_own_command``) reads ``exhaust_command`` instead."""
    sl = np.asarray(slots, dtype=np.float64)
    u = dead_band(spool_V, sl[S["deadband_halfwidth_V"]], sl[S["deadband_rounding_V"]])
    a_in = gompertz_area(u, *(sl[S[f"inlet_{k}"]] for k in _PORT))
    own = np.asarray(sl[S["exhaust_own_command"]]) != 0
    if np.any(own) and exhaust_command is None:
        raise ValueError("port_areas: the exhaust is a separate valve (slot "
                         "exhaust_own_command); give its exhaust_command")
    ue = np.zeros_like(u) if exhaust_command is None else np.asarray(exhaust_command, float)
    exhaust_u = np.where(own, ue, u)
    a_ex = gompertz_area(exhaust_u, *(sl[S[f"exhaust_{k}"]] for k in _PORT))
    s_in, _ = switching_areas(u, sl[S["inlet_open_area_m2"]], 0.0)
    # the one valve's exhaust opens as its inlet closes; a separate one with its command
    s_ex = sl[S["exhaust_open_area_m2"]] * np.where(own, np.clip(ue, 0.0, 1.0),
                                                    1.0 - np.clip(u, 0.0, 1.0))
    t_in, t_ex = tabulated_areas(sl, u)
    return a_in + s_in + t_in, a_ex + s_ex + t_ex


def _piecewise_linear(x, xs, ys, n, extend: bool):
    """``(y, dy/dx)`` of the tables ``(xs[k], ys[k])``, k < n, at ``x``: linear between
    points, beyond the ends flat (``extend`` False) or the end segments extended. ``xs``
    and ``ys`` are lists of slot values (each an array broadcasting against ``x``); ``n``
    may differ per slot row (rows with n < 2 give zeros)."""
    y = slope = np.zeros(np.broadcast_shapes(np.shape(x), np.shape(n)))
    for k in range(int(np.max(n)) - 1):
        live = k < n - 1
        width = np.where(live, xs[k + 1] - xs[k], 1.0)
        sk = np.where(live, (ys[k + 1] - ys[k]) / width, 0.0)
        first, last = k == 0, k == n - 2
        # segment k holds x above its start (or all below, the first) and at or below
        # its end (or all above, the last); flat ends hold y_0 below, y_n-1 above
        here = live & ((x > xs[k]) | first) & ((x <= xs[k + 1]) | last)
        xk = x if extend else np.clip(x, xs[k], xs[k + 1])
        y = np.where(here, ys[k] + sk * (xk - xs[k]), y)
        inside = (x > xs[k]) & (x < xs[k + 1])
        slope = np.where(here & (extend | inside), sk, slope)
    return y, slope


def tabulated_areas(slots: np.ndarray, u) -> tuple[np.ndarray, np.ndarray]:
    """A tabulated valve map's inlet and exhaust areas (m^2) at commands ``u`` (after the
    dead band; zeros without a table, slot ``table_points`` 0), linear between points
    and flat beyond the ends. ``slots`` may carry trailing dimensions that broadcast
    against ``u``."""
    sl = np.asarray(slots, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    n = sl[S["table_points"]]
    cmds = [sl[S[f"table_command_{k}"]] for k in range(TABLE_MAX_POINTS)]
    return tuple(_piecewise_linear(u, cmds, [sl[S[f"table_{port}_m2_{k}"]]
                                             for k in range(TABLE_MAX_POINTS)], n, False)[0]
                 for port in ("inlet", "exhaust"))


def tabulated_volume(slots: np.ndarray, pressure_Pa) -> tuple[np.ndarray, np.ndarray]:
    """A compliant chamber's tabulated volume change and its slope at ``pressure_Pa``:
    ``(dV m^3, dV/dp m^3/Pa)``, linear between points, the end segments extended; zeros
    without a table (slot ``volume_table_points`` 0). ``slots`` may carry trailing
    dimensions that broadcast against the pressure."""
    sl = np.asarray(slots, dtype=np.float64)
    return _piecewise_linear(
        np.asarray(pressure_Pa, dtype=np.float64),
        [sl[S[f"volume_table_pressure_Pa_{k}"]] for k in range(TABLE_MAX_POINTS)],
        [sl[S[f"volume_table_volume_m3_{k}"]] for k in range(TABLE_MAX_POINTS)],
        sl[S["volume_table_points"]], True)


def rate_terms(slots: np.ndarray, rig: Rig, pressure_Pa, spool_V, position_m,
               velocity_m_per_s, supply_measured_Pa, exhaust_command=None,
               command_direction=None, histories=None, time_s=None,
               include_closure: bool = True) -> RateTerms:
    """Eq. 5 at the given state for one slot row ``(N_SLOTS,)``.

    ``spool_V`` is the command after any delay and lag (the caller shifts or filters
    it); the dead band, Gompertz maps (eq. 11), supply weighting, attenuation and leaks
    come from ``slots``. Pressures absolute, Pa; position m; velocity m/s.
    ``exhaust_command`` drives a separately commanded exhaust valve. An open-form
    closure's features read the spool ``spool_V``, the port flows ``a f`` before the
    attenuation, the volume after compliance and ``velocity_m_per_s`` times the bore's
    area as the volume rate (:func:`closure_mass_flow`), and ``command_direction``
    (+1, -1 or 0: the delayed command's last change,
    :func:`~pneubayes.effects.closure_histories.held_direction`), which must be given
    when a term reads it. A low-pass feature (``pressure_relaxation``,
    ``net_flow_lag``, ``command_lag``) reads its signal's history: ``histories`` maps
    ``"pressure_history"`` / ``"net_flow_history"`` / ``"spool_history"`` to
    :class:`~pneubayes.effects.closure_histories.SignalHistory` objects along the
    evaluation points (held as given: the slope in ``pressure_Pa`` is the instant's);
    without one, ``time_s`` (the points' times, s) low-passes the given pressure and
    the flows computed here along them. A dead-time feature (``*_late_fall``,
    ``*_late_rise``) reads ``histories["held_command"]`` (a
    :class:`~pneubayes.effects.closure_histories.HeldCommand`); without one, ``time_s``
    holds ``spool_V`` between the points as the command.
    ``include_closure=False`` leaves a closure's term at zero (for callers that read
    only the ports' terms). Beside a restriction at the port (``port_restriction``) the
    ports pass their flows at its node's pressure
    (:func:`pneubayes.simulation.restriction.node_pressures`), the inlet at a supply
    restriction's node (:func:`inlet_supply`); the leak and the closure's flows read as
    the simulator reads them. A supply tank
    (slot ``tank_volume_m3``) needs a trajectory: here the supply is the given one; so
    does a second compartment's pressure (slot ``lung_volume_m3``): its flow is left out
    here (the simulator carries it).
    """
    sl = np.asarray(slots, dtype=np.float64)
    g = rig.gas
    kappa = g.heat_capacity_ratio
    rs_t = g.specific_gas_constant_J_per_kg_K * g.temperature_K
    p_atm = rig.atmospheric_pressure_Pa
    p = np.asarray(pressure_Pa, dtype=np.float64)
    a_in, a_ex = port_areas(sl, spool_V, exhaust_command)
    p_nom = rig.supply_pressure_Pa
    p_sup = p_nom + sl[S["supply_gain"]] * (np.asarray(supply_measured_Pa) - p_nom)
    atten = np.exp(-sl[S["flow_attenuation_Pa"]] / p)
    vol = sl[S["volume_m3"]] + rig.bore_area_m2 * np.asarray(position_m, dtype=np.float64)
    vdot = rig.bore_area_m2 * np.asarray(velocity_m_per_s, dtype=np.float64)
    dvol, compl = tabulated_volume(sl, p)  # a tabulated V(p) (0: none)
    compl = compl + sl[S["compliance_m3_per_Pa"]]
    vol = vol + sl[S["compliance_m3_per_Pa"]] * (p - p_atm) + dvol  # a compliant chamber
    denom = vol + kappa * p * compl
    scale = kappa * rs_t / denom
    x = port_pressure(sl, rig, p, p_sup, a_in, a_ex)
    b_in, b_ex, m_sub = port_laws(sl)
    f_in = flow_function(inlet_supply(sl, rig, p_sup, x, a_in), x, g, b_in, m_sub)
    f_ex = flow_function(x, p_atm, g, b_ex, m_sub)
    q_in, q_ex = a_in * f_in, a_ex * f_ex
    inlet = scale * atten * q_in
    exhaust = -scale * atten * q_ex
    leak = -scale * (sl[S["leak_orifice_area_m2"]] * flow_function(p, p_atm, g)
                     + np.maximum(sl[S["leak_laminar_kg_per_s_Pa2"]]
                                  + sl[S["leak_laminar_gradient_kg_per_s_Pa2_m"]]
                                  * np.asarray(position_m, dtype=np.float64), 0.0)
                     * (p * p - p_atm * p_atm))
    volume = -kappa * p * vdot / denom
    closure = np.zeros(np.broadcast_shapes(np.shape(p), np.shape(sl[S["closure_terms"]])))
    if include_closure and np.any(sl[S["closure_terms"]] > 0):
        if command_direction is None and _reads_feature(sl, "command_direction"):
            raise ValueError("rate_terms: the closure reads the command's direction; give "
                             "command_direction (closure_histories.held_direction of the "
                             "command at the evaluation times)")
        histories = dict(histories or {})
        for name, key in LOW_PASS_HISTORIES.items():
            if key not in histories and time_s is None and _reads_feature(sl, name):
                raise ValueError(f"rate_terms: the closure reads feature {name!r}, a "
                                 f"low-pass; give histories[{key!r}] (a SignalHistory "
                                 "along the evaluation points) or time_s")
        if "held_command" not in histories and any(_reads_feature(sl, name)
                                                   for name in DEAD_TIME_FEATURES):
            if time_s is None:
                raise ValueError("rate_terms: the closure reads a dead-time feature; give "
                                 "histories['held_command'] (a HeldCommand) or time_s")
            histories["held_command"] = HeldCommand(
                time_s, time_s, spool_V, 0.0, None,
                lambda u: port_areas(sl, u, exhaust_command))
        signals = {"pressure_Pa": p, "supply_pressure_Pa": p_sup,
                   "atmospheric_pressure_Pa": p_atm, "spool": np.asarray(spool_V, float),
                   "inlet_area_m2": a_in, "exhaust_area_m2": a_ex,
                   "inlet_flow_kg_per_s": q_in, "exhaust_flow_kg_per_s": q_ex,
                   "inlet_flux_kg_per_s_m2": f_in, "exhaust_flux_kg_per_s_m2": f_ex,
                   "volume_m3": vol, "volume_rate_m3_per_s": vdot,
                   "command_direction": (0.0 if command_direction is None
                                         else np.asarray(command_direction, float)),
                   **histories}
        if time_s is not None:
            signals["time_s"] = np.asarray(time_s, dtype=np.float64)
        closure = scale * closure_mass_flow(sl, signals)
    crit = (2.0 / (kappa + 1.0)) ** (kappa / (kappa - 1.0))
    return RateTerms(inlet, exhaust, leak, volume, closure,
                     inlet_choked=x < crit * p_sup, exhaust_choked=p_atm < crit * x)
