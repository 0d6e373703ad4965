"""Pressure derivative from noisy samples: Savitzky-Golay differentiation.

Eq. 10 needs the measured dp/dt. A Savitzky-Golay filter fits a local polynomial in a
sliding window and differentiates it: unbiased for polynomials up to its order, with a
noise gain that falls as the window grows. We chose it over pysindy's smoothed finite
differences because its bias and variance are known in closed form and it handles the
kinks at command switches in a predictable way: samples whose window straddles a
switch are flagged (:func:`switch_mask`) and left out of the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter


@dataclass(frozen=True)
class SavitzkyGolay:
    """Savitzky-Golay differentiator.

    Parameters
    ----------
    window_s : float
        Window length, s (rounded to an odd number of samples, at least polyorder + 2).
    polyorder : int
        Local polynomial order.
    """

    window_s: float
    polyorder: int

    def window_samples(self, dt_s: float) -> int:
        n = int(round(self.window_s / dt_s))
        n = max(n, self.polyorder + 2)
        return n if n % 2 == 1 else n + 1

    def derivative(self, time_s, values) -> np.ndarray:
        """d(values)/dt on a uniform grid (units of values per s)."""
        t = np.asarray(time_s, dtype=np.float64)
        y = np.asarray(values, dtype=np.float64)
        dt = float(np.median(np.diff(t)))
        if np.max(np.abs(np.diff(t) - dt)) > 1e-6 * dt:
            raise ValueError("SavitzkyGolay.derivative needs uniformly sampled time_s")
        n = self.window_samples(dt)
        if n > y.size:
            raise ValueError(f"window of {n} samples is longer than the signal ({y.size})")
        return savgol_filter(y, n, self.polyorder, deriv=1, delta=dt, mode="interp")

    def smooth(self, time_s, values) -> np.ndarray:
        """The smoothed signal (the local polynomial's value)."""
        t = np.asarray(time_s, dtype=np.float64)
        dt = float(np.median(np.diff(t)))
        return savgol_filter(np.asarray(values, np.float64), self.window_samples(dt),
                             self.polyorder, mode="interp")


def switch_mask(command_V, half_window: int) -> np.ndarray:
    """True where no command switch lies within ``half_window`` samples (usable samples).

    The command is held between samples, so a switch at sample i changes the slope of
    the pressure between samples i and i + 1: windows that reach across it are biased.
    """
    u = np.asarray(command_V)
    switches = np.nonzero(np.diff(u) != 0)[0] + 1
    bad = np.zeros(u.size, dtype=bool)
    for s in switches:
        bad[max(0, s - half_window): s + half_window] = True
    bad[:half_window] = True
    bad[-half_window:] = True
    return ~bad


def consistency_mask(time_s, values, fine: SavitzkyGolay, coarse: SavitzkyGolay,
                     noise_std: float, rel_tol: float = 0.05) -> np.ndarray:
    """True where two differentiators agree: ``|d_fine - d_coarse| <= tol``.

    Where the signal bends faster than the windows resolve (a sub-millisecond transient
    in a tiny chamber at 1 kHz), both derivatives are biased and they disagree; there
    the samples carry no reliable dp/dt. ``tol = rel_tol |d_fine| + 3 sigma_d`` with
    sigma_d the fine derivative's noise for white noise of ``noise_std``.
    """
    t = np.asarray(time_s, dtype=np.float64)
    dt = float(np.median(np.diff(t)))
    d1 = fine.derivative(t, values)
    d2 = coarse.derivative(t, values)
    n = fine.window_samples(dt)
    # noise gain of the SG derivative: sqrt(sum of squared coefficients) / dt
    from scipy.signal import savgol_coeffs

    gain = float(np.sqrt(np.sum(savgol_coeffs(n, fine.polyorder, deriv=1, delta=dt) ** 2)))
    return np.abs(d1 - d2) <= rel_tol * np.abs(d1) + 3.0 * noise_std * gain
