"""An online posterior by refitting: the run so far, anchored to a shared fit.

:class:`OnlineRefit` is the second sequential method beside the particle filter of
:mod:`pneubayes.inference.online`. Where the plant differs from run to run in more
quantities than a particle filter can carry (a ventilator's valves and circuit as well
as its lung), it refits every chosen quantity on the run so far, each time from the last
estimate:

1. *Prior*: Gaussian, centred on a shared fit (other runs'), each quantity's SD a
   fraction ``relative_sd`` of its scale (one for all, or each its own: how far per-run
   fits of the other runs spread, :func:`~pneubayes.inference.refine.relative_spread`)
   (:meth:`~pneubayes.inference.refine.GaussianAnchor.relative`); the run's windows
   are scored with Gaussian errors of ``error_Pa``.
2. *Update*: the posterior mode, by multiple shooting on the run's 2-s windows (the
   last ``memory_s`` of it, or all), warm-started from the previous mode
   (:class:`~pneubayes.inference.refine.TrajectoryRefiner` with the prior as rows).
3. *Posterior*: Laplace, the Gauss-Newton precision of the windows plus the prior's;
   its draws feed a :class:`~pneubayes.inference.predictive.PressurePredictor`.

Why: with many quantities free, particles spread thin and the posterior mode is what a
refit finds in a second; the prior keeps quantities the run has not yet informed where
other runs put them (unanchored, a refit on a run's first seconds can move them anywhere
the data allow, and mispredict the phases it has not seen). The cost is a refit per
update (under a second for the ventilator's 13 quantities), so a controller refits every
``refit_every_s`` (e.g. in a background thread) and predicts from the latest posterior
at every tick. A Gaussian posterior cannot show a bimodal one; the prior's centre and
width are the user's (choose them on training runs, as ``experiments/real_respiraworks_refit.py``
does).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.stats import norm

from pneubayes.inference.flow_channels import flow_rows
from pneubayes.inference.predictive import PressurePredictor
from pneubayes.inference.refine import GaussianAnchor, TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


class OnlineRefit:
    """Sequential posterior mode and Laplace covariance of ``names`` on the run so far.

    Parameters
    ----------
    model : Model
    params : mapping of str to float
        Every parameter's value (a shared fit): the prior's centre and the first start.
    names : sequence of str
        The quantities refitted (the others stay at ``params``).
    relative_sd : float or mapping of str to float
        Each prior SD as a fraction of the quantity's scale (> 0): one for all, or each
        refitted quantity's own.
    error_Pa : float
        Scale of the windows' Gaussian errors, Pa (the model's, not the sensor's).
    solver : SolverConfig
    horizon_s : float
        The windows' length and stride, s.
    memory_s : float or None
        Refit on the last ``memory_s`` s of the run (None: all of it).
    refit_every_s : float
        :meth:`update` refits when this much of the run is new since the last refit.
    max_nfev : int
        The refit's budget of simulations.
    channels : sequence of FlowChannel
        Measured port flows (:mod:`~pneubayes.inference.flow_channels`) scored beside
        the pressure (none: the pressure alone).
    min_windows : int
        Windows of ``horizon_s`` the run must hold before the first refit (>= 1): a
        refit on one window alone is poorly informed under a wide anchor.

    Attributes
    ----------
    params_ : dict
        Every parameter, the refitted ones at the posterior mode.
    covariance_ : ndarray
        Laplace covariance of ``names`` (their units, in order).
    time_s_, n_refits_, refit_seconds_ : float, int, list of float
        The run's time at the last refit (None before one), refits made, wall time of
        each.
    """

    def __init__(self, model: Model, params: Mapping[str, float], names: Sequence[str],
                 relative_sd: float | Mapping[str, float], error_Pa: float,
                 solver: SolverConfig,
                 horizon_s: float = 2.0, memory_s: float | None = None,
                 refit_every_s: float = 2.0, max_nfev: int = 100, channels=(),
                 min_windows: int = 2):
        self.model = model
        self.params = dict(params)
        self.names = tuple(names)
        self.relative_sd = relative_sd
        self.error_Pa = error_Pa
        self.solver = solver
        self.horizon_s = horizon_s
        self.memory_s = memory_s
        self.refit_every_s = refit_every_s
        self.max_nfev = max_nfev
        self.channels = tuple(channels)
        self.min_windows = min_windows

    def reset(self) -> "OnlineRefit":
        """Check the arguments; the posterior is the prior (the shared fit)."""
        for name in ("horizon_s", "refit_every_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ValueError(f"OnlineRefit: {name} must be > 0, got {v!r}")
        if self.memory_s is not None and not (np.isfinite(self.memory_s)
                                              and self.memory_s >= self.horizon_s):
            raise ValueError(f"OnlineRefit: memory_s must be None or >= horizon_s, got "
                             f"{self.memory_s!r}")
        if not self.names:
            raise ValueError("OnlineRefit: names is empty")
        if not (isinstance(self.min_windows, int) and self.min_windows >= 1):
            raise ValueError(f"OnlineRefit: min_windows must be an integer >= 1, got "
                             f"{self.min_windows!r}")
        missing = [n for n in self.model.parameter_names if n not in self.params]
        if missing:
            raise ValueError(f"OnlineRefit: params has no value for {missing}")
        self.anchor_ = GaussianAnchor.relative(self.model, self.params, self.names,
                                               self.relative_sd, self.error_Pa)
        self.params_ = dict(self.params)
        self.covariance_ = np.diag([self.anchor_.sd[n] ** 2 for n in self.names])
        self.time_s_ = None
        self.n_refits_ = 0
        self.refit_seconds_ = []
        return self

    def update(self, recording, stop: int | None = None) -> "OnlineRefit":
        """Take the run so far, a :class:`~pneubayes.io.Recording` from its first sample
        to the latest (or, with ``stop``, its first ``stop`` samples: a replay need not
        cut the recording at every tick), and refit when ``refit_every_s`` of it is new
        (or none was made); a run shorter than ``min_windows`` windows refits nothing."""
        if not hasattr(self, "anchor_"):
            raise RuntimeError("OnlineRefit: call reset() before update")
        t = np.asarray(recording.time_s[:stop], dtype=np.float64)
        # (a sample's rounding short of the windows counts as holding them)
        if t.size < 2 or t[-1] - t[0] < self.min_windows * self.horizon_s - 1e-9:
            return self
        now = float(t[-1])
        if self.time_s_ is not None and now - self.time_s_ < self.refit_every_s:
            return self
        first = 0
        if self.memory_s is not None and now - t[0] > self.memory_s:
            first = int(np.searchsorted(t, now - self.memory_s))
        rec = recording if first == 0 and stop is None else recording.slice(first, stop)
        started = time.perf_counter()
        extra = None
        if self.channels:
            def extra(theta, rec=rec):
                return flow_rows(self.model, theta, rec, self.channels)
        fit = TrajectoryRefiner(self.model, self.solver, free=self.names,
                                max_nfev=self.max_nfev, anchor=self.anchor_,
                                extra_residuals=extra).fit(
            WindowSet([rec], self.horizon_s, self.horizon_s), self.params_)
        self.refit_seconds_.append(time.perf_counter() - started)
        self.params_ = dict(fit.params_)
        if fit.covariance_ is not None and np.all(np.isfinite(fit.covariance_)):
            self.covariance_ = fit.covariance_
        self.time_s_ = now
        self.n_refits_ += 1
        return self

    def draws(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, P)`` parameter sets: the Laplace posterior's draws, within the bounds."""
        if not isinstance(rng, np.random.Generator):
            raise TypeError("rng must be a numpy.random.Generator (np.random.default_rng(seed))")
        theta = np.repeat(self.model.vector(self.params_)[None, :], n, axis=0)
        cols = [self.model.parameter_names.index(m) for m in self.names]
        mean = theta[0, cols]
        # drawn from the correlation matrix (the quantities' scales differ by up to 30
        # orders of magnitude: a covariance in their units is not decomposed reliably)
        sd = np.sqrt(np.clip(np.diag(self.covariance_), 0.0, None))
        safe = np.where(sd > 0, sd, 1.0)
        corr = self.covariance_ / np.outer(safe, safe)
        lam, vec = np.linalg.eigh(0.5 * (corr + corr.T))
        z = (rng.standard_normal((n, mean.size)) * np.sqrt(np.clip(lam, 0.0, None))) @ vec.T
        z *= sd
        lo, hi = self.model.bounds
        theta[:, cols] = np.clip(mean + z, lo[cols], hi[cols])
        return theta

    def quantiles(self, q=(0.05, 0.5, 0.95)) -> dict[str, list[float]]:
        """Each refitted quantity's Laplace quantiles (its unit), ``{name: [...]}``."""
        sd = np.sqrt(np.clip(np.diag(self.covariance_), 0.0, None))
        z = norm.ppf(np.asarray(q, dtype=np.float64))
        return {n: (self.params_[n] + z * s).tolist() for n, s in zip(self.names, sd)}

    def predictor(self, n_draws: int, rng: np.random.Generator, rig,
                  quantiles=(0.05, 0.5, 0.95)) -> PressurePredictor:
        """A :class:`PressurePredictor` of ``n_draws`` posterior draws on ``rig``: the
        updated quantiles for a controller's candidate commands."""
        return PressurePredictor(self.model, self.draws(n_draws, rng), rig, self.solver,
                                 quantiles)
