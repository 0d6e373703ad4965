"""The open-form search on the command: a valve driver on its own clock in the prediction
windows' residual.

A driver that takes the command at the ticks of its clock
(:class:`~pneubayes.effects.command_clock.CommandClock`) makes every command change wait
a share of a period that depends on where it falls between the ticks, and a
pulse-width-modulated valve fill and vent in bursts within each period. The ticks are
locked to a clock the recording does not carry, and over a 20-s recording a period must
be known to a part in 10^5 for them to stay in phase: no grid of simulations reaches
that. The search reads the clock from the data instead (:class:`CommandClockSearch`):

1. each command change's wait: the windows simulated with the command delayed by each
   of a grid of waits (one batch), and per change the wait whose residual over the
   samples after it is least (its gain over no wait its weight);
2. the clock: where the valve took each change (its time plus its wait) falls on the
   driver's ticks plus the latency, so the period is the one at which those times are
   most in phase (the weighted mean of ``exp(2 pi i t / T)`` over a fine grid of
   frequencies, the longest period among its near-equals: a tick pattern is also in
   phase at its period's fractions), and the phase of that mean is where the ticks fall;
3. the driver itself: both forms at latencies that split the phase between the clock
   and the latency (the shortest waits bound the latency), a modulator's pulses from
   the tick and centred, simulated, the best refined locally.

A driver is kept when it removes at least ``min_explained_fraction`` of the residual's
sum of squares and the windows' reductions, each as a share of the window's own sum of
squares, are ``min_t`` standard errors above zero, or when it removes
``strong_explained_fraction`` of it at a mean reduction above zero (as the volume's
walls are, :mod:`pneubayes.discovery.openform.volume_play`), or when the takes are in
phase beyond a chance the valve maps cannot fake (a model fitted without the driver
bends them to take part of the waits; the stage's trial refits them).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.clock_reading import (
    change_onsets,
    change_takes,
    clock_in_phase,
    ripple_periods,
)
from pneubayes.discovery.openform.gate import check_gate, earns_trial
from pneubayes.discovery.openform.volume import window_reduction
from pneubayes.effects.command_clock import (
    ALIGNMENT,
    ALIGNMENT_BOUNDS,
    FORMS,
    FULL_COMMAND,
    FULL_COMMAND_BOUNDS_V,
    LATENCY,
    LATENCY_BOUNDS_S,
    PERIOD,
    PERIOD_BOUNDS_S,
    PHASE,
    PULSE_TRIM,
    PULSE_TRIM_BOUNDS_S,
    CommandClock,
)


@dataclass(frozen=True)
class ClockTerm:
    """A kept driver: its ``form``, ``period_s``, ``phase``, ``latency_s`` and (PWM)
    ``full_command_V``, ``pulse_trim_s`` and ``alignment``, the share of the residual's
    sum of squares it removes (``explained``), the windows' mean relative reduction over
    its standard error (``t``) and the model's values it replaces (``cleared``,
    name-value pairs)."""

    form: str
    period_s: float
    phase: float
    latency_s: float
    full_command_V: float
    pulse_trim_s: float
    explained: float
    t: float
    cleared: tuple = ()
    alignment: float = 0.0

    def values(self) -> dict[str, float]:
        """The parameter values the term stands for: the component's, and the model's
        it replaces (``cleared``: a transport delay the latency carries)."""
        out = {PERIOD: self.period_s, PHASE: self.phase, LATENCY: self.latency_s,
               **dict(self.cleared)}
        if self.form == "pwm":
            out.update({FULL_COMMAND: self.full_command_V, PULSE_TRIM: self.pulse_trim_s,
                        ALIGNMENT: self.alignment})
        return out

    def __str__(self) -> str:
        what = ("a driver holding the command" if self.form == "hold" else
                f"a PWM driver (full at {self.full_command_V:.3g} V)")
        return (f"{what} on a {self.period_s * 1e3:.3g}-ms clock (phase "
                f"{self.phase:.2f}, latency {self.latency_s * 1e3:.3g} ms)")


@dataclass(frozen=True)
class CommandClockProblem:
    """What the search simulates: the training windows, the current model and its
    parameters, and the solver."""

    window_set: object
    model: object
    params: dict
    solver: object

    def check(self) -> None:
        """Raise ValueError where a driver's clock cannot join the model."""
        if self.model.has(CommandClock.name):
            raise ValueError("the model already has a driver's clock")

    def full_command_V(self) -> float:
        """The largest command magnitude the windows' recordings carry (V): a PWM
        driver's full scale to start from."""
        u = np.concatenate([np.abs(b.inputs.command_V) for b in self.window_set.blocks])
        return float(np.clip(np.max(u), *FULL_COMMAND_BOUNDS_V))

    @property
    def cleared(self) -> dict[str, float]:
        """The model's values a driver replaces: a transport delay of the command (the
        tube's, fitted before the driver for the waits' mean), which the driver's
        latency then carries (the waits the search reads cannot be negative)."""
        if self.model.has("tube_delay") and self.model.effect("tube_delay").form \
                == "transport":
            return {"tube_delay_s": 0.0}
        return {}

    def window_residuals(self, form: str, rows: Sequence[dict],
                         current: bool = False) -> np.ndarray:
        """Prediction minus measurement ``(S, W, L - 1)`` (Pa; NaN where a simulation
        failed) for ``S`` drivers of ``form``, each a dict of the component's values (an
        empty one: the model without a driver, its :attr:`cleared` values cleared unless
        ``current``)."""
        trial = self.model.with_effect(CommandClock(form))
        off = {**self.params, **CommandClock(form).neutral_values(),
               **({} if current else self.cleared)}
        theta = np.stack([trial.vector({**off, **r}) for r in rows])
        return self.window_set.residuals(trial, theta, self.solver, on_failure="nan")

    def window_sse(self, form: str, rows: Sequence[dict]) -> np.ndarray:
        """Each window's sum of squared residuals ``(S, W)`` (Pa^2; inf where a
        simulation failed), as :meth:`window_residuals`."""
        sse = np.sum(self.window_residuals(form, rows) ** 2, axis=2)
        return np.where(np.isfinite(sse), sse, np.inf)

    def changes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The command's changes inside the windows: ``(window, sample, time_s)``, each
        ``(C,)``: the window's index (block order), the window sample (>= 1) from which
        the new command holds, and its time on the recording's clock."""
        out, w0 = [], 0
        for b in self.window_set.blocks:
            t, u = b.inputs.time_s, b.inputs.command_V
            n = self.window_set.length
            for w, s in enumerate(b.starts):
                i = np.flatnonzero(u[s + 1:s + n] != u[s:s + n - 1]) + 1
                out += [(w0 + w, k, t[s + k]) for k in i]
            w0 += b.starts.size
        if not out:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        w, k, tc = zip(*out)
        return np.array(w), np.array(k), np.array(tc, dtype=np.float64)

    def residual_times_s(self) -> np.ndarray:
        """The times (s, on each recording's clock) of the residuals ``(W, L - 1)``."""
        n = self.window_set.length
        return np.concatenate([b.inputs.time_s[b.starts[:, None] + np.arange(1, n)]
                               for b in self.window_set.blocks])

    def sample_interval_s(self) -> float:
        """The recordings' median sample interval (s)."""
        return float(np.median(np.diff(self.window_set.blocks[0].inputs.time_s)))

    def duration_s(self) -> float:
        """The longest recording's span on its clock (s)."""
        return max(float(b.inputs.time_s[-1]) for b in self.window_set.blocks)


class CommandClockSearch:
    """A valve driver's clock read from the windows' residual (scikit-learn contract:
    settings in the constructor, :meth:`fit` sets the ``_`` attributes).

    Parameters
    ----------
    forms : sequence of str
        The drivers tried (``"hold"``, ``"pwm"``).
    longest_wait_s, after_change_s : float
        The longest wait of a command change tried (a period and a latency), s; how
        long after a change its wait is judged (s; cut at the next change).
    shortest_period_s, longest_period_s : float
        The periods the clock may have (not under two sample intervals).
    latencies : int
        How many splits of the ticks' phase between the clock and the latency are tried.
    refine_passes : int
        Rounds of local refinement of the best (steps halved each round; 0: as found).
    min_explained_fraction, min_t, strong_explained_fraction : float
        The gate (as :class:`~pneubayes.discovery.openform.volume_play.VolumePlaySearch`).
    max_p_value, any_t_p_value : float
        A driver whose changes' takes are in phase beyond the first chance
        (:attr:`p_value_`) is kept at any ``t`` above 0, beyond the second whatever it
        removes: beside valve maps bent to take the waits it gains little, or loses,
        until the trial refits them.
    max_change_coherence : float
        Periods where the changes themselves are in phase this share of their takes'
        coherence are not read (:func:`.clock_reading.clock_in_phase`).

    Attributes
    ----------
    terms_ : list of ClockTerm
        The kept driver (one at most).
    explained_fraction_ : float
        Share of the residual's sum of squares it removes.
    best_ : ClockTerm or None
        The best driver, kept or not (what the search saw).
    coherence_ : float
        How much in phase the changes' takes are at the found period (0-1).
    p_value_ : float
        The chance that takes without a clock are as much in phase at some period.
    """

    def __init__(self, forms: Sequence[str] = FORMS, longest_wait_s: float = 0.06,
                 after_change_s: float = 0.08, shortest_period_s: float = 2e-3,
                 longest_period_s: float = 0.05, latencies: int = 8, refine_passes: int = 3,
                 min_explained_fraction: float = 0.02, min_t: float = 4.0,
                 strong_explained_fraction: float = 0.5, max_p_value: float = 1e-3,
                 any_t_p_value: float = 1e-6, max_change_coherence: float = 0.5):
        self.forms = forms
        self.max_p_value = max_p_value
        self.any_t_p_value = any_t_p_value
        self.max_change_coherence = max_change_coherence
        self.longest_wait_s = longest_wait_s
        self.after_change_s = after_change_s
        self.shortest_period_s = shortest_period_s
        self.longest_period_s = longest_period_s
        self.latencies = latencies
        self.refine_passes = refine_passes
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t
        self.strong_explained_fraction = strong_explained_fraction

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {k: getattr(self, k) for k in (
            "forms", "longest_wait_s", "after_change_s", "shortest_period_s",
            "longest_period_s", "latencies", "refine_passes", "min_explained_fraction",
            "min_t", "strong_explained_fraction", "max_p_value", "any_t_p_value",
            "max_change_coherence")}

    def _validate(self, problem):
        if isinstance(self.forms, str) or not len(self.forms) \
                or any(f not in FORMS for f in self.forms):
            raise ValueError(f"forms must be a non-empty sequence of {FORMS}, got "
                             f"{self.forms!r}")
        for name in ("latencies", "refine_passes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (name == "latencies"):
                raise ValueError(f"{name} must be an integer >= "
                                 f"{int(name == 'latencies')}, got {v!r}")
        if not 0.0 < self.shortest_period_s < self.longest_period_s <= PERIOD_BOUNDS_S[1]:
            raise ValueError("need 0 < shortest_period_s < longest_period_s <= "
                             f"{PERIOD_BOUNDS_S[1]} s, got {self.shortest_period_s!r}, "
                             f"{self.longest_period_s!r}")
        if not 0.0 < self.longest_wait_s <= LATENCY_BOUNDS_S[1] + PERIOD_BOUNDS_S[1] \
                or not self.after_change_s > 0.0:
            raise ValueError("longest_wait_s and after_change_s must be > 0, got "
                             f"{self.longest_wait_s!r}, {self.after_change_s!r}")
        check_gate(self.min_explained_fraction, self.min_t, self.strong_explained_fraction)
        for name in ("max_p_value", "any_t_p_value", "max_change_coherence"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)!r}")
        if not isinstance(problem, CommandClockProblem):
            raise ValueError("fit takes a CommandClockProblem")
        problem.check()

    def fit(self, problem: CommandClockProblem) -> "CommandClockSearch":
        """Search the training windows of ``problem``."""
        self._validate(problem)
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        self.coherence_, self.p_value_ = 0.0, 1.0
        dt = problem.sample_interval_s()
        # a clock faster than half the sampling rate is read at its aliases
        shortest = max(self.shortest_period_s, 2.0 * dt)
        if shortest >= self.longest_period_s:
            return self
        waits = np.arange(0.0, self.longest_wait_s + 0.5 * dt, dt)
        resid = problem.window_residuals("hold", [{LATENCY: float(w)} for w in waits])
        # the current model is the scan's zero wait unless the scan cleared its values
        now = resid[0] if not problem.cleared else \
            problem.window_residuals("hold", [{}], current=True)[0]
        current = np.sum(now**2, axis=1)
        total = float(np.sum(current))
        if not np.isfinite(total) or total <= 0.0:
            return self
        duration = problem.duration_s()
        held = []
        # the changes' takes as the current model sees them, and their onsets in the
        # measured pressure (which a model whose valve maps the wait has bent misses)
        changes, measured = problem.changes(), problem.window_set.measured
        for took, weight in (
                change_takes(changes, measured, resid, waits, self.after_change_s / dt),
                change_onsets(changes, measured, int(round(self.longest_wait_s / dt)), dt)):
            if took.shape[0] < 3:
                continue
            period, offset, coherence, p_value = clock_in_phase(
                took[:, 0], weight, shortest, self.longest_period_s, duration,
                changes[2], self.max_change_coherence)
            if not np.isfinite(period):
                continue
            if coherence > self.coherence_:
                self.coherence_, self.p_value_ = coherence, p_value
            # the latency: at most the shortest waits (a change taken at once waits it
            # alone)
            most = float(np.quantile(took[:, 1], 0.1, weights=weight, method="inverted_cdf"))
            for k in range(self.latencies):
                lat = min(max(most - (k / self.latencies) * period, 0.0), LATENCY_BOUNDS_S[1])
                held.append({PERIOD: period, PHASE: float(((offset - lat) / period) % 1.0),
                             LATENCY: lat})
        full = problem.full_command_V()
        # a modulating driver's ripple: the residual's strongest lines, at phases spread
        pulsed = [{PERIOD: p, PHASE: k / self.latencies, LATENCY: 0.0, FULL_COMMAND: full}
                  for p in ripple_periods(problem.residual_times_s(), resid[0], dt,
                                          shortest, self.longest_period_s,
                                          duration)
                  for k in range(self.latencies)]
        best = None
        for form in self.forms:
            # a modulator's pulses from the tick (an edge-aligned timer) or centred (a
            # phase-correct one)
            rows = ([{**r, ALIGNMENT: a} for r in pulsed + [{**r, FULL_COMMAND: full}
                                                          for r in held]
                     for a in (0.0, ALIGNMENT_BOUNDS[1])] if form == "pwm" else held)
            sse = problem.window_sse(form, rows)
            total_sse = np.sum(sse, axis=1)
            # the best row of each of the two best periods found, refined (a period's
            # best phase on the grid may lose to another period's before either is)
            firsts = {}
            for i in np.argsort(total_sse):
                firsts.setdefault(rows[i][PERIOD], int(i))
            for j in list(firsts.values())[:2]:
                if not np.isfinite(sse[j]).all():
                    continue
                row, row_sse = _refined(problem, form, rows[j], sse[j], self.refine_passes,
                                        0.02 / duration)
                if best is None or np.sum(row_sse) < np.sum(best[2]):
                    best = (form, row, row_sse)
        if best is None:
            return self
        form, row, row_sse = best
        explained, t = window_reduction(current, row_sse, total, relative=True)
        self.best_ = ClockTerm(form, row[PERIOD], row[PHASE], row[LATENCY],
                               row.get(FULL_COMMAND, full), row.get(PULSE_TRIM, 0.0),
                               explained, t, tuple(problem.cleared.items()),
                               row.get(ALIGNMENT, 0.0))
        if earns_trial(explained, t, self.min_explained_fraction, self.min_t,
                       self.strong_explained_fraction, self.p_value_ <= self.max_p_value) \
                or self.p_value_ <= self.any_t_p_value:
            self.terms_ = [self.best_]
            self.explained_fraction_ = explained
        return self


def _refined(problem, form, centre, sse, passes, freq_step):
    """Local refinement of a driver ``centre`` (the component's values) with windows'
    sums of squares ``sse``: ``passes`` rounds of the 3 x 3 x 3 neighbours in frequency
    (``freq_step`` Hz at first), phase (1/16) and latency (1/16 period) and, for a PWM
    driver, the 3 x 3 of its full command (x 1.1) and pulse trim (1/16 period) and its
    alignment either way (1/4), each round's steps halved; the best kept. Returns
    ``(centre, sse)``."""
    d_f, d_ph, d_l, f_u, d_a = freq_step, 1.0 / 16.0, 1.0 / 16.0, 1.1, 0.25
    for _ in range(passes):
        f0, ph0, l0 = 1.0 / centre[PERIOD], centre[PHASE], centre[LATENCY]
        cand = [{**centre, PERIOD: float(1.0 / (f0 + a)), PHASE: float((ph0 + b) % 1.0),
                 LATENCY: float(np.clip(l0 + c / f0, *LATENCY_BOUNDS_S))}
                for a in (-d_f, 0.0, d_f) for b in (-d_ph, 0.0, d_ph)
                for c in (-d_l, 0.0, d_l)]
        if form == "pwm":  # and the pulses: their full command, trim and alignment
            u0, e0 = centre[FULL_COMMAND], centre.get(PULSE_TRIM, 0.0)
            a0 = centre.get(ALIGNMENT, 0.0)
            cand += [{**centre, FULL_COMMAND: float(np.clip(u0 * a, *FULL_COMMAND_BOUNDS_V)),
                      PULSE_TRIM: float(np.clip(e0 + c / f0, *PULSE_TRIM_BOUNDS_S))}
                     for a in (1.0 / f_u, 1.0, f_u) for c in (-d_l, 0.0, d_l)]
            cand += [{**centre, ALIGNMENT: float(np.clip(a0 + b, *ALIGNMENT_BOUNDS))}
                     for b in (-d_a, d_a)]
        got = problem.window_sse(form, cand)
        j = int(np.argmin(np.sum(got, axis=1)))
        if np.isfinite(got[j]).all() and np.sum(got[j]) < np.sum(sse):
            centre, sse = cand[j], got[j]
        d_f, d_ph, d_l, f_u, d_a = 0.5 * d_f, 0.5 * d_ph, 0.5 * d_l, np.sqrt(f_u), 0.5 * d_a
    return centre, sse


__all__ = ["ClockTerm", "CommandClockProblem", "CommandClockSearch"]
