"""The spool's position along a recording, evaluated at given times (the valve's
command after its stiction, delay and lag), outside the compiled kernel: for what is read
from a trajectory after it is simulated (the reading's flow terms,
:mod:`pneubayes.simulation.reading_flow`) and for the open-form search's signals
(:mod:`pneubayes.discovery.openform.signals`).
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.command_clock import command_delay_s
from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.simulation.drive import Inputs
from pneubayes.simulation.spool import spool_step
from pneubayes.simulation.stiction import valve_command_of


def held_before(inputs: Inputs) -> float:
    """The command held before the recording's first sample (its pre-trigger command,
    else the first sample's)."""
    u = inputs.command_V
    return float(u[0] if inputs.command_before_start is None else inputs.command_before_start)


def spool_at(times_s: np.ndarray, inputs: Inputs, slots: np.ndarray) -> np.ndarray:
    """The spool position at ``times_s`` (increasing, inside the record), command unit.

    The command is held between samples, taken as a sticking valve sees it (slots
    ``stiction_*``, :mod:`pneubayes.simulation.stiction`), delayed by slot
    ``command_delay_s`` (before the first sample: the pre-trigger command, else the
    first sample's, held since long before) and passed through the spool's lag (slots
    ``spool_time_constant_s`` with ``spool_rate_limit_V_per_s`` or
    ``spool_fall_time_constant_s``, or
    ``spool_natural_frequency_rad_per_s`` / ``spool_damping``), stepped exactly with
    :func:`~pneubayes.simulation.spool.spool_step` between the delayed command's
    changes, from rest at the command held at the start.

    Parameters
    ----------
    times_s : (M,) array
        Evaluation times, s, non-decreasing.
    inputs : Inputs
        The recording's drive signals.
    slots : (N_SLOTS,) array
        One lowered slot row of the model.

    Returns
    -------
    (M,) array
    """
    t, u = inputs.time_s, inputs.command_V
    before = held_before(inputs)
    u = valve_command_of(u, before, slots)  # (a sticking valve: where it stuck)
    delay = float(command_delay_s(slots))
    tau = float(slots[S["spool_time_constant_s"]])
    rate = float(slots[S["spool_rate_limit_V_per_s"]])
    tau_dn = float(slots[S["spool_fall_time_constant_s"]])
    w, z = float(slots[S["spool_natural_frequency_rad_per_s"]]), float(slots[S["spool_damping"]])
    times = np.asarray(times_s, dtype=np.float64)
    shifted = t + delay

    def held(at):
        j = np.searchsorted(shifted, at, side="right") - 1
        return np.where(j < 0, before, u[np.maximum(j, 0)])

    if not (tau > 0.0 or tau_dn > 0.0 or w > 0.0):
        return held(times)
    # step through the delayed command's changes and the evaluation times in order
    cuts = shifted[(shifted > t[0]) & (shifted < times[-1])]
    grid = np.union1d(np.concatenate(([t[0]], cuts)), times)
    cmd = held(grid)  # the command in force from each grid point on
    s, v = float(cmd[0]), 0.0
    out_grid = np.empty(grid.size)
    out_grid[0] = s
    for i in range(1, grid.size):
        s, v = spool_step(s, v, float(cmd[i - 1]), float(grid[i] - grid[i - 1]), tau, w, z,
                          rate, tau_dn)
        out_grid[i] = s
    return out_grid[np.searchsorted(grid, times)]
