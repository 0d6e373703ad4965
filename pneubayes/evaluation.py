"""The paper's metric: open-loop predictions over short windows started from the
measured pressure (section VIII), RMSE in Pa and as a percentage of the working range
(supply minus atmosphere, Table III)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.model import Model
from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

#: The paper's prediction horizon (section VI, Table III), s: open-loop windows of this
#: length started from the measured pressure, the default window length and stride of
#: fits, samplers, refinement, baselines and studies (declared here once).
PAPER_HORIZON_S = 2.0


def window_starts(time_s, horizon_s: float, stride_s: float) -> tuple[np.ndarray, int]:
    """Start indices of windows of ``horizon_s`` every ``stride_s``, and the window length.

    Windows are whole: the last one ends at or before the last sample.
    """
    t = np.asarray(time_s, dtype=np.float64)
    dt = float(np.median(np.diff(t)))
    length = int(round(horizon_s / dt)) + 1
    stride = max(1, int(round(stride_s / dt)))
    if not length >= 3:
        raise ValueError(f"horizon {horizon_s:g} s is shorter than two sample intervals "
                         f"({dt:.3g} s): a window needs several samples")
    if length > t.size:
        raise ValueError(f"horizon {horizon_s} s is longer than the recording "
                         f"({t[-1] - t[0]:.3f} s)")
    return np.arange(0, t.size - length + 1, stride, dtype=np.int64), length


@dataclass(frozen=True)
class WindowPrediction:
    """Predictions ``(B, W, L)`` over windows, with the measured pressure ``(W, L)``."""

    starts: np.ndarray
    length: int
    predicted_Pa: np.ndarray
    measured_Pa: np.ndarray
    working_range_Pa: float

    @property
    def residual_Pa(self) -> np.ndarray:
        return self.predicted_Pa - self.measured_Pa[None]

    def rmse_Pa(self) -> np.ndarray:
        """RMSE per parameter set over all windows (the start sample excluded), Pa."""
        r = self.residual_Pa[:, :, 1:]
        return np.sqrt(np.mean(r * r, axis=(1, 2)))

    def rmse_percent_of_range(self) -> np.ndarray:
        return 100.0 * self.rmse_Pa() / self.working_range_Pa


def predict_windows(model: Model, params, recording, horizon_s: float, stride_s: float,
                    solver: SolverConfig) -> WindowPrediction:
    """Run ``horizon_s`` predictions from the measured pressure every ``stride_s``."""
    starts, length = window_starts(recording.time_s, horizon_s, stride_s)
    inputs = Inputs.from_recording(recording)
    p_meas = np.asarray(recording.pressure_Pa, dtype=np.float64)
    pred = simulate_windows(model, params, inputs, recording.rig(), starts, length,
                            p_meas[starts], solver)
    idx = starts[:, None] + np.arange(length)[None, :]
    return WindowPrediction(starts, length, pred, p_meas[idx], recording.working_range_Pa)
