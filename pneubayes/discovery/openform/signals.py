"""The closure features' signals along a recording, and the missing mass flow.

:func:`path_signals` evaluates the :data:`~pneubayes.effects.closure_features.SIGNALS`
of a fitted model along the *measured* pressure, at the midpoint of each sample
interval (one value per interval, aligned with the one-step errors ``e[k]`` over
``[t_k, t_k+1]``): the measured pressure's chord mean, the supply the valve sees, the
spool (the command after the model's delay and lag), the port areas and flows
(:func:`~pneubayes.simulation.rates.port_areas`, eqs. 1-3), the volume and its rate,
and the delayed command's direction.

:func:`missing_mass_flow` turns the one-step errors into the target of the open-form
search: the mass flow into the chamber that the model lacks, kg/s. By eq. 5 a mass flow
``m`` moves the pressure at ``kappa Rs T m / (V + kappa p C)`` (C the chamber's
compliance dV/dp; T the supply temperature, as in :mod:`~pneubayes.simulation.rates`).
Over one interval of length h the chamber relaxes the extra rate ``d`` with its own
pressure slope ``J = d(dp/dt)/dp``, so the error it leaves is ``e = d (exp(J h) - 1) /
J`` (``d h`` for J = 0); inverted, ``d = e J / (exp(J h) - 1)``. Approximations: ``d``
is taken constant over the interval (its value at the midpoint), ``J`` is the model's
slope there (central difference of :func:`~pneubayes.simulation.rates.rate_terms` in
p), and the states the rates module leaves out (a heat-transfer temperature, a tank,
a second compartment, an acoustic line's cells) are not modelled here either.
"""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.absorbers import sensitivity_points
from pneubayes.discovery.openform.trajectory import phi1, pressure_gain
from pneubayes.effects.closure_histories import (
    HeldCommand,
    SignalHistory,
    held_direction,
)
from pneubayes.effects.command_clock import command_delay_s
from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.physics.orifice import flow_function
from pneubayes.simulation import Inputs
from pneubayes.simulation.rates import (
    inlet_supply,
    port_areas,
    port_laws,
    port_pressure,
    rate_terms,
    tabulated_volume,
)
from pneubayes.simulation.spool_path import held_before, spool_at
from pneubayes.simulation.stiction import valve_command_of

#: Relative pressure step of the central difference that gives the chamber's slope J.
JACOBIAN_STEP = 1e-4


def _as_inputs(data) -> tuple[Inputs, object]:
    """``(inputs, rig or None)`` of a OneStepData or an Inputs."""
    if isinstance(data, Inputs):
        return data, None
    return data.inputs, getattr(data, "rig", None)


def path_signals(model, params, recording, data, rig=None) -> dict:
    """The closure features' signals at the midpoints of a recording's sample intervals.

    Parameters
    ----------
    model : Model
        The fitted model.
    params : dict or (P,) array
        Its parameter values (one set).
    recording : Recording
        Supplies the measured pressure (absolute, Pa).
    data : OneStepData or Inputs
        The drive signals (command, position, supply, exhaust command), e.g.
        ``one_step_data(recording, block)``.
    rig : Rig or None
        None: the OneStepData's rig, else the recording's.

    Returns
    -------
    dict
        Every name of :data:`~pneubayes.effects.closure_features.SIGNALS` -> ``(N - 1,)``
        array (absolute pressures Pa, spool in the command's unit, areas m^2, port flows
        kg/s, their flow functions kg/(s m^2), volume m^3, volume rate m^3/s, the
        command's direction, the measured pressure's and the net port flow's histories
        for the low-pass features, the delayed command's for the dead-time features:
        ``"held_command"``), plus
        ``"time_s"`` (the midpoints, s), ``"interval_s"`` (each interval's length, s),
        ``"compliance_m3_per_Pa"`` (dV/dp of a compliant chamber, 0 if rigid) and
        ``"jacobian_per_s"`` (the model's d(dp/dt)/dp there, 1/s), which
        :func:`missing_mass_flow` reads, and ``"valid"``
        (both ends of the interval valid: the recording's ``valid`` column), which
        :class:`~pneubayes.discovery.openform.search.OpenFormSearch` reads.
    """
    inputs, data_rig = _as_inputs(data)
    rig = rig or data_rig or recording.rig()
    theta = model.as_matrix(params)
    if theta.shape[0] != 1:
        raise ValueError(f"path_signals: give one parameter set, got {theta.shape[0]}")
    sl = model.lower(theta, rig)[0]
    t = inputs.time_s
    p_meas = np.asarray(recording.pressure_Pa, dtype=np.float64)
    if p_meas.shape != t.shape:
        raise ValueError("path_signals: the recording and the inputs differ in length")
    valid = np.asarray(recording.valid_mask(), dtype=bool)
    mid = 0.5 * (t[1:] + t[:-1])
    h = np.diff(t)
    p = 0.5 * (p_meas[1:] + p_meas[:-1])
    g = rig.gas
    p_atm = rig.atmospheric_pressure_Pa
    p_nom = rig.supply_pressure_Pa
    ps_meas = 0.5 * (inputs.supply_pressure_Pa[1:] + inputs.supply_pressure_Pa[:-1])
    p_sup = p_nom + sl[S["supply_gain"]] * (ps_meas - p_nom)
    x = 0.5 * (inputs.position_m[1:] + inputs.position_m[:-1])
    xdot = np.diff(inputs.position_m) / h  # the position is linear between samples
    spool = spool_at(mid, inputs, sl)
    # the delayed command's direction (its last change's sign) at the midpoints
    valve_u = valve_command_of(inputs.command_V, held_before(inputs), sl)
    delay = float(command_delay_s(sl))
    direction = held_direction(mid, t, valve_u, delay, inputs.command_before_start)
    ue = None if inputs.exhaust_command is None else inputs.exhaust_command[:-1]
    a_in, a_ex = port_areas(sl, spool, ue)
    ports = port_pressure(sl, rig, p, p_sup, a_in, a_ex)  # (a restriction's node)
    b_in, b_ex, m_sub = port_laws(sl)
    f_in = flow_function(inlet_supply(sl, rig, p_sup, ports, a_in), ports, g, b_in, m_sub)
    f_ex = flow_function(ports, p_atm, g, b_ex, m_sub)
    inlet, exhaust = a_in * f_in, a_ex * f_ex
    dvol, slope = tabulated_volume(sl, p)
    compliance = sl[S["compliance_m3_per_Pa"]] + slope
    vol = (sl[S["volume_m3"]] + rig.bore_area_m2 * x
           + sl[S["compliance_m3_per_Pa"]] * (p - p_atm) + dvol)
    vdot = rig.bore_area_m2 * xdot
    # the low-pass features' histories: the measured pressure's, the net port flow
    # along it and the spool's (held in the slope below, as the simulator holds them
    # over a step)
    histories = {"pressure_history": SignalHistory(mid, p),
                 "net_flow_history": SignalHistory(mid, inlet - exhaust),
                 "spool_history": SignalHistory(mid, spool),
                 "held_command": HeldCommand(mid, t, valve_u, delay,
                                             inputs.command_before_start,
                                             lambda u: port_areas(sl, u, ue))}
    dp = JACOBIAN_STEP * p
    rates = [rate_terms(sl, rig, p + s * dp, spool, x, xdot, ps_meas, ue, direction,
                        histories).total
             for s in (1.0, -1.0)]
    jac = (rates[0] - rates[1]) / (2.0 * dp)
    return {"pressure_Pa": p, "supply_pressure_Pa": p_sup,
            "atmospheric_pressure_Pa": np.full(p.shape, p_atm), "spool": spool,
            "inlet_area_m2": a_in, "exhaust_area_m2": a_ex, "inlet_flow_kg_per_s": inlet,
            "exhaust_flow_kg_per_s": exhaust, "inlet_flux_kg_per_s_m2": f_in,
            "exhaust_flux_kg_per_s_m2": f_ex, "volume_m3": vol,
            "volume_rate_m3_per_s": vdot, "command_direction": direction,
            **histories, "time_s": mid,
            "interval_s": h,
            "compliance_m3_per_Pa": compliance + 0.0 * p, "jacobian_per_s": jac,
            "valid": valid[1:] & valid[:-1]}


def missing_mass_flow(signals: dict, errors_Pa, rig) -> np.ndarray:
    """The mass flow into the chamber the model lacks over each interval, kg/s.

    ``d = e J / (exp(J h) - 1)`` (``e / h`` where J h is 0) is the missing pressure
    rate, Pa/s, and ``d (V + kappa p C) / (kappa Rs T)`` its mass flow (module doc).

    Parameters
    ----------
    signals : dict
        :func:`path_signals`' output for the recording.
    errors_Pa : (N - 1,) array
        One-step errors (measured minus predicted), Pa, e.g.
        ``one_step_data(rec, block).errors(model, params, solver)[0]``.
    rig : Rig
        Gas constants (kappa, Rs, the supply temperature T).

    Returns
    -------
    (N - 1,) array
    """
    e = np.asarray(errors_Pa, dtype=np.float64)
    h = np.asarray(signals["interval_s"], dtype=np.float64)
    if e.shape != h.shape:
        raise ValueError(f"missing_mass_flow: {e.shape[0]} errors for {h.shape[0]} intervals")
    jh = np.asarray(signals["jacobian_per_s"], dtype=np.float64) * h
    rate = e / (h * phi1(jh))
    return rate / pressure_gain(signals, rig)


def parameter_flows(model, params, data, solver, signals) -> np.ndarray:
    """The model's sensitivities to its own parameters along the measured path, each as
    the mass flow into the chamber its change adds (kg/s per unit of the parameter),
    ``(N - 1, P)`` in ``model.parameter_names``' order: the catalogue search's absorbers
    (:func:`~pneubayes.discovery.absorbers.sensitivity_points`, the one-step predictions
    stepped up and down, in one batched call) per interval, converted as
    :func:`missing_mass_flow` converts the errors along ``signals``. A parameter that
    does not move the prediction (a noise model's) gives a column of zeros.

    Parameters
    ----------
    model : Model
        The fitted model.
    params : dict or (P,) array
        Its parameter values (one set).
    data : OneStepData
        The recording prepared for one-step predictions.
    solver : SolverConfig
        The one-step predictions' solver.
    signals : dict
        :func:`path_signals` at ``params``.

    Returns
    -------
    (N - 1, P) array
    """
    points, widths, _ = sensitivity_points(model, model.as_matrix(params)[0])
    pred = data.predict(model, points, solver)
    per_Pa = missing_mass_flow(signals, np.ones(pred.shape[1]), data.rig)  # kg/s per Pa
    return ((pred[0::2] - pred[1::2]) / widths[:, None]).T * per_Pa[:, None]
