"""An online posterior for the quantities of a plant that change between or within runs.

A fitted model's fixed quantities (the valves, the circuit) stay at their fitted values;
the *varying* ones (a test lung's compliance and resistance, a chamber's volume) are
tracked while the samples arrive, so a controller's predictions follow the plant.

Method: a particle filter over the varying quantities in log space, by resample-move
(Gilks & Berzuini 2001) with a sliding likelihood (docs/architecture.md, "The online
tracker", has each step in full):

1. *Prior*: a population (:mod:`pneubayes.inference.population`): the log-normal of
   other runs' point fits widened by a floor, or log-uniform over the bounds.
2. *Drift* (optional): a Gaussian step in log space between ticks,
   ``drift_log_per_sqrt_s`` per root second, reflected at the bounds.
3. *Reweight* at every tick: each particle is simulated from the measured pressure
   ``lookback_s`` before the tick's last sample (after warm-up windows that bring the
   unmeasured states there) and the new samples score it with Gaussian errors of
   ``noise_std_Pa`` (or a scale that follows the run's errors, ``adapt_noise_s``), the
   log-likelihood times ``temper`` in (0, 1] (correlated residuals would otherwise
   collapse the posterior at once).
4. *Resample* (systematic) below ``ess_threshold`` x the particles as ESS.
5. *Rejuvenate*: ``n_moves`` random-walk Metropolis moves in log space whose target is
   the prior times the tempered likelihood of the last ``memory_s`` seconds. An
   approximation: the weights carry the whole run, the moves only the recent samples.

*Carried states* (``update_mode="carried"``): each particle carries its model state
(:func:`~pneubayes.simulation.simulate_carried`) and a tick simulates only its new
samples, from its pressure moved by ``pressure_gain`` of its error towards the measured
one; ``lookback_s`` is not read. Resampling copies the states; a move's proposal is
scored on, and takes the state of, a replay from a fresh state ``(1 + warm_up_windows)
x memory_s`` back (docs/architecture.md, "Carried states").

Why: the varying quantities are few, the model is a simulator (no gradients), and a
controller needs the predictive distribution at every tick at a bounded cost; the
particles are the draws a :class:`~pneubayes.inference.predictive.PressurePredictor`
simulates. Refitting the run so far gives a point, no uncertainty, at a growing cost.
Every knob is an argument of :class:`OnlineTracker`; randomness comes only from the
generator passed to :meth:`OnlineTracker.reset`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.inference.predictive import PressurePredictor
from pneubayes.model import Model
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    fresh_carry,
    simulate_carried,
    simulate_windows,
)

#: The tracker's update modes (:class:`OnlineTracker`'s ``update_mode``).
UPDATE_MODES = ("lookback", "carried")


def systematic_resample(weights, rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling (one uniform draw for all the particles).

    Parameters
    ----------
    weights : (N,) normalised weights
    rng : numpy.random.Generator

    Returns
    -------
    (N,) int ndarray
        Indices of the particles kept, in order.
    """
    w = np.asarray(weights, dtype=np.float64)
    n = w.size
    positions = (rng.uniform() + np.arange(n)) / n
    cum = np.cumsum(w)
    cum[-1] = 1.0
    return np.searchsorted(cum, positions)


class OnlineTracker:
    """Sequential Monte Carlo over a model's varying quantities (see the module's text).

    Parameters
    ----------
    model, rig, solver, params : Model, Rig, SolverConfig, mapping of str to float
        Every parameter's value in ``params``; the varying ones (the prior's) are tracked.
    prior : LogNormalPrior or LogUniformPrior
        Over the varying quantities (its ``names``).
    noise_std_Pa : float
        Scale of a prediction's Gaussian errors, Pa (the model's error, not the sensor's).
    n_particles, n_moves : int
        Particles; Metropolis moves after each resample (0: none).
    lookback_s, memory_s : float
        A tick's predictions start from the measured pressure ``lookback_s`` before its
        last sample; the moves' target scores the last ``memory_s`` (<= ``lookback_s``).
    warm_up_windows : int
        Windows of ``lookback_s`` before that start that bring unmeasured states to it.
    temper, ess_threshold : float
        The likelihood's power in (0, 1]; resample below this share of particles as ESS.
    move_scale, move_floor_log, drift_log_per_sqrt_s : float
        The random walk's scale relative to the particles' spread; its least log SD; the
        log SD per root second of the quantities' walk between ticks (0: constant).
    adapt_noise_s, history_s : float
        > 0: the error scale follows the run's own errors (an exponential average over
        this many seconds, never below ``noise_std_Pa``); 0: fixed. Samples kept before
        the windows (a delayed or lagging valve's command history).
    update_mode, pressure_gain : {"lookback", "carried"}, float in [0, 1]
        ``"carried"``: each particle carries its state, a tick simulates its new samples
        from its pressure moved by ``pressure_gain`` of its error (module's text).

    Attributes
    ----------
    particles_, log_weights_ : ndarray
        ``(N, k)`` log values and ``(N,)`` normalised log weights.
    ess_, acceptance_, noise_scale_Pa_ : float
        Effective sample size; the last moves' accept rate; the error scale in use, Pa.
    n_resamples_, time_s_ : int, float or None
    pressure_Pa_, carry_ : ndarray or None
        Carried: the last predicted pressures ``(N,)``, Pa; the other states, ``(N, ·)``.
    """

    def __init__(self, model: Model, params: Mapping[str, float], prior, rig,
                 solver: SolverConfig, noise_std_Pa: float, n_particles: int = 64,
                 lookback_s: float = 1.0, warm_up_windows: int = 1, temper: float = 1.0,
                 ess_threshold: float = 0.5, n_moves: int = 1, move_scale: float = 0.5,
                 move_floor_log: float = 1e-3, memory_s: float = 1.0,
                 drift_log_per_sqrt_s: float = 0.0, adapt_noise_s: float = 0.0,
                 history_s: float = 0.0, update_mode: str = "lookback",
                 pressure_gain: float = 1.0):
        self.model = model
        self.params = dict(params)
        self.prior = prior
        self.rig = rig
        self.solver = solver
        self.noise_std_Pa = noise_std_Pa
        self.n_particles = n_particles
        self.lookback_s = lookback_s
        self.warm_up_windows = warm_up_windows
        self.temper = temper
        self.ess_threshold = ess_threshold
        self.n_moves = n_moves
        self.move_scale = move_scale
        self.move_floor_log = move_floor_log
        self.memory_s = memory_s
        self.drift_log_per_sqrt_s = drift_log_per_sqrt_s
        self.adapt_noise_s = adapt_noise_s
        self.history_s = history_s
        self.update_mode = update_mode
        self.pressure_gain = pressure_gain

    # ------------------------------------------------------------------ checks
    def _check(self) -> None:
        def positive(name, low=0.0, high=None, integer=False):
            v = getattr(self, name)
            ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            ok = ok and np.isfinite(v) and v > low and (high is None or v <= high)
            if integer:
                ok = ok and int(v) == v
            if not ok:
                rng = f"in ({low:g}, {high:g}]" if high is not None else f"> {low:g}"
                raise ValueError(f"OnlineTracker: {name} must be {'an integer ' if integer else ''}"
                                 f"{rng}, got {v!r}")
        positive("noise_std_Pa")
        positive("n_particles", 1, integer=True)
        positive("lookback_s")
        positive("temper", high=1.0)
        positive("ess_threshold", high=1.0)
        positive("move_scale")
        positive("move_floor_log")
        if self.update_mode not in UPDATE_MODES:
            raise ValueError(f"OnlineTracker: update_mode must be one of {UPDATE_MODES}, "
                             f"got {self.update_mode!r}")
        positive("memory_s", high=float(self.lookback_s) if self.update_mode == "lookback"
                 else None)
        g = self.pressure_gain
        if not (isinstance(g, (int, float, np.integer, np.floating)) and not isinstance(g, bool)
                and 0.0 <= g <= 1.0):
            raise ValueError(f"OnlineTracker: pressure_gain must be a number in [0, 1], "
                             f"got {g!r}")
        if self.update_mode == "carried" and self.rig.pressure_filter is not None:
            raise ValueError("OnlineTracker: update_mode 'carried' cannot carry a declared "
                             "pressure filter's reading (computed over whole windows); use "
                             "'lookback'")
        if self.update_mode == "carried" and self.model.relaxes_reading:
            raise ValueError("OnlineTracker: update_mode 'carried' cannot carry a "
                             "relaxation or a play of the reading (its effect "
                             f"{[e.name for e in self.model.effects if e.relaxes_reading]} "
                             "starts warm from each window's recorded readings); use "
                             "'lookback'")
        for name in ("n_moves", "warm_up_windows"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0):
                raise ValueError(f"OnlineTracker: {name} must be an integer >= 0, got {v!r}")
        for name in ("history_s", "drift_log_per_sqrt_s", "adapt_noise_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool)
                    and np.isfinite(v) and v >= 0):
                raise ValueError(f"OnlineTracker: {name} must be a number >= 0, got {v!r}")
        if not isinstance(self.solver, SolverConfig):
            raise TypeError("OnlineTracker: solver must be a SolverConfig")
        names = tuple(getattr(self.prior, "names", ()))
        if not names:
            raise ValueError("OnlineTracker: the prior names no varying quantity")
        unknown = [n for n in names if n not in self.model.parameter_names]
        if unknown:
            raise ValueError(f"OnlineTracker: varying {unknown} are not parameters of the "
                             f"model; it has {self.model.parameter_names}")
        missing = [n for n in self.model.parameter_names if n not in self.params]
        if missing:
            raise ValueError(f"OnlineTracker: params has no value for {missing}")

    # ------------------------------------------------------------------ state
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.prior.names)

    def reset(self, rng: np.random.Generator) -> "OnlineTracker":
        """Check the arguments, draw the particles from the prior, empty the buffer."""
        self._check()
        if not isinstance(rng, np.random.Generator):
            raise TypeError("rng must be a numpy.random.Generator (np.random.default_rng(seed))")
        self.rng_ = rng
        self.particles_ = self.prior.sample(int(self.n_particles), rng)
        self.log_weights_ = np.full(int(self.n_particles), -np.log(self.n_particles))
        self.ess_ = float(self.n_particles)
        self.n_resamples_ = 0
        self.acceptance_ = None
        self.time_s_ = None
        self._columns = [self.model.parameter_names.index(n) for n in self.names]
        self._base = self.model.vector(self.params)
        self._buf = None
        self._dt = None
        self._last_time = None
        self.noise_scale_Pa_ = float(self.noise_std_Pa)
        self._noise_ms = float(self.noise_std_Pa) ** 2
        self._carried = self.update_mode == "carried"
        self._first = 0  # the buffer's first sample's index in the stream
        self._ends = []  # carried: the stream indices of the ticks' last samples
        self.pressure_Pa_ = None
        self.carry_ = None
        return self

    def theta(self, z) -> np.ndarray:
        """Full parameter matrix ``(n, P)`` for log values ``z`` ``(n, k)``."""
        z = np.atleast_2d(z)
        out = np.repeat(self._base[None, :], z.shape[0], axis=0)
        out[:, self._columns] = np.exp(z)
        return out

    @property
    def weights_(self) -> np.ndarray:
        w = np.exp(self.log_weights_ - self.log_weights_.max())
        return w / w.sum()

    def quantiles(self, q=(0.05, 0.5, 0.95)) -> dict[str, list[float]]:
        """Weighted quantiles of each varying quantity (its unit), ``{name: [...]}``."""
        w = self.weights_
        out = {}
        for j, n in enumerate(self.names):
            order = np.argsort(self.particles_[:, j])
            cw = np.cumsum(w[order]) - 0.5 * w[order]
            out[n] = np.exp(np.interp(q, cw, self.particles_[order, j])).tolist()
        return out

    def draws(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, P)`` parameter draws: a systematic resample of the particles."""
        if n == self.n_particles:
            idx = systematic_resample(self.weights_, rng)
        else:
            idx = rng.choice(self.n_particles, size=n, p=self.weights_)
        return self.theta(self.particles_[idx])

    def predictor(self, n_draws: int, rng: np.random.Generator,
                  quantiles=(0.05, 0.5, 0.95)) -> PressurePredictor:
        """A :class:`PressurePredictor` of ``n_draws`` resampled particles: the updated
        quantiles for a controller's candidate commands. Its windows start with every
        state the recording does not measure at the measured pressure (as the
        predictor's always do); :meth:`forecast` carries them from the recent samples."""
        return PressurePredictor(self.model, self.draws(n_draws, rng), self.rig,
                                 self.solver, quantiles)

    # ------------------------------------------------------------------ streaming
    def update(self, time_s, command_V, pressure_Pa, exhaust_command=None,
               position_m=None, supply_pressure_Pa=None) -> "OnlineTracker":
        """Take a block of new samples (1-D arrays of equal length; ``position_m``
        default: the rig's fixed position 0, ``supply_pressure_Pa`` the rig's supply),
        reweight, and resample and move when the effective sample size is low."""
        if not hasattr(self, "particles_"):
            raise RuntimeError("OnlineTracker: call reset(rng) before update")
        block = self._block(time_s, command_V, pressure_Pa, exhaust_command, position_m,
                            supply_pressure_Pa)
        m = block[0].size
        self._append(block)
        n_buf = self._buf[0].size
        if self._carried and self.pressure_Pa_ is None:  # the stream's first sample
            n = int(self.n_particles)
            self.pressure_Pa_ = np.full(n, self._buf[2][0])
            self.carry_ = fresh_carry(n, self.rig)
            self._ends = [self._first]
        if self._carried and n_buf < 2 or not self._carried and n_buf < 3:
            self.time_s_ = float(self._buf[0][-1])
            return self
        if self.drift_log_per_sqrt_s > 0 and self._last_time is not None:
            step = self.drift_log_per_sqrt_s * np.sqrt(self._buf[0][-1] - self._last_time)
            moved = self.particles_ + step * self.rng_.normal(size=self.particles_.shape)
            lo, hi = self.prior.log_lower, self.prior.log_upper
            moved = np.where(moved < lo, 2 * lo - moved, moved)  # reflected at the bounds
            self.particles_ = np.clip(np.where(moved > hi, 2 * hi - moved, moved), lo, hi)
        gap = None if self._last_time is None else self._buf[0][-1] - self._last_time
        self._last_time = float(self._buf[0][-1])
        if self._carried:
            ll, r = self._tick_carried()
        else:
            ll, r = self._loglik(self.particles_, min(m, n_buf - 1), residuals=True)
        if self.adapt_noise_s > 0 and gap is not None:
            ok = np.isfinite(ll)
            w = self.weights_[ok]
            mean_r = (w / w.sum()) @ r[ok] if ok.any() else np.zeros(0)
            if mean_r.size:
                a = 1.0 - np.exp(-gap / self.adapt_noise_s)
                self._noise_ms = (1.0 - a) * self._noise_ms + a * float(np.mean(mean_r**2))
                self.noise_scale_Pa_ = max(float(self.noise_std_Pa), np.sqrt(self._noise_ms))
        self.log_weights_ = self.log_weights_ + ll
        self.log_weights_ -= np.logaddexp.reduce(self.log_weights_)
        if not np.isfinite(self.log_weights_).any():  # every particle failed: start over
            raise FloatingPointError("OnlineTracker: no particle simulates the samples at "
                                     f"t = {self._buf[0][-1]:g} s")
        w = self.weights_
        self.ess_ = float(1.0 / np.sum(w**2))
        if self.ess_ < self.ess_threshold * self.n_particles:
            self._resample_move(w)
        self.time_s_ = float(self._buf[0][-1])
        return self

    def _block(self, t, u, p, ue, x, ps):
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        n = t.size
        cols = [t, u, p]
        for _name, v, default in (("exhaust_command", ue, 0.0), ("position_m", x, 0.0),
                                  ("supply_pressure_Pa", ps, self.rig.supply_pressure_Pa)):
            cols.append(np.full(n, default) if v is None else v)
        out = []
        for name, c in zip(("time_s", "command_V", "pressure_Pa", "exhaust_command",
                            "position_m", "supply_pressure_Pa"), cols):
            a = np.atleast_1d(np.asarray(c, dtype=np.float64))
            if a.shape != (n,) or not np.all(np.isfinite(a)):
                raise ValueError(f"update: {name} must be finite and of time_s's shape {(n,)}, "
                                 f"got shape {a.shape}")
            out.append(a)
        if n == 0:
            raise ValueError("update: an empty block")
        self._own_exhaust = ue is not None
        return out

    def _append(self, block) -> None:
        if self._buf is None:
            self._buf = block
        else:
            if block[0][0] <= self._buf[0][-1]:
                raise ValueError(f"update: time_s must increase (block starts at "
                                 f"{block[0][0]:g} s, the last sample was at "
                                 f"{self._buf[0][-1]:g} s)")
            self._buf = [np.concatenate([a, b]) for a, b in zip(self._buf, block)]
        t = self._buf[0]
        if t.size > 1:
            self._dt = float(np.median(np.diff(t[-min(t.size, 50):])))
            span = (self._memory_samples() if self.update_mode == "carried"
                    else self._window_samples())
            keep = span * (1 + int(self.warm_up_windows)) + 1 + int(
                np.ceil(self.history_s / self._dt))
            if self._carried and self._ends:  # never past the last tick's end
                keep = max(keep, self._first + t.size - self._ends[-1])
            if t.size > keep:
                self._first += t.size - keep
                self._buf = [a[-keep:] for a in self._buf]

    def _window_samples(self) -> int:
        return max(2, int(round(self.lookback_s / self._dt)))

    def _memory_samples(self) -> int:
        return max(1, int(round(self.memory_s / self._dt)))

    def _inputs(self) -> Inputs:
        t, u, p, ue, x, ps = self._buf
        return Inputs(t, u, x, ps, None, ue if self._own_exhaust else None, p)

    def _tempered(self, r) -> np.ndarray:
        ll = -0.5 * self.temper * np.sum(r**2, axis=1) / self.noise_scale_Pa_**2
        return np.where(np.isfinite(ll), ll, -np.inf)

    def _tick_carried(self):
        """Carried mode: advance every particle's state over the samples since the last
        tick; their tempered log-likelihood and prediction errors."""
        p = self._buf[2]
        last = self._first + p.size - 1
        done = self._ends[-1]
        g = float(self.pressure_gain)
        p0 = self.pressure_Pa_ + g * (p[done - self._first] - self.pressure_Pa_)
        p0 = np.where(np.isfinite(p0), p0, p[done - self._first])  # (failed: weight 0)
        sim, self.pressure_Pa_ = simulate_carried(
            self.model, self.theta(self.particles_), self._inputs(), self.rig,
            [done - self._first, last - self._first], p0, self.carry_, p, g, self.solver)
        self._ends.append(last)
        while self._ends[0] < self._first:
            self._ends.pop(0)
        r = sim[:, 1:] - p[done - self._first + 1:]
        return self._tempered(r), r

    def _replay(self, z):
        """Carried mode: the particles ``z`` replayed from a fresh state at the measured
        pressure through the kept ticks of the last ``(1 + warm_up_windows) x memory_s``;
        the tempered log-likelihood of the last ``memory_s`` and the states at the end
        (pressure ``(n,)``, carry ``(n, N_CARRY)``)."""
        p = self._buf[2]
        last = self._first + p.size - 1
        span = self._memory_samples() * (1 + int(self.warm_up_windows))
        bounds = [e for e in self._ends if e >= max(self._first, last - span)]
        if bounds[0] == last:  # (a tick longer than the span: from the tick before)
            bounds = self._ends[-2:]
        bounds = np.asarray(bounds) - self._first
        n = z.shape[0]
        carry = fresh_carry(n, self.rig)
        sim, p_end = simulate_carried(self.model, self.theta(z), self._inputs(), self.rig,
                                      bounds, p[bounds[0]], carry, p,
                                      float(self.pressure_gain), self.solver)
        n_mem = min(self._memory_samples(), sim.shape[1] - 1)
        return self._tempered(sim[:, -n_mem:] - p[-n_mem:]), p_end, carry

    def _loglik(self, z, n_scored: int, residuals: bool = False):
        """Tempered log-likelihood of the last ``n_scored`` samples for log values ``z``
        (and with ``residuals`` the prediction errors ``(n, n_scored)``, Pa)."""
        p = self._buf[2]
        n = p.size
        length = min(self._window_samples(), n - 1) + 1
        sim = forecast(self.model, self.theta(z), self._inputs(), self.rig, n - length,
                       length, p, self.solver, int(self.warm_up_windows))
        r = sim[:, -n_scored:] - p[-n_scored:]
        ll = self._tempered(r)
        return (ll, r) if residuals else ll

    def _resample_move(self, w: np.ndarray) -> None:
        z = self.particles_
        mean = w @ z
        cov = ((z - mean).T * w) @ (z - mean)
        cov = self.move_scale**2 * cov + self.move_floor_log**2 * np.eye(z.shape[1])
        chol = np.linalg.cholesky(cov)
        idx = systematic_resample(w, self.rng_)
        z = z[idx]
        if self._carried:
            self.pressure_Pa_ = self.pressure_Pa_[idx]
            self.carry_ = np.ascontiguousarray(self.carry_[idx])
        self.n_resamples_ += 1
        n = z.shape[0]
        self.log_weights_ = np.full(n, -np.log(n))
        self.ess_ = float(n)
        if self.n_moves == 0:
            self.particles_ = z
            return
        n_mem = min(self._memory_samples(), self._buf[0].size - 1)
        accepted = 0
        if self._carried:  # the moves' target and the proposals' states: a replay
            # (once per distinct particle: resampling left duplicates)
            uz, inv = np.unique(z, axis=0, return_inverse=True)
            cur = self._replay(uz)[0][inv.reshape(-1)] + self.prior.logpdf(z)
        else:
            cur = self._loglik(z, n_mem) + self.prior.logpdf(z)
        for _ in range(int(self.n_moves)):
            prop = z + self.rng_.normal(size=z.shape) @ chol.T
            lp = self.prior.logpdf(prop)
            ok = np.isfinite(lp)
            new = np.full(n, -np.inf)
            if ok.any() and self._carried:
                ll, p_end, carry = self._replay(prop[ok])
                new[ok] = ll + lp[ok]
            elif ok.any():
                new[ok] = self._loglik(prop[ok], n_mem) + lp[ok]
            accept = np.log(self.rng_.uniform(size=n)) < new - cur
            if self._carried and accept.any():
                # an accepted proposal's state: its replay's (rows of the ok ones)
                row = np.cumsum(ok) - 1
                self.pressure_Pa_ = np.where(accept, p_end[row], self.pressure_Pa_)
                self.carry_ = np.ascontiguousarray(
                    np.where(accept[:, None], carry[row], self.carry_))
            z = np.where(accept[:, None], prop, z)
            cur = np.where(accept, new, cur)
            accepted += int(accept.sum())
        self.acceptance_ = accepted / (n * int(self.n_moves))
        self.particles_ = z


def forecast(model: Model, theta, inputs: Inputs, rig, start: int, length: int,
             pressure_Pa, solver: SolverConfig, warm_up_windows: int = 1) -> np.ndarray:
    """Predict ``length`` samples from sample ``start``, from the measured pressure there.

    The states the recording does not measure (a second compartment's pressure, a
    tube's waves) are brought to the start by up to ``warm_up_windows`` contiguous
    warm-up windows of the same length before it (as many as the inputs hold; each
    restarted from the measured pressure, the kernel carrying the other states across
    them).

    Parameters
    ----------
    model : Model
    theta : (B, P) parameter sets
    inputs : Inputs
        The drive signals, reaching back over the warm-up and on over the window.
    rig : Rig
    start : int
        The window's first sample.
    length : int
        Samples of the window, its start included.
    pressure_Pa : (N,) measured pressure, Pa absolute (the windows' starts)
    solver : SolverConfig
    warm_up_windows : int

    Returns
    -------
    (B, length) ndarray
        Predicted pressure, Pa (column 0 the measured start; NaN rows where a set
        fails to simulate).
    """
    p = np.asarray(pressure_Pa, dtype=np.float64)
    n_warm = min(int(warm_up_windows), start // (length - 1)) if length > 1 else 0
    s = start - (length - 1) * np.arange(n_warm, -1, -1)
    return simulate_windows(model, theta, inputs, rig, s, length, p[s], solver,
                            check_bounds=False, on_failure="nan")[:, -1, :]
