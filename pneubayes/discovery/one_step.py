"""One-step-ahead prediction errors: the dp/dt residual in discrete, exact form.

The paper's equation error compares a differentiated pressure with the model's dp/dt;
both are biased at every command step, exactly where delays and lags show. Instead we
integrate the model over each sample interval from the *measured* pressure with the
compiled simulator and compare with the next measured sample:

    e[k] = p[k+1] - p_model(t[k+1] | p(t[k]) = p[k]),

the integral of the dp/dt residual over the interval, with no derivative and no
interpolation of a fast transient. The predictions are of the chamber pressure, with no
declared pressure filter applied: each starts from a measured reading, which already
holds the filter's rounding of a nearby corner, so adding the corner term again
(:mod:`pneubayes.simulation.measurement`) would count it twice.

Rows of the regression are sums of ``block`` consecutive errors (Pa); a candidate term
is the same sum of the difference between the one-step predictions with and without
the candidate mechanism.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter

from pneubayes.model import Model
from pneubayes.simulation import Inputs, SolverConfig, simulate_windows


def first_order_lag(values: np.ndarray, dt_s: float, time_constant_s: float) -> np.ndarray:
    """First-order lag of a held signal sampled every ``dt_s``, from ``values[0]``.

    Exact at the sample times for a signal held between samples.
    """
    v = np.asarray(values, dtype=np.float64)
    if time_constant_s <= 0:
        return v.copy()
    a = np.exp(-dt_s / time_constant_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], v, zi=[a * v[0]])
    return y


@dataclass(frozen=True)
class OneStepData:
    """One recording prepared for one-step predictions."""

    recording: object
    inputs: Inputs
    rig: object
    block: int

    @property
    def n_rows(self) -> int:
        return (self.recording.n_samples - 1) // self.block

    def valid_rows(self) -> np.ndarray:
        """Per row (block of intervals), whether all its samples are valid (the
        recording's ``valid`` column)."""
        ok = self.recording.valid_mask()
        rows = np.arange(self.n_rows)
        bad = np.concatenate([[0], np.cumsum(~ok)])  # invalid samples before each index
        # row r spans samples r * block .. (r + 1) * block
        return bad[(rows + 1) * self.block + 1] - bad[rows * self.block] == 0

    def rows(self, per_interval: np.ndarray) -> np.ndarray:
        """Sum ``(..., N - 1)`` per-interval values over blocks -> ``(..., n_rows)``."""
        v = np.asarray(per_interval)
        n = self.n_rows * self.block
        return v[..., :n].reshape(*v.shape[:-1], self.n_rows, self.block).sum(axis=-1)

    def predict(self, model: Model, params, solver: SolverConfig,
                inputs: Inputs | None = None) -> np.ndarray:
        """One-step predictions ``(B, N - 1)`` of ``p[k+1]`` from the measured ``p[k]``.

        A lagged reading (an effect with a
        :meth:`~pneubayes.effects.Effect.reading_lead_parameter`, the group delay tau:
        a first-order lag's time constant, a second-order lag's 2 z / w) is predicted
        from the chamber ahead of the reading by tau times the reading's rate: the
        chamber's rate without the lag (its one-step increments from the measured
        readings, held over each interval) through a first-order lag of tau, ``q[k] =
        m[k-1] + (q[k-1] - m[k-1]) exp(-h / tau)`` (h the median sample interval), from
        the model and not from differences of noisy readings. A chamber started at the
        reading itself would
        move the reading by only a fraction of its increment in one step."""
        p = np.asarray(self.recording.pressure_Pa, dtype=np.float64)
        inputs = inputs or self.inputs
        theta = model.as_matrix(params)
        starts = np.arange(p.size - 1)
        rate = None
        lags = [e for e in model.effects if e.reading_lead_parameter() is not None]
        lead = np.zeros(theta.shape[0])  # the reading's group delay, s
        for e in lags:
            lead = lead + theta[:, model.parameter_names.index(e.reading_lead_parameter())]
        if np.any(lead > 0):
            plain = theta.copy()
            for e in lags:
                for k, v in e.neutral_values().items():
                    plain[:, model.parameter_names.index(k)] = v
            step = simulate_windows(model, plain, inputs, self.rig, starts, 2, p[:-1], solver,
                                    check_bounds=False)[:, :, 1]
            dt = float(np.median(np.diff(self.recording.time_s)))
            rate = np.zeros(step.shape)
            for b in np.nonzero(lead > 0)[0]:
                a = np.exp(-dt / lead[b])
                m = (step[b] - p[:-1]) / dt  # the chamber's rate over interval k, Pa/s
                rate[b] = lfilter([0.0, 1.0 - a], [1.0, -a], m)
        out = simulate_windows(model, theta, inputs, self.rig, starts, 2, p[:-1], solver,
                               check_bounds=False, initial_rate_Pa_per_s=rate)
        return out[:, :, 1]

    def errors(self, model: Model, params, solver: SolverConfig) -> np.ndarray:
        """One-step errors ``(B, N - 1)``, Pa (measured minus predicted)."""
        p = np.asarray(self.recording.pressure_Pa, dtype=np.float64)
        return p[None, 1:] - self.predict(model, params, solver)

    def lagged_inputs(self, time_constant_s: float) -> Inputs:
        """Inputs whose command has passed through a first-order lag (held mid-interval)."""
        t = self.inputs.time_s
        dt = float(np.median(np.diff(t)))
        u = np.asarray(self.inputs.command_V, dtype=np.float64)
        # value of the lagged held command half-way through each interval
        a = np.exp(-0.5 * dt / time_constant_s)
        lag = first_order_lag(u, dt, time_constant_s)
        before = self.inputs.command_before_start
        prev = np.concatenate([[u[0] if before is None else before], lag[:-1]])
        mid = u + (prev - u) * a
        return self.inputs.with_command(mid)


def one_step_data(recording, block: int) -> OneStepData:
    if block < 1:
        raise ValueError(f"block must be >= 1 sample interval, got {block}")
    if recording.n_samples < block + 1:
        raise ValueError(f"{recording.source}: shorter than one block of {block} intervals")
    # the chamber pressure from each measured reading: no sensor term (see module doc)
    rig = replace(recording.rig(), pressure_filter=None)
    return OneStepData(recording, Inputs.from_recording(recording), rig, block)
