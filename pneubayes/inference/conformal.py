"""A prediction band calibrated online on the run's own earlier prediction errors.

A model's predictive band (its posterior's or a tracker's draws plus an error model)
covers what it should only if the model's errors on the data at hand are those it was
fitted to expect. A plant that changes between runs makes them larger; the band then
covers less than its level says. :class:`OnlineConformalBand` keeps the band's shape
(its width per step ahead, from the draws) and rescales it by the run's own earlier
errors: the normalised errors ``|y_j - m_j| / s_j`` of the predictions whose outcomes
are already measured (split conformal prediction, Vovk et al. 2005, normalised as in
Lei et al. 2018), at a level that adaptive conformal inference (Gibbs and Candes 2021)
moves after each completed prediction towards the target coverage. Only outcomes
measured before a prediction is made enter its band.

The band then says how large the errors of *this* run have been, not what the model
explains: a band widened this way is misfit made visible, and its width is reported
beside the model's own.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import norm


class OnlineConformalBand:
    """A central band of level ``coverage`` around a predictive mean, rescaled by the
    run's completed predictions.

    Parameters
    ----------
    coverage : float
        Target coverage of the band, in (0, 1).
    min_predictions : int
        Completed predictions needed before the band is rescaled; before, it is the
        model's own band (mean +- z s).
    step : float
        Adaptive conformal inference's step: after each completed prediction the
        miscoverage level moves by ``step`` x (target miss rate - its miss rate).
    memory : int or None
        Completed predictions whose scores are kept (the most recent); None: all.

    Attributes
    ----------
    level_ : float
        The quantile level of the scores the band uses now.
    n_completed_ : int
        Completed predictions so far.
    """

    def __init__(self, coverage: float = 0.9, min_predictions: int = 3,
                 step: float = 0.02, memory: int | None = None):
        if not 0.0 < coverage < 1.0:
            raise ValueError(f"OnlineConformalBand: coverage must be in (0, 1), got "
                             f"{coverage!r}")
        if not (isinstance(min_predictions, int) and min_predictions >= 1):
            raise ValueError(f"OnlineConformalBand: min_predictions must be an integer "
                             f">= 1, got {min_predictions!r}")
        if not (math.isfinite(step) and step >= 0.0):
            raise ValueError(f"OnlineConformalBand: step must be finite and >= 0, got "
                             f"{step!r}")
        if memory is not None and not (isinstance(memory, int) and memory >= 1):
            raise ValueError(f"OnlineConformalBand: memory must be None or an integer "
                             f">= 1, got {memory!r}")
        self.coverage = coverage
        self.min_predictions = min_predictions
        self.step = step
        self.memory = memory
        self.level_ = coverage
        self.n_completed_ = 0
        self._scores: list[np.ndarray] = []
        self._pool: np.ndarray | None = None  # the scores kept, joined once per change
        self._pending: list[tuple[int, np.ndarray, np.ndarray]] = []

    @staticmethod
    def centre_and_scale(draws, noise_std_Pa: float) -> tuple[np.ndarray, np.ndarray]:
        """The predictive mean and the model's own per-step scale of ``draws`` (D, H):
        the draws' spread and the error model's standard deviation in quadrature, Pa."""
        d = np.asarray(draws, dtype=np.float64)
        spread = d.std(axis=0) if d.shape[0] > 1 else np.zeros(d.shape[1])
        scale = np.sqrt(spread**2 + float(noise_std_Pa) ** 2)
        return d.mean(axis=0), np.maximum(scale, 1e-12)

    def interval(self, mean, scale) -> tuple[np.ndarray, np.ndarray]:
        """The band ``(lower, upper)`` around ``mean`` with per-step ``scale`` (Pa): the
        model's own (mean +- z s) until :attr:`min_predictions` have completed, then
        mean +- q s with q the current quantile of the completed scores."""
        mean, scale = np.asarray(mean, float), np.asarray(scale, float)
        if self.n_completed_ < self.min_predictions or self._pool is None:
            half = float(norm.ppf(0.5 + self.coverage / 2.0)) * scale
        else:
            level = min(max(self.level_, 0.0), 1.0)
            q = float(np.quantile(self._pool, level)) if level < 1.0 else math.inf
            half = q * scale
        return mean - half, mean + half

    def predict(self, sample: int, mean, scale) -> tuple[np.ndarray, np.ndarray]:
        """The band of a prediction made at ``sample`` (its first predicted sample is
        ``sample + 1``), remembered so that :meth:`observe` can score it."""
        lo, hi = self.interval(mean, scale)
        self._pending.append((int(sample), np.asarray(mean, float).copy(),
                              np.asarray(scale, float).copy()))
        return lo, hi

    def observe(self, sample: int, measured_Pa) -> int:
        """Score every remembered prediction whose last predicted sample is at or before
        ``sample``, with ``measured_Pa`` the measured pressure indexed by sample (the
        run so far); returns how many completed. Each completed prediction moves the
        level by adaptive conformal inference."""
        y = np.asarray(measured_Pa, dtype=np.float64)
        done = 0
        keep = []
        for start, mean, scale in self._pending:
            end = start + mean.size
            if end > sample or end >= y.size:
                keep.append((start, mean, scale))
                continue
            lo, hi = self.interval(mean, scale)
            outcome = y[start + 1:end + 1]
            miss = float(np.mean((outcome < lo) | (outcome > hi)))
            self._scores.append(np.abs(outcome - mean) / scale)
            if self.memory is not None and len(self._scores) > self.memory:
                self._scores.pop(0)
            self._pool = np.concatenate(self._scores)
            self.n_completed_ += 1
            if self.n_completed_ > self.min_predictions:
                self.level_ += self.step * (miss - (1.0 - self.coverage))
            done += 1
        self._pending = keep
        return done
