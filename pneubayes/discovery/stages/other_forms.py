"""Stage: each named effect refitted in its other forms beside the rest of the model."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from pneubayes.discovery.candidates import effect_candidates, first_free, form_label
from pneubayes.discovery.rounds import min_gain_Pa
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.state import RoundState
from pneubayes.effects import make_effect
from pneubayes.errors import FIT_FAILURES


class OtherForms(Stage):
    """When nothing passed and the held-out error is far above the noise floor, refit
    each named effect in the other forms it proposes beside the rest of the model,
    started at the current fit (ledger action ``form``). A form chosen beside fewer
    effects need not be the best beside more: a tube fitted as a wave tube alone can be
    a lumped line beside heat transfer. A form passes as a trial does against the
    current fit (its control is the current fit itself); the passing one with the
    lowest held-out RMSE replaces the named form (``swap form``) and the loop searches
    again. A form whose training RMSE ends more than ``max_train_rise`` above the
    current fit's does not pass, whatever its held-out windows say: it is a fit that
    did not find what the current one found, and its held-out error is a draw from an
    optimum the training data do not prefer (a sensor lag's second form on all channels
    had fitted 5151 -> 9609 Pa in training, held out 4873 -> 3863 Pa, and its refit
    6105 Pa).

    Parameters
    ----------
    max_swaps : int
        Most swaps in one run.
    max_train_rise : float
        The share by which a form's training RMSE may exceed the current fit's.
    """

    name = "other_forms"
    reshapes = True

    def __init__(self, max_swaps: int = 2, max_train_rise: float = 0.1):
        if not max_train_rise >= 0.0:
            raise ValueError(f"OtherForms: max_train_rise must be >= 0, got "
                             f"{max_train_rise!r}")
        self.max_swaps = max_swaps
        self.max_train_rise = max_train_rise

    def options(self):
        return {"max_swaps": self.max_swaps, "max_train_rise": self.max_train_rise}

    def run(self, state: RoundState, runner) -> None:
        if state.passing or state.counts.get(self.name, 0) >= self.max_swaps \
                or not state.far():
            return
        swapped = self._swap(state.current, runner)
        if swapped is not None:
            state.replacement = swapped
            state.counts[self.name] = state.counts.get(self.name, 0) + 1

    @staticmethod
    def _options(current, runner) -> list:
        """``[(effect, model, start), ...]``: every named effect's other forms."""
        s, rig = runner.settings, runner.data.rig()
        options = []
        for g in current.model.effect_names:
            rest = current.model.without(g)
            effect = make_effect(g, **current.model.effect_options(g))
            term = {k: current.params[k] for k in effect.discovery_fallback
                    if k in current.params}
            here = SimpleNamespace(model=rest, params={k: current.params[k]
                                                       for k in rest.parameter_names})
            for m, start in effect_candidates(here, g, {"best_term_start": term or None},
                                              rig, s.forms):
                if form_label(m, g) == form_label(current.model, g):
                    continue
                # the rest of the model where it was fitted; the new form's own values
                start = {**start, **{k: current.params[k] for k in rest.parameter_names}}
                options.append((g, m, start))
        return options

    def _swap(self, current, runner):
        """The passing refit with the lowest held-out RMSE, or None."""
        options = self._options(current, runner)
        if not options:
            return None
        s, noise, ledger = runner.settings, runner.data.noise_Pa, runner.ledger
        runner.log("discover: nothing passed; refitting the named effects in their other "
                   "forms: " + ", ".join(f"{g} {form_label(m, g)}" for g, m, _ in options))
        ledger.record("other forms", groups=[f"{g} {form_label(m, g)}" for g, m, _ in options])
        least = min_gain_Pa(noise, current.heldout_rmse_Pa - noise, s)
        passing = []
        for g, m, start in options:
            try:
                fit = runner.fit(m, start, first_free(m, g))
            except FIT_FAILURES as exc:
                runner.log(f"discover: {g} {form_label(m, g)} failed ({type(exc).__name__})")
                continue
            ok, gain, pval, diff = runner.better(fit, current)
            ok = ok and current.heldout_rmse_Pa - fit.heldout_rmse_Pa >= least \
                and fit.train_rmse_Pa <= current.train_rmse_Pa * (1.0 + self.max_train_rise)
            names = m.effect(g).parameter_names()
            ledger.record(
                "form", effect=g, passed=ok,
                **{"from": form_label(current.model, g), "to": form_label(m, g)},
                effect_options=m.effect(g).options(),
                fitted={k: fit.params[k] for k in names},
                train_rmse_Pa=fit.train_rmse_Pa,
                heldout_rmse_before_Pa=current.heldout_rmse_Pa,
                heldout_rmse_after_Pa=fit.heldout_rmse_Pa,
                score_gain=gain, score_p_value=pval,
                windows_improved=int(np.sum(diff > 0)), windows=int(diff.size),
                wall_time_s=fit.wall_time_s)
            runner.log(f"discover: {'passes' if ok else 'reject'} {g} as {form_label(m, g)} "
                       f"(was {form_label(current.model, g)}): training RMSE "
                       f"{current.train_rmse_Pa:.0f} -> {fit.train_rmse_Pa:.0f} Pa, held-out "
                       f"{current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa, better "
                       f"in {int(np.sum(diff > 0))}/{diff.size} windows (p = {pval:.2g})")
            if ok:
                passing.append((fit.heldout_rmse_Pa, g, m, fit))
        if not passing:
            return None
        _, g, m, fit = min(passing, key=lambda t: t[0])
        runner.log(f"discover: SWAP {g} to {form_label(m, g)} (the largest held-out "
                   "improvement)")
        ledger.record("swap form", effect=g, to=form_label(m, g),
                      heldout_rmse_before_Pa=current.heldout_rmse_Pa,
                      heldout_rmse_after_Pa=fit.heldout_rmse_Pa)
        return fit
