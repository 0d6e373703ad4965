"""Closed-loop pressure tracking at 200 Hz with a sampling-based MPC that uses the posterior.

    python experiments/mpc_tracking.py [--out results/mpc] [--seeds 0,1,2,3,4] [--quick]
                                       [--scenario hidden_delay|weak_data|changing_plant]
                                       [--json OUT.json] [--figure OUT.png]
                                       [--no-dense-output]

Figures: OUT/mpc_tracking.png (seed 0's loops) and OUT/mpc_tradeoff.png (violations
against tracking over the seeds, the fixed back-offs as a curve).

``--scenario weak_data`` fits only the delay model on one 2-s recording of small
commands, so the posterior is wide where the controller works (``SCENARIOS``); the
default is the design below. ``--scenario changing_plant`` (issue 67) fits the delay
model as here, then changes the plant during the loop (its volume steps down and
drifts) and compares the frozen posterior, an online one (``OnlineTracker``) and the
point estimate; its figure is OUT/mpc_changing.png (seed 0's loops, the tracked
volume, the seeds' violations and tracking).

Per seed:

1. **Data.** The virtual bench records AIR37 / valve1 at half stroke (two 10-s fixed
   recordings, command ranges +-5 and +-1.5 V) with a hidden 15-ms transport delay (a long
   tube; catalogue ``tube_delay``) beside the orifice leak.
2. **Posterior.** ``pneubayes fit`` (least squares, refinement, emcee) fits the paper's
   model (Gompertz maps, dead volume, leak; no delay) with the bench's declared pressure
   filter. 64 draws of (parameters, AR(1) noise) are taken from the posterior.
3. **Closed loop.** The plant is the planted model (delay and leak at their true values)
   stepped tick by tick by the reference solver; the controller reads it through the
   bench's sensor noise (500 Pa) at 200 Hz. The reference is a seeded sequence of
   pressure set-points (0.5 s each, 1.6-5.0 bar absolute) over 6 s; the safety limit is
   ``P_MAX`` = 4.8 bar, so a set-point above it asks the loop to ride the limit.
   Each tick the MPC scores ``CANDIDATES`` command sequences over a 150-ms horizon (a
   first level for 10 ms, then a second one, from fixed grids, plus the previous best
   plan shifted) and applies the first command of the best. A candidate is
   feasible if its predicted pressure stays under ``P_MAX``; the best feasible one has the
   smallest predicted squared tracking error; with none feasible, the smallest predicted
   excess wins. The controllers differ only in the prediction:

   * ``nominal``: the fit's point estimate (the posterior median of each parameter, the
     model card ``pneubayes fit`` writes), one trajectory;
   * ``nominal_mean``: the same with the posterior mean;
   * ``posterior``: the 64 parameter draws, feasible if the 95 % quantile stays under
     ``P_MAX``, tracking scored on the median;
   * ``predictive``: as ``posterior`` with a path of each draw's fitted stationary AR(1)
     noise added (one fixed path per draw): the posterior predictive, whose noise model
     carries what the paper's model misses on the recordings (here, the delay);
   * ``chance``: chance-constrained: feasible if the predictive's 95 % quantile (as
     ``predictive``) stays under ``P_MAX``, tracking scored on the median of the
     parameter draws without the noise paths (the noise is the risk, not the expected
     path; scoring the noisy median makes the choice among candidates noisy);
   * ``chance_window``: as ``chance``, but its noise is the likelihood's own for a
     prediction started at the measured pressure (``r_k = n_k - S_k n_0``,
     :meth:`PressurePredictor.predictive_draws`): ``predictive`` and ``chance`` add
     stationary noise to a prediction that starts at the reading, so they count the start's
     noise twice and their margin is wider than the posterior's own predictive;
   * ``delay_nominal``, ``delay_chance``, ``delay_chance_window``: ``nominal``,
     ``chance`` and ``chance_window`` on a second fit of
     the same recordings whose model has the bench's tube (``tube_delay``, the effect
     the discovery loop names on such data; its delay fitted, not given);
   * ``nominal_backoff5k`` ... ``_backoff40k``: ``nominal`` with the limit lowered by a
     fixed 5-40 kPa (``BACKOFF_PA``), the margin an engineer adds without a posterior;
     each posterior-aware controller is also compared with these.

Reported per controller and seed: tracking RMSE (true pressure against the reference,
Pa; against the reference capped at ``P_MAX``; and over the settled part of each hold,
``SETTLE_S`` after a change to the horizon before the next, against the capped
reference), ticks above ``P_MAX`` and the largest excess (Pa), and the controller's compute per
tick (ms, wall, both threads). The controllers predict with dense output (steps cross the
ticks over which a candidate's command holds; ``SolverConfig.sampling()``,
``benchmarks/controller.py`` states its error); ``--no-dense-output`` stops at every tick
as before. Seeds are recorded; each seed's result is written
atomically under ``--out`` and a finished seed is not run again (interrupt and rerun to
resume).
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numba
import numpy as np
from scipy import stats

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.bench.sensors import SensorChain
from pneubayes.effects import effects_from_names
from pneubayes.inference.error_band import PredictionErrorBand, recording_errors
from pneubayes.inference.fit import FitSettings, identify
from pneubayes.inference.fit_folder import read_fit, write_fit
from pneubayes.inference.online import OnlineTracker
from pneubayes.inference.population import LogNormalPrior
from pneubayes.inference.predictive import PressurePredictor, ar1_noise, draw_quantiles
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.provenance import provenance
from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

RATE_HZ = 200.0
RECORDING_RATE_HZ = 1000.0   # the bench's sample rate, at which the noise was fitted
DT_S = 1.0 / RATE_HZ
HIDDEN_DELAY_S = 0.015
P_MAX_PA = 4.8e5
SETPOINT_RANGE_PA = (1.6e5, 5.0e5)  # some above the limit: the loop must ride it
SETPOINT_HOLD_S = 0.5
RUN_S = 6.0
HORIZON_TICKS = 30           # 150 ms
FIRST_TICKS = 2              # the first level's hold, 10 ms
# (finer than the first design's 0, +-0.8, +-2, +-5 V for 20 ms then +-0.3 V: with those
# even the model with the delay held a set-point only to about 15 kPa RMS)
FIRST_LEVELS_V = (-5.0, -2.0, -1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0, 2.0, 5.0)
SECOND_LEVELS_V = (-0.3, 0.0, 0.3)
#: The settled part of a hold: from SETTLE_S after its set-point change to the horizon
#: before the next one (the rise, and the preview of the next set-point, are left out).
SETTLE_S = 0.2
#: A settled hold "at the limit": its set-point lies above the limit or within this much
#: below it (Pa), where a controller's margin, not its holding, sets its error.
NEAR_LIMIT_PA = 30e3
N_DRAWS = 64
QUANTILE = 0.95
CONTROLLERS = ("nominal", "nominal_mean", "posterior", "predictive", "chance",
               "chance_window", "calibrated", "calibrated_near", "calibrated_online",
               "delay_nominal", "delay_chance", "delay_chance_window")
#: ``calibrated_near``'s band covers the first steps only (20 ms: the first level's hold
#: and two more ticks), where a decision made now shows in the pressure before the next
#: ones can correct it; beyond, the draws' quantile alone (a design choice, stated).
BAND_TICKS = 4
#: ``calibrated_online`` refits its band every this many ticks (100 ms) on the
#: identification recordings' errors and the loop's own: each tick, the point estimate's
#: prediction from the reading HORIZON_TICKS ago under the commands since applied,
#: against the readings since (the loop may go where the recordings did not, e.g. ride
#: the limit with small openings)
BAND_REFIT_TICKS = 20
#: Nominal MPC as an engineer runs it without a posterior: the point estimate with a
#: fixed back-off from the limit (Pa). Seven sizes trace its trade-off between
#: violations and tracking, so a posterior-aware controller is compared with the
#: nominal at every margin, not only at none (added after the second design's runs).
BACKOFF_PA = {f"nominal_backoff{k}k": k * 1e3 for k in (5, 10, 15, 20, 25, 30, 40)}


def backoff_Pa(kind: str) -> float | None:
    """A back-off controller's fixed margin below the limit (Pa), on either fitted model
    (``nominal_backoff20k``, ``delay_nominal_backoff20k``); None for any other kind."""
    return BACKOFF_PA.get(kind.removeprefix("delay_"))


#: The posterior-aware controllers compared with each back-off.
POSTERIOR_AWARE = ("posterior", "predictive", "chance", "chance_window", "calibrated",
                   "calibrated_near", "calibrated_online")
#: The effects of the fitted models: the paper's, and the paper's with the tube the
#: bench hides (what the discovery loop names on such data) for the ``delay_`` ones.
FITTED = {"paper": ["cylinder_leak"], "delay": ["cylinder_leak", "tube_delay"]}
#: What the posterior is fitted on and which controllers run (``--scenario``):
#:
#: * ``hidden_delay`` (the default, the design above): two 10-s recordings at +-5 and
#:   +-1.5 V; the paper's model and the delay model; every controller;
#: * ``weak_data``: one 2-s recording of small commands (+-1 V) only, the delay model
#:   only (the model class holds the plant): the posterior is narrow where the data
#:   were and wide where the controller works (large openings, high pressures), so a
#:   point estimate can be wrong there in a way the draws know. Beside the posterior's
#:   median and mean, ``delay_nominal_lsq`` is the trajectory least-squares fit the
#:   posterior started from (the point a user identifies without the posterior).
SCENARIOS = {
    "hidden_delay": {"duration_s": 10.0, "quick_duration_s": 4.0, "ranges_V": (5.0, 1.5),
                     "fitted": ("paper", "delay"),
                     "controllers": CONTROLLERS + tuple(BACKOFF_PA),
                     "baseline": "nominal"},
    "weak_data": {"duration_s": 2.0, "quick_duration_s": 2.0, "ranges_V": (1.0,),
                  "fitted": ("delay",),
                  "controllers": ("delay_nominal", "delay_nominal_mean",
                                  "delay_nominal_lsq", "delay_posterior", "delay_chance",
                                  "delay_chance_window",
                                  *(f"delay_{b}" for b in BACKOFF_PA),
                                  "delay_calibrated", "delay_calibrated_near",
                                  "delay_calibrated_online"),
                  "baseline": "delay_nominal"},
    "changing_plant": {"duration_s": 10.0, "quick_duration_s": 4.0, "ranges_V": (5.0, 1.5),
                       "fitted": ("delay",),
                       "controllers": ("delay_nominal", "delay_frozen", "delay_chance",
                                       "delay_online"),
                       "baseline": "delay_frozen",
                       "change": {"parameter": "dead_volume_m3", "at_s": 2.0,
                                  "factor": 0.4, "drift_log_per_s": -0.05},
                       "varying": {"dead_volume_m3": 0.3},
                       "setpoint_range_Pa": (3.5e5, 5.0e5),
                       "second_levels_V": (-0.3, 0.0, 0.1, 0.2, 0.3)},
}
#: ``changing_plant`` (issue 67): the bench and the delay model's fit of ``hidden_delay``,
#: but the plant changes during the closed loop: at ``at_s`` the volume the valve fills
#: (the model's dead volume, 1.6e-5 m^3 on this bench: the tube's and the port's) falls
#: to ``factor`` times the value the recordings had (a reservoir sharing the chamber's
#: port is valved off; the tube's delay is unchanged) and then drifts by
#: ``drift_log_per_s`` in log per second. A smaller volume fills faster: a prediction
#: made with the recordings' volume is slow, and the loop overshoots the limit. The
#: set-points are drawn from ``setpoint_range_Pa`` (3.5-5.0 bar), near the limit, where
#: the constraint is active (a first probe with the default 1.6-5.0 bar and a 0.6 x
#: volume had no violation from any controller). The second level of every candidate
#: is one of ``second_levels_V`` (-0.3, 0, 0.1, 0.2, 0.3 V: the default grid's 0 and
#: +-0.3 V cannot hold a pressure near the limit in a plant 2.5 x as fast, and a
#: controller that knows the plant then stays low: on seed 0 with that grid the online
#: controller had no violation but a capped RMSE 3.4 kPa above the frozen one's; the
#: same grid for every controller). The controllers:
#:
#: * ``delay_nominal``: the posterior median (the point estimate);
#: * ``delay_frozen``: the offline posterior's draws, feasible if their 95 % quantile
#:   stays under the limit, tracking on their median (``posterior``'s rule);
#: * ``delay_chance``: the offline posterior predictive's margin (``chance``'s rule);
#: * ``delay_online``: ``delay_frozen``'s rule on the particles of an
#:   :class:`~pneubayes.inference.online.OnlineTracker` over the quantities the scenario
#:   declares as varying (``varying``: each one's log-normal prior is the offline
#:   posterior's, its spread widened to at least the stated log SD; the other parameters
#:   at their posterior medians), updated from the measured pressure at every tick after
#:   the tick's command is chosen (``ONLINE``). The scenario declares which quantity may
#:   vary, never the truth's value or time of change.
#:
#: The baseline the floor is read against is ``delay_frozen``.
#: The tracker's settings for ``delay_online`` (every argument of :class:`OnlineTracker`
#: not given keeps its default; a design choice, stated): 64 particles; each tick scores
#: its new sample by a prediction from the reading ``lookback_s`` before, with errors of
#: sqrt(2) x the sensor noise (the start's reading and the sample's each carry it); a
#: drift of the declared quantities of ``drift_log_per_sqrt_s`` (the state-space model of
#: a quantity that steps or drifts); resample-move with a floor on the moves' scale.
ONLINE = {"n_particles": N_DRAWS, "lookback_s": 0.1, "memory_s": 0.1,
          "warm_up_windows": 0, "temper": 0.5, "n_moves": 1, "move_floor_log": 0.03,
          "drift_log_per_sqrt_s": 0.1, "history_s": 0.05}


def candidates(previous: np.ndarray, second_levels=SECOND_LEVELS_V) -> np.ndarray:
    """The candidate command sequences (K, HORIZON_TICKS): every (first, second) level
    pair, plus the previous best plan shifted by one tick."""
    rows = [np.concatenate([np.full(FIRST_TICKS, a), np.full(HORIZON_TICKS - FIRST_TICKS, b)])
            for a in FIRST_LEVELS_V for b in second_levels]
    rows.append(np.append(previous[1:], previous[-1]))
    return np.asarray(rows)


CANDIDATES = len(FIRST_LEVELS_V) * len(SECOND_LEVELS_V) + 1


def scenario_candidates(scenario: str) -> int:
    """The number of candidate sequences of a scenario's controllers."""
    second = SCENARIOS[scenario].get("second_levels_V", SECOND_LEVELS_V)
    return len(FIRST_LEVELS_V) * len(second) + 1


def choose(pred_Pa: np.ndarray, reference_Pa: np.ndarray, limit_Pa: np.ndarray) -> int:
    """Index of the best candidate: among those whose ``limit_Pa`` (K, H) stays under
    P_MAX, the smallest squared error of ``pred_Pa`` (K, H) against the reference; with
    none, the smallest largest excess."""
    excess = np.max(limit_Pa - P_MAX_PA, axis=1)
    feasible = excess <= 0.0
    if not feasible.any():
        return int(np.argmin(excess))
    cost = np.mean((pred_Pa - reference_Pa[None, :]) ** 2, axis=1)
    cost[~feasible] = np.inf
    return int(np.argmin(cost))


def controller_solver(dense_output: bool) -> SolverConfig:
    """The controllers' solver (and their band's): the standard tolerances, with dense
    output or stopping at every tick."""
    return SolverConfig.sampling() if dense_output else SolverConfig.standard()


class Controller:
    """One MPC: a predictor over some draws and how its predictions are scored
    (``nominal``, ``nominal_mean``: one parameter vector)."""

    def __init__(self, kind, model, draws, noise, rig, rng, dense_output: bool,
                 band: PredictionErrorBand | None = None, point=None,
                 varying: dict | None = None, second_levels_V=SECOND_LEVELS_V):
        self.kind = kind.removeprefix("delay_")  # the same controllers on the delay model
        solver = controller_solver(dense_output)
        self.band = band
        self.second_levels_V = tuple(second_levels_V)
        if self.kind == "online":
            # the offline draws are its prior (and the other parameters' medians)
            if not varying:
                raise ValueError(f"{kind} needs the scenario's varying quantities")
            self.tracker = online_tracker(model, draws, rig, solver, varying, rng)
            self.rng = rng
            self.tick = 0
            #: the tracker's 5/50/95 % of each varying quantity after each tick's update
            self.tracked: dict[str, list] = {n: [] for n in varying}
        if self.kind.startswith("calibrated") and band is None:
            raise ValueError(f"{kind} needs the fitted model's PredictionErrorBand")
        if self.kind == "calibrated_online":
            # the point estimate predicts the loop's windows afterwards; the band
            # (a copy: every loop starts from the recordings' band) learns from them
            if point is None:
                raise ValueError(f"{kind} needs the point estimate")
            self.band = copy.deepcopy(band)
            self.point = PressurePredictor(model, point, rig, solver)
            self.readings: list[float] = []
            # the loop's windows since the band's last refit (it keeps the earlier ones)
            self.pending: list[tuple[np.ndarray, np.ndarray]] = []
        self.backoff_Pa = backoff_Pa(kind) or 0.0
        self.predictor = PressurePredictor(model, draws, rig, solver)
        # predictive only: one fixed path per draw of its stationary AR(1) noise (fitted
        # per recording sample), read at the control ticks; the start's own noise is
        # forgotten within the first tick (the chamber's time constant is a few ms)
        self.noise = None
        per_tick = round(RECORDING_RATE_HZ * DT_S)
        if self.kind in ("predictive", "chance"):
            path = ar1_noise(rng, noise[:, 0], noise[:, 1],
                             (draws.shape[0], 1, HORIZON_TICKS * per_tick), stationary=True)
            self.noise = path[:, :, per_tick - 1::per_tick]
        elif self.kind == "chance_window":
            # the likelihood's own noise for a prediction started at the measured pressure
            # (r_k = n_k - S_k n_0; PressurePredictor.predictive_draws subtracts the start)
            path = ar1_noise(rng, noise[:, 0], noise[:, 1],
                             (draws.shape[0], 1, HORIZON_TICKS * per_tick + 1),
                             stationary=True)
            self.noise = path[:, 0, ::per_tick]
        self.plan = np.zeros(HORIZON_TICKS)

    def step(self, measured_Pa, reference_Pa, history_V, position_m):
        if self.kind == "calibrated_online":
            self._learn(measured_Pa, history_V, position_m)
        cands = candidates(self.plan, self.second_levels_V)
        if self.kind == "online":  # the tracker's particles, as the samples so far left them
            self.predictor = self.tracker.predictor(self.tracker.n_particles, self.rng)
        if self.kind == "chance_window":
            sims, noisy = self.predictor.predictive_draws(
                measured_Pa, cands, position_m, DT_S, self.noise, command_history_V=history_V)
            sims, noisy = sims[:, :, 1:], noisy[:, :, 1:]
        else:
            full = self.predictor.predict_draws(measured_Pa, cands, position_m, DT_S,
                                                command_history_V=history_V)
            sims = full[:, :, 1:]
            noisy = sims if self.noise is None else sims + self.noise
        if self.kind.startswith("nominal"):
            pred, limit = sims[0], sims[0] + self.backoff_Pa
        elif self.kind.startswith("chance"):  # expected tracking, the predictive's risk
            pred = np.median(sims, axis=0)
            limit = draw_quantiles(noisy, (QUANTILE,))[0]
        elif self.kind.startswith("calibrated"):
            # the draws' quantile plus the calibrated k-step error of the median's path
            median = np.median(full, axis=0)
            margin = self.band.margin(median)[:, 1:]
            if self.kind == "calibrated_near":
                margin[:, BAND_TICKS:] = 0.0
            pred = median[:, 1:]
            limit = draw_quantiles(sims, (QUANTILE,))[0] + margin
        else:
            pred = np.median(noisy, axis=0)
            limit = draw_quantiles(noisy, (QUANTILE,))[0]
        best = choose(pred, reference_Pa, limit)
        self.plan = cands[best]
        if self.kind == "online":
            self._track(measured_Pa, float(self.plan[0]), position_m)
        return float(self.plan[0])

    def _track(self, measured_Pa, command_V, position_m):
        """The tick's sample into the tracker, with the command just chosen (held from
        this tick on: it scores the sample with the commands before it)."""
        self.tracker.update([self.tick * DT_S], [command_V], [measured_Pa],
                            position_m=[position_m])
        self.tick += 1
        for name, q in self.tracker.quantiles((0.05, 0.5, 0.95)).items():
            self.tracked[name].append(q)

    def _learn(self, measured_Pa, history_V, position_m):
        """The point estimate's prediction from the reading HORIZON_TICKS ago under the
        commands applied since, against the readings since; the band refitted every
        BAND_REFIT_TICKS on the recordings' errors and these."""
        self.readings.append(float(measured_Pa))
        k = len(self.readings) - 1  # this tick
        start = k - HORIZON_TICKS
        if start < 0:
            return
        applied = np.asarray(history_V, dtype=np.float64)
        pred = self.point.predict_draws(self.readings[start], applied[start:k], position_m,
                                        DT_S, command_history_V=applied[:start] if start
                                        else None)[0, 0]
        self.pending.append((pred, np.asarray(self.readings[start:k + 1])))
        if len(self.pending) == BAND_REFIT_TICKS:
            self.band.partial_fit(np.stack([a for a, _ in self.pending]),
                                  np.stack([b for _, b in self.pending]), DT_S)
            self.pending = []


def online_tracker(model, draws, rig, solver, varying: dict, rng) -> OnlineTracker:
    """``delay_online``'s tracker (``ONLINE``): over the ``varying`` quantities (name: the
    least log SD of its prior), whose log-normal prior has the offline ``draws``' median
    and log SD (at least the stated one), the other parameters at the draws' medians."""
    names = tuple(varying)
    logs = np.log(draws[:, [model.parameter_names.index(n) for n in names]])
    prior = LogNormalPrior(model, names, dict(zip(names, np.exp(np.median(logs, axis=0)))),
                           {n: max(float(np.std(logs[:, i], ddof=1)), float(varying[n]))
                            for i, n in enumerate(names)})
    params = dict(zip(model.parameter_names, np.median(draws, axis=0).tolist()))
    return OnlineTracker(model, params, prior, rig, solver,
                         noise_std_Pa=np.sqrt(2.0) * SensorChain().pressure_noise_Pa,
                         **ONLINE).reset(rng)


def plant_schedule(model, truth, change: dict, n_ticks: int) -> np.ndarray:
    """The plant's parameter vector at each tick, ``(n_ticks, P)``: ``truth`` until
    ``change["at_s"]``, then ``change["parameter"]`` times ``change["factor"]``, drifting
    on by ``change["drift_log_per_s"]`` in log per second."""
    theta = np.repeat(model.vector(truth)[None, :], n_ticks, axis=0)
    t = np.arange(n_ticks) * DT_S
    after = t >= change["at_s"]
    scale = np.where(after, change["factor"] * np.exp(change.get("drift_log_per_s", 0.0)
                                                       * (t - change["at_s"])), 1.0)
    theta[:, model.parameter_names.index(change["parameter"])] *= scale
    return theta


def setpoints(rng, n_ticks, range_Pa=SETPOINT_RANGE_PA):
    """A seeded staircase of set-points, SETPOINT_HOLD_S each, uniform over ``range_Pa``,
    with HORIZON_TICKS more at the end for the last prediction."""
    hold = round(SETPOINT_HOLD_S * RATE_HZ)
    levels = rng.uniform(*range_Pa, size=(n_ticks + HORIZON_TICKS) // hold + 1)
    return np.repeat(levels, hold)[: n_ticks + HORIZON_TICKS]


def closed_loop(controller, plant_model, truth, rig, position_m, reference, noise_rng,
                plant_theta=None, n_ticks: int | None = None):
    """Run one controller against the plant; returns the true pressure, the measured one,
    the commands and the compute per tick (s). ``plant_theta`` ``(n, P)``: the plant's
    parameters at each tick (a plant that changes; default ``truth`` throughout);
    ``n_ticks``: the run's ticks (default ``RUN_S``'s)."""
    n = round(RUN_S * RATE_HZ) if n_ticks is None else int(n_ticks)
    t = np.arange(n + 1) * DT_S
    p_true = np.empty(n + 1)
    p_true[0] = rig.atmospheric_pressure_Pa
    measured = np.empty(n + 1)
    u = np.zeros(n + 1)
    compute = np.empty(n)
    x = np.full(n + 1, position_m)
    sup = np.full(n + 1, rig.supply_pressure_Pa)
    theta = plant_model.vector(truth)
    ref_solver = SolverConfig.reference()
    noise_Pa = SensorChain().pressure_noise_Pa
    for k in range(n):
        measured[k] = p_true[k] + noise_rng.normal(0.0, noise_Pa)
        a = time.perf_counter()
        u[k] = controller.step(measured[k], reference[k + 1:k + 1 + HORIZON_TICKS],
                               u[:k] if k else None, position_m)
        compute[k] = time.perf_counter() - a
        u[k + 1] = u[k]
        inputs = Inputs(t[:k + 2], u[:k + 2], x[:k + 2], sup[:k + 2],
                        command_before_start=0.0)
        if plant_theta is not None:
            theta = plant_theta[k]
        p_true[k + 1] = simulate_windows(plant_model, theta, inputs, rig, np.array([k]), 2,
                                         np.array([p_true[k]]), ref_solver)[0, 0, -1]
    measured[n] = p_true[n] + noise_rng.normal(0.0, noise_Pa)
    return {"time_s": t, "pressure_Pa": p_true, "measured_Pa": measured, "command_V": u,
            "compute_s": compute}


def fit_model(recs, names, fit_dir: Path, seed: int, quick: bool, log):
    """emcee fit of the named effects (with the bench's declared filter), kept in
    ``fit_dir`` and reused when it is finished there."""
    if (fit_dir / "posterior.nc").exists():  # a finished fit of an earlier run: reuse it
        return read_fit(fit_dir)
    settings = FitSettings(pressure_filter=SensorChain().declared_filter(),
                           sampler=SamplerSettings(n_walkers=32, seed=seed,
                                                   max_steps=600 if quick else 4000))
    log(f"seed {seed}: fitting {' + '.join(names)} ...")
    fit = identify(recs, Model(effects_from_names(names)), settings, checkpoint_dir=fit_dir)
    write_fit(fit, fit_dir, figures=False)
    return fit


def code_revision() -> str:
    """The git revision of the running code (``-dirty`` with uncommitted changes): read
    once at the start of a run, so loops record the code that ran, not a commit made
    while they ran."""
    prov = provenance()
    return (prov.get("git_revision") or "unknown") + ("-dirty" if prov.get("git_dirty")
                                                      else "")


def run_seed(seed: int, out: Path, quick: bool, log, scenario: str = "hidden_delay",
             dense_output: bool = True, revision: str | None = None) -> dict:
    """Bench, fit and the closed loops of one seed (skipped if already written; loops run
    with the other ``dense_output`` are run again, the fits reused). ``revision``: the
    running code's (:func:`code_revision`, read here when not given)."""
    revision = revision or code_revision()
    sc = SCENARIOS[scenario]
    controllers = sc["controllers"]
    done = out / f"seed{seed}.json"
    reuse: dict = {}
    if done.exists():
        saved = json.loads(done.read_text())
        if saved.get("scenario", "hidden_delay") != scenario:
            raise SystemExit(f"{done}: a seed of scenario {saved.get('scenario')!r}, not "
                             f"{scenario!r}: give each scenario its own --out")
        # seeds written before the option stepped at every tick
        if saved.get("dense_output", False) != dense_output:
            log(f"seed {seed}: {done} was run with dense_output="
                f"{saved.get('dense_output', False)}; running its loops again (the fits "
                "are reused)")
        elif saved.get("candidates") == scenario_candidates(scenario):
            reuse = {k: v for k, v in saved["controllers"].items() if k in controllers}
            if set(controllers) <= set(reuse):
                return saved
            log(f"seed {seed}: {done} lacks controllers {sorted(set(controllers) - set(reuse))}"
                "; running those (the fits and the other loops are reused)")
        else:
            log(f"seed {seed}: {done} has another candidate grid; running its loops again "
                "(the fits are reused)")
    work = out / f"seed{seed}"
    eff = effects_from_names(["cylinder_leak", "tube_delay"])
    cfg = BenchConfig("AIR37", "valve1", eff, protocol="fixed",
                      duration_s=sc["quick_duration_s"] if quick else sc["duration_s"],
                      seed=seed, positions=(0.5,), ranges_V=sc["ranges_V"],
                      overrides={"tube_delay_s": HIDDEN_DELAY_S})
    bench_dir = work / "bench"
    if (bench_dir / "truth.json").exists():  # in the bench's order, as the first run had
        listed = json.loads((bench_dir / "truth.json").read_text())["bench"]["recordings"]
        recordings = [bench_dir / e["file"] for e in listed]
    else:
        recordings = list(run_bench(cfg, bench_dir).recordings)
    plant_model, truth = Model.load_card(bench_dir / "truth.json")
    recs = [read_recording(p) for p in recordings]
    rig = recs[0].rig()
    position = float(recs[0].metadata.position_m)
    fits = {name: fit_model(recs, FITTED[name],
                            work / ("fit" if name == "paper" else "fit_delay"), seed, quick,
                            log) for name in sc["fitted"]}
    # the draws, the reference, the sensor noise and the predictive noise factors: the
    # same streams for every controller (children 0-3 as before the delay model's 4-5)
    seqs = np.random.SeedSequence(seed).spawn(6)
    ref_rng = np.random.default_rng(seqs[1])
    # per fitted model: (model, draws, noise, posterior median vector, least-squares
    # vector, controller stream)
    fitted = {}
    for name, fit in fits.items():
        draws, noise = fit.draws(N_DRAWS, np.random.default_rng(seqs[0 if name == "paper"
                                                                     else 4]))
        median = {k: v["median"] for k, v in fit.summary["parameters"].items()
                  if k in fit.model.parameter_names}
        # the trajectory least-squares point estimate the posterior started from (what a
        # user identifies without the posterior)
        refined = (fit.summary.get("refined") or {}).get("parameters")
        lsq = fit.model.vector(refined)[None] if refined else None
        fitted[name] = (fit.model, draws, noise, fit.model.vector(median)[None], lsq,
                        seqs[3 if name == "paper" else 5])
    # per fitted model: the calibrated k-step error of its point estimate on the
    # identification recordings (in sample), for the calibrated controllers
    solver = controller_solver(dense_output)
    bands = {}
    for name, (model, _, _, median, _, _) in fitted.items():
        pred, meas = recording_errors(model, median[0], recs, HORIZON_TICKS, DT_S, DT_S,
                                      solver)
        bands[name] = PredictionErrorBand(QUANTILE).fit(pred, meas, DT_S)
    n = round(RUN_S * RATE_HZ)
    reference = setpoints(ref_rng, n, sc.get("setpoint_range_Pa", SETPOINT_RANGE_PA))
    result = {"seed": seed, "scenario": scenario, "hidden_delay_s": HIDDEN_DELAY_S,
              "p_max_Pa": P_MAX_PA, "candidates": scenario_candidates(scenario),
              "dense_output": dense_output,
              "bench": {"duration_s": cfg.duration_s, "ranges_V": list(cfg.ranges_V)},
              "posterior_noise_scale_Pa": float(np.median(
                  fitted[sc["fitted"][0]][2][:, 0])),
              "reference_Pa": reference[: n + 1].tolist(), "controllers": {},
              "error_band": {name: b.summary() for name, b in bands.items()}}
    plant_theta = None
    if "change" in sc:  # the plant changes during the loop (the same for every controller)
        change = sc["change"]
        plant_theta = plant_schedule(plant_model, truth, change, n)
        j = plant_model.parameter_names.index(change["parameter"])
        result["change"] = {**change, "varying": sc["varying"],
                            # the offline posterior's median of the changed quantity
                            "offline_median": float(np.median(fitted["delay"][1][
                                :, fitted["delay"][0].parameter_names.index(
                                    change["parameter"])])),
                            "true_before": float(plant_theta[0, j]),
                            "true_at_end": float(plant_theta[-1, j]),
                            # the plant's value at every tick (the figure's)
                            "true_per_tick": plant_theta[:, j].tolist()}
    if "paper" in fits:
        result["fit"] = {k: fits["paper"].summary.get(k)
                         for k in ("converged", "steps", "tau_max")}
    if "delay" in fits:
        d_sum = fits["delay"].summary
        result["fit_delay"] = {**{k: d_sum.get(k) for k in ("converged", "steps", "tau_max")},
                               "tube_delay_s": d_sum["parameters"]["tube_delay_s"]}
        # how wide the posterior is: each parameter's 90 % interval over its median
        result["fit_delay"]["relative_width_90"] = {
            k: (v["q95"] - v["q05"]) / abs(v["median"]) if v.get("median") else None
            for k, v in d_sum["parameters"].items() if "q95" in v and "q05" in v}
    for kind in controllers:
        if kind in reuse:  # a finished loop of an earlier run
            result["controllers"][kind] = reuse[kind]
            continue
        model, draws, noise, median, lsq, stream = fitted["delay" if kind.startswith("delay_")
                                                          else "paper"]
        use = {"nominal": median, "nominal_mean": draws.mean(axis=0, keepdims=True),
               "nominal_lsq": lsq, **dict.fromkeys(BACKOFF_PA, median)}.get(
                   kind.removeprefix("delay_"), draws)
        if use is None:
            raise SystemExit(f"seed {seed}: {kind} needs the fit's refined point estimate, "
                             "which its summary lacks")
        which = "delay" if kind.startswith("delay_") else "paper"
        ctrl = Controller(kind, model, use, noise, rig, np.random.default_rng(stream),
                          dense_output, bands[which], median, sc.get("varying"),
                          sc.get("second_levels_V", SECOND_LEVELS_V))
        log(f"seed {seed}: closed loop, {kind} MPC ...")
        a = time.perf_counter()
        run = closed_loop(ctrl, plant_model, truth, rig, position, reference,
                          np.random.default_rng(seqs[2]), plant_theta)
        err = run["pressure_Pa"][1:] - reference[1:n + 1]
        over = run["pressure_Pa"] - P_MAX_PA
        result["controllers"][kind] = {
            "tracking_rmse_Pa": float(np.sqrt(np.mean(err ** 2))),
            "feasible_tracking_rmse_Pa": feasible_rmse(run["pressure_Pa"], reference),
            "settled_tracking_rmse_Pa": settled_rmse(run["pressure_Pa"], reference),
            "ticks_above_limit": int(np.count_nonzero(over > 0)),
            "largest_excess_Pa": float(max(over.max(), 0.0)),
            "compute_ms_per_tick_median": 1e3 * float(np.median(run["compute_s"])),
            "compute_ms_per_tick_p95": 1e3 * float(np.quantile(run["compute_s"], 0.95)),
            # the threads the controller's predictions ran on (the compute depends on it)
            "numba_threads": numba.get_num_threads(),
            "wall_s": time.perf_counter() - a,
            # loops of one seed may be run at different revisions (a resumed seed runs
            # only the controllers it lacks): each records its own
            "git_revision": revision,
            "pressure_Pa": run["pressure_Pa"].tolist(),
            "command_V": run["command_V"].tolist()}
        if plant_theta is not None:  # after the change only
            after = slice(round(sc["change"]["at_s"] * RATE_HZ), None)
            result["controllers"][kind]["ticks_above_limit_after_change"] = int(
                np.count_nonzero(over[after] > 0))
        if hasattr(ctrl, "tracked"):  # the tracker's 5/50/95 % after each tick
            result["controllers"][kind]["tracked"] = ctrl.tracked
        c = result["controllers"][kind]
        log(f"  {kind:10s} RMSE {c['tracking_rmse_Pa']:7.0f} Pa, {c['ticks_above_limit']:3d} "
            f"ticks above the limit (largest {c['largest_excess_Pa']:6.0f} Pa), "
            f"{c['compute_ms_per_tick_median']:.2f} ms per tick")
    write_json_atomic(done, result)
    return result


def excess_integral_Pa_s(pressure_Pa) -> float:
    """The pressure's excess over P_MAX_PA integrated over the run, Pa s (ticks of DT_S)."""
    p = np.asarray(pressure_Pa, dtype=np.float64)
    return float(np.sum(np.maximum(p - P_MAX_PA, 0.0)) * DT_S)


def feasible_rmse(pressure_Pa, reference_Pa) -> float:
    """RMSE (Pa) of the true pressure against the reference capped at ``P_MAX``: the
    tracking a loop that respects the limit can reach (against the raw reference, a set
    -point above the limit rewards crossing it)."""
    p = np.asarray(pressure_Pa, dtype=np.float64)
    ref = np.minimum(np.asarray(reference_Pa, dtype=np.float64)[: p.size], P_MAX_PA)
    return float(np.sqrt(np.mean((p[1:] - ref[1:]) ** 2)))


def _settled(n_ticks: int) -> np.ndarray:
    """The settled ticks of each hold (``SETTLE_S`` after a set-point change until
    ``HORIZON_TICKS`` before the next), as a mask over ``n_ticks`` (tick 0 excluded)."""
    hold = round(SETPOINT_HOLD_S * RATE_HZ)
    phase = np.arange(n_ticks) % hold
    keep = (phase >= round(SETTLE_S * RATE_HZ)) & (phase < hold - HORIZON_TICKS)
    keep[0] = False
    if not keep.any():
        raise ValueError(f"settled_rmse: {n_ticks} ticks hold no settled part of a hold "
                         f"({hold} ticks each)")
    return keep


def settled_rmse(pressure_Pa, reference_Pa, near_limit: bool | None = None) -> float:
    """As :func:`feasible_rmse`, over the settled part of each hold only (``SETTLE_S``
    after a set-point change until ``HORIZON_TICKS`` before the next): how well a loop
    holds a set-point, or rides the limit, without the rise and the preview that the
    total RMSE is mostly made of. ``near_limit`` True keeps only the holds whose
    set-point lies above the limit or within ``NEAR_LIMIT_PA`` below it, False only the
    others (NaN where a run has none), None all."""
    p = np.asarray(pressure_Pa, dtype=np.float64)
    raw = np.asarray(reference_Pa, dtype=np.float64)[: p.size]
    ref = np.minimum(raw, P_MAX_PA)
    keep = _settled(p.size)
    if near_limit is not None:
        keep &= (raw >= P_MAX_PA - NEAR_LIMIT_PA) == near_limit
        if not keep.any():
            return float("nan")
    return float(np.sqrt(np.mean((p[keep] - ref[keep]) ** 2)))


def _versus(k: dict, nom: dict) -> dict:
    """One controller's seeds against another's: violations, and each tracking measure
    (raw, capped at the limit, settled holds) as its medians and the seeds on which the
    first is not worse."""
    out = {
        "total_ticks_above_limit": [sum(k["ticks_above_limit"]), sum(nom["ticks_above_limit"])],
        "seeds_fewer_violations": int(sum(a < b for a, b in zip(k["ticks_above_limit"],
                                                                 nom["ticks_above_limit"]))),
    }
    for measure, key in (("", "tracking_rmse_Pa"), ("feasible_", "feasible_tracking_rmse_Pa"),
                         ("settled_", "settled_tracking_rmse_Pa")):
        out[f"median_{key}"] = [float(np.median(k[key])), float(np.median(nom[key]))]
        out[f"seeds_{measure}rmse_not_worse"] = int(sum(a <= b for a, b in zip(k[key],
                                                                               nom[key])))
    out["paired_feasible_rmse_difference_Pa"] = paired_difference(
        k["feasible_tracking_rmse_Pa"], nom["feasible_tracking_rmse_Pa"])
    out["paired_rmse_difference_Pa"] = paired_difference(k["tracking_rmse_Pa"],
                                                         nom["tracking_rmse_Pa"])
    out["paired_ticks_above_limit_difference"] = paired_difference(
        k["ticks_above_limit"], nom["ticks_above_limit"])
    if "excess_integral_Pa_s" in k and "excess_integral_Pa_s" in nom:
        out["paired_excess_integral_difference_Pa_s"] = paired_difference(
            k["excess_integral_Pa_s"], nom["excess_integral_Pa_s"])
    return out


def tracked_summary(result: dict, kind: str) -> dict | None:
    """How the online controller's tracker followed the change on one seed
    (``changing_plant``), in ratios to the values before the change (the fitted model's
    volume need not be the plant's: the other parameters trade off with it; the
    tracker's, its median over the 0.5 s before): the change its median saw by the last
    tick against the plant's; after the change, the first time its ratio came within
    20 % of the plant's and the time from which it stayed there (None: it left again
    by the last tick); and its ratio over the plant's from 1 s after the change on
    (median, 5 and 95 %). None without a change or a tracker."""
    change = result.get("change")
    tracked = result["controllers"][kind].get("tracked")
    if not change or not tracked or change["parameter"] not in tracked:
        return None
    med = np.asarray(tracked[change["parameter"]], dtype=np.float64)[:, 1]
    true = np.asarray(change["true_per_tick"], dtype=np.float64)[: med.size]
    start = round(change["at_s"] * RATE_HZ)
    base = float(np.median(med[max(start - round(0.5 * RATE_HZ), 0):start]))
    rel = (med / base) / (true / true[start - 1])
    off = np.abs(rel[start:] - 1.0) > 0.20
    late = np.nonzero(off)[0]
    stays = (None if late.size and late[-1] == off.size - 1
             else (0.0 if not late.size else float((late[-1] + 1) * DT_S)))
    first = np.nonzero(~off)[0]
    later = rel[start + round(RATE_HZ):]
    return {"change_seen": float(med[-1] / base),
            "change_planted": float(true[-1] / true[start - 1]),
            "before_over_plant": float(base / true[start - 1]),
            "first_within_20pc_s": float(first[0] * DT_S) if first.size else None,
            "stays_within_20pc_s": stays,
            "ratio_after_1s": (np.quantile(later, (0.5, 0.05, 0.95)).tolist()
                               if later.size else None)}


def paired_difference(a, b) -> dict:
    """The per-seed difference ``a - b`` (same seeds, same units): its mean, its sample
    standard deviation and the mean's two-sided 95 % Student-t interval (None with
    fewer than two seeds), so "equal tracking" is judged against the spread over seeds
    rather than on one seed's sign."""
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    if d.size < 2:
        return {"mean": float(d.mean()) if d.size else None, "sd": None, "ci95": None,
                "seeds": int(d.size)}
    sd = float(d.std(ddof=1))
    half = float(stats.t.ppf(0.975, d.size - 1)) * sd / np.sqrt(d.size)
    return {"mean": float(d.mean()), "sd": sd,
            "ci95": [float(d.mean() - half), float(d.mean() + half)], "seeds": int(d.size)}


def summarise(results: list[dict], scenario: str = "hidden_delay") -> dict:
    """Per controller: the seeds' RMSE and violations, and the comparison the issue's
    floor asks for (fewer violations at equal or better tracking, over the seeds)."""
    out = {}
    controllers = SCENARIOS[scenario]["controllers"]
    baseline = SCENARIOS[scenario]["baseline"]
    for kind in controllers:
        rows = [r["controllers"][kind] for r in results]
        out[kind] = {
            "tracking_rmse_Pa": [c["tracking_rmse_Pa"] for c in rows],
            # from the saved trajectories, so a seed run before this metric has it too
            "feasible_tracking_rmse_Pa": [feasible_rmse(c["pressure_Pa"], r["reference_Pa"])
                                          for r, c in zip(results, rows)],
            "settled_tracking_rmse_Pa": [settled_rmse(c["pressure_Pa"], r["reference_Pa"])
                                         for r, c in zip(results, rows)],
            # where the settled error is made: holds at the limit, and the others
            "settled_near_limit_rmse_Pa": [settled_rmse(c["pressure_Pa"], r["reference_Pa"],
                                                        True) for r, c in zip(results, rows)],
            "settled_below_limit_rmse_Pa": [settled_rmse(c["pressure_Pa"], r["reference_Pa"],
                                                         False)
                                            for r, c in zip(results, rows)],
            "ticks_above_limit": [c["ticks_above_limit"] for c in rows],
            "largest_excess_Pa": [c["largest_excess_Pa"] for c in rows],
            # how much and how long: the true pressure's excess over the limit, integrated
            # over the run (Pa s; from the saved trajectories)
            "excess_integral_Pa_s": [excess_integral_Pa_s(c["pressure_Pa"]) for c in rows],
            "compute_ms_per_tick_median": [c["compute_ms_per_tick_median"] for c in rows],
            # None: a loop run before the loops recorded their threads
            "numba_threads": [c.get("numba_threads") for c in rows],
            # None: a loop run before the loops recorded their revision
            "git_revisions": [c.get("git_revision") for c in rows],
        }
        if all("ticks_above_limit_after_change" in c for c in rows):
            out[kind]["ticks_above_limit_after_change"] = [
                c["ticks_above_limit_after_change"] for c in rows]
        tracked = [tracked_summary(r, kind) for r in results]
        if any(t is not None for t in tracked):
            out[kind]["tracked"] = tracked
    for kind in controllers:
        if kind != baseline:
            out[kind][f"versus_{baseline}"] = _versus(out[kind], out[baseline])
    # the posterior-aware controllers against the nominal at each fixed back-off
    prefix = baseline.removesuffix("nominal")
    for kind in POSTERIOR_AWARE:
        for b in BACKOFF_PA:
            if prefix + kind in out and prefix + b in out:
                out[prefix + kind][f"versus_{prefix}{b}"] = _versus(out[prefix + kind],
                                                                   out[prefix + b])
    if scenario == "changing_plant":  # the online posterior against the point estimate too
        for kind in ("delay_online", "delay_chance"):
            out[kind]["versus_delay_nominal"] = _versus(out[kind], out["delay_nominal"])
    if baseline == "nominal":
        # the same-model comparison: posterior-aware against nominal, both with the delay
        for kind in ("delay_chance", "delay_chance_window"):
            out[kind]["versus_delay_nominal"] = _versus(out[kind], out["delay_nominal"])
    return out


#: The loops the figure shows (those the seed has, on either fitted model): more than a
#: handful of traces on one axis cannot be read.
FIGURE_KINDS = ("nominal", "chance", "calibrated_online", "delay_nominal")


def figure(results: list[dict], path: Path) -> None:
    """Seed 0's closed loops of ``FIGURE_KINDS`` (and their ``delay_`` twins) against the
    reference and the limit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = results[0]
    n = len(r["reference_Pa"])
    t = np.arange(n) * DT_S
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1]})
    axes[0].step(t, np.asarray(r["reference_Pa"]) / 1e5, where="post", color="k", lw=1,
                 label="reference")
    axes[0].axhline(P_MAX_PA / 1e5, color="r", ls="--", lw=1, label="limit")
    colours = ("tab:orange", "tab:red", "tab:blue", "tab:green", "tab:purple", "tab:pink",
               "tab:brown", "tab:olive", "tab:cyan")
    kinds = [k for k in dict.fromkeys(FIGURE_KINDS + tuple(f"delay_{k}" for k in
                                                           FIGURE_KINDS))
             if k in r["controllers"]]
    for kind, colour in zip(kinds, colours):
        c = r["controllers"][kind]
        axes[0].plot(t, np.asarray(c["pressure_Pa"]) / 1e5, color=colour, lw=1,
                     label=f"{kind}: RMSE {c['tracking_rmse_Pa'] / 1e3:.1f} kPa, "
                           f"{c['ticks_above_limit']} ticks over")
        axes[1].step(t, c["command_V"], where="post", color=colour, lw=0.8)
    axes[0].set_ylabel("pressure, bar (abs)")
    axes[0].legend(fontsize=8, loc="lower right")
    axes[1].set_ylabel("command, V")
    axes[1].set_xlabel("time, s")
    axes[0].set_title(f"200-Hz MPC on the bench with a hidden {HIDDEN_DELAY_S * 1e3:g}-ms "
                      f"delay (seed {r['seed']}, {r.get('scenario', 'hidden_delay')})")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


#: ``changing_figure``'s loops and their colours.
CHANGING_KINDS = {"delay_nominal": "tab:orange", "delay_frozen": "tab:red",
                  "delay_online": "tab:blue"}


def changing_figure(results: list[dict], controllers: dict, path: Path) -> None:
    """``changing_plant``: seed 0's loops of ``CHANGING_KINDS`` against the reference and
    the limit, the online tracker's volume against the plant's, and per seed the ticks
    above the limit and the capped tracking RMSE of every controller."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = results[0]
    change = r["change"]
    n = len(r["reference_Pa"])
    t = np.arange(n) * DT_S
    fig = plt.figure(figsize=(10, 10))
    grid = fig.add_gridspec(3, 2, height_ratios=[3, 1.6, 1.8])
    ax = fig.add_subplot(grid[0, :])
    ax.step(t, np.asarray(r["reference_Pa"]) / 1e5, where="post", color="k", lw=1,
            label="reference")
    ax.axhline(P_MAX_PA / 1e5, color="r", ls="--", lw=1, label="limit")
    for kind, colour in CHANGING_KINDS.items():
        c = r["controllers"].get(kind)
        if c is None:
            continue
        ax.plot(t, np.asarray(c["pressure_Pa"]) / 1e5, color=colour, lw=1,
                label=f"{kind.removeprefix('delay_')}: capped RMSE "
                      f"{feasible_rmse(c['pressure_Pa'], r['reference_Pa']) / 1e3:.1f} kPa, "
                      f"{c['ticks_above_limit']} ticks over")
    ax.axvline(change["at_s"], color="grey", lw=0.8, ls=":")
    ax.set_ylabel("pressure, bar (abs)")
    ax.set_ylim(max(ax.get_ylim()[0], 2.0), None)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"{change['parameter']} x {change['factor']:g} at {change['at_s']:g} s, "
                 f"then {change.get('drift_log_per_s', 0.0):+g} log/s (seed {r['seed']})")
    ax = fig.add_subplot(grid[1, :], sharex=fig.axes[0])
    true = np.asarray(change["true_per_tick"])
    ax.plot(t[: true.size], true, color="k", lw=1, label="plant")
    online = r["controllers"].get("delay_online", {}).get("tracked", {}).get(
        change["parameter"])
    if online:
        q = np.asarray(online)
        ax.fill_between(t[: len(q)], q[:, 0], q[:, 2], color="tab:blue", alpha=0.3, lw=0,
                        label="online 5-95 %")
        ax.plot(t[: len(q)], q[:, 1], color="tab:blue", lw=1, label="online median")
    if change.get("offline_median") is not None:
        ax.axhline(change["offline_median"], color="tab:red", lw=1,
                   label="offline posterior median (frozen)")
    ax.axvline(change["at_s"], color="grey", lw=0.8, ls=":")
    ax.set_ylabel(f"{change['parameter']}")
    ax.set_xlabel("time, s")
    ax.legend(fontsize=8, loc="upper right")
    seeds = [x["seed"] for x in results]
    kinds = [k for k in controllers if k in CHANGING_KINDS] + [
        k for k in controllers if k not in CHANGING_KINDS]
    width = 0.8 / max(len(kinds), 1)
    for col, (key, label) in enumerate((("ticks_above_limit", "ticks above the limit"),
                                        ("feasible_tracking_rmse_Pa",
                                         "capped tracking RMSE, kPa"))):
        ax = fig.add_subplot(grid[2, col])
        for i, kind in enumerate(kinds):
            v = np.asarray(controllers[kind][key], dtype=np.float64)
            v = v / 1e3 if key.endswith("_Pa") else v
            ax.bar(np.arange(len(seeds)) + (i - (len(kinds) - 1) / 2) * width, v, width,
                   color=CHANGING_KINDS.get(kind, "tab:grey" if i % 2 else "tab:olive"),
                   label=kind.removeprefix("delay_"))
        ax.set_xticks(np.arange(len(seeds)), [str(x) for x in seeds])
        ax.set_xlabel("seed")
        ax.set_ylabel(label)
        if key.endswith("_Pa"):
            lo = min(np.min(controllers[k][key]) for k in kinds) / 1e3
            ax.set_ylim(0.95 * lo, None)
        if col == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def tradeoff_figure(controllers: dict, path: Path, baseline: str = "nominal") -> None:
    """Total ticks over the limit (over the seeds) against the median capped RMSE: the
    ``baseline`` nominal and its fixed back-offs as one curve, every other controller a
    point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def point(k):
        v = controllers[k]
        return sum(v["ticks_above_limit"]), np.median(v["feasible_tracking_rmse_Pa"]) / 1e3

    fig, ax = plt.subplots(figsize=(7, 4.5))
    prefix = baseline.removesuffix("nominal")
    curve = [k for k in (baseline, *(prefix + b for b in BACKOFF_PA)) if k in controllers]
    if len(curve) > 1:
        xy = np.array([point(k) for k in curve])
        margins_kPa = [(backoff_Pa(k) or 0.0) / 1e3 for k in curve]
        ax.plot(xy[:, 0], xy[:, 1], "o-", color="tab:orange", label="nominal, back-off "
                + ", ".join(f"{m:g}" for m in margins_kPa) + " kPa")
        for m, (x, y) in zip(margins_kPa, xy):
            ax.annotate(f"{m:g}", (x, y), fontsize=7, textcoords="offset points",
                        xytext=(4, 4))
    for k in controllers:
        if k in curve:
            continue
        x, y = point(k)
        ax.plot([x], [y], "s" if k.startswith("delay_") and not prefix else "^", label=k)
    ax.set_xlabel("ticks above the limit, total over the seeds")
    ax.set_ylabel("capped tracking RMSE, kPa (median over seeds)")
    ax.set_xscale("symlog", linthresh=1.0)
    ax.legend(fontsize=7)
    ax.set_title("violations against tracking: fixed margins and the posterior")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/mpc")
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--quick", action="store_true", help="short recordings and chains")
    ap.add_argument("--scenario", choices=tuple(SCENARIOS), default="hidden_delay",
                    help="what the posterior is fitted on (SCENARIOS; default hidden_delay)")
    ap.add_argument("--json", default=None, help="summary (default OUT/summary.json)")
    ap.add_argument("--figure", default=None, help="figure (default OUT/mpc_tracking.png)")
    ap.add_argument("--dense-output", action=argparse.BooleanOptionalAction, default=True,
                    help="predict with dense output (default; --no-dense-output stops the "
                         "integrator at every tick)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]

    def log(m):
        print(m, file=sys.stderr, flush=True)

    revision = code_revision()  # before the seeds: the code that runs them
    results = [run_seed(s, out, args.quick, log, args.scenario, args.dense_output, revision)
               for s in seeds]
    summary = {"seeds": seeds, "quick": args.quick, "scenario": args.scenario,
               "dense_output": args.dense_output,
               "rate_Hz": RATE_HZ,
               "horizon_s": HORIZON_TICKS * DT_S,
               "candidates": scenario_candidates(args.scenario),
               "draws": N_DRAWS, "hidden_delay_s": HIDDEN_DELAY_S, "p_max_Pa": P_MAX_PA,
               "run_s": RUN_S, "controllers": summarise(results, args.scenario),
               "fits": [r.get("fit") for r in results],
               "fits_delay": [r.get("fit_delay") for r in results],
               "posterior_noise_scale_Pa": [r["posterior_noise_scale_Pa"] for r in results],
               "provenance": provenance()}
    if args.scenario == "changing_plant":
        sc = SCENARIOS["changing_plant"]
        summary.update(change=sc["change"], varying=sc["varying"], online=ONLINE,
                       setpoint_range_Pa=list(sc["setpoint_range_Pa"]),
                       second_levels_V=list(sc["second_levels_V"]))
    write_json_atomic(args.json or out / "summary.json", summary)
    if args.scenario == "changing_plant":
        changing_figure(results, summary["controllers"],
                        Path(args.figure) if args.figure else out / "mpc_changing.png")
    else:
        figure(results, Path(args.figure) if args.figure else out / "mpc_tracking.png")
    tradeoff_figure(summary["controllers"], out / "mpc_tradeoff.png",
                    SCENARIOS[args.scenario]["baseline"])
    for kind, s in summary["controllers"].items():
        print(f"{kind:10s} RMSE {np.median(s['tracking_rmse_Pa']):7.0f} Pa (median), ticks "
              f"above the limit {s['ticks_above_limit']}, compute "
              f"{np.median(s['compute_ms_per_tick_median']):.2f} ms/tick")
    return 0


if __name__ == "__main__":
    sys.exit(main())
