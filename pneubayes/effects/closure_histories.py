"""The signals' memories the open-form closure's features read
(:mod:`pneubayes.effects.closure_features`): a series' first-order low-pass
(:class:`SignalHistory`, what ``pressure_relaxation``, ``net_flow_lag`` and the command
lags read), the delayed command's extremes over a trailing window and the valve's areas
there (:class:`HeldCommand`, the dead-time features) and the command's direction
(:func:`held_direction`). The compiled simulator carries the same memories as states
(:mod:`pneubayes.simulation.relaxation`, :mod:`pneubayes.simulation.held`).
"""

from __future__ import annotations

import numpy as np


def first_order_low_pass(time_s, values, tau_s: float, start=None) -> np.ndarray:
    """The first-order low-pass ``y`` of a series (a pressure's ``p_bar``, a flow's
    ``q_bar``; the series' unit): ``tau dy/dt = v - y`` stepped exactly for ``v`` linear
    between its samples, from ``y = start`` (None: the first finite sample, at rest). A
    non-finite sample holds ``y`` (the interval is skipped and the next finite sample
    starts a new segment).

    Parameters
    ----------
    time_s, values : (N,) arrays
        Sample times (s, increasing) and the series.
    tau_s : float
        The time constant, s (> 0).
    start : float or None

    Returns
    -------
    (N,) array
    """
    t = np.asarray(time_s, dtype=np.float64)
    p = np.asarray(values, dtype=np.float64)
    if t.shape != p.shape or t.ndim != 1:
        raise ValueError(f"first_order_low_pass: time_s and values must be 1-D of one "
                         f"length, got {t.shape} and {p.shape}")
    if not (np.isfinite(tau_s) and tau_s > 0):
        raise ValueError(f"first_order_low_pass: tau_s must be > 0, got {tau_s!r}")
    out = np.empty_like(p)
    if p.size == 0:
        return out
    finite = np.isfinite(p)
    if start is None:
        start = p[np.argmax(finite)] if finite.any() else np.nan
    h = np.diff(t)
    ok = finite[1:] & finite[:-1]
    a = np.exp(-h / tau_s)
    # p linear over [t_k, t_k+1] at slope s: p_bar' = p' - s tau + (p_bar - p + s tau) a
    s = np.where(ok, (p[1:] - p[:-1]) / np.where(h > 0, h, 1.0), 0.0)
    b = np.where(ok, p[1:] - s * tau_s - a * (p[:-1] - s * tau_s), 0.0)
    a = np.where(ok, a, 1.0)  # a skipped interval holds p_bar
    out[0] = float(start)
    if h.size and np.all(a == a[0]):  # uniform sampling, no gap: one linear filter
        from scipy.signal import lfilter  # (imported here: scipy.signal costs the
        # simulator's import about a second, and a plain simulation needs none of it)
        out[1:] = lfilter([1.0], [1.0, -a[0]], b, zi=[a[0] * out[0]])[0]
        return out
    y = out[0]
    for k in range(h.size):  # (a first-order recursion)
        y = a[k] * y + b[k]
        out[k + 1] = y
    return out


class SignalHistory:
    """A signal's series whose first-order low-passes :func:`first_order_low_pass` gives per
    time constant (cached: a search evaluates one time constant many times).

    Parameters
    ----------
    time_s, values : (N,) arrays
        The series (s; the signal's unit), e.g. the measured chamber pressure at a
        recording's interval midpoints.
    """

    def __init__(self, time_s, values):
        self.time_s = np.asarray(time_s, dtype=np.float64)
        self.values = np.asarray(values, dtype=np.float64)
        self._cache: dict[float, np.ndarray] = {}

    def relaxed(self, tau_s: float) -> np.ndarray:
        """The low-pass at the series' points for time constant ``tau_s`` (s)."""
        key = float(tau_s)
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = first_order_low_pass(self.time_s, self.values, key)
        return self._cache[key]


class HeldCommand:
    """The delayed command's extremes over a trailing window and the valve's port areas
    there: what the dead-time features read.

    The command is held between its samples and takes effect ``delay_s`` after each
    (before the first: ``before``, else the first sample's). At a time t its highest
    (lowest) value over ``[t - d, t]`` is the position of a valve that follows the
    command's falls (rises) ``d`` s late and its other changes at once.

    Parameters
    ----------
    times_s : (M,) array
        Where the features are evaluated, s.
    command_times_s, command : (N,) arrays
        The command's sample times (s, increasing) and values (the command's unit).
    delay_s : float
        The command's delay (s).
    before : float or None
        The command held before its first sample.
    port_areas : callable
        ``port_areas(command_values) -> (a_in, a_ex)``, m^2, the valve's map at the
        evaluation points (e.g. :func:`pneubayes.simulation.rates.port_areas` of a slot
        row).
    """

    def __init__(self, times_s, command_times_s, command, delay_s: float, before,
                 port_areas):
        self.times_s = np.asarray(times_s, dtype=np.float64)
        u = np.asarray(command, dtype=np.float64)
        # index 0: the command held before the first sample takes effect
        self._held = np.concatenate(([u[0] if before is None else float(before)], u))
        self._shifted = np.asarray(command_times_s, dtype=np.float64) + float(delay_s)
        self._port_areas = port_areas
        self._now_index = np.searchsorted(self._shifted, self.times_s, side="right")
        self._now_areas = None
        self._cache: dict[tuple[float, str], tuple[np.ndarray, np.ndarray]] = {}

    def extreme(self, dead_time_s: float, late: str) -> np.ndarray:
        """The command's highest (``late="fall"``) or lowest (``"rise"``) value over the
        last ``dead_time_s`` s at each evaluation time."""
        if late not in ("fall", "rise"):
            raise ValueError(f"HeldCommand: late must be 'fall' or 'rise', got {late!r}")
        if not (np.isfinite(dead_time_s) and dead_time_s > 0):
            raise ValueError(f"HeldCommand: dead_time_s must be > 0, got {dead_time_s!r}")
        now = self._now_index
        old = np.searchsorted(self._shifted, self.times_s - dead_time_s, side="right")
        pick = np.maximum if late == "fall" else np.minimum
        out = self._held[now]
        for k in range(int(np.max(now - old, initial=0))):  # (short windows: a few samples)
            out = pick(out, self._held[np.minimum(old + k, now)])
        return out

    def area_change(self, dead_time_s: float, port: str, late: str) -> np.ndarray:
        """``port``'s (``"inlet"`` or ``"exhaust"``) area at :meth:`extreme` less its area
        at the command now, m^2."""
        key = (float(dead_time_s), late)
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            if self._now_areas is None:
                self._now_areas = self._port_areas(self._held[self._now_index])
            a_in, a_ex = self._port_areas(self.extreme(dead_time_s, late))
            self._cache[key] = (a_in - self._now_areas[0], a_ex - self._now_areas[1])
        return self._cache[key][0 if port == "inlet" else 1]


def command_direction(command, before=None) -> np.ndarray:
    """The held command's direction once each sample is in force: the sign of its last
    change up to and including sample k (+1 a rise, -1 a fall, 0 none yet).

    Parameters
    ----------
    command : (N,) array
        The command samples (held between them).
    before : float or None
        The command held before the first sample (``Inputs.command_before_start``; its
        change to sample 0 counts); None: none.

    Returns
    -------
    (N,) array of -1.0, 0.0 or 1.0
    """
    u = np.asarray(command, dtype=np.float64)
    prev = np.concatenate(([u[0] if before is None else float(before)], u[:-1]))
    step = np.sign(u - prev)
    changed = np.nonzero(step)[0]
    if not changed.size:
        return np.zeros(u.size)
    last = np.searchsorted(changed, np.arange(u.size), side="right") - 1
    return np.where(last >= 0, step[changed[np.maximum(last, 0)]], 0.0)


def held_direction(times_s, time_s, command, delay_s=0.0, before=None) -> np.ndarray:
    """:func:`command_direction` of the command delayed by ``delay_s`` at ``times_s``:
    the direction of the sample in force, the last j with ``time_s[j] + delay_s <= t``
    (0 before the first sample takes over, as the pre-trigger command is held)."""
    d = command_direction(command, before)
    j = np.searchsorted(np.asarray(time_s, dtype=np.float64) + delay_s,
                        np.asarray(times_s, dtype=np.float64), side="right") - 1
    return np.where(j >= 0, d[np.maximum(j, 0)], 0.0)
