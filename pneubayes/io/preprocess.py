"""Preprocessing of measured inputs before they drive a model.

The chamber model uses the piston position through the volume and its rate (eq. 5:
``-kappa p dV/dt / V``). A length sensor's white noise, differentiated sample to
sample, becomes a large spurious volume rate: 10 um of noise on a 20 mm bore in a
3.5 cm^3 chamber moves the predicted pressure by several hundred Pa per sample, as
much as the pressure sensor's own noise. The true piston motion is slow (tens of Hz at
most), so the position is low-passed before use. The filter is zero-phase (forward and
backward Butterworth), which suits fitting and scoring recorded data; a controller
passes its own planned (smooth) trajectory instead.

The measured supply pressure drives the inlet of a model with ``supply_fluctuation``.
Its sensor noise is noise in a regressor, which pulls the fitted supply gain towards 0
(errors in variables: by about the noise variance over the supply's variance, 0.2 % for
500 Pa of noise on 12 kPa of wander, several posterior SDs). A supply fed through a
hose varies slowly, so the supply column is low-passed too.

:func:`prepare_recording` applies a fit's whole preparation, as its model card records
it: both low-passes, the pressure's isolated one-sample spikes replaced by their
neighbours' mean where the fit asked for it (:func:`despike_pressure`), and the
pressure channel's anti-alias filter when one is declared (the recording format does
not carry it; the simulator then predicts the reading).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np
from scipy import signal

from pneubayes.io.recording import Recording
from pneubayes.io.spikes import despiked
from pneubayes.physics.sensor_filter import PressureFilter


def _lowpass_column(recording: Recording, column: str, cutoff_Hz: float | None,
                    order: int) -> Recording:
    """The recording with ``column`` low-passed (zero-phase Butterworth) at ``cutoff_Hz``."""
    values = getattr(recording, column)
    if not cutoff_Hz or values is None:
        return recording
    what = column.split("_")[0]
    t = np.asarray(recording.time_s, dtype=np.float64)
    fs = (t.size - 1) / (t[-1] - t[0])
    where = recording.source or "recording"
    if not 0 < cutoff_Hz < 0.5 * fs:
        raise ValueError(f"{where}: {what} cutoff {cutoff_Hz:g} Hz must be in (0, "
                         f"{0.5 * fs:g}) Hz (below the Nyquist frequency of this "
                         f"{fs:.3g}-Hz recording); set a lower one or 0 for the raw "
                         f"{what}: fit's --{what}-cutoff (0: raw), discover's --set "
                         f"fit.{what}_cutoff_Hz=0")
    sos = signal.butter(order, cutoff_Hz, fs=fs, output="sos")
    # odd extension over 10 filter time constants, so the ends settle (value and slope);
    # a short recording (a triggered trial) is extended by as much as it has
    pad = min(int(np.ceil(10.0 * fs / cutoff_Hz)), t.size - 1)
    if t.size < 8:
        raise ValueError(f"{where}: {t.size} samples are too few to low-pass the {what} "
                         f"(need at least 8); set 0 for the raw {what}")
    x = signal.sosfiltfilt(sos, np.asarray(values, dtype=np.float64), padtype="odd",
                           padlen=pad)
    return replace(recording, **{column: x})


def smooth_position(recording: Recording, cutoff_Hz: float | None, order: int = 2) -> Recording:
    """The recording with its ``position_m`` column low-passed at ``cutoff_Hz`` (Hz).

    ``cutoff_Hz`` None or 0 returns the recording unchanged, as does a recording
    without a position column. The input is not modified (recordings are immutable);
    the new recording keeps its ``source``. Raises ``ValueError`` naming the recording
    when the cutoff is not below the Nyquist frequency or the recording is too short
    for the filter.
    """
    return _lowpass_column(recording, "position_m", cutoff_Hz, order)


def smooth_inputs(recording: Recording, cutoffs: Mapping[str, float | None]) -> Recording:
    """Both low-passes: ``cutoffs["position_cutoff_Hz"]`` and
    ``cutoffs["supply_cutoff_Hz"]`` (a missing key or None: that column raw), as a fit
    records them in its model card."""
    out = smooth_position(recording, cutoffs.get("position_cutoff_Hz"))
    return smooth_supply(out, cutoffs.get("supply_cutoff_Hz"))


def smooth_supply(recording: Recording, cutoff_Hz: float | None, order: int = 2) -> Recording:
    """The recording with its ``supply_pressure_Pa`` column low-passed at ``cutoff_Hz``
    (Hz); as :func:`smooth_position` otherwise (unchanged without a supply column)."""
    return _lowpass_column(recording, "supply_pressure_Pa", cutoff_Hz, order)


def despike_pressure(recording: Recording) -> Recording:
    """The recording with each isolated one-sample spike of its pressure
    (:func:`pneubayes.io.spikes.find_spikes`) replaced by its neighbours' mean (the same
    recording where there is none)."""
    p, idx = despiked(recording.pressure_Pa)
    return recording if idx.size == 0 else replace(recording, pressure_Pa=p)


def prepare_recording(recording: Recording, preparation: Mapping) -> Recording:
    """The recording as a fit uses it: :func:`smooth_inputs` with
    ``preparation``'s cutoffs, its pressure despiked where
    ``preparation["despike_pressure"]`` is true (:func:`despike_pressure`; absent:
    not), and ``preparation["pressure_filter"]`` (a
    :class:`~pneubayes.physics.sensor_filter.PressureFilter`, its dict form, or
    None/absent: the reading is the chamber pressure) declared on it."""
    out = smooth_inputs(recording, preparation)
    if preparation.get("despike_pressure"):
        out = despike_pressure(out)
    filt = preparation.get("pressure_filter")
    if filt is not None and not isinstance(filt, PressureFilter):
        filt = PressureFilter.from_dict(filt, source=recording.source or "recording")
    return out if filt is None else replace(out, pressure_filter=filt)
