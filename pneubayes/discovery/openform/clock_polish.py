"""Polishing a valve driver's clock beside a fitted model: a batched compass search over
its timing, the model's other parameters held.

A driver's timing is a needle in the trajectory error: over a 20-s recording a period a
few parts in 10^5 off, or a latency a tenth of a millisecond off, costs many times the
noise, and the error is a staircase in the period and the phase (each tick takes the
command sample held there), so a refinement's finite differences do not move them. This
search steps each timing coordinate either way at once (one batched simulation), moves
to the best candidate while one gains, and halves the steps when none does (a compass
search; Kolda, Lewis and Torczon 2003). The coordinates, in the driver's own terms:

- ``period``: the period, the tick nearest ``pivot_s`` held in place (the ticks turn
  about the windows' middle, so the period is not traded against the phase);
- ``ticks``: the ticks and the latency moved against each other (which command samples
  are taken changes, when the valve acts does not);
- ``latency``: when the valve acts after each tick;
- for a pulse-width modulator, ``full_command`` (V, the duty's scale), ``pulse_trim``
  and ``alignment`` (where the pulse lies in its period).
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.command_clock import (
    ALIGNMENT,
    FULL_COMMAND,
    LATENCY,
    PERIOD,
    PHASE,
    PULSE_TRIM,
)


def moved(clock: dict, coordinate: str, step: float, pivot_s: float) -> dict:
    """``clock`` (the driver's parameters by name) moved ``step`` along ``coordinate``
    (s for the timings, V for ``full_command``); see the module's list."""
    out = dict(clock)
    if coordinate == "period":
        t0, ph0 = clock[PERIOD], clock[PHASE]
        n = np.floor(pivot_s / t0 - ph0)
        t = t0 + step
        out[PERIOD] = float(t)
        out[PHASE] = float(((ph0 + n) * t0 / t - n) % 1.0)
    elif coordinate == "ticks":
        out[PHASE] = float((clock[PHASE] + step / clock[PERIOD]) % 1.0)
        out[LATENCY] = clock[LATENCY] - step
    elif coordinate == "latency":
        out[LATENCY] = clock[LATENCY] + step
    elif coordinate == "full_command":
        out[FULL_COMMAND] = clock[FULL_COMMAND] + step
    elif coordinate == "pulse_trim":
        out[PULSE_TRIM] = clock[PULSE_TRIM] + step
    elif coordinate == "alignment":
        out[ALIGNMENT] = clock[ALIGNMENT] + step
    else:
        raise ValueError(f"unknown clock coordinate {coordinate!r}")
    return out


def first_steps(clock: dict, duration_s: float) -> dict[str, float]:
    """The compass's first step per coordinate: a period step that moves the ticks at the
    windows' ends by about a five-hundredth of a period, timing steps of a 360th of a
    period, a full command step of 0.4 %, an alignment step of 1/32 (polled 16 steps
    away: the centre from the edge)."""
    period = clock[PERIOD]
    steps = {"period": 0.004 * period**2 / max(duration_s, period),
             "ticks": period / 360.0, "latency": period / 360.0}
    if FULL_COMMAND in clock:
        steps.update(full_command=0.004 * clock[FULL_COMMAND], pulse_trim=period / 360.0)
    if ALIGNMENT in clock:
        steps["alignment"] = 1.0 / 32.0
    return steps


def polish_clock(rmse, clock: dict, bounds: dict, pivot_s: float, duration_s: float,
                 halvings: int, reach: int = 4, max_batches: int = 200
                 ) -> tuple[dict, float, float]:
    """The compass search from ``clock``.

    Parameters
    ----------
    rmse : callable
        ``rmse(rows) -> (S,)`` training RMSE (Pa; inf or NaN where a simulation failed)
        of the model with each of ``rows``' driver parameters.
    clock : dict
        The driver's parameters (name -> value) where the search starts.
    bounds : dict
        Parameter name -> (lower, upper); a candidate outside is not simulated.
    pivot_s, duration_s : float
        The time (s, on the recordings' clock) the period turns about; the windows' span.
    halvings : int
        The steps are halved this many times before the search ends.
    reach : int
        Each coordinate is polled at 1, 2, 4, ... 2^reach steps either way (a staircase
        has local minima a step apart).
    max_batches : int
        A bound on the batched simulations.

    Returns
    -------
    (clock, rmse_start_Pa, rmse_end_Pa)
    """
    steps = first_steps(clock, duration_s)
    best = dict(clock)
    start_rmse = float(np.asarray(rmse([best]))[0])
    best_rmse = start_rmse if np.isfinite(start_rmse) else np.inf
    left = halvings
    for _ in range(max_batches):
        cands = [moved(best, c, sign * d * 2.0**j, pivot_s) for c, d in steps.items()
                 for sign in (-1.0, 1.0) for j in range(reach + 1)]
        cands = [r for r in cands if all(bounds[k][0] <= v <= bounds[k][1]
                                         for k, v in r.items())]
        got = np.asarray(rmse(cands), dtype=float) if cands else np.zeros(0)
        got = np.where(np.isfinite(got), got, np.inf)
        j = int(np.argmin(got)) if got.size else -1
        if j >= 0 and got[j] < best_rmse:
            best, best_rmse = cands[j], float(got[j])
            continue
        if left == 0:
            break
        left -= 1
        steps = {c: d / 2.0 for c, d in steps.items()}
    return best, start_rmse, best_rmse
