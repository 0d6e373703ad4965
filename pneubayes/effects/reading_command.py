"""An open-form term at the reading: a reading that moves with the valve's drive.

Some sensors report, beside the chamber's pressure, something of what the valve's
driver does: the coil's current returning through the sensor's ground shifts its zero,
the solenoid's field or heat reaches the transducer, the valve's body vibrates the
gauge. Such a term follows the command, not the pressure, with the lag of what carries
it (a coil's L / R, a body's heat). No relaxation or play of the pressure
(:mod:`pneubayes.effects.reading_closure`, :mod:`pneubayes.effects.reading_play`)
expresses it; this component adds ``K`` first-order lags of the command's magnitude
(a coil's current, whichever coil a two-sided valve drives) to the reading::

    r = p + sum_k c_k l_k,    tau_k dl_k/dt = |u| - l_k,

``c_k`` (``reading_command_gain_{k}``, Pa per command unit) and ``tau_k``
(``reading_command_time_constant_{k}``, s), ``u`` the recorded command as the driver
receives it (held between samples; before any delay of the valve or its tube). Every
gain 0 is the reading without the component, whatever the time constants.

The chamber's physics is unchanged: the simulator adds the lags to each simulated
window's reading after the kernel (:mod:`pneubayes.simulation.reading_command`), each
lag warm from the recording's first sample, and starts the chamber at the pressure that
reads the window's first reading. The discovery library never searches for it: the
open-form stage at the reading
(:class:`~pneubayes.discovery.stages.reading_command_form.ReadingCommandForm`)
proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.reading_closure import named_pairs
from pneubayes.rig import Rig

#: The most lags one component carries.
COMMAND_MAX_TERMS = 2
#: A gain's bounds, Pa per command unit (a few kPa at a few volts, or at a command's
#: full scale of 1, well inside).
COMMAND_GAIN_BOUNDS_PA = (-1.0e5, 1.0e5)
#: A time constant's bounds and start, s.
COMMAND_TIME_CONSTANT_BOUNDS_S = (1e-4, 20.0)
COMMAND_TIME_CONSTANT_START_S = 0.01


def command_gain_name(k: int) -> str:
    """Lag ``k``'s gain parameter."""
    return f"reading_command_gain_{k}"


def command_time_constant_name(k: int) -> str:
    """Lag ``k``'s time constant parameter."""
    return f"reading_command_time_constant_{k}"


class ReadingCommand(Effect):
    """``terms`` lags of the command's magnitude in the reading, ``r = p + sum_k c_k
    l_k`` (``reading_command_gain_{k}``, ``reading_command_time_constant_{k}``)."""

    name = "reading_command"
    acts_on = ()  # (the simulator adds it after the kernel, to the windows' reading)
    library_searched = False
    cheap_forms = True
    relaxes_reading = True

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) \
                or not 1 <= terms <= COMMAND_MAX_TERMS:
            raise ValueError(f"reading_command: option 'terms' must be an integer in "
                             f"1..{COMMAND_MAX_TERMS}, got {terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def parameters(self):
        lo, hi = COMMAND_TIME_CONSTANT_BOUNDS_S
        out = []
        for k in range(self.terms):
            out.append(Parameter(command_gain_name(k), "Pa", *COMMAND_GAIN_BOUNDS_PA,
                                 "uniform", f"reading command lag {k}: the reading's shift "
                                 "per unit of the command's magnitude, once settled",
                                 neutral=0.0))
            out.append(Parameter(command_time_constant_name(k), "s", lo, hi, "log-uniform",
                                 f"reading command lag {k}: the time constant with which "
                                 "the shift follows the command (the term vanishes with its "
                                 "gain whatever its time constant)",
                                 neutral=COMMAND_TIME_CONSTANT_START_S))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {}  # (no slot of the kernel: see the module's docstring)

    def reading_commands(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray]:
        """``(gains Pa per command unit, time constants s)``, each ``(B, terms)``."""
        return self.commands_named(values, [command_gain_name(k) for k in range(self.terms)],
                                   [command_time_constant_name(k) for k in range(self.terms)])

    @staticmethod
    def commands_named(values: Mapping[str, np.ndarray], gains: list[str],
                       time_constants: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """``(gains, time constants)``, each ``(B, K)``, read from ``values`` under the
        parameter names ``gains`` and ``time_constants`` (one per lag)."""
        return named_pairs(values, gains, time_constants)

    def bench_defaults(self):
        """A reading 600 Pa high per command unit, following in 5 ms (a second: 200 Pa
        low per unit, in 0.5 s)."""
        out = {command_gain_name(0): 600.0, command_time_constant_name(0): 5e-3}
        if self.terms > 1:
            out.update({command_gain_name(1): -200.0, command_time_constant_name(1): 0.5})
        return out
