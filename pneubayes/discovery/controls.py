"""The discovery loop's basin controls: does a trial's held-out gain belong to its effect?

Refinement finds local optima. A trial (the current model plus an effect) is refined
from a new point, and its gain on the held-out windows may come from the other
parameters moving to a better basin, not from the effect: an effect fitted to zero
strength can still "pass". Its *control* is the current model refined from the trial's
other parameters; a trial must beat its control as it beats the current fit
(:class:`~pneubayes.discovery.loop.Discovery`, step 5 of the loop). Only a trial that
beats the current fit gets a control, and a control that fits the training data
better than the current fit becomes the current fit.

:class:`BasinControls` is a mixin of :class:`~pneubayes.discovery.loop.Discovery`: it
uses the loop's ``_fit``, ``_better`` and ``log``.
"""

from __future__ import annotations

from pneubayes.discovery.verification import StepFit
from pneubayes.errors import SimulationError


class BasinControls:
    """The controls of a round's trials (a mixin of the discovery loop)."""

    def _controls(self, fits: list, current: StepFit, ctx):
        """The controls (:meth:`_control`) of those of ``fits`` (``(label, fit)`` pairs)
        that beat the current fit on the held-out windows; a fit that does not needs
        none (only a fit that passes is asked whether its gain is its basin's). A control
        that becomes the current fit makes every fit without one be checked again,
        until each that beats the current fit has its control. Returns (controls, None
        for a fit without one; current)."""
        controls = [None] * len(fits)
        changed = True
        while changed:
            changed = False
            for i, (label, fit) in enumerate(fits):
                if controls[i] is None and self._better(fit, current)[0]:
                    before = current
                    controls[i], current = self._control(fit, current, label, ctx)
                    changed = changed or current is not before
        return controls, current

    def _control(self, trial: StepFit, current: StepFit, label: str, ctx):
        """A trial's control: the current model refined from the trial's other
        parameters. Refinement finds local optima; if the trial's gain came from moving
        the other parameters to a better basin, the control gets it too. Where the
        control fits the training data better than ``current`` it becomes the current
        fit (ledger action ``refit current``). Returns (control, current)."""
        sindy, train, train_ws, held_ws, data_key, noise, ledger = ctx
        try:
            control = self._fit(current.model, {k: trial.params[k] for k in
                                                current.model.parameter_names},
                                train_ws, held_ws, data_key)
        except (FloatingPointError, SimulationError) as exc:
            # the trial's point leaves the current model's simulable region: no better
            # optimum of the current model there
            self.log(f"discover: {label}: no control fit from the trial's point "
                     f"({type(exc).__name__})")
            return current, current
        if control.train_rmse_Pa < current.train_rmse_Pa - 1e-9:
            self.log(f"discover: a better optimum of the current model: train RMSE "
                     f"{current.train_rmse_Pa:.1f} -> {control.train_rmse_Pa:.1f} Pa "
                     f"({current.train_rmse_Pa - control.train_rmse_Pa:.2g} Pa lower; "
                     f"held-out {current.heldout_rmse_Pa:.0f} -> "
                     f"{control.heldout_rmse_Pa:.0f} Pa)")
            ledger.append({"step": len(ledger), "action": "refit current",
                           "model": list(current.model.effect_names),
                           "train_rmse_Pa": control.train_rmse_Pa,
                           "heldout_rmse_Pa": control.heldout_rmse_Pa,
                           "heldout_lpd": control.heldout_lpd})
            current = control
        return control, current
