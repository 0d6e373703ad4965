"""Drive signals of the paper's experiments (section VI-B and VII, Fig. 6).

- Random step commands: levels uniform in [-range, +range], each held for a duration
  uniform in [30, 300] ms, switching on the controller's sample clock.
- Aggressive piston motion for moving-volume recordings: minimum-jerk moves between
  random positions across the stroke, with random durations and pauses.
"""

from __future__ import annotations

import numpy as np


def step_commands(time_s, rng: np.random.Generator, range_V: float,
                  hold_s: tuple[float, float] = (0.030, 0.300),
                  clock_s: float | None = None) -> np.ndarray:
    """Random step command on ``time_s`` (V), held between switches.

    Parameters
    ----------
    time_s : (N,) sample times, s.
    rng : numpy Generator (the caller owns the seed).
    range_V : levels are uniform in [-range_V, +range_V], within [-5, 5].
    hold_s : (min, max) hold duration, s.
    clock_s : switches happen on multiples of this period (the controller clock);
        None switches at any sample.
    """
    if not 0 < range_V <= 5.0:
        raise ValueError(f"range_V must be in (0, 5], got {range_V}")
    lo, hi = hold_s
    if not 0 < lo <= hi:
        raise ValueError(f"hold_s must satisfy 0 < min <= max, got {hold_s}")
    t = np.asarray(time_s, dtype=np.float64)
    u = np.empty_like(t)
    t_switch = t[0]
    i = 0
    while i < t.size:
        hold = rng.uniform(lo, hi)
        t_next = t_switch + hold
        if clock_s:
            t_next = t[0] + np.ceil((t_next - t[0]) / clock_s - 1e-9) * clock_s
        j = int(np.searchsorted(t, t_next - 1e-12, side="left"))
        j = max(j, i + 1)
        u[i:j] = rng.uniform(-range_V, range_V)
        i, t_switch = j, t_next
    return u


def _min_jerk(s):
    return s**3 * (10 - 15 * s + 6 * s * s)


def piston_motion(time_s, rng: np.random.Generator, stroke_m: float,
                  move_s: tuple[float, float] = (0.08, 0.6),
                  pause_s: tuple[float, float] = (0.0, 0.4),
                  margin: float = 0.03) -> np.ndarray:
    """Aggressive manual piston motion (m): min-jerk moves between random positions.

    Targets are uniform in ``[margin, 1 - margin]`` of the stroke; a full-stroke move in
    the shortest duration reaches a peak speed of 1.875 stroke / duration.
    """
    t = np.asarray(time_s, dtype=np.float64)
    lo, hi = margin * stroke_m, (1 - margin) * stroke_m
    x = np.empty_like(t)
    pos = rng.uniform(lo, hi)
    t0 = t[0]
    i = 0
    while i < t.size:
        pause = rng.uniform(*pause_s)
        j = int(np.searchsorted(t, t0 + pause, side="left"))
        x[i:j] = pos
        i = max(i, j)
        dur = rng.uniform(*move_s)
        target = rng.uniform(lo, hi)
        j = int(np.searchsorted(t, t0 + pause + dur, side="left"))
        if j > i:
            s = np.clip((t[i:j] - (t0 + pause)) / dur, 0.0, 1.0)
            x[i:j] = pos + (target - pos) * _min_jerk(s)
        pos, t0, i = target, t0 + pause + dur, max(i, j)
    return x
