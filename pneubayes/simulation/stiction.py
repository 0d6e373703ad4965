"""The command a sticking valve sees (effect ``valve_stiction``).

A spool (or a poppet, a pinch) held by static friction does not follow small command
changes: it stays where it stuck until the command has moved ``band`` away, then
breaks free and slides to within ``(1 - slip) band`` of the command. Applied to the
held command samples in order, from the command held before the recording::

    s_k = s_(k-1)                                  if |u_k - s_(k-1)| < band
    s_k = u_k - sign(u_k - s_(k-1)) (1 - slip) band  otherwise

``slip = 0`` is play (backlash of half-width ``band``: the spool trails the command by
the band once it moves), ``slip = 1`` a stick-slip valve that jumps onto the command.
The transform acts on the command before the delay and the spool's lag (a held
command series in, a held command series out), so every later part of the signal
path sees the valve's own command. ``band = 0`` leaves the command unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pneubayes.effects.path import SLOT_INDEX

_BAND = SLOT_INDEX["stiction_band_V"]
_SLIP = SLOT_INDEX["stiction_slip_fraction"]


@njit(cache=True, error_model="numpy")
def stuck_command(command, before, band, slip):
    """The held commands the valve sees, ``(N,)`` in the command's unit.

    Parameters
    ----------
    command : (N,) float64
        The commands, each held until the next.
    before : float
        The command held before the first sample, where the valve rests at the start.
    band : float
        The break-away distance (command unit, >= 0).
    slip : float
        The slip fraction in [0, 1].
    """
    out = np.empty_like(command)
    s = before
    stop = (1.0 - slip) * band
    for k in range(command.shape[0]):
        d = command[k] - s
        if abs(d) >= band and d != 0.0:
            s = command[k] - stop if d > 0.0 else command[k] + stop
        out[k] = s
    return out


def sticks(slots: np.ndarray) -> np.ndarray:
    """``(B,)`` bool: which parameter sets (rows of lowered ``slots``) have a sticking
    valve."""
    return np.atleast_2d(slots)[:, _BAND] > 0.0


def valve_commands(slots: np.ndarray, command: np.ndarray, before: float):
    """Group parameter sets by the command their valve sees.

    Returns a list of ``(rows, command)``: the row indices of ``slots`` (B, N_SLOTS)
    that share one transformed command ``(N,)`` (the sets without stiction share the
    command itself)."""
    slots = np.atleast_2d(slots)
    key = slots[:, [_BAND, _SLIP]].copy()
    key[key[:, 0] <= 0.0] = 0.0  # a free valve whatever its slip
    uniq, which = np.unique(key, axis=0, return_inverse=True)
    which = which.reshape(-1)
    out = []
    for g, (band, slip) in enumerate(uniq):
        rows = np.flatnonzero(which == g)
        u = command if band <= 0.0 else stuck_command(command, float(before), float(band),
                                                      float(slip))
        out.append((rows, u))
    return out


def valve_command_of(command: np.ndarray, before: float, slots_row: np.ndarray) -> np.ndarray:
    """The commands the valve of one parameter set (a lowered slot row) sees: the
    command itself for a free valve."""
    band = float(slots_row[_BAND])
    if not band > 0.0:
        return command
    return stuck_command(np.asarray(command, dtype=np.float64), float(before), band,
                         float(slots_row[_SLIP]))
