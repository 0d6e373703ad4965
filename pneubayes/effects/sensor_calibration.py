"""A miscalibrated pressure sensor: a zero offset and a gain error on the reading.

A lab's transducer is rarely exactly what its data sheet says: a zero offset of 1-2 % of
full scale (a few kPa on a 10-bar sensor) and a span error of a few per cent are within
an industrial transducer's specification, and an amplifier or ADC adds its own. The
DAQ then records

    r = P_atm + g (p - P_atm) + o,

p the chamber pressure, ``reading_offset_Pa`` o (what the sensor reads at atmospheric
pressure, less P_atm) and ``reading_gain_error`` g - 1. GTDynamics' muscles read
18-24 kPa gauge at rest (``../shared/realdata``'s README: "sensor offset or residual
pressure, undocumented"), which is what this effect is for.

The chamber's physics sees the true pressure, so the flows of eqs. 1-3, the leak and a
full exhaust's end at atmosphere (a reading of P_atm + o) are unchanged; only what is
recorded moves. Two forms:

- ``form="offset"`` (default): the zero offset alone;
- ``form="offset_gain"``: the offset and the gain error.

The gain error is nearly confounded with the chamber's volume (both scale dp/dt) and,
at full inlet, with the supply; it separates only through the pressure the flows see,
so fit it where the recordings reach both atmosphere and the supply.

The calibration is applied by the simulator (:mod:`pneubayes.simulation.kernel`): a
window starts at the pressure its measured reading stands for, and every output is read
back through the sensor. Its discovery terms are off by default (no library strength):
an offset looks like a leak into a closed chamber, a gain like the supply's, and the
loop names it only when a :class:`~pneubayes.discovery.library.LibraryGrid` gives it
strengths (e.g. ``{"sensor_calibration": SensorCalibration.opt_in_strengths}``, Pa).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.rig import Rig

_FORMS = ("offset", "offset_gain")
_OFFSET = Parameter("reading_offset_Pa", "Pa", -50_000.0, 50_000.0, "uniform",
                    "the pressure sensor's zero offset (its reading at atmospheric "
                    "pressure, less P_atm)", neutral=0.0)
_GAIN = Parameter("reading_gain_error", "-", -0.2, 0.2, "uniform",
                  "the pressure sensor's gain error, g - 1", neutral=0.0)


class SensorCalibration(Effect):
    """The pressure reading's zero offset (``reading_offset_Pa``) and, in form
    ``offset_gain``, its gain error (``reading_gain_error``)."""

    name = "sensor_calibration"
    forms = _FORMS
    cheap_forms = True
    acts_on = ("reading_offset_Pa", "reading_gain_error")

    def __init__(self, form: str = "offset"):
        self.form = form

    def options(self):
        return {"form": self.form}

    def parameters(self):
        self._check()
        return (_OFFSET,) if self.form == "offset" else (_OFFSET, _GAIN)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        out = {"reading_offset_Pa": np.asarray(values["reading_offset_Pa"], np.float64)}
        if self.form == "offset_gain":
            out["reading_gain_error"] = np.asarray(values["reading_gain_error"], np.float64)
        return out

    def bench_defaults(self):
        """A zero offset of 0.5 % of a 10-bar sensor's span (and a 3 % span error)."""
        if self.form == "offset":
            return {"reading_offset_Pa": 5000.0}
        return {"reading_offset_Pa": 5000.0, "reading_gain_error": 0.03}

    # ------------------------------------------------------------------ discovery
    #: None by default: the loop looks for a calibration only when asked (module doc)
    library_strengths = ()
    opt_in_strengths = (2000.0, 5000.0, 10_000.0)

    def library_terms(self, strengths):
        """The model read through a sensor offset of each trial strength (Pa; the
        regression's signed coefficient gives the offset's sign)."""
        return tuple(TrialTerm(f"reading offset {1e-3 * o:g} kPa", {"reading_offset_Pa": o},
                               values={"reading_offset_Pa": o}) for o in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """The offset alone and the offset with the gain error, both from a calibrated
        sensor (the term's sign is the regression's, not its start's)."""
        if self.form != "offset":
            return [(self, {})]
        return [(self, {}), (SensorCalibration(form="offset_gain"), {})]
