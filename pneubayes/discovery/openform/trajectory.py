"""The open-form search on prediction windows: how an extra mass flow moves the
pressure a model predicts over a window, to first order.

Along a recording, a small extra mass flow ``q(t)`` into the chamber changes the
pressure the model predicts over a window started from the measured pressure by ``dp``,
which follows the chamber's pressure equation (eq. 5) linearised about the path::

    d(dp)/dt = J dp + G q,    dp(window start) = 0,

``J = d(dp/dt)/dp`` the model's slope and ``G = kappa Rs T / (V + kappa p C)`` the
pressure rate one kg/s gives (both from
:func:`~pneubayes.discovery.openform.signals.path_signals`). Over each sample interval,
``q`` held: ``dp_{k+1} = exp(J h) dp_k + G h phi1(J h) q_k`` (``phi1(x) = (e^x - 1) /
x``). A closure term's column is its feature's response; the target is the windows'
residual, measured minus predicted. Regressing one on the other searches the quantity
the verification scores, integrated over the window as a weak form integrates a
derivative away: a slow term (a small leak during a hold) accumulates over a window
instead of vanishing in one interval's noise.

What the linearisation leaves out (a sensor's lag, an acoustic line's states, the
term's effect on the flows through the chamber's pressure beyond ``J``) the refit
through the simulator restores; the search only ranks and starts terms.
"""

from __future__ import annotations

import numpy as np


def pressure_gain(signals: dict, rig) -> np.ndarray:
    """``G = kappa Rs T / (V + kappa p C)``: the pressure rate (Pa/s) one kg/s into the
    chamber gives along ``signals`` (eq. 5; T the supply's temperature)."""
    g = rig.gas
    kappa = g.heat_capacity_ratio
    denom = (np.asarray(signals["volume_m3"], dtype=np.float64)
             + kappa * np.asarray(signals["pressure_Pa"], dtype=np.float64)
             * np.asarray(signals["compliance_m3_per_Pa"], dtype=np.float64))
    return kappa * g.specific_gas_constant_J_per_kg_K * g.temperature_K / denom


def phi1(x: np.ndarray) -> np.ndarray:
    """``(exp(x) - 1) / x``, 1 at x = 0."""
    x = np.asarray(x, dtype=np.float64)
    small = np.abs(x) < 1e-8
    return np.where(small, 1.0 + 0.5 * x, np.expm1(x) / np.where(small, 1.0, x))


class WindowResponse:
    """The first-order response of a recording's prediction windows to an extra mass
    flow, sampled every ``every`` samples.

    Parameters
    ----------
    signals : dict
        :func:`~pneubayes.discovery.openform.signals.path_signals` of the recording
        (one value per sample interval).
    starts : (W,) int array
        The windows' first samples.
    length : int
        Samples per window, its start included.
    rig : Rig
        Gas constants.
    every : int
        Rows are the window's samples ``every, 2 every, ...`` after its start (the
        response and the residual both; neighbouring samples repeat each other).
    """

    def __init__(self, signals: dict, starts, length: int, rig, every: int):
        self.starts = np.asarray(starts, dtype=np.int64).reshape(-1)
        self.length = int(length)
        if not (isinstance(every, (int, np.integer)) and 1 <= every < self.length):
            raise ValueError(f"every must be an integer in [1, {self.length - 1}], got "
                             f"{every!r}")
        self.every = int(every)
        h = np.asarray(signals["interval_s"], dtype=np.float64)
        if self.starts.size and (self.starts.min() < 0
                                 or self.starts.max() + self.length - 1 > h.size):
            raise ValueError(f"windows of {self.length} samples from starts in "
                             f"[{self.starts.min()}, {self.starts.max()}] run past the "
                             f"{h.size} intervals of the signals")
        jh = np.asarray(signals["jacobian_per_s"], dtype=np.float64) * h
        self.decay = np.exp(jh)
        self.drive = pressure_gain(signals, rig) * h * phi1(jh)
        self.kept = np.arange(self.every, self.length, self.every)  # samples after start

    @property
    def n_rows(self) -> int:
        return self.starts.size * self.kept.size

    @property
    def rows_per_window(self) -> int:
        return int(self.kept.size)

    def __call__(self, values) -> np.ndarray:
        """Per-interval mass flows ``(M,)`` or ``(M, K)`` (kg/s, or a feature per unit
        coefficient) -> the windows' pressure responses at the kept samples,
        ``(W * R,)`` or ``(W * R, K)`` Pa, window by window."""
        v = np.asarray(values, dtype=np.float64)
        flat = v.ndim == 1
        v2 = v[:, None] if flat else v.reshape(v.shape[0], -1)
        w = self.starts.size
        out = np.empty((w, self.kept.size, v2.shape[1]))
        dp = np.zeros((w, v2.shape[1]))
        r = 0
        for j in range(self.length - 1):
            k = self.starts + j  # each window's interval j
            dp = self.decay[k, None] * dp + self.drive[k, None] * v2[k]
            if r < self.kept.size and j + 1 == self.kept[r]:
                out[:, r] = dp
                r += 1
        out = out.reshape(w * self.kept.size, v2.shape[1])
        return out[:, 0] if flat else out.reshape(out.shape[0], *v.shape[1:])

    def sample(self, window_values) -> np.ndarray:
        """A per-window quantity ``(W, L - 1)`` (samples 1 .. L - 1 of each window, e.g.
        a residual) at the kept samples, ``(W * R,)``."""
        x = np.asarray(window_values, dtype=np.float64)
        if x.shape != (self.starts.size, self.length - 1):
            raise ValueError(f"expected ({self.starts.size}, {self.length - 1}) window "
                             f"values, got {x.shape}")
        return x[:, self.kept - 1].reshape(-1)
