"""A pressure sensor whose zero drifts during a recording.

A strain-gauge or piezoresistive transducer's zero moves with the bridge's temperature
(a data sheet's "thermal zero shift", typically 0.01-0.05 % of full scale per kelvin: a
few hundred Pa per kelvin on a 10-bar sensor). Switched on, or heated by the valve's
coil or by the gas it measures, it settles over seconds to minutes; a slow ambient change
or an amplifier's creep looks linear over a recording. The DAQ then records

    r = P_atm + g (p - P_atm) + o(t),    o(t) = o + a t + b (1 - exp(-t / tau)),

``t`` on the recording's clock (its ``time_s``, which the recording format's writers start
at 0; the warm-up is held at 0 before t = 0), ``a`` = ``reading_drift_Pa_per_s``, ``b``
= ``reading_warm_up_Pa`` and ``tau`` = ``reading_warm_up_time_constant_s``; the constant
``o`` and the gain ``g`` are :mod:`~pneubayes.effects.sensor_calibration`'s. Forms:

- ``form="warm_up"`` (default): ``b`` and ``tau``;
- ``form="linear"``: ``a`` alone;
- ``form="linear_warm_up"``: all three.

Like the calibration, the drift moves only what is recorded: a window starts at the
pressure its measured reading stands for at its own time, and every output is read back
through the zero of its time (:mod:`pneubayes.simulation.kernel`). Its signature is in
time, not in state: a closed chamber's reading creeps the same whatever its pressure,
where a leak's creep follows the pressure and stops at atmosphere.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.rig import Rig

_FORMS = ("warm_up", "linear", "linear_warm_up")
_RATE = Parameter("reading_drift_Pa_per_s", "Pa/s", -2000.0, 2000.0, "uniform",
                  "the sensor zero's linear drift a (Pa/s)", neutral=0.0)
_WARM = Parameter("reading_warm_up_Pa", "Pa", -50_000.0, 50_000.0, "uniform",
                  "how far the sensor's zero moves as it warms, b (Pa)", neutral=0.0)
_TAU = Parameter("reading_warm_up_time_constant_s", "s", 0.05, 1000.0, "log-uniform",
                 "the warming zero's time constant tau (s)", neutral=2.0)


class SensorDrift(Effect):
    """The pressure reading's zero moving during a recording: a warm-up
    (``reading_warm_up_Pa``, ``reading_warm_up_time_constant_s``) and/or a linear drift
    (``reading_drift_Pa_per_s``), by ``form``."""

    name = "sensor_drift"
    forms = _FORMS
    cheap_forms = True
    acts_on = ("reading_drift_Pa_per_s", "reading_warm_up_Pa",
               "reading_warm_up_time_constant_s")

    def __init__(self, form: str = "warm_up"):
        self.form = form

    def options(self):
        return {"form": self.form}

    def parameters(self):
        self._check()
        return {"warm_up": (_WARM, _TAU), "linear": (_RATE,),
                "linear_warm_up": (_RATE, _WARM, _TAU)}[self.form]

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        return {p.name: np.asarray(values[p.name], np.float64) for p in self.parameters()}

    def bench_defaults(self):
        """A zero that settles 3 kPa (0.3 % of a 10-bar span) over 5 s, and/or drifts
        by 20 Pa/s."""
        out = {"reading_drift_Pa_per_s": 20.0, "reading_warm_up_Pa": 3000.0,
               "reading_warm_up_time_constant_s": 5.0}
        return {p.name: out[p.name] for p in self.parameters()}

    # ------------------------------------------------------------------ discovery
    #: the trial zeros move by :data:`TRIAL_SHIFT_PA` over these times (s): a warm-up's
    #: time constant, a linear drift's time to move that far
    library_strengths = (1.0, 5.0, 30.0)
    TRIAL_SHIFT_PA = 2000.0

    def library_terms(self, strengths):
        """The model read through a zero that moves :data:`TRIAL_SHIFT_PA` over each
        trial time (s): a warm-up of that time constant, or (form ``linear``) a drift of
        that rate; the regression's signed coefficient gives the sign."""
        if self.form == "linear":
            return tuple(TrialTerm(f"reading drift {self.TRIAL_SHIFT_PA / s:g} Pa/s",
                                   {"reading_drift_Pa_per_s": self.TRIAL_SHIFT_PA / s},
                                   values={"reading_drift_Pa_per_s": self.TRIAL_SHIFT_PA / s})
                         for s in strengths)
        shift = self.TRIAL_SHIFT_PA
        return tuple(TrialTerm(f"reading warm-up ({1e-3 * shift:g} kPa, {tau:g} s)",
                               {"reading_warm_up_Pa": shift,
                                "reading_warm_up_time_constant_s": tau},
                               values={"reading_warm_up_Pa": shift,
                                       "reading_warm_up_time_constant_s": tau})
                     for tau in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """The warm-up at the best term's time constant, and the warm-up with a linear
        drift beside it (a zero that has not settled by the recording's end)."""
        start = self.candidate_start(ctx.term_start)
        if self.form != "warm_up":
            return [(self, start)]
        return [(self, start), (SensorDrift(form="linear_warm_up"),
                                {**start, "reading_drift_Pa_per_s": 0.0})]
