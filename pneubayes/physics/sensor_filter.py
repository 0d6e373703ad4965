"""The pressure sensor's anti-alias filter, as a known property of the rig.

A DAQ low-passes the pressure before sampling. A delay-compensated (zero-phase) filter,
as an oversampling DAQ with a linear-phase decimator applies, has unit gain and no lag
at low frequency: a smooth pressure passes unchanged to within (f / f_c)^(2 n). What it
changes is a *corner*: where the delayed command switches a port, dp/dt jumps, and the
reading rounds the corner over about one filter time constant on both sides. At 1 kHz
sampling with a 1-kHz filter that is worth tens of Pa per corner (up to a kPa on the
steepest edges), enough to bias a fitted tube delay by a few microseconds -- several
posterior SDs with 2 minutes of data.

For a jump ``D`` (Pa/s) in dp/dt at time ``tau``, the reading differs from the true
pressure by ``D * K(t - tau)``, where ``K = h * r - r`` is the filter's *kink response*:
its response to the unit ramp ``r(s) = max(s, 0)`` minus the ramp. ``K`` vanishes
away from the corner (the zero-phase impulse response ``h`` has unit area and no first
moment), so the correction is local. The correction is exact for piecewise-linear
pressure; the curvature's own jump adds a term smaller by about the filter time
constant over the chamber's (a few per cent).

Only zero-phase filters are described here: a causal (analogue) filter also delays the
whole signal by its group delay, which is a different measurement model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

#: Grid of the kink response, in filter periods 1 / cutoff: step and half-width.
_STEP_PERIODS = 1e-3
_HALF_WIDTH_PERIODS = 20.0
#: The response is cut where it falls below this fraction of its peak.
_SUPPORT_FRACTION = 1e-5


@dataclass(frozen=True)
class PressureFilter:
    """Zero-phase Butterworth anti-alias filter of the pressure channel.

    Parameters
    ----------
    order : int
        Order of the Butterworth prototype (1-8); the zero-phase filter is its
        forward-backward application, magnitude ``1 / (1 + (f / cutoff_Hz)^(2 order))``.
    cutoff_Hz : float
        -3 dB frequency of the prototype, Hz (the bench's DAQ: order 2 at 1 kHz).
    """

    order: int
    cutoff_Hz: float

    def __post_init__(self):
        if isinstance(self.order, bool) or not isinstance(self.order, (int, np.integer)) \
                or not 1 <= self.order <= 8:
            raise ValueError(f"PressureFilter.order must be an integer in 1..8, got "
                             f"{self.order!r}")
        if not (isinstance(self.cutoff_Hz, (int, float)) and math.isfinite(self.cutoff_Hz)
                and self.cutoff_Hz > 0):
            raise ValueError(f"PressureFilter.cutoff_Hz must be a finite number > 0, got "
                             f"{self.cutoff_Hz!r}")
        object.__setattr__(self, "order", int(self.order))
        object.__setattr__(self, "cutoff_Hz", float(self.cutoff_Hz))

    @classmethod
    def parse(cls, text: str) -> "PressureFilter":
        """From ``"ORDER:CUTOFF_HZ"``, e.g. ``"2:1000"``."""
        order, sep, cutoff = str(text).partition(":")
        try:
            if not sep:
                raise ValueError
            return cls(int(order), float(cutoff))
        except ValueError as exc:
            why = f": {exc}" if sep and str(exc) else ""
            raise ValueError(f"pressure filter: expected ORDER:CUTOFF_HZ (e.g. 2:1000), got "
                             f"{text!r}{why}") from None

    def to_dict(self) -> dict:
        return {"order": self.order, "cutoff_Hz": self.cutoff_Hz, "phase": "zero"}

    @classmethod
    def from_dict(cls, data, source: str = "pressure filter") -> "PressureFilter":
        """From :meth:`to_dict`'s form; ``source`` names the file in errors."""
        if not isinstance(data, dict) or "order" not in data or "cutoff_Hz" not in data:
            raise ValueError(f"{source}: a pressure filter needs 'order' and 'cutoff_Hz', "
                             f"got {data!r}")
        if data.get("phase", "zero") != "zero":
            raise ValueError(f"{source}: only zero-phase pressure filters are modelled, got "
                             f"phase {data['phase']!r}")
        try:
            return cls(data["order"], data["cutoff_Hz"])
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None

    @cached_property
    def kink_response(self) -> tuple[np.ndarray, np.ndarray]:
        """``(s, K)``: the kink response ``K(s)`` (s per unit of Pa/s, i.e. seconds) on a
        uniform grid of ``s`` (s) that covers its support; zero outside.

        Computed from the analogue filter's impulse response, approximated by the
        digital Butterworth at 1000 x the cutoff: ``K(s_i) = sum_j h_j (s_i - s_j)_+ ds
        - (s_i)_+``.
        """
        from scipy import signal  # here: importing scipy.signal costs about 1 s

        ds = _STEP_PERIODS / self.cutoff_Hz
        n = int(round(_HALF_WIDTH_PERIODS / _STEP_PERIODS))
        s = ds * np.arange(-n, n + 1)
        sos = signal.butter(self.order, self.cutoff_Hz, fs=1.0 / ds, output="sos")
        impulse = np.zeros(s.size)
        impulse[n] = 1.0 / ds
        h = signal.sosfiltfilt(sos, impulse, padlen=0)
        c0 = np.cumsum(h) * ds
        c1 = np.cumsum(h * s) * ds
        k = s * c0 - c1 - np.maximum(s, 0.0)
        keep = np.nonzero(np.abs(k) > _SUPPORT_FRACTION * np.abs(k).max())[0]
        lo, hi = max(keep[0] - 1, 0), min(keep[-1] + 2, s.size)
        s, k = s[lo:hi], k[lo:hi].copy()
        k[0] = k[-1] = 0.0  # zero outside, continuously
        s.setflags(write=False)
        k.setflags(write=False)
        return s, k
