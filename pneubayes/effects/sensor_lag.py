"""A lag of the pressure reading behind the chamber pressure (issue 22).

An undeclared causal anti-alias filter (an analogue RC or Butterworth stage before the
ADC), a sensor on a short stub or a slow transducer: the DAQ records a reading ``r``
that lags the chamber pressure p. Four forms:

- ``form="first_order"`` (default): ``dr/dt = (p - r) / tau``, an RC stage;
- ``form="second_order"``: ``r'' = w^2 (p - r) - 2 z w r'``, an analogue 2-pole filter
  (Butterworth z = 0.71, Bessel z = 0.87), parametrised by its group delay at DC
  ``D = 2 z / w`` (the lag a slow signal sees; 0 is no filter) and its damping z. A
  large z is the first-order lag of time constant D;
- ``form="pressure_dependent"``: ``dr/dt = (p - r) / tau``, ``tau = tau_a (2 P_atm /
  (p + r))^n``: a sensor that reads a small cavity fed through a passage. Laminar flow
  of a gas through a passage carries the mass ``k (p^2 - r^2) = k (p + r)(p - r)``, so
  the cavity's lag is inversely proportional to the mean pressure (n = 1: a capillary,
  a snubber, a sintered filter; 5 x slower at the atmosphere than at 5 bar); n = 0 is
  the first-order lag. ``tau_a`` (``sensor_time_constant_s``) is the lag at the
  atmosphere, n (``sensor_pressure_exponent``) is fitted;
- ``form="delay"``: ``r(t) = p(t - d)``, ``d`` = ``sensor_transport_delay_s``: the
  reading logged late against the other channels (a separate ADC, a bus's latency),
  unsmoothed. The chamber is stepped in the reading's time (the command ``d`` late, the
  position and supply ``d`` early: ``inputs_advance_s = -d``), so a window starts
  exactly at its reading; with ``channels="all"``, a pure latency of the command.

The lag sits at the sensor point of the signal path, after the chamber (the kernel
steps it with the chamber, exactly for p linear over each step). A declared zero-phase
filter (:class:`~pneubayes.physics.sensor_filter.PressureFilter`) is a known property
of the rig, not this effect.

``channels="pressure"`` (default) lags the pressure reading only (a sensor on a stub, a
slow transducer). ``channels="all"`` is a filter on every channel of the DAQ: the
measured position and supply passed it too, so the chamber at time t sees them as
measured at t + D, D the lag's group delay at DC (a slow signal's lag through the
filter), while the generated command is not lagged.

A window starts at a measured reading; with a lag the chamber starts ahead of it by
the lag times the reading's rate (p = r + tau dr/dt at steady tracking). The discovery
library's one-step predictions pass the chamber rate through a first-order lag of the
same group delay; a fit's 2-s windows warm the lead up over the command history.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.effects.second_order import delay_and_damping, natural_frequency
from pneubayes.rig import Rig

_FORMS = ("first_order", "second_order", "pressure_dependent", "delay")
_CHANNELS = ("pressure", "all")


class SensorLag(Effect):
    """Lag of the pressure reading: first order (``sensor_time_constant_s``), second
    order (``sensor_delay_s``, ``sensor_damping``), first order with a time constant
    that depends on the pressure (``sensor_time_constant_s`` at the atmosphere,
    ``sensor_pressure_exponent``) or a pure delay (``sensor_transport_delay_s``)."""

    name = "sensor_lag"
    forms = _FORMS
    acts_on = ("sensor_time_constant_s", "sensor_natural_frequency_rad_per_s",
               "sensor_damping", "inputs_advance_s", "sensor_pressure_exponent",
               "command_delay_s")

    def __init__(self, form: str = "first_order", channels: str = "pressure"):
        self.form = form
        self.channels = channels

    def _check(self):
        super()._check()
        if self.channels not in _CHANNELS:
            raise ValueError(f"sensor_lag: channels must be one of {_CHANNELS}, got "
                             f"{self.channels!r}")

    def options(self):
        # (the default channel is left out: cards written before the option read alike)
        return {"form": self.form} if self.channels == "pressure" else \
            {"form": self.form, "channels": self.channels}

    def parameters(self):
        self._check()
        if self.form == "first_order":
            return (Parameter("sensor_time_constant_s", "s", 0.0, 0.01, "uniform",
                              "first-order lag of the pressure reading", neutral=0.0),)
        if self.form == "pressure_dependent":
            return (Parameter("sensor_time_constant_s", "s", 0.0, 0.05, "uniform",
                              "the reading's first-order lag at the atmosphere",
                              neutral=0.0),
                    Parameter("sensor_pressure_exponent", "-", -1.0, 3.0, "uniform",
                              "the lag's pressure dependence n, tau = tau_a (2 P_atm / "
                              "(p + r))^n (1: a laminar passage; 0: none)", neutral=0.0))
        if self.form == "delay":
            return (Parameter("sensor_transport_delay_s", "s", 0.0, 0.05, "uniform",
                              "the reading's delay behind the chamber (logged late against "
                              "the other channels)", neutral=0.0),)
        return delay_and_damping("sensor", "the reading's second-order lag", 0.01)

    def reading_lead_parameter(self) -> str:
        """The parameter that is the reading's group delay at DC, s (the chamber's lead
        on a reading that tracks a ramp; the pressure-dependent lag's at the
        atmosphere)."""
        self._check()
        return {"second_order": "sensor_delay_s", "delay": "sensor_transport_delay_s"}.get(
            self.form, "sensor_time_constant_s")

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        lead = np.asarray(values[self.reading_lead_parameter()], dtype=np.float64)
        if self.form == "delay":  # (the chamber stepped in the reading's time)
            return {"command_delay_s": lead} if self.channels == "all" else \
                {"command_delay_s": lead, "inputs_advance_s": -lead}
        out = {"inputs_advance_s": lead} if self.channels == "all" else {}
        if self.form == "first_order":
            return {"sensor_time_constant_s": lead, **out}
        if self.form == "pressure_dependent":
            return {"sensor_time_constant_s": lead, "sensor_pressure_exponent": np.asarray(
                values["sensor_pressure_exponent"], dtype=np.float64), **out}
        w, z = natural_frequency(lead, values["sensor_damping"])
        return {"sensor_natural_frequency_rad_per_s": w, "sensor_damping": z, **out}

    def bench_defaults(self):
        if self.form == "first_order":  # a 300-Hz RC stage
            return {"sensor_time_constant_s": 5.3e-4}
        if self.form == "pressure_dependent":  # a snubber: 2 ms at 1 bar, 0.5 ms at 7 bar
            return {"sensor_time_constant_s": 2e-3, "sensor_pressure_exponent": 1.0}
        if self.form == "delay":  # a channel logged 5 ms late
            return {"sensor_transport_delay_s": 5e-3}
        # a 2-pole Butterworth at 250 Hz: w = 1571 rad/s, D = 0.90 ms
        return {"sensor_delay_s": 9.0e-4, "sensor_damping": 0.7071}

    # ------------------------------------------------------------------ discovery
    library_strengths = (0.0002, 0.0005, 0.001, 0.002, 0.004)
    discovery_fallback = {"sensor_time_constant_s": 0.0005}

    def library_terms(self, strengths):
        """The model's reading through a lag of each trial group delay (s): first order
        (the pressure-dependent lag at its neutral exponent, the first-order lag),
        second order at its neutral (critical) damping, or a delay of that length."""
        if self.form == "second_order":
            return tuple(TrialTerm(f"reading lag (2nd order) {1e3 * d:g} ms",
                                   {"sensor_delay_s": d}, values={"sensor_delay_s": d})
                         for d in strengths)
        if self.form == "delay":
            return tuple(TrialTerm(f"reading delay {1e3 * d:g} ms",
                                   {"sensor_transport_delay_s": d},
                                   values={"sensor_transport_delay_s": d})
                         for d in strengths)
        extra = {"sensor_pressure_exponent": 0.0} if self.form == "pressure_dependent" else {}
        return tuple(TrialTerm(f"reading lag {1e3 * tau:g} ms",
                               {"sensor_time_constant_s": tau},
                               values={"sensor_time_constant_s": tau, **extra})
                     for tau in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """The first-order lag at the best term's time constant, the second-order lag
        (Butterworth damping) at the same group delay (an analogue anti-alias filter is
        usually of order two or more), both on every channel (``channels="all"``:
        an undeclared DAQ filter lags the measured position and supply too), the
        pressure-dependent lag starting as the first-order one (n = 0), and a delay of
        the reading as long as that lag (a channel logged late)."""
        start = self.candidate_start(ctx.term_start)
        out = [(self, start)]
        if self.form != "first_order" or self.channels != "pressure":
            return out
        delay = start.get("sensor_time_constant_s",
                          self.discovery_fallback["sensor_time_constant_s"])
        second = {"sensor_delay_s": delay, "sensor_damping": 0.7071}
        out.append((SensorLag(form="second_order"), second))
        out.append((SensorLag(channels="all"), {"sensor_time_constant_s": delay}))
        out.append((SensorLag(form="second_order", channels="all"), second))
        out.append((SensorLag(form="pressure_dependent"),
                    {"sensor_time_constant_s": delay, "sensor_pressure_exponent": 0.0}))
        out.append((SensorLag(form="delay"), {"sensor_transport_delay_s": delay}))
        return out
