"""Spool dynamics: the area maps see the spool position s instead of the command u
(paper VI-A: 125 Hz bandwidth at full stroke). Three forms:

- ``form="first_order"`` (default): ``ds/dt = (u - s) / tau``;
- ``form="rate_limited"``: ``ds/dt = clip((u - s) / tau, -r, r)``, the first order with
  a speed limit r (command unit/s): a proportional valve whose spool drive saturates
  (its current or force limit) ramps across a step larger than r tau at r and then
  lags (at the upper bound of r, steps under 100 units never ramp behind a 1-ms lag);
- ``form="asymmetric"``: ``ds/dt = (u - s) / tau`` while the command is above the spool
  (rising) and ``(u - s) / tau_down`` while it is below (falling): a single-solenoid
  valve whose spring returns the spool at another speed than its coil drives it, an
  on/off valve whose opening and closing times differ (data sheets give both);
- ``form="second_order"``: ``s'' = w^2 (u - s) - 2 z w s'``, a proportional valve's
  spool under its position loop (a mass on the solenoid's spring, damped), parametrised
  like the sensor lag's second order by its group delay at DC ``D = 2 z / w`` (the lag a
  slow command sees; 0 is no lag) and its damping z. A large z is the first-order lag
  of time constant D; a small z overshoots the commanded opening.

Within a sample interval the command is held, so each is integrated exactly
(:mod:`pneubayes.simulation.kernel`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, InputLagTerm
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.effects.second_order import delay_and_damping, natural_frequency
from pneubayes.rig import Rig

_FORMS = ("first_order", "second_order", "rate_limited", "asymmetric")
#: Bounds of the speed limit r, command unit/s (log-uniform); the upper is neutral.
RATE_BOUNDS = (0.1, 1e5)
#: Where a speed-limited candidate starts, command unit/s (10 V in 20 ms).
START_RATE = 500.0
#: Damping a second-order candidate starts at (a well-tuned position loop).
START_DAMPING = 0.7


class SpoolLag(Effect):
    """Spool lag: first order (``spool_time_constant_s``; with a speed limit
    ``spool_rate_limit_V_per_s``, or falling with ``spool_fall_time_constant_s``) or
    second order (``spool_delay_s``, ``spool_damping``)."""

    name = "spool_lag"
    forms = _FORMS
    acts_on = ("spool_time_constant_s", "spool_natural_frequency_rad_per_s",
               "spool_damping", "spool_rate_limit_V_per_s", "spool_fall_time_constant_s")
    #: 125 Hz bandwidth at full spool stroke (paper VI-A).
    bench_value = 1.0 / (2.0 * math.pi * 125.0)

    def __init__(self, form: str = "first_order"):
        self.form = form

    def options(self):
        return {"form": self.form}

    def parameters(self):
        self._check()
        tau = Parameter("spool_time_constant_s", "s", 0.0, 0.02, "uniform",
                        "first-order spool time constant", neutral=0.0)
        if self.form == "first_order":
            return (tau,)
        if self.form == "asymmetric":
            return (Parameter("spool_time_constant_s", "s", 0.0, 0.02, "uniform",
                              "the spool's time constant while the command is above it "
                              "(rising)", neutral=0.0),
                    Parameter("spool_fall_time_constant_s", "s", 0.0, 0.02, "uniform",
                              "the spool's time constant while the command is below it "
                              "(falling)", neutral=0.0))
        if self.form == "rate_limited":
            return (tau, Parameter("spool_rate_limit_V_per_s", "command unit/s",
                                   *RATE_BOUNDS, "log-uniform",
                                   "the spool's speed limit r: ds/dt = clip((u - s) / tau, "
                                   "-r, r)", neutral=RATE_BOUNDS[1]))
        return delay_and_damping("spool", "the second-order spool", 0.02)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        if self.form == "first_order":
            return {"spool_time_constant_s": values["spool_time_constant_s"]}
        if self.form == "rate_limited":
            return {"spool_time_constant_s": values["spool_time_constant_s"],
                    "spool_rate_limit_V_per_s": values["spool_rate_limit_V_per_s"]}
        if self.form == "asymmetric":
            return {"spool_time_constant_s": values["spool_time_constant_s"],
                    "spool_fall_time_constant_s": values["spool_fall_time_constant_s"]}
        w, z = natural_frequency(values["spool_delay_s"], values["spool_damping"])
        return {"spool_natural_frequency_rad_per_s": w, "spool_damping": z}

    def bench_defaults(self):
        if self.form == "first_order":
            return {"spool_time_constant_s": float(self.bench_value)}
        if self.form == "asymmetric":  # the spring returns it three times slower
            return {"spool_time_constant_s": float(self.bench_value),
                    "spool_fall_time_constant_s": 3.0 * float(self.bench_value)}
        if self.form == "rate_limited":  # a 10-V step takes 10 ms
            return {"spool_time_constant_s": float(self.bench_value),
                    "spool_rate_limit_V_per_s": 1000.0}
        # 125 Hz natural frequency, damping 0.7: D = 2 z / w = 1.78 ms
        w = 2.0 * math.pi * 125.0
        return {"spool_delay_s": 2.0 * START_DAMPING / w, "spool_damping": START_DAMPING}

    # ------------------------------------------------------------------ discovery
    library_strengths = (0.001, 0.002, 0.004, 0.007, 0.012, 0.02)
    discovery_fallback = {"spool_time_constant_s": 0.003}

    def library_terms(self, strengths):
        """The command through a first-order lag of each trial time constant (s); for
        the second order, of each trial group delay (a first-order stand-in: the
        one-step library does not resolve the spool's damping)."""
        keys = {"second_order": ("spool_delay_s",),
                "asymmetric": ("spool_time_constant_s", "spool_fall_time_constant_s")}.get(
                    self.form, ("spool_time_constant_s",))
        return tuple(InputLagTerm(f"lag {1e3 * tau:g} ms", dict.fromkeys(keys, tau), lag_s=tau)
                     for tau in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """The first-order lag at the best term's time constant, the second-order spool
        (damping 0.7) at the same group delay, the speed-limited lag at the same time
        constant (from :data:`START_RATE`) and the asymmetric lag (rising and falling
        from the same time constant): a proportional valve's spool is a damped mass on a
        spring whose drive saturates and whose return may be slower or faster than its
        drive, and where the data resolve its overshoot, its ramp or its two speeds a
        first-order lag leaves a misfit that a lag elsewhere (the reading's, the tube's)
        fills."""
        start = self.candidate_start(ctx.term_start)
        out = [(self, start)]
        if self.form != "first_order":
            return out
        delay = start.get("spool_time_constant_s",
                          self.discovery_fallback["spool_time_constant_s"])
        out.append((SpoolLag(form="second_order"),
                    {"spool_delay_s": delay, "spool_damping": START_DAMPING}))
        out.append((SpoolLag(form="rate_limited"),
                    {"spool_time_constant_s": delay, "spool_rate_limit_V_per_s": START_RATE}))
        out.append((SpoolLag(form="asymmetric"),
                    {"spool_time_constant_s": delay, "spool_fall_time_constant_s": delay}))
        return out


def spool_settle_s(slots: np.ndarray) -> np.ndarray:
    """Time constant (s) of the slowest spool mode for lowered slot rows ``(B, N_SLOTS)``:
    the first-order lag's tau (the larger of its rise's and fall's), or 1 / (z w) for a
    second-order spool at z <= 1 and (z + sqrt(z^2 - 1)) / w above; 0 without a spool
    lag."""
    slots = np.atleast_2d(slots)
    w = slots[:, SLOT_INDEX["spool_natural_frequency_rad_per_s"]]
    z = slots[:, SLOT_INDEX["spool_damping"]]
    on = w > 0.0
    ws, zs = np.where(on, w, 1.0), np.where(on, z, 1.0)
    second = np.where(zs <= 1.0, 1.0 / (zs * ws), (zs + np.sqrt(np.maximum(zs * zs - 1.0, 0.0)))
                      / ws)
    first = np.maximum(slots[:, SLOT_INDEX["spool_time_constant_s"]],
                       slots[:, SLOT_INDEX["spool_fall_time_constant_s"]])
    return np.where(on, second, first)
