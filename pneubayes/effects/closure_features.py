"""The open-form closure's feature catalogue: physically typed signals on the chamber's
signal path that a found term is built from.

A *closure term* is an extra mass flow into the chamber (kg/s; mass is conserved, so it
enters eq. 5 exactly as a port flow does)::

    mdot_k = c_k * F_a(state) * F_b(state)

with ``F_b = one`` for a single feature (a pair's product otherwise). ``c_k`` carries
the unit ``kg/s / (unit_a unit_b)``. The hinge features carry a threshold ``theta``
(their own unit) that is fitted as a parameter too.

The same table is evaluated in two places that must agree to rounding: in numpy by
:func:`evaluate_features` (the residual search, :mod:`pneubayes.discovery.openform`), and
in the compiled simulator by the feature codes (:mod:`pneubayes.simulation.chamber`).
Some features have memory: ``command_direction``, the sign of the delayed command's
last change (the kernel tracks it as it walks the command); ``pressure_relaxation``,
the chamber pressure less its first-order low-pass ``p_bar`` with a fitted time
constant (the kernel carries ``p_bar`` as a state); ``net_flow_lag``, the net port
flow's low-pass less the flow itself; ``command_lag``, the spool position's low-pass
less the position (and its two one-way parts, ``command_lag_fall`` and
``command_lag_rise``); and the dead-time features, a port's area at the command's
extreme over the last theta s less its area now (a valve that follows the command's
falls, or rises, late). Their memories are in :mod:`pneubayes.effects.closure_histories`.
The relaxation is what a chamber shows when something behind it follows the pressure
with a lag: a side volume behind a narrow passage (``m = -k (p - p_bar)`` exactly, to
first order in the passage's law), a wall that creeps after a pressure step, gas that
trades heat with the wall.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.effects.closure_histories import SignalHistory

#: Scale of the area features: areas enter in mm^2 so coefficients are O(flow).
AREA_SCALE_M2 = 1e-6
#: Scale of the volume feature: volumes enter in cm^3.
VOLUME_SCALE_M3 = 1e-6


@dataclass(frozen=True)
class Feature:
    """One base feature of the closure library.

    ``code`` is its index in the compiled simulator's switch; ``unit`` the unit of its
    value; ``hinge`` whether it has a fitted parameter in the closure's threshold slot:
    a hinge's threshold (in ``unit``) or, with ``time_constant``, a relaxation's time
    constant (s); ``port`` whether it reads the valve's ports as the chamber sees them
    (their areas, flows or flow functions at the chamber's pressure), which a tube
    simulated as a line puts at its far end (:data:`PORT_FEATURES`); ``dead_time``
    whether its parameter is a dead time (s) over which it remembers the command
    (:class:`~pneubayes.effects.closure_histories.HeldCommand`)."""

    name: str
    code: int
    unit: str
    description: str
    hinge: bool = False
    time_constant: bool = False
    port: bool = False
    dead_time: bool = False

    @property
    def parameter_unit(self) -> str:
        """The unit of its fitted parameter (a threshold's, a time constant's or a dead
        time's)."""
        return "s" if self.time_constant or self.dead_time else self.unit


FEATURES: tuple[Feature, ...] = (
    Feature("one", 0, "1", "a constant"),
    Feature("pressure_ratio", 1, "-", "chamber pressure over atmospheric, p / P_atm"),
    Feature("supply_ratio", 2, "-", "supply pressure the valve sees over atmospheric, "
            "p_s / P_atm"),
    Feature("spool", 3, "command unit", "spool position s: the command after the model's "
            "delay and lag, before the dead band"),
    Feature("inlet_area", 4, "mm^2", "inlet port area a_in / 1e-6 m^2", port=True),
    Feature("exhaust_area", 5, "mm^2", "exhaust port area a_ex / 1e-6 m^2", port=True),
    Feature("inlet_flow", 6, "kg/s", "inlet port mass flow a_in f(p_s, p) (eqs. 1-3, "
            "before any attenuation; negative when the chamber blows back)", port=True),
    Feature("exhaust_flow", 7, "kg/s", "exhaust port mass flow a_ex f(p, P_atm) out of "
            "the chamber", port=True),
    Feature("volume", 8, "cm^3", "chamber volume V / 1e-6 m^3"),
    Feature("volume_rate", 9, "1/s", "relative volume rate dV/dt / V"),
    Feature("pressure_hinge", 10, "-", "max(0, p / P_atm - theta)", hinge=True),
    Feature("spool_hinge_up", 11, "command unit", "max(0, s - theta)", hinge=True),
    Feature("spool_hinge_down", 12, "command unit", "max(0, theta - s)", hinge=True),
    Feature("net_flow", 13, "kg/s", "net port mass flow into the chamber, inlet minus "
            "exhaust (what a compliance or a volume that follows the pressure scales)",
            port=True),
    Feature("pressure_hinge_down", 14, "-", "max(0, theta - p / P_atm)", hinge=True),
    Feature("command_direction", 15, "-", "the sign of the delayed command's last change: "
            "+1 after a rise, -1 after a fall, 0 before its first (a valve's memory of "
            "its direction: hysteresis, play)"),
    Feature("pressure_relaxation", 16, "-", "(p - p_bar) / P_atm, p_bar the chamber "
            "pressure low-passed with time constant theta (s): what follows the pressure "
            "with a lag (a side volume behind a passage, a creeping wall, heat exchange)",
            hinge=True, time_constant=True),
    Feature("volume_hinge_up", 17, "cm^3", "max(0, V / 1e-6 m^3 - theta): what starts as "
            "the piston passes a place (a port it uncovers, a scored barrel)", hinge=True),
    Feature("volume_hinge_down", 18, "cm^3", "max(0, theta - V / 1e-6 m^3): what acts near "
            "the end of the stroke (a cushion throttling the exhaust)", hinge=True),
    Feature("net_flow_lag", 19, "kg/s", "q_bar - (m_in - m_ex), q_bar the net port flow "
            "low-passed with time constant theta (s): with c = 1 the ports' flow reaches "
            "the chamber through a lag (a volume or a soft tube between valve and "
            "chamber; gas still arriving after the valve shuts)", hinge=True,
            time_constant=True, port=True),
    Feature("inlet_drop", 20, "-", "the pressure difference across the inlet over "
            "atmospheric, |p_s - p| / P_atm (a bypass or leak across the valve body "
            "scales with it)"),
    Feature("inlet_drop_hinge", 21, "-", "max(0, theta - |p_s - p| / P_atm): what acts "
            "when the difference across the inlet is small (a pilot stage or a check "
            "valve that needs a minimum difference to stay open)", hinge=True),
    Feature("inlet_flux", 22, "kg/(s mm^2)", "the flow one mm^2 of inlet area passes, "
            "f(p_s, p) x 1e-6 m^2 (eqs. 1-3): with a coefficient in mm^2 an extra inlet "
            "area (a bypass across the valve, a port that opens more or less than its "
            "map says), open even where the valve's own inlet is shut", port=True),
    Feature("exhaust_flux", 23, "kg/(s mm^2)", "the flow one mm^2 of exhaust area passes "
            "out of the chamber, f(p, P_atm) x 1e-6 m^2: with a (negative) coefficient "
            "in mm^2 an extra exhaust area", port=True),
    Feature("spool_null_hinge", 24, "command unit", "max(0, theta - |s|): what opens "
            "as the spool nears its null (theta >= 0; lands that do not quite close, an "
            "underlapped spool's leak to both ports)", hinge=True),
    Feature("net_flux", 25, "kg/(s mm^2)", "the net flow one mm^2 at both ports passes "
            "into the chamber, (f(p_s, p) - f(p, P_atm)) x 1e-6 m^2: with a coefficient in "
            "mm^2 an equal extra area at the inlet and the exhaust (a crossport leak "
            "through the valve, an underlap)", port=True),
    Feature("inlet_area_hinge", 26, "mm^2", "max(0, a_in / 1e-6 m^2 - theta): the inlet "
            "area beyond theta; times inlet_flux with c = -1 the inlet passes no more than "
            "theta (a fixed restriction in series that caps it: a fitting, a needle, a "
            "narrow tube)", hinge=True, port=True),
    Feature("exhaust_area_hinge", 27, "mm^2", "max(0, a_ex / 1e-6 m^2 - theta): the "
            "exhaust area beyond theta; times exhaust_flux with c = 1 the exhaust passes "
            "no more than theta (a silencer, a meter-out needle, a fitting)", hinge=True,
            port=True),
    Feature("command_lag", 28, "command unit", "s_bar - s, s_bar the spool position s "
            "low-passed with time constant theta (s): how far the command has moved that "
            "a slower part of the valve has not followed yet; times a port's flux, an area "
            "that lags the command (a pilot stage, a solenoid slower than its map)",
            hinge=True, time_constant=True),
    Feature("command_lag_fall", 29, "command unit", "max(0, s_bar - s), s_bar as in "
            "command_lag: the part of a fall that a slower part of the valve has not "
            "followed yet (times a port's flux, a port that closes or opens late after a "
            "fall only: a solenoid that releases slower than it pulls)", hinge=True,
            time_constant=True),
    Feature("command_lag_rise", 30, "command unit", "max(0, s - s_bar): the part of a rise "
            "not followed yet (a port that lags after a rise only)", hinge=True,
            time_constant=True),
    Feature("inlet_area_late_fall", 31, "mm^2", "(a_in(u_hi) - a_in(u)) / 1e-6 m^2, u the "
            "delayed command and u_hi its highest value over the last theta s, both "
            "through the valve's map (s): the inlet area a valve that follows the "
            "command's falls theta s late still shows; times inlet_flux with c = 1 (a "
            "solenoid that releases later than it pulls)", hinge=True, port=True,
            dead_time=True),
    Feature("exhaust_area_late_fall", 32, "mm^2", "(a_ex(u_hi) - a_ex(u)) / 1e-6 m^2: the "
            "exhaust area of a valve that follows falls theta s late less its own; times "
            "exhaust_flux with c = -1", hinge=True, port=True, dead_time=True),
    Feature("inlet_area_late_rise", 33, "mm^2", "(a_in(u_lo) - a_in(u)) / 1e-6 m^2, u_lo "
            "the command's lowest value over the last theta s: the inlet area of a valve "
            "that follows rises theta s late less its own; times inlet_flux with c = 1",
            hinge=True, port=True, dead_time=True),
    Feature("exhaust_area_late_rise", 34, "mm^2", "(a_ex(u_lo) - a_ex(u)) / 1e-6 m^2: the "
            "exhaust area of a valve that follows rises theta s late less its own; times "
            "exhaust_flux with c = -1", hinge=True, port=True, dead_time=True),
    Feature("volume_speed", 35, "cm^3/s", "the piston's swept-volume speed whichever its "
            "direction, |dV/dt| / 1e-6 m^3/s: what a seal or a wiper does in motion "
            "only (a film that lifts and leaks, friction's heat)"),
)

FEATURE_BY_NAME: dict[str, Feature] = {f.name: f for f in FEATURES}
#: The features that read the valve's ports at the chamber. Beside a tube simulated as
#: a line (``tube_delay`` form ``"wave"``) the valve sits at the tube's far end and the
#: chamber's port flow is the tube's: a closure there may read every other feature.
PORT_FEATURES: frozenset[str] = frozenset(f.name for f in FEATURES if f.port)


#: Names of the signals :func:`evaluate_features` reads (arrays of one shape): absolute
#: pressures in Pa, the spool in the command's unit, areas in m^2, port mass flows in
#: kg/s, the ports' flow functions f(p_s, p) and f(p, P_atm) (eqs. 1-3, the flow per unit
#: area) in kg/(s m^2), the volume in m^3 and its rate in m^3/s, the command's direction
#: (+1, -1 or 0; :func:`~pneubayes.effects.closure_histories.command_direction`).
SIGNALS = ("pressure_Pa", "supply_pressure_Pa", "atmospheric_pressure_Pa", "spool",
           "inlet_area_m2", "exhaust_area_m2", "inlet_flow_kg_per_s",
           "exhaust_flow_kg_per_s", "inlet_flux_kg_per_s_m2", "exhaust_flux_kg_per_s_m2",
           "volume_m3", "volume_rate_m3_per_s", "command_direction")
#: The low-pass features (``pressure_relaxation``, ``net_flow_lag``, ``command_lag``) read
#: their signal's history too: ``"pressure_history"`` / ``"net_flow_history"`` /
#: ``"spool_history"``, ``SignalHistory`` objects
#: (:mod:`pneubayes.effects.closure_histories`) along the signals' points, or else the
#: points' times ``"time_s"`` (s) to low-pass the signal along.
LOW_PASS_HISTORIES: dict[str, str] = {"pressure_relaxation": "pressure_history",
                                      "net_flow_lag": "net_flow_history",
                                      "command_lag": "spool_history",
                                      "command_lag_fall": "spool_history",
                                      "command_lag_rise": "spool_history"}
#: The dead-time features (``*_late_fall``, ``*_late_rise``) read the delayed command's
#: history and the valve's map: ``"held_command"``, a ``HeldCommand``.
DEAD_TIME_FEATURES: tuple[str, ...] = tuple(f.name for f in FEATURES if f.dead_time)


def _relaxed(signals: dict, tau_s: float, key: str, values) -> np.ndarray:
    history = signals.get(key)
    if history is None:
        if "time_s" not in signals:
            raise ValueError(f"a low-pass closure feature needs its signal's history: give "
                             f"signals 'time_s' (the points' times, s) or {key!r} (a "
                             "SignalHistory)")
        history = SignalHistory(signals["time_s"], values)
    return history.relaxed(tau_s)


def feature(name: str) -> Feature:
    """The feature called ``name``; ValueError naming the known ones otherwise."""
    try:
        return FEATURE_BY_NAME[name]
    except KeyError:
        raise ValueError(f"unknown closure feature {name!r}; the features are "
                         f"{[f.name for f in FEATURES]}") from None


def evaluate_feature(name: str, signals: dict, threshold: float = 0.0) -> np.ndarray:
    """The value of base feature ``name`` on ``signals`` (see :data:`SIGNALS`);
    ``threshold`` is a hinge feature's theta or a relaxation's time constant in s
    (ignored otherwise)."""
    f = feature(name)
    s = signals
    p_atm = np.asarray(s["atmospheric_pressure_Pa"], dtype=np.float64)
    p = np.asarray(s["pressure_Pa"], dtype=np.float64)
    if f.code == 0:
        return np.ones_like(p)
    if f.code == 1:
        return p / p_atm
    if f.code == 2:
        return np.asarray(s["supply_pressure_Pa"], dtype=np.float64) / p_atm + 0.0 * p
    spool = np.asarray(s["spool"], dtype=np.float64) + 0.0 * p
    if f.code == 3:
        return spool
    if f.code == 4:
        return np.asarray(s["inlet_area_m2"], dtype=np.float64) / AREA_SCALE_M2 + 0.0 * p
    if f.code == 5:
        return np.asarray(s["exhaust_area_m2"], dtype=np.float64) / AREA_SCALE_M2 + 0.0 * p
    if f.code == 6:
        return np.asarray(s["inlet_flow_kg_per_s"], dtype=np.float64) + 0.0 * p
    if f.code == 7:
        return np.asarray(s["exhaust_flow_kg_per_s"], dtype=np.float64) + 0.0 * p
    vol = np.asarray(s["volume_m3"], dtype=np.float64) + 0.0 * p
    if f.code == 8:
        return vol / VOLUME_SCALE_M3
    if f.code == 9:
        return np.asarray(s["volume_rate_m3_per_s"], dtype=np.float64) / vol
    if f.code == 35:
        return np.abs(np.asarray(s["volume_rate_m3_per_s"], dtype=np.float64)
                      ) / VOLUME_SCALE_M3 + 0.0 * p
    if f.code == 10:
        return np.maximum(p / p_atm - threshold, 0.0)
    if f.code == 11:
        return np.maximum(spool - threshold, 0.0)
    if f.code == 12:
        return np.maximum(threshold - spool, 0.0)
    if f.code == 13:
        return (np.asarray(s["inlet_flow_kg_per_s"], dtype=np.float64)
                - np.asarray(s["exhaust_flow_kg_per_s"], dtype=np.float64) + 0.0 * p)
    if f.code == 14:
        return np.maximum(threshold - p / p_atm, 0.0)
    if f.code == 16:
        return (p - _relaxed(s, threshold, "pressure_history", p)) / p_atm
    if f.code == 19:
        net = (np.asarray(s["inlet_flow_kg_per_s"], dtype=np.float64)
               - np.asarray(s["exhaust_flow_kg_per_s"], dtype=np.float64) + 0.0 * p)
        return _relaxed(s, threshold, "net_flow_history", net) - net
    if f.code == 17:
        return np.maximum(vol / VOLUME_SCALE_M3 - threshold, 0.0)
    if f.code == 18:
        return np.maximum(threshold - vol / VOLUME_SCALE_M3, 0.0)
    if f.code in (20, 21):
        drop = np.abs(np.asarray(s["supply_pressure_Pa"], dtype=np.float64) - p) / p_atm
        return drop if f.code == 20 else np.maximum(threshold - drop, 0.0)
    if f.code in (22, 23, 25):  # the flow functions per mm^2: inlet, exhaust, their difference
        f_in = np.asarray(s["inlet_flux_kg_per_s_m2"], dtype=np.float64)
        f_ex = np.asarray(s["exhaust_flux_kg_per_s_m2"], dtype=np.float64)
        flux = f_in if f.code == 22 else (f_ex if f.code == 23 else f_in - f_ex)
        return flux * AREA_SCALE_M2 + 0.0 * p
    if f.code == 24:
        return np.maximum(threshold - np.abs(spool), 0.0)
    if f.code in (28, 29, 30):
        lag = _relaxed(s, threshold, "spool_history", spool) - spool
        return lag if f.code == 28 else np.maximum(lag if f.code == 29 else -lag, 0.0)
    if f.dead_time:
        held = s.get("held_command")
        if held is None:
            raise ValueError(f"closure feature {name!r} needs the command's history: give "
                             "signals 'held_command' (a HeldCommand)")
        late = "fall" if f.code in (31, 32) else "rise"
        return (held.area_change(threshold, "inlet" if f.code in (31, 33) else "exhaust",
                                 late) / AREA_SCALE_M2 + 0.0 * p)
    if f.code in (26, 27):
        area = np.asarray(s["inlet_area_m2" if f.code == 26 else "exhaust_area_m2"],
                          dtype=np.float64)
        return np.maximum(area / AREA_SCALE_M2 - threshold, 0.0) + 0.0 * p
    return np.asarray(s["command_direction"], dtype=np.float64) + 0.0 * p
