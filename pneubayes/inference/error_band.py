"""A calibrated band of a model's k-step prediction error, for chance constraints.

A posterior's draws carry the parameters' uncertainty, and its noise model carries
misfit as if it were stationary noise. Where the model misses an effect (a tube's delay,
say) its error is neither: it is small while the pressure holds and large while the
pressure moves fast, and it grows with the horizon. :class:`PredictionErrorBand`
measures that error where it can be measured, on recordings: predictions started at the
measured pressure (as a controller's are), their error at each horizon step, and its
upper quantile by horizon and by how fast the prediction has moved since its start.
A controller adds the band to its predicted pressure before testing an upper limit.

The band is empirical (no model of the error), so it holds where the calibration
recordings went: a prediction faster than any calibrated gets the fastest bin's margin.
"""

from __future__ import annotations

import numpy as np

from pneubayes.evaluation import predict_windows
from pneubayes.simulation import SolverConfig


class PredictionErrorBand:
    """Upper ``quantile`` of ``measured - predicted`` pressure by horizon step and rate.

    Follows the scikit-learn contract: the constructor stores settings, :meth:`fit`
    learns ``margin_Pa_`` and ``rate_edges_Pa_s_``, :meth:`margin` applies them, and
    :meth:`partial_fit` adds errors met later (a controller's own, in closed loop) and
    refits on all of them.

    Parameters
    ----------
    quantile : the quantile of the signed error ``measured - predicted`` (0.5, 1)
    rate_bins : number of bins of the prediction's rate; edges at equal quantiles of
        the calibration's rates (so the bins follow the data, not fixed units)
    min_count : fewest errors a (step, bin) cell needs; emptier cells take the nearest
        slower bin's margin (or the nearest faster one's)

    The rate of a prediction at step k is the largest ``|p_j - p_{j-1}| / dt`` over its
    steps ``j <= k`` (Pa/s): how fast it has moved since its start. The margin is made
    non-decreasing in both the step and the rate (an error that shrinks with the horizon
    or the rate is sampling noise of the quantile), and at least 0 (a model that
    over-predicts somewhere does not loosen the limit there). Step 0 is the measured
    start: margin 0.
    """

    def __init__(self, quantile: float = 0.95, rate_bins: int = 5, min_count: int = 30):
        self.quantile = quantile
        self.rate_bins = rate_bins
        self.min_count = min_count

    def _check(self):
        if not 0.5 < float(self.quantile) < 1.0:
            raise ValueError(f"quantile must be in (0.5, 1), got {self.quantile!r}")
        if int(self.rate_bins) != self.rate_bins or self.rate_bins < 1:
            raise ValueError(f"rate_bins must be an integer >= 1, got {self.rate_bins!r}")
        if int(self.min_count) != self.min_count or self.min_count < 1:
            raise ValueError(f"min_count must be an integer >= 1, got {self.min_count!r}")

    @staticmethod
    def rate_Pa_s(predicted_Pa, dt_s: float) -> np.ndarray:
        """The largest ``|dp/dt|`` since the start, Pa/s, ``(..., L)`` (0 at step 0)."""
        p = np.asarray(predicted_Pa, dtype=np.float64)
        r = np.abs(np.diff(p, axis=-1)) / dt_s
        r = np.maximum.accumulate(r, axis=-1)
        return np.concatenate([np.zeros(p.shape[:-1] + (1,)), r], axis=-1)

    def fit(self, predicted_Pa, measured_Pa, dt_s: float) -> "PredictionErrorBand":
        """Learn the band from predictions ``(W, L)`` started at ``measured_Pa[:, 0]`` and
        the measurements ``(W, L)`` on the same grid of step ``dt_s`` (s)."""
        self._check()
        pred = np.asarray(predicted_Pa, dtype=np.float64)
        meas = np.asarray(measured_Pa, dtype=np.float64)
        if pred.ndim != 2 or pred.shape != meas.shape or pred.shape[1] < 2:
            raise ValueError(f"predicted_Pa and measured_Pa must both be (W, L) with L >= 2,"
                             f" got {pred.shape} and {meas.shape}")
        if not (np.isfinite(pred).all() and np.isfinite(meas).all()):
            raise ValueError("predicted_Pa and measured_Pa must be finite")
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
        n_w, n_l = pred.shape
        if n_w < self.min_count:
            raise ValueError(f"{n_w} windows are fewer than min_count={self.min_count}")
        rate = self.rate_Pa_s(pred, dt_s)
        err = meas - pred
        qs = np.linspace(0.0, 1.0, int(self.rate_bins) + 1)[1:-1]
        edges = np.quantile(rate[:, 1:], qs)
        which = np.searchsorted(edges, rate, side="right")
        margin = np.full((n_l, int(self.rate_bins)), np.nan)
        count = np.zeros((n_l, int(self.rate_bins)), dtype=np.int64)
        for k in range(1, n_l):
            for b in range(int(self.rate_bins)):
                e = err[which[:, k] == b, k]
                count[k, b] = e.size
                if e.size >= self.min_count:
                    margin[k, b] = np.quantile(e, self.quantile)
            filled = np.flatnonzero(np.isfinite(margin[k]))
            if filled.size == 0:  # every cell thin: the step's errors pooled
                margin[k] = np.quantile(err[:, k], self.quantile)
                continue
            for b in np.flatnonzero(~np.isfinite(margin[k])):
                slower = filled[filled < b]
                margin[k, b] = margin[k, slower[-1] if slower.size else filled[0]]
        margin[0] = 0.0
        margin = np.maximum(margin, 0.0)
        margin = np.maximum.accumulate(np.maximum.accumulate(margin, axis=0), axis=1)
        self.margin_Pa_ = margin
        self.count_ = count
        self.predicted_Pa_, self.measured_Pa_ = pred, meas
        self.rate_edges_Pa_s_ = edges
        self.dt_s_ = float(dt_s)
        return self

    def partial_fit(self, predicted_Pa, measured_Pa, dt_s: float | None = None
                    ) -> "PredictionErrorBand":
        """Add windows ``(W', L)`` to those the band was fitted on and refit on all of
        them (``dt_s``, if given, must be the fitted one); unfitted, the same as
        :meth:`fit`. The refit's cost grows with the windows (about 11 ms for 4000 x 31
        on this project's VM): in a fast control loop, refit beside the loop or
        seldom, not every tick."""
        if not hasattr(self, "margin_Pa_"):
            if dt_s is None:
                raise ValueError("partial_fit on an unfitted band needs dt_s")
            return self.fit(predicted_Pa, measured_Pa, dt_s)
        if dt_s is not None and abs(dt_s - self.dt_s_) > 1e-12 * self.dt_s_:
            raise ValueError(f"dt_s={dt_s} differs from the fitted {self.dt_s_}")
        pred = np.asarray(predicted_Pa, dtype=np.float64)
        meas = np.asarray(measured_Pa, dtype=np.float64)
        n_l = self.predicted_Pa_.shape[1]
        if pred.ndim != 2 or pred.shape != meas.shape or pred.shape[1] != n_l:
            raise ValueError(f"predicted_Pa and measured_Pa must both be (W, {n_l}), got "
                             f"{pred.shape} and {meas.shape}")
        return self.fit(np.concatenate([self.predicted_Pa_, pred]),
                        np.concatenate([self.measured_Pa_, meas]), self.dt_s_)

    def margin(self, predicted_Pa) -> np.ndarray:
        """The margin ``(..., L')`` (Pa) for predictions ``(..., L')`` on the fitted grid,
        ``L' <= L``: add it to the prediction to bound the measurement's ``quantile``."""
        if not hasattr(self, "margin_Pa_"):
            raise RuntimeError("PredictionErrorBand is not fitted; call fit first")
        p = np.asarray(predicted_Pa, dtype=np.float64)
        if p.shape[-1] > self.margin_Pa_.shape[0]:
            raise ValueError(f"predictions of {p.shape[-1]} steps are longer than the "
                             f"calibrated {self.margin_Pa_.shape[0]}")
        which = np.searchsorted(self.rate_edges_Pa_s_, self.rate_Pa_s(p, self.dt_s_),
                                side="right")
        return self.margin_Pa_[np.arange(p.shape[-1]), which]

    def summary(self) -> dict:
        """The fitted band as plain lists (JSON)."""
        return {"quantile": self.quantile, "dt_s": self.dt_s_,
                "rate_edges_Pa_s": self.rate_edges_Pa_s_.tolist(),
                "margin_Pa": self.margin_Pa_.tolist(), "count": self.count_.tolist()}


def recording_errors(model, params, recordings, steps: int, dt_s: float, stride_s: float,
                     solver: SolverConfig) -> tuple[np.ndarray, np.ndarray]:
    """Predictions from the measured pressure over ``steps`` steps of ``dt_s`` (a
    whole number of each recording's samples), started every ``stride_s``, and the
    measurements, both ``(W, steps + 1)`` Pa over all ``recordings``: what
    :meth:`PredictionErrorBand.fit` takes. ``params`` is one parameter vector."""
    preds, meas = [], []
    for rec in recordings:
        t = np.asarray(rec.time_s, dtype=np.float64)
        sample_s = float(np.median(np.diff(t)))
        per = round(dt_s / sample_s)
        if per < 1 or abs(per * sample_s - dt_s) > 1e-6 * dt_s:
            name = getattr(rec, "source", None) or "recording"
            raise ValueError(f"{name}: dt_s={dt_s} s is not a whole number of its "
                             f"{sample_s} s samples")
        w = predict_windows(model, params, rec, steps * dt_s, stride_s, solver)
        preds.append(w.predicted_Pa[0][:, ::per])
        meas.append(w.measured_Pa[:, ::per])
    return np.concatenate(preds), np.concatenate(meas)
