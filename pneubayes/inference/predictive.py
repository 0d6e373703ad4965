"""Posterior-predictive pressure: bands for rolling windows, and a controller API.

Each posterior draw (model parameters plus AR(1) noise) is simulated from the measured
pressure over the horizon. The noise model of the likelihood is added: stationary AR(1)
measurement noise, and the start's own noise carried through the window by the start
sensitivity (``r_k = n_k - S_k n_0``, see :mod:`pneubayes.inference.likelihood`), so the
bands are predictive for *measurements*, which is what their coverage is checked
against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.effects.command_clock import command_delay_s
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.effects.spool_lag import spool_settle_s
from pneubayes.evaluation import window_starts
from pneubayes.model import Model
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    simulate_windows,
    simulate_windows_sensitivity,
)

#: The command span (command units) a speed-limited spool is assumed to ramp across when
#: the predictor sizes its command history (the kernel itself looks back over the
#: commands' actual span).
RAMP_SPAN = 20.0


def estimate_noise_std(pressure_Pa) -> float:
    """White-noise std of a sampled pressure, Pa, from its second differences.

    ``std(p[k+1] - 2 p[k] + p[k-1]) / sqrt(6)`` is unbiased for white noise on a signal
    whose curvature per sample is small; the median absolute deviation makes it robust
    to the kinks at command steps.
    """
    d2 = np.diff(np.asarray(pressure_Pa, dtype=np.float64), 2)
    mad = np.median(np.abs(d2 - np.median(d2)))
    return float(1.4826 * mad / np.sqrt(6.0))


def noise_floor_Pa(recordings) -> float:
    """The recordings' noise floor: the median over recordings of
    :func:`estimate_noise_std` of their pressure, Pa (fits and discovery report errors
    against it)."""
    return float(np.median([estimate_noise_std(r.pressure_Pa) for r in recordings]))


def ar1_noise(rng: np.random.Generator, sigma, rho, shape,
              stationary: bool = False) -> np.ndarray:
    """AR(1) sequences ``shape = (N, W, K)`` with per-draw sigma and rho ``(N,)``.

    They start from zero, or with ``stationary`` from the stationary distribution
    (column 0 then has variance ``sigma^2 / (1 - rho^2)``).
    """
    e = rng.normal(size=shape) * np.asarray(sigma)[:, None, None]
    out = np.empty(shape)
    rho = np.asarray(rho)[:, None]
    prev = np.zeros(shape[:2])
    if stationary:
        prev = e[:, :, 0] / np.sqrt(1.0 - rho**2)
        out[:, :, 0] = prev
        for k in range(1, shape[2]):
            prev = rho * prev + e[:, :, k]
            out[:, :, k] = prev
        return out
    for k in range(shape[2]):
        prev = rho * prev + e[:, :, k]
        out[:, :, k] = prev
    return out


def window_noise(noise_Pa, sensitivity) -> np.ndarray:
    """The likelihood's residual for a prediction started at the measured pressure,
    ``r_k = n_k - S_k n_0`` (:mod:`pneubayes.inference.likelihood`): ``noise_Pa`` holds
    stationary AR(1) paths ``n`` (last axis the samples, broadcast against
    ``sensitivity``), ``sensitivity`` the start sensitivities ``S`` (1 at the start, so
    nothing is added there)."""
    n = np.asarray(noise_Pa, dtype=np.float64)
    return n - np.asarray(sensitivity) * n[..., :1]


@dataclass(frozen=True)
class PredictionBands:
    """Rolling-window predictions of one recording.

    Arrays are ``(W, L)``: window w starts at sample ``starts[w]``; column 0 is the
    measured start. Quantiles are of the posterior predictive (noise included); ``mean``
    is the posterior mean of the noise-free prediction.
    """

    time_s: np.ndarray
    starts: np.ndarray
    measured: np.ndarray
    mean: np.ndarray
    q05: np.ndarray
    q25: np.ndarray
    q50: np.ndarray
    q75: np.ndarray
    q95: np.ndarray
    working_range_Pa: float
    noise_floor_Pa: float

    def metrics(self) -> dict:
        m, y = self.mean[:, 1:], self.measured[:, 1:]
        rmse = float(np.sqrt(np.mean((m - y) ** 2)))
        c90 = float(np.mean((y >= self.q05[:, 1:]) & (y <= self.q95[:, 1:])))
        c50 = float(np.mean((y >= self.q25[:, 1:]) & (y <= self.q75[:, 1:])))
        lo, hi = np.percentile(y, [1, 99])
        width = float(np.median(self.q95[:, 1:] - self.q05[:, 1:]))
        # white sensor noise alone gives a 90 % band 2 x 1.645 noise floors wide: a band
        # much wider covers because the noise model absorbed misfit, not because the
        # model predicts
        return {"rmse_Pa": rmse, "rmse_percent_of_range": 100.0 * rmse / self.working_range_Pa,
                "measured_span_Pa": float(hi - lo),
                "rmse_percent_of_span": 100.0 * rmse / float(hi - lo) if hi > lo else None,
                "coverage_50": c50, "coverage_90": c90, "noise_floor_Pa": self.noise_floor_Pa,
                "rmse_over_noise_floor": rmse / self.noise_floor_Pa,
                "band_90_width_Pa": width,
                "band_90_width_over_sensor_noise": width / (2 * 1.645 * self.noise_floor_Pa),
                "n_windows": int(self.starts.size), "window_samples": int(self.mean.shape[1])}


class PosteriorPredictive:
    """Posterior draws of a model, ready to predict.

    Parameters
    ----------
    model : Model
    draws : (N, P) model-parameter draws
    noise : (N, 2) draws of (noise_scale_Pa, noise_ar1), or None for noise-free bands
    solver : SolverConfig
    """

    def __init__(self, model: Model, draws, noise, solver: SolverConfig):
        self.model = model
        self.draws = model.as_matrix(draws)
        self.noise = None if noise is None else np.asarray(noise, dtype=np.float64)
        self.solver = solver

    def bands(self, recording, horizon_s: float, stride_s: float,
              rng: np.random.Generator) -> PredictionBands:
        """Predict ``horizon_s`` windows every ``stride_s`` from the measured pressure."""
        starts, length = window_starts(recording.time_s, horizon_s, stride_s)
        valid = recording.valid_mask() if hasattr(recording, "valid_mask") else None
        if valid is not None and not valid.all():  # as a fit: no window on a masked sample
            bad = np.concatenate([[0], np.cumsum(~valid)])
            starts = starts[bad[starts + length] - bad[starts] == 0]
            if starts.size == 0:
                raise ValueError(f"{recording.source}: no {horizon_s:g}-s window lies within "
                                 "the samples its 'valid' column marks valid")
        p = np.asarray(recording.pressure_Pa, dtype=np.float64)
        sim, sens = simulate_windows_sensitivity(
            self.model, self.draws, Inputs.from_recording(recording), recording.rig(),
            starts, length, p[starts], self.solver)
        meas = p[starts[:, None] + np.arange(length)[None, :]]
        noisy = sim.copy()
        if self.noise is not None:
            n = ar1_noise(rng, self.noise[:, 0], self.noise[:, 1], sim.shape,
                          stationary=True)
            noisy += window_noise(n, sens)
        q = np.quantile(noisy, [0.05, 0.25, 0.5, 0.75, 0.95], axis=0)
        t = np.asarray(recording.time_s)[starts[:, None] + np.arange(length)[None, :]]
        return PredictionBands(t, starts, meas, sim.mean(axis=0), *q,
                               working_range_Pa=recording.working_range_Pa,
                               noise_floor_Pa=estimate_noise_std(p))


def draw_quantiles(draws, quantiles) -> np.ndarray:
    """``np.quantile(draws, quantiles, axis=0)`` (its default linear method), bit for
    bit, by one sort: np.quantile partitions the draws once per quantile, 9 x the time
    for 64 draws x 401 samples x 3 quantiles (2.09 against 0.24 ms on a loaded machine).
    Draws with a NaN go to np.quantile itself (a NaN makes its slice NaN)."""
    x = np.asarray(draws, dtype=np.float64)
    s = np.sort(x, axis=0)  # NaN last
    if np.isnan(s[-1]).any():
        return np.quantile(x, quantiles, axis=0)
    q = np.asarray(quantiles, dtype=np.float64)
    pos = (s.shape[0] - 1) * q
    lo = np.floor(pos).astype(np.intp)
    hi = np.minimum(lo + 1, s.shape[0] - 1)
    t = (pos - lo).reshape(q.shape + (1,) * (x.ndim - 1))
    a, b = s[lo], s[hi]
    diff = b - a
    # numpy's interpolation: from the nearer neighbour
    return np.where(t >= 0.5, b - diff * (1.0 - t), a + diff * t)


class PressurePredictor:
    """Controller API: predicted pressure quantiles for candidate command sequences.

    Every (posterior draw, candidate) pair is one window of one compiled call, so the
    batch runs on numba's threads. Simulate on the controller's own grid (``dt_s`` the
    control period, e.g. 5 ms at 200 Hz): without dense output the integrator stops at
    every sample, so a finer grid than the command's costs steps and buys nothing.

    Parameters
    ----------
    model : Model
    draws : (N, P) posterior draws (e.g. 64)
    rig : Rig
    solver : SolverConfig
        :meth:`SolverConfig.standard` serves: ``benchmarks/controller.py`` times 64
        draws x 2 s at 200 Hz on 2 threads (3.1-8.0 ms on this project's 2-core VM,
        whose speed moves between days) and finds them within 19-98 Pa of the
        reference preset (1e-7 to 2.4e-6 m^3). With dense output
        (:meth:`SolverConfig.sampling`, or any config's
        :meth:`SolverConfig.with_dense_output`) steps cross the samples where the
        command holds, reading those samples from the step's interpolant
        (:func:`pneubayes.simulation.simulate_windows`; models with a sensor lag or a
        second state step as without it). ``benchmarks/controller.py --quick`` on a
        quiet machine (64 draws x 2 s at 200 Hz, 2 threads, worst over the volumes):
        2.60 ms against 3.95 ms; largest error against the reference preset 14-82 Pa
        at 200 Hz (19-98 Pa stopping at every sample) and 47-119 Pa at 1 kHz (12-293
        Pa), within 0.1 % of a 450-kPa range.
    quantiles : the quantiles returned (default 5/50/95 %)
    """

    def __init__(self, model: Model, draws, rig, solver: SolverConfig,
                 quantiles=(0.05, 0.5, 0.95)):
        self.model = model
        self.draws = model.as_matrix(draws)
        self.rig = rig
        self.solver = solver
        self.quantiles = tuple(quantiles)
        slots = model.lower(self.draws, rig)
        #: how far back (s) the valve still sees the command: the longest transport delay
        #: and driver clock's period and latency plus 20 spool time constants (or
        #: settling times of a second-order spool), and a speed-limited spool's ramp
        #: across :data:`RAMP_SPAN` command units, over the draws
        rate = slots[:, SLOT_INDEX["spool_rate_limit_V_per_s"]]
        ramp = np.where(rate > 0.0, RAMP_SPAN / np.where(rate > 0.0, rate, 1.0), 0.0)
        self.lookback_s = float(np.max(command_delay_s(slots)
                                       + slots[:, SLOT_INDEX["command_clock_period_s"]]
                                       + 20.0 * spool_settle_s(slots) + ramp))
        #: whether a draw's sensor zero moves on the recording's clock (sensor_drift):
        #: then every candidate is simulated from ``time_s`` on its own
        self.clocked = bool(np.any(slots[:, [SLOT_INDEX["reading_drift_Pa_per_s"],
                                             SLOT_INDEX["reading_warm_up_Pa"]]] != 0.0))

    def predict_draws(self, pressure_Pa: float, commands_V, position_m, dt_s: float,
                      supply_pressure_Pa=None, command_history_V=None,
                      time_s: float = 0.0, reading_history_Pa=None) -> np.ndarray:
        """Pressure of every draw under every candidate, ``(N, C, L + 1)`` Pa.

        ``commands_V`` is ``(C, L)`` (each held for ``dt_s``) or ``(L,)``; ``position_m``
        and ``supply_pressure_Pa`` are ``(L + 1,)`` or scalars (default: the rig's
        supply); the first output column is the current pressure. ``command_history_V``
        holds the commands already applied, oldest first, one per ``dt_s`` (what a delayed
        or lagging valve still sees); default: the candidate's first command, held. A
        history shorter than :attr:`lookback_s` is extended back by its oldest command.
        A sticking valve (``valve_stiction``) rests at the oldest command given: pass the
        history since it last moved. ``time_s`` is now on the recording's clock, where a
        drifting sensor's zero is read (:attr:`clocked`; ignored otherwise).
        ``reading_history_Pa`` holds the readings before now, oldest first, one per
        ``dt_s``: a model with a reading closure starts its relaxations warm from them and
        ``pressure_Pa`` (default: at rest at ``pressure_Pa``).
        """
        return self._each_candidate(
            lambda *args: simulate_windows(self.model, self.draws, *args, self.solver,
                                           check_bounds=False),
            pressure_Pa, commands_V, position_m, dt_s, supply_pressure_Pa,
            command_history_V, time_s, reading_history_Pa)

    def _each_candidate(self, run, pressure_Pa, commands_V, position_m, dt_s,
                        supply_pressure_Pa, command_history_V, time_s,
                        reading_history_Pa=None):
        """``run(*window arguments)`` for all candidates at once, or (a clocked model)
        for each from ``time_s``, joined along the candidate axis (1)."""
        rest = (position_m, dt_s, supply_pressure_Pa, command_history_V, time_s,
                reading_history_Pa)
        if not self.clocked:
            return run(*self._windows(pressure_Pa, commands_V, *rest))
        u = np.atleast_2d(np.asarray(commands_V, dtype=np.float64))
        outs = [run(*self._windows(pressure_Pa, u[c:c + 1], *rest))
                for c in range(u.shape[0])]
        if isinstance(outs[0], tuple):
            return tuple(np.concatenate(parts, axis=1) for parts in zip(*outs))
        return np.concatenate(outs, axis=1)

    def predictive_draws(self, pressure_Pa: float, commands_V, position_m, dt_s: float,
                         noise_Pa, supply_pressure_Pa=None, command_history_V=None,
                         time_s: float = 0.0,
                         reading_history_Pa=None) -> tuple[np.ndarray, np.ndarray]:
        """The posterior predictive of the *reading* under every candidate: returns
        ``(pressure_Pa, reading_Pa)``, both ``(N, C, L + 1)``: :meth:`predict_draws`'s
        pressure, and the same plus each draw's noise as the
        likelihood models it for a prediction started at the measured pressure,
        ``r_k = n_k - S_k n_0`` (:mod:`pneubayes.inference.likelihood`): ``n`` is the
        stationary AR(1) noise and ``S_k`` the start sensitivity, so the start's own
        noise is not counted twice (a reading one tick ahead is close to the one now).

        ``noise_Pa`` is ``(N, L + 1)``: one noise path per draw on the candidates' grid
        (e.g. :func:`ar1_noise` with ``stationary=True`` at the recording rate, read every
        ``dt_s``); every candidate sees the same path (common random numbers). The other
        arguments are :meth:`predict_draws`'.
        """
        noise = np.asarray(noise_Pa, dtype=np.float64)
        length = np.atleast_2d(np.asarray(commands_V)).shape[-1] + 1
        if noise.shape != (self.draws.shape[0], length):
            raise ValueError(f"noise_Pa must be (draws, L + 1) = "
                             f"{(self.draws.shape[0], length)}, got {noise.shape}")
        sim, sens = self._each_candidate(
            lambda *args: simulate_windows_sensitivity(self.model, self.draws, *args,
                                                       self.solver, check_bounds=False),
            pressure_Pa, commands_V, position_m, dt_s, supply_pressure_Pa,
            command_history_V, time_s, reading_history_Pa)
        return sim, sim + window_noise(noise[:, None, :], sens)

    def _windows(self, pressure_Pa, commands_V, position_m, dt_s, supply_pressure_Pa,
                 command_history_V, time_s=0.0, reading_history_Pa=None):
        """(inputs, rig, starts, length, start pressures): one window per candidate, the
        first starting at ``time_s``."""
        dt = float(dt_s)
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt_s must be finite and > 0, got {dt_s!r}")
        u = np.atleast_2d(np.asarray(commands_V, dtype=np.float64))
        if u.ndim != 2 or u.shape[1] < 1:
            raise ValueError(f"commands_V must be (C, L) or (L,) with L >= 1, got shape "
                             f"{np.shape(commands_V)}")
        n_c, n_l = u.shape
        n_h = int(np.ceil(self.lookback_s / dt)) + 1
        if command_history_V is None:
            hist = np.repeat(u[:, :1], n_h, axis=1)
        else:
            h = np.asarray(command_history_V, dtype=np.float64).reshape(-1)
            if h.size == 0:
                raise ValueError("command_history_V is empty; pass None for no history")
            n_h = max(n_h, h.size)
            h = np.concatenate([np.full(n_h - h.size, h[0]), h])
            hist = np.broadcast_to(h, (n_c, n_h))
        reading = None
        if reading_history_Pa is not None:
            r = np.asarray(reading_history_Pa, dtype=np.float64).reshape(-1)
            if r.size == 0 or not np.all(np.isfinite(r)):
                raise ValueError("reading_history_Pa must be a non-empty array of finite "
                                 "readings (Pa), oldest first")
            if r.size > n_h:  # (the command history reaches as far back, held)
                hist = np.concatenate([np.repeat(hist[:, :1], r.size - n_h, axis=1), hist],
                                      axis=1)
                n_h = r.size
            # each candidate's history block: the readings and now's, NaN before them and
            # after now (each block's relaxations warm up from its own first reading)
            reading = np.concatenate([np.full(n_h - r.size, np.nan), r,
                                      [float(pressure_Pa)], np.full(n_l, np.nan)])
        x = np.broadcast_to(np.asarray(position_m, dtype=np.float64), (n_l + 1,))
        sup = np.broadcast_to(np.asarray(self.rig.supply_pressure_Pa if supply_pressure_Pa
                                         is None else supply_pressure_Pa, np.float64),
                              (n_l + 1,))
        # one block per candidate: its history, then the candidate (the last command held
        # to the end); blocks one sample apart in time, each window starting after its
        # history
        block = n_h + n_l + 1
        t_block = (np.arange(block) - n_h) * dt
        offsets = np.arange(n_c) * (block + 1) * dt
        t = float(time_s) + (offsets[:, None] + t_block[None, :]).reshape(-1)
        cmd = np.concatenate([hist, u, u[:, -1:]], axis=1).reshape(-1)
        pos = np.concatenate([np.full(n_h, x[0]), x])
        sp = np.concatenate([np.full(n_h, sup[0]), sup])
        inputs = Inputs(t, cmd, np.tile(pos, n_c), np.tile(sp, n_c),
                        reading_Pa=None if reading is None else np.tile(reading, n_c))
        starts = np.arange(n_c) * block + n_h
        return inputs, self.rig, starts, n_l + 1, np.full(n_c, float(pressure_Pa))

    def predict(self, pressure_Pa: float, commands_V, position_m, dt_s: float,
                supply_pressure_Pa=None, command_history_V=None,
                time_s: float = 0.0, reading_history_Pa=None) -> np.ndarray:
        """Quantiles ``(C, Q, L + 1)`` of the pressure under each candidate (Pa); the
        arguments are :meth:`predict_draws`'."""
        sim = self.predict_draws(pressure_Pa, commands_V, position_m, dt_s,
                                 supply_pressure_Pa, command_history_V, time_s,
                                 reading_history_Pa)
        return np.moveaxis(draw_quantiles(sim, self.quantiles), 0, 1)
