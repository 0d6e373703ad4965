"""Isolated one-sample spikes of a sampled pressure (sensor or ADC glitches).

A sample is a spike when it sits off the line of its neighbours while they sit on it:
its departure from its neighbours' mean ``d_i = p_i - (p_{i-1} + p_{i+1}) / 2`` exceeds
``SPIKE_NOISE_MULTIPLE`` robust standard deviations of all departures (and
``SPIKE_MIN_Pa``), and its neighbours depart by ``-d_i / 2`` each (between 0.25 and 0.75
of it, opposite in sign), as a single-sample glitch of height ``d_i`` makes them. A valve
reversal bends the pressure at one sample and leaves its neighbours' departures near 0;
it is not a spike. More than ``SPIKE_MAX_SHARE`` of the samples so flagged is the
signal's texture (a ringing near the sample rate), and none is reported.

The plausibility rule ``pressure-spikes`` (:mod:`pneubayes.io.plausibility`) reports them;
a fit's ``despike_pressure`` setting replaces each by its neighbours' mean
(:func:`pneubayes.io.preprocess.prepare_recording`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A spike departs from its neighbours' mean by this many robust SDs of that departure.
SPIKE_NOISE_MULTIPLE = 10.0
#: ... and by at least this much, Pa.
SPIKE_MIN_Pa = 1e3
#: Above this share of the samples flagged, the pattern is texture, not glitches.
SPIKE_MAX_SHARE = 0.05


@dataclass(frozen=True)
class Spikes:
    """The spikes of one pressure series: their sample ``indices``, their ``sizes_Pa``
    (departures from the neighbours' mean, Pa), the ``limit_Pa`` they exceed and the
    robust ``scatter_Pa`` of all departures (Pa)."""

    indices: np.ndarray
    sizes_Pa: np.ndarray
    limit_Pa: float
    scatter_Pa: float


def find_spikes(pressure_Pa) -> Spikes:
    """The isolated one-sample spikes of ``pressure_Pa`` (the module's rule); none for
    fewer than 5 samples or a texture of more than ``SPIKE_MAX_SHARE``."""
    p = np.asarray(pressure_Pa, dtype=np.float64)
    none = np.zeros(0, dtype=np.int64)
    if p.size < 5:
        return Spikes(none, np.zeros(0), np.inf, 0.0)
    departure = p[1:-1] - 0.5 * (p[:-2] + p[2:])  # d at samples 1 .. n-2
    scatter = 1.4826 * float(np.median(np.abs(departure - np.median(departure))))
    limit = max(SPIKE_NOISE_MULTIPLE * scatter, SPIKE_MIN_Pa)
    mid = departure[1:-1]
    spike = np.abs(mid) > limit
    for side in (departure[:-2], departure[2:]):
        share = -side / np.where(mid == 0.0, 1.0, mid)
        spike &= (share > 0.25) & (share < 0.75)
    idx = np.flatnonzero(spike) + 2  # the samples' indices
    if idx.size > SPIKE_MAX_SHARE * p.size:
        idx = none
    return Spikes(idx, np.abs(departure[idx - 1]), limit, scatter)


def despiked(pressure_Pa) -> tuple[np.ndarray, np.ndarray]:
    """``pressure_Pa`` with each spike (:func:`find_spikes`) replaced by its neighbours'
    mean (Pa; a new array), and the replaced samples' indices."""
    p = np.array(pressure_Pa, dtype=np.float64)
    idx = find_spikes(p).indices
    p[idx] = 0.5 * (p[idx - 1] + p[idx + 1])
    return p, idx
