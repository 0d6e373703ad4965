"""A pressure sensor whose reading curves off its straight line.

A transducer's reading is linear in the pressure only to its data sheet's accuracy: a
bridge's or a diaphragm's response bends (a "non-linearity" or "BFSL" error of 0.1-0.5 %
of full scale, a few kPa on a 10-bar sensor), and an uncalibrated gauge or a cheap
board sensor bends more. To second order about atmospheric pressure the DAQ records

    r = P_atm + g y + k (y / 1 bar)^2 + o,    y = p - P_atm,

``k`` = ``reading_curvature_Pa`` (how far the reading departs from its straight line at
1 bar gauge); ``g`` and ``o`` are :mod:`~pneubayes.effects.sensor_calibration`'s (a bow
that vanishes at both ends of a sensor's range is a curvature with a gain error beside
it: name both). The chamber's physics sees p; the simulator inverts each window's first
reading on the curve's rising branch and reads every output (and the start
sensitivity) through it (:mod:`pneubayes.simulation.kernel`).

A curvature scales the reading's rate by g + 2 k y / (1 bar)^2: what a volume or a
supply that changes with the pressure would also do, but here the flows are not
touched, so a full exhaust still ends at atmosphere and a full inlet at the supply, read
through the curve.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.rig import Rig

_FORMS = ("curvature", "curvature_gain")
_CURVATURE = Parameter("reading_curvature_Pa", "Pa", -20_000.0, 20_000.0, "uniform",
                       "the sensor reading's departure from its straight line at 1 bar "
                       "gauge, k in r = P_atm + g y + k (y / 1 bar)^2 + o", neutral=0.0)
_GAIN = Parameter("reading_curve_gain_error", "-", -0.2, 0.2, "uniform",
                  "the curved sensor's gain error at atmospheric pressure, g - 1 (it adds "
                  "to a sensor_calibration's)", neutral=0.0)


class SensorNonlinearity(Effect):
    """The pressure reading's curvature ``reading_curvature_Pa`` (Pa at 1 bar gauge) and,
    in form ``curvature_gain``, the gain error beside it (``reading_curve_gain_error``:
    a bow that vanishes at both ends of a range is both)."""

    name = "sensor_nonlinearity"
    forms = _FORMS
    cheap_forms = True
    acts_on = ("reading_curvature_Pa", "reading_gain_error")

    def __init__(self, form: str = "curvature"):
        self.form = form

    def options(self):
        return {"form": self.form}

    def parameters(self):
        self._check()
        return (_CURVATURE,) if self.form == "curvature" else (_CURVATURE, _GAIN)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        out = {"reading_curvature_Pa": np.asarray(values["reading_curvature_Pa"], np.float64)}
        if self.form == "curvature_gain":
            out["reading_gain_error"] = np.asarray(values["reading_curve_gain_error"],
                                                   np.float64)
        return out

    def bench_defaults(self):
        """A curvature of 1 kPa at 1 bar gauge (and a 2 % gain error)."""
        out = {"reading_curvature_Pa": 1000.0, "reading_curve_gain_error": 0.02}
        return {p.name: out[p.name] for p in self.parameters()}

    #: trial curvatures (Pa at 1 bar gauge; the regression's signed coefficient gives
    #: the sign)
    library_strengths = (500.0, 2000.0)

    def library_terms(self, strengths):
        """The model read through a curvature of each trial strength (Pa at 1 bar)."""
        return tuple(TrialTerm(f"reading curvature {1e-3 * k:g} kPa/bar^2",
                               {"reading_curvature_Pa": k}, values={"reading_curvature_Pa": k})
                     for k in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """The curvature at the best term's, and the curvature with a gain error beside
        it (started straight)."""
        start = self.candidate_start(ctx.term_start)
        if self.form != "curvature":
            return [(self, start)]
        return [(self, start), (SensorNonlinearity(form="curvature_gain"), start)]
