"""Stage: an open-form term on the command, a valve driver on its own clock, when the
catalogue does not close the gap.

A driver that takes the command at the ticks of a clock the recording does not carry (a
fieldbus output, a control loop slower than the logger, a pulse-width-modulated on/off
valve) makes every command change wait a share of a period that depends on where it
falls between the ticks: no delay or lag of the catalogue expresses it, and a sensor lag
or a spool lag stands in for its mean. This stage reads the clock from the training
windows (:class:`~pneubayes.discovery.openform.command_clock.CommandClockSearch`) and
adds the found driver as one :class:`~pneubayes.effects.command_clock.CommandClock`,
fitted and weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm`
does, then read and fitted again in turn: a model fitted without the driver has bent its
valve maps to take part of the waits, so the first reading is off by milliseconds and
the first fit settles beside it; read again beside the refitted maps, the takes move
toward the true ticks (``joint_passes``). The ticks end in the middle of the span the
training changes allow (:func:`~pneubayes.discovery.openform.clock_reading.ticks_centred`).
It runs first among the open forms and challenges a passing trial that closes
under 90 % of the gap (``compete_below_gap_closed``), replacing it where the driver
predicts the held-out windows better.
"""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.openform.clock_polish import polish_clock
from pneubayes.discovery.openform.clock_reading import ticks_centred
from pneubayes.discovery.openform.command_clock import CommandClockProblem, CommandClockSearch
from pneubayes.discovery.stages.component_form import ComponentForm, clipped_start
from pneubayes.discovery.trials import NESTED_TOLERANCE
from pneubayes.effects.command_clock import (
    LATENCY,
    LATENCY_BOUNDS_S,
    PERIOD,
    PHASE,
    SHORTEST_PERIOD_S,
    CommandClock,
)
from pneubayes.errors import FIT_FAILURES

#: The component's name in a model and in the ledger.
COMMAND_CLOCK = "command_clock"


class CommandClockForm(ComponentForm):
    """Read a valve driver's clock from the training windows' residual and add it as a
    command clock (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs only while the held-out RMSE exceeds this x the noise floor.
    compete_below_gap_closed : float
        With a passing trial, the stage runs only if the best closes less than this share
        of the held-out gap above the noise floor.
    search : CommandClockSearch or None
        The residual search (its settings); None: ``CommandClockSearch()``.
    joint_passes : int
        After the first fit, at most this many rounds of reading the clock again beside
        the fitted model and refitting from there (0: the first fit only).
    joint_min_gain : float
        A round that lowers the training RMSE by less than this share ends them.
    polish_halvings : int
        After each fit, the driver's timing is polished by a compass search whose steps
        are halved this many times (0: not polished).
    """

    name = "command_clock_form"
    component = COMMAND_CLOCK
    label = "command clock form"
    term_word = "driver clock"
    search_class = CommandClockSearch

    def __init__(self, min_noise_ratio: float = 1.5, compete_below_gap_closed: float = 0.9,
                 search=None, joint_passes: int = 3, joint_min_gain: float = 0.02,
                 polish_halvings: int = 6):
        super().__init__(min_noise_ratio, compete_below_gap_closed, search)
        if isinstance(joint_passes, bool) or not isinstance(joint_passes, int) \
                or joint_passes < 0:
            raise ValueError(f"CommandClockForm: joint_passes must be an integer >= 0, got "
                             f"{joint_passes!r}")
        if not 0.0 <= joint_min_gain < 1.0:
            raise ValueError(f"CommandClockForm: joint_min_gain must be in [0, 1), got "
                             f"{joint_min_gain!r}")
        if isinstance(polish_halvings, bool) or not isinstance(polish_halvings, int) \
                or polish_halvings < 0:
            raise ValueError(f"CommandClockForm: polish_halvings must be an integer >= 0, "
                             f"got {polish_halvings!r}")
        self.joint_passes = joint_passes
        self.joint_min_gain = joint_min_gain
        self.polish_halvings = polish_halvings

    def options(self):
        return {**super().options(), "joint_passes": self.joint_passes,
                "joint_min_gain": self.joint_min_gain, "polish_halvings": self.polish_halvings}

    def _search_data(self, state, runner) -> CommandClockProblem:
        return CommandClockProblem(runner.data.train_ws, state.current.model,
                                   state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        return CommandClock()

    def _component_for(self, terms):
        return CommandClock(terms[0].form)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return PERIOD, PHASE, LATENCY

    def _search_record(self, search) -> dict:
        return {"coherence": search.coherence_, "p_value": search.p_value_}

    def _strength_names(self, k: int) -> tuple[str, ...]:
        return PERIOD, LATENCY

    def _searched_values(self, terms, params) -> dict[str, float]:
        return terms[0].values()

    def _fit(self, state, runner, terms):
        fit = super()._fit(state, runner, terms)
        if fit is None:
            return None
        fit = self._joint(self._polished(fit, runner, terms[0].form), runner)
        return self._centred(fit, runner)

    @staticmethod
    def _problem(fit, runner) -> CommandClockProblem:
        """The search's problem beside ``fit``'s model, its driver taken out (the other
        parameters as fitted)."""
        without = fit.model.without(COMMAND_CLOCK)
        return CommandClockProblem(runner.data.train_ws, without,
                                   {n: fit.params[n] for n in without.parameter_names},
                                   runner.settings.fit.refine_solver)

    def _joint(self, fit, runner):
        """Read the clock again beside ``fit``'s model (the driver taken out, the other
        parameters as fitted; in every form the search tries, so a PWM valve first read
        as a holding driver can change form) and refit from there, while a round gains
        ``joint_min_gain`` of the training RMSE."""
        s = self.search if self.search is not None else self.search_class()
        for k in range(self.joint_passes):
            problem = self._problem(fit, runner)
            search = type(s)(**s.get_params()).fit(problem)
            if search.best_ is None:
                break
            model = problem.model.with_effect(CommandClock(search.best_.form))
            start = clipped_start(model, {**model.neutral_values(), **fit.params},
                                  search.best_.values())
            try:
                again = runner.fit(model, {n: start[n] for n in model.parameter_names})
            except FIT_FAILURES as exc:
                runner.log(f"discover: {self.label}: reading {k + 2}: {type(exc).__name__}")
                break
            again = self._polished(again, runner, search.best_.form)
            runner.log(f"discover: {self.label}: read again beside the fitted model "
                       f"({search.best_}), training RMSE {fit.train_rmse_Pa:.0f} -> "
                       f"{again.train_rmse_Pa:.0f} Pa")
            gained = again.train_rmse_Pa < fit.train_rmse_Pa * (1.0 - self.joint_min_gain)
            if again.train_rmse_Pa < fit.train_rmse_Pa:
                fit = again
            if not gained:
                break
        return fit

    def _polished(self, fit, runner, form):
        """``fit`` with the driver's timing polished beside the rest as fitted
        (:func:`~pneubayes.discovery.openform.clock_polish.polish_clock`, its steps halved
        ``polish_halvings`` times) and refitted from there, in turn while a round lowers
        the training RMSE by ``joint_min_gain`` (at most ``joint_passes`` rounds). The
        trajectory refinement's finite differences do not move a driver's timing (a
        staircase: each tick takes the sample held there), so the polish does."""
        if not fit.params[PERIOD] >= SHORTEST_PERIOD_S or not self.polish_halvings:
            return fit  # no clock (a pure delay), or no polish
        names = CommandClock(form).parameter_names()
        bounds = {n: (fit.model.parameter(n).lower, fit.model.parameter(n).upper)
                  for n in names}
        for _ in range(max(self.joint_passes, 1)):
            problem = self._problem(fit, runner)
            clock, before, after = polish_clock(
                _training_rmse(problem, form), {n: fit.params[n] for n in names}, bounds,
                float(np.mean(problem.residual_times_s())), problem.duration_s(),
                self.polish_halvings)
            if not after < before:
                return fit
            try:
                again = runner.fit(fit.model, {**fit.params, **clock})
            except FIT_FAILURES:
                again = runner.score(fit.model, {**fit.params, **clock})
            runner.log(f"discover: {self.label}: timing polished (period "
                       f"{fit.params[PERIOD] * 1e3:.6g} -> {clock[PERIOD] * 1e3:.6g} ms, "
                       f"latency {fit.params[LATENCY] * 1e3:.3f} -> "
                       f"{clock[LATENCY] * 1e3:.3f} ms), training RMSE "
                       f"{fit.train_rmse_Pa:.0f} -> {after:.0f} Pa, refitted "
                       f"{again.train_rmse_Pa:.0f} Pa")
            if not again.train_rmse_Pa < fit.train_rmse_Pa:
                return fit
            gained = again.train_rmse_Pa < fit.train_rmse_Pa * (1.0 - self.joint_min_gain)
            fit = again
            if not gained:
                break
        return fit

    def _centred(self, fit, runner):
        """``fit`` with its ticks in the middle of the span the training changes allow,
        kept if its training RMSE stays within the nested tolerance."""
        if not fit.params[PERIOD] >= SHORTEST_PERIOD_S:
            return fit
        changes = self._problem(fit, runner).changes()[2]
        phase, latency = ticks_centred(changes, fit.params[PERIOD], fit.params[PHASE],
                                       fit.params[LATENCY], LATENCY_BOUNDS_S)
        if (phase, latency) == (fit.params[PHASE], fit.params[LATENCY]):
            return fit
        centred = runner.score(fit.model, {**fit.params, PHASE: phase, LATENCY: latency})
        if centred.train_rmse_Pa > fit.train_rmse_Pa * (1.0 + NESTED_TOLERANCE):
            return fit
        runner.log(f"discover: {self.label}: ticks centred between the training changes "
                   f"(phase {fit.params[PHASE]:.3f} -> {phase:.3f}, latency "
                   f"{fit.params[LATENCY] * 1e3:.2f} -> {latency * 1e3:.2f} ms), training "
                   f"RMSE {fit.train_rmse_Pa:.0f} -> {centred.train_rmse_Pa:.0f} Pa")
        return centred


def _training_rmse(problem: CommandClockProblem, form: str):
    """``rows -> (S,)``: the training RMSE (Pa; NaN where a simulation failed) of
    ``problem``'s model with each row's driver of ``form``."""
    def rmse(rows):
        r = problem.window_residuals(form, rows, current=True)
        return np.sqrt(np.mean(r**2, axis=(1, 2)))
    return rmse
