"""The compass search that polishes a driver's timing
(:mod:`pneubayes.discovery.openform.clock_polish`), on objectives with known optima."""

import numpy as np
import pytest

from pneubayes.discovery.openform.clock_polish import first_steps, moved, polish_clock
from pneubayes.effects.command_clock import (
    ALIGNMENT,
    FULL_COMMAND,
    LATENCY,
    PERIOD,
    PHASE,
    PULSE_TRIM,
)

PIVOT_S = 6.0
BOUNDS = {PERIOD: (0.0, 0.2), PHASE: (0.0, 1.0), LATENCY: (0.0, 0.05),
          FULL_COMMAND: (0.1, 20.0), PULSE_TRIM: (-0.01, 0.01)}
TRUE = {PERIOD: 0.036055, PHASE: 0.0, LATENCY: 0.00175, FULL_COMMAND: 5.0,
        PULSE_TRIM: -0.00037}


def _ticks(clock, times):
    """When the valve acts after the ticks nearest ``times`` (s), and which tick."""
    k = np.round(times / clock[PERIOD] - clock[PHASE])
    return (clock[PHASE] + k) * clock[PERIOD] + clock[LATENCY], k


def _staircase_rmse(rows):
    """An RMSE (Pa) that is a staircase in the timing, as a trajectory error is: the
    valve's action times at 0-13 s against the planted ones, each tick's command sample
    taken on a 1-ms grid, the duty's scale and the trim."""
    times = np.linspace(0.0, 13.0, 400)
    acts, k = _ticks(TRUE, times)
    out = []
    for r in rows:
        got = (r[PHASE] + k) * r[PERIOD] + r[LATENCY]
        sampled = np.floor((got - r[LATENCY]) / 1e-3) - np.floor((acts - TRUE[LATENCY]) / 1e-3)
        out.append(np.sqrt(np.mean((got - acts) ** 2)) * 1e6 + 50.0 * np.mean(sampled != 0)
                   + 1e3 * abs(r[FULL_COMMAND] - 5.0) + 1e6 * abs(r[PULSE_TRIM] - TRUE[PULSE_TRIM]))
    return np.array(out)


def test_each_coordinate_moves_what_its_name_says():
    clock = dict(TRUE)
    period = moved(clock, "period", 1e-6, PIVOT_S)
    a, _ = _ticks(clock, np.array([PIVOT_S]))
    b, _ = _ticks(period, np.array([PIVOT_S]))
    assert period[PERIOD] == pytest.approx(TRUE[PERIOD] + 1e-6)
    assert b[0] == pytest.approx(a[0], abs=1e-12)  # the tick at the pivot held
    ticks = moved(clock, "ticks", 2e-4, PIVOT_S)
    assert ticks[LATENCY] == pytest.approx(TRUE[LATENCY] - 2e-4)
    b, _ = _ticks(ticks, np.array([PIVOT_S]))
    assert b[0] == pytest.approx(a[0], abs=1e-12)  # the valve acts when it did
    assert moved(clock, "latency", 1e-4, PIVOT_S)[LATENCY] == pytest.approx(0.00185)
    assert moved(clock, "full_command", 0.1, PIVOT_S)[FULL_COMMAND] == pytest.approx(5.1)
    assert moved(clock, "pulse_trim", 1e-4, PIVOT_S)[PULSE_TRIM] == pytest.approx(-0.00027)
    aligned = moved({**clock, ALIGNMENT: 0.0}, "alignment", 0.25, PIVOT_S)
    assert aligned[ALIGNMENT] == 0.25
    assert "alignment" in first_steps(aligned, 20.0) and "alignment" not in first_steps(
        clock, 20.0)
    with pytest.raises(ValueError, match="unknown clock coordinate"):
        moved(clock, "phase", 0.1, PIVOT_S)
    assert set(first_steps({PERIOD: 0.01, PHASE: 0.0, LATENCY: 0.0}, 20.0)) \
        == {"period", "ticks", "latency"}


def test_the_search_finds_a_planted_timing_on_a_staircase():
    """From a period 1.7e-6 s short, ticks 0.14 ms late, latency 0.23 ms late and the
    duty's scale 0.6 % high (the spent z00 case's fit), the search ends at the planted
    timing to a few microseconds, never worse than it started."""
    start = {PERIOD: TRUE[PERIOD] - 1.7e-6, PHASE: 0.0039, LATENCY: 0.00198,
             FULL_COMMAND: 5.03, PULSE_TRIM: -0.00036}
    clock, before, after = polish_clock(_staircase_rmse, start, BOUNDS, PIVOT_S, 13.0, 8)
    assert after < 0.02 * before
    assert clock[PERIOD] == pytest.approx(TRUE[PERIOD], abs=5e-8)
    acts, _ = _ticks(clock, np.array([0.0, PIVOT_S, 13.0]))
    want, _ = _ticks(TRUE, np.array([0.0, PIVOT_S, 13.0]))
    assert np.max(np.abs(acts - want)) < 5e-6
    assert clock[FULL_COMMAND] == pytest.approx(5.0, abs=0.005)


def test_the_search_stays_in_bounds_and_never_ends_worse():
    """A latency at its bound of 0 is not stepped below it; a start at the optimum stays
    there; failed simulations (NaN) are never moved to."""
    start = {**TRUE, LATENCY: 0.0}
    clock, before, after = polish_clock(_staircase_rmse, start, BOUNDS, PIVOT_S, 13.0, 4)
    assert clock[LATENCY] >= 0.0 and after <= before
    clock, before, after = polish_clock(_staircase_rmse, dict(TRUE), BOUNDS, PIVOT_S, 13.0, 2)
    assert clock == TRUE and after == before
    failing = lambda rows: np.array([0.0 if r == TRUE else np.nan for r in rows])  # noqa: E731
    clock, before, after = polish_clock(failing, dict(TRUE), BOUNDS, PIVOT_S, 13.0, 2)
    assert clock == TRUE and after == 0.0
