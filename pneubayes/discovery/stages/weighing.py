"""The held-out test an open-form trial passes, shared by the stages that propose one.

A fitted open-form trial (the closure's mass flow, the reading's relaxations) is weighed
as a named effect is: against the current model on the held-out windows (the runner's
score test), against its control (the current model refined from the trial's point, so a
gain that is only a better basin of the current model does not count), for a gain of at
least the round's least share of the gap above the noise, with no parameter newly at a
bound, and against the round's best passing catalogue trial when there is one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.discovery.openform.closure_model import newly_at_bounds
from pneubayes.discovery.rounds import gain_shortfall, min_gain_Pa


@dataclass(frozen=True)
class Weighing:
    """What :func:`weigh` found; ``passed`` is the verdict."""

    passed: bool
    gain: float
    p_value: float
    window_gains: np.ndarray
    gap_closed: float
    under: bool
    least_Pa: float
    drop_Pa: float
    bounded: list
    basin: bool
    beats_best: bool | None
    control_heldout_rmse_Pa: float | None

    def reasons(self, best) -> list[str]:
        """Why a trial that failed failed, in words."""
        return ([] if not self.basin else ["its gain is its basin's"]) + (
            [f"{', '.join(self.bounded)} at a bound"] if self.bounded else []) + (
            [f"it gains {self.drop_Pa:.1f} Pa, under {self.least_Pa:.1f} Pa"]
            if self.under else []) + (
            [f"not better than {best[1]}"] if self.beats_best is False else [])

    def record(self, fit, current, best) -> dict:
        """The ledger's fields of the test."""
        return dict(
            gap_closed=self.gap_closed, gain_under_floor=bool(self.under),
            min_gain_Pa=self.least_Pa, train_rmse_Pa=fit.train_rmse_Pa,
            heldout_rmse_before_Pa=current.heldout_rmse_Pa,
            heldout_rmse_after_Pa=fit.heldout_rmse_Pa,
            score_gain=self.gain, score_p_value=self.p_value,
            control_heldout_rmse_Pa=self.control_heldout_rmse_Pa,
            not_better_than_control=self.basin, at_bounds=self.bounded,
            catalogue_best=None if best is None else {
                "effect": best[1], "heldout_rmse_Pa": best[0],
                "closure_better": self.beats_best},
            windows_improved=int(np.sum(self.window_gains > 0)),
            windows=int(self.window_gains.size), wall_time_s=fit.wall_time_s)


def weigh(fit, state, runner, best, label: str) -> Weighing:
    """Weigh the trial ``fit`` (its component ``label``) against ``state.current`` (which
    its control may replace, :meth:`~pneubayes.discovery.trials.TrialRunner.controls`)
    and the round's best passing trial ``best`` (or None)."""
    s, noise = runner.settings, runner.data.noise_Pa
    control = runner.controls([(label, fit)], state)[0]
    current = state.current
    ok, gain, pval, diff = runner.better(fit, current)
    basin = bool(ok and control is not None and control is not current
                 and not runner.better(fit, control)[0])
    gap_Pa = current.heldout_rmse_Pa - noise
    drop_Pa = current.heldout_rmse_Pa - fit.heldout_rmse_Pa
    least = min_gain_Pa(noise, gap_Pa, s)
    closed, _, under = gain_shortfall(drop_Pa, gap_Pa, 0.0, least)
    bounded = newly_at_bounds(fit, current)
    ok = ok and not basin and not under and not bounded
    beats = None
    if ok and best is not None:
        beats = bool(runner.better(fit, best[2])[0])
        ok = beats
    return Weighing(bool(ok), gain, pval, diff, closed, bool(under), least, drop_Pa,
                    bounded, basin, beats,
                    None if control is None else control.heldout_rmse_Pa)


def competes(state, noise_Pa: float, compete_below_gap_closed: float):
    """``(runs, the round's best passing trial or None)`` for an open-form stage: it runs
    when nothing passed, or the best passing trial closes under
    ``compete_below_gap_closed`` of the held-out gap above the noise or drives a
    parameter newly to a bound (a possible stand-in, which the open form then
    replaces only by beating it)."""
    if not state.passing:
        return True, None
    current = state.current
    best = min(state.passing, key=lambda t: t[0])
    gap = current.heldout_rmse_Pa - noise_Pa
    closed = (current.heldout_rmse_Pa - best[0]) / gap if gap > 0 else 1.0
    at = [] if best[2] is None else newly_at_bounds(best[2], current)
    return closed < compete_below_gap_closed or bool(at), best
