"""Preprocessing of measured inputs before they drive a model.

The chamber model uses the piston position through the volume and its rate (eq. 5:
``-kappa p dV/dt / V``). A length sensor's white noise, differentiated sample to
sample, becomes a large spurious volume rate: 10 um of noise on a 20 mm bore in a
3.5 cm^3 chamber moves the predicted pressure by several hundred Pa per sample, as
much as the pressure sensor's own noise. The true piston motion is slow (tens of Hz at
most), so the position is low-passed before use. The filter is zero-phase (forward and
backward Butterworth), which suits fitting and scoring recorded data; a controller
passes its own planned (smooth) trajectory instead.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import signal

from pneubayes.io.recording import Recording


def smooth_position(recording: Recording, cutoff_Hz: float | None, order: int = 2) -> Recording:
    """The recording with its ``position_m`` column low-passed at ``cutoff_Hz`` (Hz).

    ``cutoff_Hz`` None or 0 returns the recording unchanged, as does a recording
    without a position column. The input is not modified (recordings are immutable);
    the new recording keeps its ``source``. Raises ``ValueError`` naming the recording
    when the cutoff is not below the Nyquist frequency or the recording is too short
    for the filter.
    """
    if not cutoff_Hz or recording.position_m is None:
        return recording
    t = np.asarray(recording.time_s, dtype=np.float64)
    fs = (t.size - 1) / (t[-1] - t[0])
    where = recording.source or "recording"
    if not 0 < cutoff_Hz < 0.5 * fs:
        raise ValueError(f"{where}: position cutoff {cutoff_Hz:g} Hz must be in (0, "
                         f"{0.5 * fs:g}) Hz (below the Nyquist frequency)")
    sos = signal.butter(order, cutoff_Hz, fs=fs, output="sos")
    # odd extension over 10 filter time constants, so the ends settle (value and slope)
    pad = int(np.ceil(10.0 * fs / cutoff_Hz))
    if t.size <= 2 * pad:
        raise ValueError(f"{where}: {t.size} samples are too few to low-pass the position "
                         f"at {cutoff_Hz:g} Hz (need more than {2 * pad})")
    x = signal.sosfiltfilt(sos, np.asarray(recording.position_m, dtype=np.float64),
                           padtype="odd", padlen=pad)
    return replace(recording, position_m=x)
