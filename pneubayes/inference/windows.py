"""Recordings cut into prediction windows: the data every trajectory-level fit uses.

The paper judges a model by 2-s open-loop predictions started from the measured
pressure (section VIII). :class:`WindowSet` holds, for several recordings, the window
starts and the measured pressure in each window, simulates a batch of parameter sets
on all of them at once, and returns the residuals.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
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
    starts: np.ndarray  # scored windows
    measured: np.ndarray  # (W, L), scored windows
    source: str
    warmup_starts: np.ndarray  # windows simulated before the scored ones, never scored
    warmup_p0: np.ndarray

    def run_starts(self, model: Model) -> tuple[np.ndarray, np.ndarray, int]:
        """(every start to simulate, its start pressure, number of warm-up windows).

        Warm-up windows only matter to a model with a state the recording does not
        measure (an effect whose ``needs_warmup`` is set, e.g. the chamber temperature);
        others skip them.
        """
        if not any(e.needs_warmup for e in model.effects) or not self.warmup_starts.size:
            return self.starts, self.measured[:, 0], 0
        k = self.warmup_starts.size
        return (np.concatenate([self.warmup_starts, self.starts]),
                np.concatenate([self.warmup_p0, self.measured[:, 0]]), k)


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
    score_from_s : sequence of float, optional
        Per recording, the time (s) from which windows are scored. The recording before
        it is history: with ``stride_s == horizon_s`` it is covered by contiguous
        *warm-up* windows (each restarted from the measured pressure, never scored)
        that bring the unmeasured chamber temperature of a heat-transfer model to the
        first scored window, as a controller's running model would. A held-out stretch
        at the end of a recording is scored this way.
    """

    def __init__(self, recordings, horizon_s: float, stride_s: float,
                 score_from_s=None):
        self.horizon_s = float(horizon_s)
        self.stride_s = float(stride_s)
        recordings = list(recordings)
        if score_from_s is not None and len(score_from_s) != len(recordings):
            raise ValueError(f"score_from_s has {len(score_from_s)} entries for "
                             f"{len(recordings)} recordings")
        blocks = []
        length = None
        for i, rec in enumerate(recordings):
            t = np.asarray(rec.time_s, dtype=np.float64)
            first = 0
            if score_from_s is not None:
                first = int(np.searchsorted(t, float(score_from_s[i]) - 1e-9))
                if first >= t.size:
                    raise ValueError(f"{rec.source}: score_from_s {score_from_s[i]} s is "
                                     "after the recording's end")
            starts, n = window_starts(t[first:], horizon_s, stride_s)
            starts = starts + first
            valid = rec.valid_mask() if hasattr(rec, "valid_mask") else None
            if valid is not None and not valid.all():  # no window touches a masked sample
                bad = np.concatenate([[0], np.cumsum(~valid)])
                starts = starts[bad[starts + n] - bad[starts] == 0]
                if starts.size == 0:
                    continue
            if length is not None and n != length:
                raise ValueError(f"{rec.source}: sample rate differs from the other recordings "
                                 f"({n} vs {length} samples per window)")
            length = n
            p = np.asarray(rec.pressure_Pa, dtype=np.float64)
            idx = starts[:, None] + np.arange(n)[None, :]
            warm = np.zeros(0, dtype=np.int64)
            if first > 0 and np.all(np.diff(starts) == n - 1):  # contiguous windows
                warm = np.arange(first % (n - 1), first, n - 1, dtype=np.int64)
            blocks.append(_Block(Inputs.from_recording(rec), rec.rig(), starts, p[idx],
                                 str(rec.source), warm, p[warm]))
        if not blocks:
            raise ValueError("WindowSet: no recordings" if not recordings else
                             "WindowSet: no window lies within the recordings' valid samples")
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
        """Predictions ``(B, W_total, L)`` for a batch of parameter sets (scored windows)."""
        theta = model.as_matrix(params)

        def one(b):
            starts, p0, k = b.run_starts(model)
            return simulate_windows(model, theta, b.inputs, b.rig, starts, self.length, p0,
                                    solver, check_bounds=False, on_failure=on_failure)[:, k:]
        return np.concatenate(self._each_block(one, theta.shape[0]), axis=1)

    def residuals_and_sensitivity(self, model: Model, params, solver: SolverConfig,
                                  on_failure: str = "raise"):
        """Prediction minus measurement ``(B, W_total, L - 1)`` (window starts dropped)
        and the start sensitivity dp/dp(start) ``(B, W_total, L)`` (starts included)."""
        theta = model.as_matrix(params)

        def one(b):
            starts, p0, k = b.run_starts(model)
            p, s = simulate_windows_sensitivity(model, theta, b.inputs, b.rig, starts,
                                                self.length, p0, solver,
                                                check_bounds=False, on_failure=on_failure)
            return p[:, k:] - b.measured[None], s[:, k:]
        preds, sens = zip(*self._each_block(one, theta.shape[0]))
        return np.concatenate(preds, axis=1)[:, :, 1:], np.concatenate(sens, axis=1)

    def _each_block(self, fn, batch: int) -> list:
        """``fn(block)`` for every block, in order. With fewer parameter sets than
        numba's threads, the blocks run at once, one thread each: a model with a state
        the recording does not measure (a tube's waves, the chamber temperature)
        simulates a recording's windows in order, one task per parameter set, so a
        single set would keep one thread busy and leave the others idle."""
        threads = numba.get_num_threads()
        if batch >= threads or threads < 2 or len(self.blocks) < 2:
            return [fn(b) for b in self.blocks]

        def alone(b):
            numba.set_num_threads(1)  # this worker thread's own setting: the serial kernel
            return fn(b)
        with ThreadPoolExecutor(max_workers=min(threads, len(self.blocks))) as pool:
            return list(pool.map(alone, self.blocks))

    def residuals(self, model: Model, params, solver: SolverConfig,
                  on_failure: str = "raise") -> np.ndarray:
        """Prediction minus measurement ``(B, W_total, L - 1)`` (window starts dropped)."""
        pred = self.simulate(model, params, solver, on_failure)
        return (pred - self.measured[None])[:, :, 1:]
