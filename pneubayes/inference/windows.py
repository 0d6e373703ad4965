"""Recordings cut into prediction windows: the data every trajectory-level fit uses.

The paper judges a model by 2-s open-loop predictions started from the measured
pressure (section VIII). :class:`WindowSet` holds, for several recordings, the window
starts and the measured pressure in each window, simulates a batch of parameter sets
on all of them at once, and returns the residuals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.evaluation import window_starts
from pneubayes.model import Model
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    simulate_windows,
    simulate_windows_sensitivity,
)


@dataclass(frozen=True)
class _Block:
    inputs: Inputs
    rig: object
    starts: np.ndarray
    measured: np.ndarray  # (W, L)
    source: str


class WindowSet:
    """Windows of ``horizon_s`` every ``stride_s`` over one or more recordings.

    Parameters
    ----------
    recordings : sequence of Recording
    horizon_s : float
        Window length (2 s in the paper).
    stride_s : float
        Distance between window starts; equal to ``horizon_s`` for non-overlapping
        windows (each sample used once, as a likelihood needs).
    """

    def __init__(self, recordings, horizon_s: float, stride_s: float):
        self.horizon_s = float(horizon_s)
        self.stride_s = float(stride_s)
        blocks = []
        length = None
        for rec in recordings:
            starts, n = window_starts(rec.time_s, horizon_s, stride_s)
            if length is not None and n != length:
                raise ValueError(f"{rec.source}: sample rate differs from the other recordings "
                                 f"({n} vs {length} samples per window)")
            length = n
            p = np.asarray(rec.pressure_Pa, dtype=np.float64)
            idx = starts[:, None] + np.arange(n)[None, :]
            blocks.append(_Block(Inputs.from_recording(rec), rec.rig(), starts, p[idx],
                                 str(rec.source)))
        if not blocks:
            raise ValueError("WindowSet: no recordings")
        self.blocks = tuple(blocks)
        self.length = int(length)

    @property
    def n_windows(self) -> int:
        return sum(b.starts.size for b in self.blocks)

    @property
    def n_residuals(self) -> int:
        """Residuals per parameter set: every window sample except its start."""
        return self.n_windows * (self.length - 1)

    @property
    def measured(self) -> np.ndarray:
        """Measured pressures ``(W_total, L)`` in block order."""
        return np.concatenate([b.measured for b in self.blocks])

    @property
    def working_range_Pa(self) -> float:
        return float(self.blocks[0].rig.working_range_Pa)

    def simulate(self, model: Model, params, solver: SolverConfig,
                 on_failure: str = "raise") -> np.ndarray:
        """Predictions ``(B, W_total, L)`` for a batch of parameter sets."""
        theta = model.as_matrix(params)
        outs = [simulate_windows(model, theta, b.inputs, b.rig, b.starts, self.length,
                                 b.measured[:, 0], solver, check_bounds=False,
                                 on_failure=on_failure)
                for b in self.blocks]
        return np.concatenate(outs, axis=1)

    def residuals_and_sensitivity(self, model: Model, params, solver: SolverConfig,
                                  on_failure: str = "raise"):
        """Prediction minus measurement ``(B, W_total, L - 1)`` (window starts dropped)
        and the start sensitivity dp/dp(start) ``(B, W_total, L)`` (starts included)."""
        theta = model.as_matrix(params)
        preds, sens = [], []
        for b in self.blocks:
            p, s = simulate_windows_sensitivity(model, theta, b.inputs, b.rig, b.starts,
                                                self.length, b.measured[:, 0], solver,
                                                check_bounds=False, on_failure=on_failure)
            preds.append(p - b.measured[None])
            sens.append(s)
        return np.concatenate(preds, axis=1)[:, :, 1:], np.concatenate(sens, axis=1)

    def residuals(self, model: Model, params, solver: SolverConfig,
                  on_failure: str = "raise") -> np.ndarray:
        """Prediction minus measurement ``(B, W_total, L - 1)`` (window starts dropped)."""
        pred = self.simulate(model, params, solver, on_failure)
        return (pred - self.measured[None])[:, :, 1:]
