"""A lag of the pressure reading behind the chamber pressure (issue 22).

An undeclared causal anti-alias filter (an analogue RC or Butterworth stage before the
ADC), a sensor on a short stub or a slow transducer: the DAQ records ``r`` with

    dr/dt = (p - r) / tau,

a first-order lag of the chamber pressure p; a second-order Butterworth of cut-off f_c
is, below f_c, a lag of its group delay sqrt(2) / (2 pi f_c) (0.23 ms at 1 kHz). The
lag sits at the sensor point of the signal path, after the chamber: the valve, the
tube and the chamber's physics are unchanged, and the reading is what the model
predicts (:mod:`pneubayes.simulation.kernel` steps r with the chamber, exactly for p
linear over each step). A declared zero-phase filter
(:class:`~pneubayes.physics.sensor_filter.PressureFilter`) is a separate, known
property of the rig and is not this effect.

A window starts at a measured reading; the chamber then starts at the reading plus
tau times the reading's rate (``initial_rate_Pa_per_s`` of the simulator), since
p = r + tau dr/dt. The one-step predictions of the discovery library pass the
reading's backward difference; the 2-s windows of a fit start the chamber at the
reading, an error of tau dr/dt that the chamber's own time constant then decays.
"""

from __future__ import annotations

from pneubayes.effects.base import DirectEffect, Parameter
from pneubayes.effects.discovery import TrialTerm


class SensorLag(DirectEffect):
    """First-order lag of the pressure reading, time constant ``sensor_time_constant_s``."""

    name = "sensor_lag"
    slot = "sensor_time_constant_s"
    parameter = Parameter("sensor_time_constant_s", "s", 0.0, 0.01, "uniform",
                          "first-order lag of the pressure reading", neutral=0.0)
    #: A 300-Hz first-order anti-alias stage (0.53 ms).
    bench_value = 5.3e-4

    library_strengths = (0.0002, 0.0005, 0.001, 0.002, 0.004)
    discovery_fallback = {"sensor_time_constant_s": 0.0005}

    def library_terms(self, strengths):
        """The model's reading through a first-order lag of each trial time constant (s)."""
        return tuple(TrialTerm(f"reading lag {1e3 * tau:g} ms",
                               {"sensor_time_constant_s": tau},
                               values={"sensor_time_constant_s": tau}) for tau in strengths)
