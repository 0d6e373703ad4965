"""An open-form term on the command: a valve driver that takes the command only at the
ticks of its own clock.

A valve is often not driven by the recorded command itself but by a driver between them:
a fieldbus or USB output that updates every few milliseconds, a microcontroller's
control loop, an on/off solenoid driven by pulse-width modulation (PWM) in place of a
proportional valve. Each takes the command at the ticks of a clock the recording does
not carry, so a command change waits a varying share of a period, and a PWM valve is
either fully open or shut within each period. No lag or delay of the command expresses
that (a lag is the same after every change; this wait depends on where the change falls
between ticks). This component puts the driver between the command and the valve::

    ticks at t_k = (phi + k) T on the recording's clock (its time_s),
    hold:  the valve takes u(t_k) over [t_k + L, t_k+1 + L),
    pwm:   it is at +-U (the sign of u(t_k)) over [t_k + L + s_k, t_k + L + s_k + w_k)
           and shut (0) for the rest of the period, w_k = d_k T - e the pulse's width,
           d_k = min(|u(t_k)| / U, 1) (d_k = 1: open over the whole period), and
           s_k = a (1 - d_k) T where the driver's pulse lies in its period,

``T`` (``command_clock_period``, s), ``phi`` (``command_clock_phase``, a share of the
period), ``L`` (``command_clock_latency``, s), and for the PWM driver ``U``
(``command_clock_full_command``, V), ``e`` (``command_clock_pulse_trim``, s: a
solenoid that opens later than it closes shortens every pulse) and ``a``
(``command_clock_pulse_alignment``, 0 to 0.5: 0 a pulse from the tick, as a timer's
edge-aligned "fast" PWM; 0.5 centred in its period, as a phase-correct or centre-aligned
one). Option ``form``:
``"hold"`` or ``"pwm"``. A period of 0 (below 0.1 ms) is a driver that follows the
command at once, ``L`` later (a pure delay); period and latency 0, the valve without a
driver.

The compiled simulator reads the command through the clock as it steps
(:mod:`pneubayes.simulation.command_clock`); a spool lag's or a closure's warm-up before
a window reads the command at the latency but without the ticks. The clock's phase is
on the recording's clock: a prediction from a new time origin (the controller's) does
not know the driver's phase.
The discovery library never searches for it: the open-form stage on the command
(:class:`~pneubayes.discovery.stages.command_clock_form.CommandClockForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.rig import Rig

#: The driver's forms: a sample-and-hold output, a pulse-width modulator.
FORMS = ("hold", "pwm")
#: A period's bounds, s (up to a 5-Hz loop; 0: no driver).
PERIOD_BOUNDS_S = (0.0, 0.2)
#: A period below this (s) is lowered as no clock: a driver updating faster than 10 kHz
#: is a driver that follows the command at once (and a fit that starts a period near
#: its bound of 0 does not simulate ticks every few nanoseconds).
SHORTEST_PERIOD_S = 1e-4
#: A latency's bounds, s.
LATENCY_BOUNDS_S = (0.0, 0.05)
#: A PWM driver's full command's bounds, V.
FULL_COMMAND_BOUNDS_V = (0.1, 20.0)
#: A PWM pulse's trim's bounds, s.
PULSE_TRIM_BOUNDS_S = (-0.01, 0.01)
#: A PWM pulse's alignment's bounds: from the tick to centred (a pulse that ends at the
#: next tick would reach into the next period by a slow solenoid's closing, which the
#: kernel's held command, one period at a time, does not carry).
ALIGNMENT_BOUNDS = (0.0, 0.5)

PERIOD = "command_clock_period"
PHASE = "command_clock_phase"
LATENCY = "command_clock_latency"
FULL_COMMAND = "command_clock_full_command"
PULSE_TRIM = "command_clock_pulse_trim"
ALIGNMENT = "command_clock_pulse_alignment"


def command_delay_s(slots: np.ndarray) -> np.ndarray:
    """The command's delay (s) in lowered ``slots`` (``(..., N_SLOTS)``): the transport
    delay plus a driver's latency, as the compiled simulator reads it (with a clock, the
    delay after each tick)."""
    return (slots[..., SLOT_INDEX["command_delay_s"]]
            + slots[..., SLOT_INDEX["command_clock_latency_s"]])


class CommandClock(Effect):
    """A valve driver on its own clock: it takes the command at ticks of period ``T`` and
    phase ``phi`` and applies it ``L`` later, holding it (``form="hold"``) or as pulses
    of a width in proportion to it (``form="pwm"``)."""

    name = "command_clock"
    acts_on = ("command_clock_period_s", "command_clock_phase", "command_clock_latency_s",
               "command_clock_pwm", "command_clock_full_command_V",
               "command_clock_pulse_trim_s", "command_clock_pulse_alignment")
    library_searched = False
    cheap_forms = True
    forms = FORMS

    def __init__(self, form: str = "hold"):
        self.form = form
        self._check()

    def options(self):
        return {"form": self.form}

    def parameters(self):
        out = [Parameter(PERIOD, "s", *PERIOD_BOUNDS_S, "uniform",
                         "the driver clock's period (0: no clock)", neutral=0.0),
               Parameter(PHASE, "-", 0.0, 1.0, "uniform", "the driver clock's first tick "
                         "after the recording's time 0, as a share of its period",
                         neutral=0.0),
               Parameter(LATENCY, "s", *LATENCY_BOUNDS_S, "uniform", "the driver's latency "
                         "from a tick to the valve", neutral=0.0)]
        if self.form == "pwm":
            out += [Parameter(FULL_COMMAND, "V", *FULL_COMMAND_BOUNDS_V, "log-uniform",
                              "the command that keeps the valve open over the whole period",
                              neutral=5.0),
                    Parameter(PULSE_TRIM, "s", *PULSE_TRIM_BOUNDS_S, "uniform", "how much "
                              "shorter each pulse reaches the valve", neutral=0.0),
                    Parameter(ALIGNMENT, "-", *ALIGNMENT_BOUNDS, "uniform", "where each pulse lies "
                              "in its period: its start after the tick, as a share of the "
                              "period's shut time (0: at the tick, 0.5: centred)",
                              neutral=0.0)]
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        period = np.asarray(values[PERIOD], np.float64)
        out = {"command_clock_period_s": np.where(period < SHORTEST_PERIOD_S, 0.0, period),
               "command_clock_phase": np.asarray(values[PHASE], np.float64),
               "command_clock_latency_s": np.asarray(values[LATENCY], np.float64)}
        if self.form == "pwm":
            out["command_clock_pwm"] = np.ones_like(period)
            out["command_clock_full_command_V"] = np.asarray(values[FULL_COMMAND],
                                                             np.float64)
            out["command_clock_pulse_trim_s"] = np.asarray(values[PULSE_TRIM], np.float64)
            out["command_clock_pulse_alignment"] = np.asarray(values[ALIGNMENT], np.float64)
        return out

    def bench_defaults(self):
        """A driver updating every 10 ms at a third of a period, 2 ms late (PWM: open over
        the whole period at 4 V, its pulses 1 ms short and centred in their periods)."""
        out = {PERIOD: 0.01, PHASE: 0.3, LATENCY: 0.002}
        if self.form == "pwm":
            out.update({FULL_COMMAND: 4.0, PULSE_TRIM: 0.001, ALIGNMENT: 0.5})
        return out
