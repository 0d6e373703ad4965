"""Simulate a model on a recording's inputs: the one entry point of the simulation layer.

>>> traj = simulate(model, params, inputs, rig, solver=SolverConfig.standard())

``params`` may be a dict, a vector or a batch ``(B, P)``; the result's pressure has a
leading batch axis. Windows (e.g. the paper's 2-s predictions started from the measured
pressure) are simulated in one compiled call with :func:`simulate_windows`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pneubayes.effects.closure_features import FEATURES
from pneubayes.effects.closure_terms import CLOSURE_MAX_TERMS
from pneubayes.effects.path import SLOT_INDEX, VOLUME_PLAY_COMPLIANCE_SLOTS
from pneubayes.errors import FormCombinationError, SimulationError
from pneubayes.model import Model
from pneubayes.rig import Rig
from pneubayes.simulation import kernel
from pneubayes.simulation.config import SolverConfig
from pneubayes.simulation.drive import Inputs, kernel_ready_arrays
from pneubayes.simulation.layout import rig_constants
from pneubayes.simulation.measurement import sensor_reading
from pneubayes.simulation.reading_closure import read_windows, start_state
from pneubayes.simulation.reading_command import command_offsets
from pneubayes.simulation.reading_flow import PortFlows, flow_reading, flow_start
from pneubayes.simulation.reading_hinge import (
    hinged_reading,
    hinges_readable,
    unhinged_reading,
)
from pneubayes.simulation.stiction import sticks, valve_commands


@dataclass(frozen=True)
class Trajectory:
    """Simulated pressures. ``pressure_Pa`` is ``(B, W, L)`` for windows, ``(B, N)`` else."""

    time_s: np.ndarray
    pressure_Pa: np.ndarray
    solver: SolverConfig
    parameter_names: tuple[str, ...]
    parameters: np.ndarray


def _check_solver(solver) -> SolverConfig:
    if not isinstance(solver, SolverConfig):
        raise TypeError("solver must be a SolverConfig (e.g. SolverConfig.standard()); "
                        f"got {type(solver).__name__}")
    return solver


#: Slot columns whose presence (> 0) ``_window_call`` checks, gathered in one pass.
_FORM_COLUMNS = {name: i for i, name in enumerate((
    "wave_length_m", "line_length_m", "heat_coupling",
    "exhaust_own_command", "tank_volume_m3", "compliance_m3_per_Pa", "volume_table_points",
    "lung_volume_m3", "closure_terms", "loaded_wall_compliance_m3_per_Pa",
    "restriction_fill_inverse_area_per_m2", "restriction_vent_inverse_area_per_m2",
    "supply_restriction_inverse_area_per_m2", "heat_jet_coefficient_W_per_m2_K",
    "inlet_critical_ratio", "exhaust_critical_ratio", "port_subsonic_index",
    "spool_natural_frequency_rad_per_s",
    "command_clock_period_s",
    *VOLUME_PLAY_COMPLIANCE_SLOTS))}
_FORM_SLOTS = np.array([SLOT_INDEX[name] for name in _FORM_COLUMNS])
#: The form columns the pressure-only kernel leaves to the general one
#: (:func:`kernel.needs_general`).
_GENERAL_COLUMNS = np.flatnonzero(np.isin(_FORM_SLOTS, kernel.GENERAL_SLOTS))


#: The closure's feature codes that read the valve's ports at the chamber, and the slots
#: of its terms' features (term k's at columns 2k and 2k + 1).
_PORT_CODES = {f.code: f.name for f in FEATURES if f.port}
_CLOSURE_FEATURE_SLOTS = np.array([SLOT_INDEX[f"closure_feature_{side}_{k}"]
                                   for k in range(CLOSURE_MAX_TERMS) for side in "ab"])


def _check_closure_beside_wave(slots: np.ndarray, rows: np.ndarray) -> None:
    """Raise where a closure beside the wave tube (parameter sets ``rows``) reads the
    valve's ports, which the tube puts at its far end."""
    codes = slots[np.ix_(rows, _CLOSURE_FEATURE_SLOTS)]
    used = (np.arange(_CLOSURE_FEATURE_SLOTS.size)[None, :] // 2
            < slots[rows, SLOT_INDEX["closure_terms"]][:, None])
    hit = used & np.isin(codes, list(_PORT_CODES))
    if hit.any():
        r, j = np.argwhere(hit)[0]
        raise FormCombinationError(
            f"an open-form closure beside the wave tube (tube_delay form 'wave') reads "
            f"feature {_PORT_CODES[int(codes[r, j])]!r} (term {j // 2}): the valve's ports "
            "sit at the tube's far end, where the chamber does not see them; a closure "
            "there may read the features that are not ports "
            "(pneubayes.effects.closure_features.PORT_FEATURES)")


def _check_exclusive_forms(forms: np.ndarray, slots: np.ndarray) -> None:
    """Raise where a parameter set combines forms the kernel cannot step together
    (``forms``: ``(B, len(_FORM_COLUMNS))``, which forms each set has; ``slots`` its
    lowered slots)."""
    def has(name):
        return forms[:, _FORM_COLUMNS[name]]

    if np.any(has("exhaust_own_command") & (slots[:, SLOT_INDEX["inputs_advance_s"]] < 0.0)):
        raise FormCombinationError(
            "a late reading (sensor_lag form 'delay') is simulated in the "
            "reading's time, which an exhaust valve's own command (read "
            "undelayed) does not follow: not simulated")
    wave = has("wave_length_m")
    line = has("line_length_m") | wave
    hot = has("heat_coupling")
    # states the kernel steps with the pressure, one at a time: what each excludes
    tank = has("tank_volume_m3")
    # (a compliant chamber keeps the pressure the only state: the transmission line's
    # chamber step carries its V(p) and dV/dp, tests/test_wave.py)
    acoustic = "the tube's acoustic line (tube_delay form 'line')"
    lines = "the tube's acoustic line or wave line (tube_delay forms 'line', 'wave')"
    play = np.logical_or.reduce([has(name) for name in VOLUME_PLAY_COMPLIANCE_SLOTS])
    if np.any(play & (has("volume_table_points") | tank | has("lung_volume_m3"))):
        raise FormCombinationError(
            "a volume play (effect 'volume_play') lays the chamber's volume "
            "table itself: it cannot be combined with a volume closure, "
            "another tabulated volume, a supply tank or a second compartment "
            "in one model")
    wall = has("loaded_wall_compliance_m3_per_Pa")
    if np.any(wall & (has("compliance_m3_per_Pa") | has("volume_table_points") | play | tank
                      | has("lung_volume_m3") | has("line_length_m"))):
        raise FormCombinationError(
            "a loaded wall (effect 'loaded_wall') moves a rigid chamber's volume "
            "as a piston does: it cannot be combined with a compliant chamber, "
            "a volume closure or play, a supply tank, a second compartment or "
            f"{acoustic} in one model")
    exclusive = (
        (has("compliance_m3_per_Pa") | has("volume_table_points") | play,
         has("line_length_m") | hot,
         "a compliant chamber is simulated with the pressure as its only state", acoustic),
        (tank, line | hot,
         "a supply tank is simulated with the chamber's pressure and the tank's as the states",
         lines),
        (has("lung_volume_m3"), line | hot | tank,
         "a two-compartment chamber is simulated with the two pressures as the states",
         lines),
    )
    if np.any(has("closure_terms") & has("line_length_m")):
        raise FormCombinationError(
            "an open-form closure (effect 'closure') is part of the chamber's "
            "right-hand side, which the tube's acoustic line (tube_delay form "
            "'line') replaces: it cannot be combined with it in one model")
    if np.any(has("closure_terms") & wave):
        _check_closure_beside_wave(slots, np.flatnonzero(has("closure_terms") & wave))
    restricted = has("restriction_fill_inverse_area_per_m2") | has(
        "restriction_vent_inverse_area_per_m2")
    if np.any(restricted & (line | tank | has("lung_volume_m3"))):
        raise FormCombinationError(
            "a restriction at the chamber's port (effect 'port_restriction') "
            "sits between the valve's ports and the chamber: it cannot be "
            f"combined with {lines}, a supply tank or a second compartment in "
            "one model")
    supplied = has("supply_restriction_inverse_area_per_m2")
    if np.any(supplied & (line | tank | restricted)):
        raise FormCombinationError(
            "a restriction upstream of the valve's inlet (effect "
            "'supply_restriction') feeds the inlet as the chamber's ports see "
            f"it: it cannot be combined with {lines}, a supply tank or a "
            "restriction at the port in one model")
    critical = (has("inlet_critical_ratio") | has("exhaust_critical_ratio")
                | has("port_subsonic_index"))
    if np.any(critical & (tank | restricted | supplied)):
        raise FormCombinationError(
            "a port's own critical pressure ratio (effect 'critical_ratio') is stepped "
            "where the valve's ports meet the chamber or a tube: it cannot be combined "
            "with a supply tank, a restriction at the port or upstream of the inlet in "
            "one model")
    if np.any(wave & (hot | has("line_length_m"))):
        raise FormCombinationError(
            "a transmission-line tube (tube_delay form 'wave') is simulated "
            "with the chamber's pressure as its only state: it cannot be "
            "combined with heat_transfer or an acoustic line in one model")
    for present, others, what, beside in exclusive:
        if np.any(present & others):
            raise FormCombinationError(
                f"{what}: it cannot be combined with heat_transfer, {beside} "
                "or another second state "
                "(a supply tank, a second compartment) in one model")


def combination_error(model: Model, params, rig: Rig) -> str | None:
    """Why the simulator refuses to step ``model`` at ``params`` (a dict, or a vector
    in ``model.parameter_names``' order) on ``rig``: the message of the
    :class:`~pneubayes.errors.FormCombinationError` a simulation would raise (forms the
    kernel cannot step together, e.g. a port's own critical ratio beside a restriction
    at the port), or None where it can."""
    theta = np.atleast_2d(model.vector(params) if isinstance(params, Mapping) else
                          np.asarray(params, dtype=np.float64))
    slots = model.lower(theta, rig)
    try:
        _check_exclusive_forms(slots[:, _FORM_SLOTS] > 0, slots)
    except FormCombinationError as err:
        return str(err)
    return None


def _window_call(model, params, inputs, rig, starts, length, initial_pressure_Pa, solver,
                 check_bounds, on_failure, kernel_fn, initial_rate_Pa_per_s=None):
    if on_failure not in ("raise", "nan"):
        raise ValueError(f"on_failure must be 'raise' or 'nan', got {on_failure!r}")
    solver = _check_solver(solver)
    theta = model.as_matrix(params)
    if check_bounds:
        model.check_bounds(theta)
    starts = np.ascontiguousarray(starts, dtype=np.int64).reshape(-1)
    length = int(length)
    if isinstance(initial_pressure_Pa, (float, int, np.floating, np.integer)):  # every window
        p0_Pa = float(initial_pressure_Pa)
        finite_positive = math.isfinite(p0_Pa) and p0_Pa > 0
        p0 = np.full(starts.shape, p0_Pa)
    else:
        p0 = np.ascontiguousarray(np.broadcast_to(
            np.asarray(initial_pressure_Pa, np.float64), starts.shape))
        finite_positive = bool(np.all(np.isfinite(p0) & (p0 > 0)))
    if length < 1:
        raise ValueError(f"length must be >= 1, got {length}")
    if starts.size:
        first, last = int(starts.min()), int(starts.max())
        if first < 0 or last + length > inputs.n_samples:
            raise ValueError(f"windows run past the inputs: starts in [{first}, {last}], "
                             f"length {length}, {inputs.n_samples} samples")
    if not finite_positive:
        raise ValueError("initial_pressure_Pa must be finite and > 0 (absolute)")
    shape = (theta.shape[0], starts.size)
    try:
        rate0 = np.full(shape, np.nan) if initial_rate_Pa_per_s is None else \
            np.ascontiguousarray(np.broadcast_to(np.asarray(initial_rate_Pa_per_s,
                                                            np.float64), shape))
    except ValueError:
        raise ValueError(f"initial_rate_Pa_per_s must broadcast to (parameter sets, windows) "
                         f"= {shape}, got shape {np.shape(initial_rate_Pa_per_s)}") from None
    if initial_rate_Pa_per_s is not None and not np.all(np.isfinite(rate0)):
        raise ValueError("initial_rate_Pa_per_s must be finite")
    slots = model.lower(theta, rig)
    forms = slots[:, _FORM_SLOTS] > 0  # (B, forms): which forms each parameter set has
    general = False  # a state the recording does not measure (kernel.needs_general)
    if forms.any():
        if inputs.exhaust_command is None and forms[:, _FORM_COLUMNS[
                "exhaust_own_command"]].any():
            raise ValueError("the model's exhaust is a separate valve with its own command, "
                             "but the inputs have no exhaust command (a recording's "
                             "'exhaust_command' column, or the column its rig card names)")
        _check_exclusive_forms(forms, slots)
        general = bool(forms[:, _GENERAL_COLUMNS].any())
    # a reading closure: each window's chamber starts where it reads the measured start
    # (pneubayes.simulation.reading_closure), each set moved to its own along the start
    # sensitivity, which the kernel then computes
    read_through = model.relaxes_reading
    call = kernel.simulate_windows_sensitivity if read_through else kernel_fn
    if read_through:
        relax, plays = model.reading_relaxations(theta), model.reading_plays(theta)
        hinges = model.reading_hinges(theta)
        # (gains summing to -1 or less, or hinges whose map is not increasing, leave a
        # reading that does not tell the pressure: such a set fails, as a failed
        # simulation does)
        bent = ~hinges_readable(*hinges)
        unreadable = (1.0 + relax[0].sum(axis=1) + plays[0].sum(axis=1) <= 0.0) | bent
        if bent.any() and on_failure != "nan":
            b = int(np.flatnonzero(bent)[0])
            raise ValueError(f"reading hinges: parameter set {b}'s map is not increasing "
                             f"everywhere (gains {hinges[0][b].tolist()} at thresholds "
                             f"{hinges[1][b].tolist()} Pa): its reading does not tell the "
                             "pressure")
        if unreadable.any() and on_failure == "nan":
            relax = (np.where(unreadable[:, None], 0.0, relax[0]), relax[1])
            plays = (np.where(unreadable[:, None], 0.0, plays[0]), plays[1])
            hinges = (np.where(unreadable[:, None], 0.0, hinges[0]), hinges[1])
        # (the hinges read last: the rest of the reading starts at H^-1(r0))
        hinged = hinges[0].shape[1] > 0
        reading0 = p0 if not hinged else unhinged_reading(
            np.broadcast_to(p0, (theta.shape[0], starts.size)), *hinges)
        # (lags of the command add to the reading: the chamber reads r0 less them)
        commands = model.reading_commands(theta)
        offsets = (command_offsets(inputs, starts, length, *commands)
                   if commands[0].shape[1] else None)
        if offsets is not None:
            reading0 = reading0 - offsets[:, :, 0]
        # (terms of the port flows add to the reading too: the chamber reads r0 less
        # them at its own start, pneubayes.simulation.reading_flow)
        flow_gains, flow_features = model.reading_flows(theta)
        flows = PortFlows(inputs, rig, starts, length) if len(flow_features) else None
        if flows is not None:
            reading0 = flow_start(flows, slots, reading0, flow_gains, flow_features)
        start, bar0, y0 = start_state(*relax, inputs, starts, reading0, plays)
        p0 = start.mean(axis=0)
        lowered = slots
    t, u, ue, x, ps, pm, offset = inputs.kernel_arrays()
    slots, consts, sv, kstarts, p0, rate0 = kernel_ready_arrays(
        slots, rig_constants(rig), solver.as_array(), starts + offset, p0, rate0)
    if sticks(slots).any():  # a sticking valve: each set's own command
        *arrays, status = _each_valve_command(
            slots, u, lambda rows, uu: call(
                np.ascontiguousarray(slots[rows]), consts, sv, t, uu, ue, x, ps, kstarts,
                length, p0, np.ascontiguousarray(rate0[rows]), pm, general))
    else:
        *arrays, status = call(slots, consts, sv, t, u, ue, x, ps, kstarts, length, p0,
                               rate0, pm, general)
    failed = np.nonzero(status.any(axis=1))[0] if status.any() else ()
    if len(failed) and on_failure == "nan":
        for a in arrays:
            a[failed] = np.nan
    elif len(failed):
        lines = []
        for b in failed[:5]:
            w = int(np.nonzero(status[b])[0][0])
            why = kernel.STATUS_TEXT[int(status[b, w])]
            vals = ", ".join(f"{n}={v:.6g}" for n, v in zip(model.parameter_names, theta[b]))
            lines.append(f"parameter set {b} (window starting at sample {starts[w]}): "
                         f"{why}; {vals}")
        more = f" (and {failed.size - 5} more)" if failed.size > 5 else ""
        raise SimulationError(f"simulation failed for {failed.size} parameter set(s){more}:\n  "
                              + "\n  ".join(lines))
    # the sensor point: what a declared anti-alias filter reads of the chamber pressure
    arrays[0], unread = sensor_reading(arrays[0], slots, rig, inputs, starts, length)
    if len(unread) and on_failure == "nan":
        for a in arrays[1:]:
            a[unread] = np.nan
    elif len(unread):
        vals = ", ".join(f"{n}={v:.6g}" for n, v in zip(model.parameter_names,
                                                        theta[unread[0]]))
        raise SimulationError(f"simulation failed for {unread.size} parameter set(s): a "
                              f"reading at a corner the declared pressure filter rounds "
                              f"stands for no chamber pressure (beyond the curved "
                              f"sensor's turning point); parameter set {unread[0]}: {vals}")
    if read_through:  # an open-form term at the reading (effect reading_closure)
        out, sens = read_windows(*relax, inputs, starts, *arrays[:2], p0, start, bar0,
                                 plays, y0)
        if offsets is not None:
            out = out + offsets
        if flows is not None:
            out, sens = _read_flows(out, sens, arrays[0], arrays[1], p0, start, flows,
                                    lowered, flow_gains, flow_features,
                                    1.0 + relax[0].sum(axis=1) + plays[0].sum(axis=1))
        if hinged:  # the reading's last map, and the start's slope through it
            z0 = out[:, :, :1].copy()
            out, slope = hinged_reading(out, *hinges)
            sens = sens * slope / hinged_reading(z0, *hinges)[1]
        out[unreadable], sens[unreadable] = np.nan, np.nan
        arrays = [out, sens] if kernel_fn is kernel.simulate_windows_sensitivity else [out]
    return arrays


def _read_flows(out, sens, pressure, sensitivity, kernel_start, start, flows, slots, gains,
                features, stretch):
    """The windows' reading ``out`` and its sensitivity ``sens`` (to the start reading)
    with the port flows' terms added (:mod:`pneubayes.simulation.reading_flow`) along
    each parameter set's own pressure: the kernel's ``pressure`` moved along its
    ``sensitivity`` from ``kernel_start`` to the set's ``start``. The chamber's start
    moves by ``1 / (1 + sum_k c_k dF_k/dp)`` per unit of the start reading and the terms'
    own slope adds to what the relaxations and plays (``stretch``: one plus their
    gains) read."""
    p = pressure + sensitivity * (start - kernel_start[None])[:, :, None]
    shift, slope = flow_reading(flows, slots, p, gains, features)
    stretch = np.where(stretch > 0.0, stretch, 1.0)  # (an unreadable set is NaN after)
    sens = (sens + slope * sensitivity / stretch[:, None, None]) / (1.0 + slope[:, :, :1])
    return out + shift, sens


def simulate_windows(model: Model, params, inputs: Inputs, rig: Rig, starts, length: int,
                     initial_pressure_Pa, solver: SolverConfig,
                     check_bounds: bool = True, on_failure: str = "raise",
                     initial_rate_Pa_per_s=None) -> np.ndarray:
    """Simulate windows of ``length`` samples from ``starts``; returns ``(B, W, length)`` Pa.

    With heat transfer the chamber temperature starts at the supply's, an acoustic line
    at rest at the chamber's pressure; contiguous windows (each starting on the previous
    one's last sample) carry these unmeasured states, so only the pressure is reset. With
    a pressure filter declared on ``rig`` the result is the sensor's reading
    (:mod:`pneubayes.simulation.measurement`); with ``sensor_lag``, the lagged reading.

    Parameters
    ----------
    model : Model
    params : mapping, (P,) or (B, P) array
        Parameter values by name, one set, or a batch of B sets.
    inputs : Inputs
        The recording's inputs (command, position, supply).
    rig : Rig
    starts : (W,) int array
        First sample of each window.
    length : int
        Samples per window, the start included.
    initial_pressure_Pa : float or (W,) array
        Each window's starting pressure, Pa absolute (e.g. the measured one there).
    solver : SolverConfig
        With ``dense_output`` (:meth:`SolverConfig.sampling`) a step may cross the samples
        over which the command holds, reading them from its interpolant (models with the
        pressure as their only state), within the solver's tolerance of stopping at each.
    check_bounds : bool
        Refuse parameters outside their bounds (:class:`~pneubayes.errors.ParameterError`).
    on_failure : {"raise", "nan"}
        A failed parameter set raises :class:`SimulationError` naming it, or gives NaN rows
        (samplers turn them into zero likelihood).
    initial_rate_Pa_per_s : (W,) or (B, W) array, optional
        With a sensor lag: the reading's rate at each start, Pa/s, where the chamber leads
        the reading by the lag's time constant times it; None: the lead the model builds
        over 5 time constants of command history
        (:func:`pneubayes.simulation.kernel.simulate_windows`).
    """
    return _window_call(model, params, inputs, rig, starts, length, initial_pressure_Pa,
                        solver, check_bounds, on_failure, kernel.simulate_windows,
                        initial_rate_Pa_per_s)[0]


def fresh_carry(n: int, rig: Rig) -> np.ndarray:
    """``(n, N_CARRY)`` unmeasured states at a stream's start, as a recording's first
    window starts them (all NaN: the chamber's gas at its wall's temperature, a line at
    rest, a tank at the supply, a second compartment at the start's pressure): the
    ``carry`` of :func:`simulate_carried`. ``rig`` is not read (kept for callers)."""
    return np.full((int(n), kernel.N_CARRY), np.nan)


def simulate_carried(model: Model, params, inputs: Inputs, rig: Rig, bounds,
                     initial_pressure_Pa, carry: np.ndarray, measured_Pa, gain: float,
                     solver: SolverConfig, check_bounds: bool = False):
    """Simulate each parameter set through contiguous chunks, carrying its whole state.

    Chunk ``c`` runs from sample ``bounds[c]`` to ``bounds[c + 1]`` (one window, as
    :func:`simulate_windows` runs one). The states the recording does not measure (a
    chamber temperature, a line's cells, a tank's or a second compartment's pressure:
    ``carry``, one row per parameter set, **updated in place**) pass from chunk to chunk
    as contiguous windows pass them. Each chunk starts from the previous chunk's last
    predicted pressure moved by ``gain`` of its error against ``measured_Pa`` there: 0
    the set's own pressure (the chunks are one open-loop simulation of the whole span),
    1 the measured pressure (contiguous windows of :func:`simulate_windows`).

    The online tracker's carried mode calls this once per tick. Rebuilt per chunk from
    the recorded history, not carried: a spool's position (exactly), a lagged reading
    and an open-form low-pass. A declared ``rig.pressure_filter`` is refused.

    Parameters
    ----------
    model, params, inputs, rig : as :func:`simulate_windows`'s
    bounds : (K + 1,) int array
        Increasing sample indices: the chunks' ends (``K >= 1``).
    initial_pressure_Pa : (B,) array or float
        The pressure (reading) at ``bounds[0]``, Pa absolute.
    carry : (B, N_CARRY) float64 array
        The unmeasured states at ``bounds[0]`` (:func:`fresh_carry` at a stream's start);
        replaced by those at ``bounds[-1]``.
    measured_Pa : (N,) array
        The measured pressure on the inputs' samples (read at the chunks' starts).
    gain : float in [0, 1]
    solver, check_bounds : SolverConfig, bool

    Returns
    -------
    out : (B, bounds[-1] - bounds[0] + 1) ndarray
        Predicted pressure, Pa (column 0 the start; NaN rows where a set fails).
    p_end : (B,) ndarray
        The last prediction, before any correction (NaN where a set fails).
    """
    solver = _check_solver(solver)
    if rig.pressure_filter is not None:
        raise ValueError("simulate_carried: a declared pressure filter's reading is "
                         "computed over whole windows and cannot be carried")
    if model.relaxes_reading:
        raise ValueError("simulate_carried: a reading closure's relaxations (or a reading "
                         "play's plays) start at each window's start and are not carried "
                         "from chunk to chunk")
    if not (isinstance(gain, (int, float)) and not isinstance(gain, bool)
            and 0.0 <= gain <= 1.0):
        raise ValueError(f"simulate_carried: gain must be a number in [0, 1], got {gain!r}")
    theta = model.as_matrix(params)
    if check_bounds:
        model.check_bounds(theta)
    nb = theta.shape[0]
    bounds = np.ascontiguousarray(bounds, dtype=np.int64).reshape(-1)
    if bounds.size < 2 or np.any(np.diff(bounds) < 1) or bounds[0] < 0 \
            or bounds[-1] >= inputs.n_samples:
        raise ValueError(f"simulate_carried: bounds must be >= 2 increasing sample indices "
                         f"within the inputs' {inputs.n_samples}, got {bounds.tolist()}")
    if not (isinstance(carry, np.ndarray) and carry.dtype == np.float64
            and carry.shape == (nb, kernel.N_CARRY) and carry.flags.c_contiguous):
        raise ValueError(f"simulate_carried: carry must be a C-contiguous float64 array of "
                         f"shape {(nb, kernel.N_CARRY)}")
    p0 = np.ascontiguousarray(np.broadcast_to(np.asarray(initial_pressure_Pa, np.float64),
                                              (nb,)))
    measured = np.asarray(measured_Pa, dtype=np.float64)
    if measured.shape != (inputs.n_samples,):
        raise ValueError(f"simulate_carried: measured_Pa must have shape "
                         f"{(inputs.n_samples,)}, got {measured.shape}")
    slots = model.lower(theta, rig)
    forms = slots[:, _FORM_SLOTS] > 0
    if forms.any():
        if inputs.exhaust_command is None and forms[:, _FORM_COLUMNS[
                "exhaust_own_command"]].any():
            raise ValueError("the model's exhaust is a separate valve with its own command, "
                             "but the inputs have no exhaust command")
        _check_exclusive_forms(forms, slots)
    t, u, ue, x, ps, pm, offset = inputs.kernel_arrays()
    if offset:
        measured = np.concatenate(([np.nan], measured))
    slots, consts, sv, kb, measured, p0 = kernel_ready_arrays(
        slots, rig_constants(rig), solver.as_array(), bounds + offset,
        np.ascontiguousarray(measured), p0)
    general = bool(forms[:, _GENERAL_COLUMNS].any()) if forms.any() else None
    if not sticks(slots).any():
        out, p_end, _status = kernel.simulate_carried(
            slots, consts, sv, t, u, ue, x, ps, kb, measured, float(gain), p0, carry, pm,
            general)
        return out, p_end

    def one(rows, uu):  # a sticking valve: each set's own command
        sub = np.ascontiguousarray(carry[rows])
        res = kernel.simulate_carried(np.ascontiguousarray(slots[rows]), consts, sv, t, uu,
                                      ue, x, ps, kb, measured, float(gain),
                                      np.ascontiguousarray(p0[rows]), sub, pm, general)
        carry[rows] = sub
        return res
    out, p_end, _status = _each_valve_command(slots, u, one)
    return out, p_end


def _each_valve_command(slots, u, call):
    """``call(rows, command)`` for each group of parameter sets whose valve sees one
    command (:func:`pneubayes.simulation.stiction.valve_commands`), its outputs (each
    with the parameter sets first) put back in the sets' order."""
    merged = None
    for rows, uu in valve_commands(slots, u, float(u[0])):
        res = call(rows, np.ascontiguousarray(uu))
        if merged is None:
            merged = [np.empty((slots.shape[0],) + a.shape[1:], a.dtype) for a in res]
        for m, a in zip(merged, res):
            m[rows] = a
    return merged


def simulate_windows_sensitivity(model: Model, params, inputs: Inputs, rig: Rig, starts,
                                 length: int, initial_pressure_Pa, solver: SolverConfig,
                                 check_bounds: bool = True, on_failure: str = "raise",
                                 initial_rate_Pa_per_s=None):
    """:func:`simulate_windows` and the start sensitivity dp(t)/dp(t_start) (``-``).

    Returns ``(pressure_Pa, sensitivity)``, both ``(B, W, length)``. The sensitivity is 1
    at the window start and decays with the chamber's time constant; the likelihood
    uses it to carry the noise of the measured start pressure through each window.
    """
    out, sens = _window_call(model, params, inputs, rig, starts, length, initial_pressure_Pa,
                             solver, check_bounds, on_failure,
                             kernel.simulate_windows_sensitivity, initial_rate_Pa_per_s)
    return out, sens


def simulate(model: Model, params, inputs: Inputs, rig: Rig, initial_pressure_Pa: float,
             solver: SolverConfig, check_bounds: bool = True) -> Trajectory:
    """Simulate the whole input record from ``initial_pressure_Pa``.

    Parameters
    ----------
    model : Model
    params : mapping, (P,) or (B, P) array
        Parameter values by name, one set, or a batch of B sets.
    inputs : Inputs
        The recording's inputs (:meth:`Inputs.from_recording`).
    rig : Rig
        The rig's constants (e.g. ``recording.rig()``).
    initial_pressure_Pa : float
        The chamber pressure at the first sample, Pa absolute.
    solver : SolverConfig
    check_bounds : bool
        Refuse parameters outside their bounds.

    Returns
    -------
    Trajectory
        ``pressure_Pa`` is ``(B, N)``, Pa absolute.
    """
    theta = model.as_matrix(params)
    out = simulate_windows(model, theta, inputs, rig, np.zeros(1, np.int64), inputs.n_samples,
                           initial_pressure_Pa, solver, check_bounds=check_bounds)
    return Trajectory(inputs.time_s, out[:, 0, :], solver, model.parameter_names, theta)
