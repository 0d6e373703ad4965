"""An open-form term at the reading: a pressure reading that overshoots or undershoots a
change and settles.

The open-form closure (:mod:`pneubayes.effects.closure`) acts as a mass flow into the
chamber. Some of what a rig carries acts only on what its sensor reports: a diaphragm
whose temperature follows the gas it sees, a transducer's creep, a cavity in front of
the gauge that relaxes to the chamber's pressure. This component adds, to the reading
of the chamber pressure p, ``K`` relaxations of it::

    r = p + sum_k g_k (p - p_bar_k),    tau_k dp_bar_k/dt = p - p_bar_k,

``g_k`` (``reading_closure_gain_{k}``, -) and ``tau_k``
(``reading_closure_time_constant_{k}``, s). A positive gain reads a step high at first
and settles to it with ``tau_k``; a negative one reads it low at first. Every gain 0 is
the reading without the component, whatever the time constants.

The chamber's physics is unchanged: the simulator applies the relaxation to each
simulated window's pressure after the kernel
(:func:`pneubayes.simulation.reading_closure.relaxed_reading`), each ``p_bar_k``
starting at the window's start pressure (a window starts from a measured reading, the
chamber at rest in the relaxation). A recording simulated in one window is read the
same way. The discovery library never searches for it: the open-form stage at the
reading (:class:`~pneubayes.discovery.stages.reading_form.ReadingForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig

#: The most relaxations one reading closure carries.
READING_MAX_TERMS = 2
#: A gain's bounds (-): a reading up to twice a change at first, or down to 55 % of it;
#: with both relaxations at the lower bound it still moves 10 % of a change at once (``1 +
#: sum_k g_k > 0``: at -1 a relaxation is a pure lag, which is ``sensor_lag``'s, and
#: the reading at a window's start no longer tells the chamber's pressure).
GAIN_BOUNDS = (-0.45, 1.0)
#: A time constant's bounds and start, s.
TIME_CONSTANT_BOUNDS_S = (1e-3, 20.0)
TIME_CONSTANT_START_S = 0.1


def named_pairs(values: Mapping[str, np.ndarray], first: list[str],
                second: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(first, second)``, each ``(B, K)``: a reading map's per-term parameters (a gain
    and its time constant or half-width) read from ``values`` under the names
    ``first`` and ``second`` (one per term), broadcast to one batch."""
    a = np.stack([np.atleast_1d(np.asarray(values[n], np.float64)) for n in first], axis=-1)
    b = np.stack([np.atleast_1d(np.asarray(values[n], np.float64)) for n in second], axis=-1)
    return tuple(np.broadcast_arrays(a, b))


def gain_name(k: int) -> str:
    """Relaxation ``k``'s gain parameter."""
    return f"reading_closure_gain_{k}"


def time_constant_name(k: int) -> str:
    """Relaxation ``k``'s time-constant parameter."""
    return f"reading_closure_time_constant_{k}"


class ReadingClosure(Effect):
    """``terms`` relaxations of the reading, ``r = p + sum_k g_k (p - p_bar_k)``
    (``reading_closure_gain_{k}``, ``reading_closure_time_constant_{k}``)."""

    name = "reading_closure"
    acts_on = ()  # (the simulator applies it after the kernel, on the windows' pressure)
    library_searched = False
    cheap_forms = True
    relaxes_reading = True

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) \
                or not 1 <= terms <= READING_MAX_TERMS:
            raise ValueError(f"reading_closure: option 'terms' must be an integer in "
                             f"1..{READING_MAX_TERMS}, got {terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def parameters(self):
        lo, hi = TIME_CONSTANT_BOUNDS_S
        out = []
        for k in range(self.terms):
            out.append(Parameter(gain_name(k), "-", *GAIN_BOUNDS, "uniform",
                                 f"reading relaxation {k}: its gain g, the reading being "
                                 "p + g (p - p_bar)", neutral=0.0))
            out.append(Parameter(time_constant_name(k), "s", lo, hi, "log-uniform",
                                 f"reading relaxation {k}: the time constant with which "
                                 "p_bar follows p (the term vanishes with its gain "
                                 "whatever its time constant)", neutral=TIME_CONSTANT_START_S))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {}  # (no slot of the kernel: see the module's docstring)

    def reading_relaxations(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray]:
        """``(gains, time constants)``, each ``(B, terms)``, of a batch of values."""
        return self.relaxations_named(values, [gain_name(k) for k in range(self.terms)],
                                      [time_constant_name(k) for k in range(self.terms)])

    @staticmethod
    def relaxations_named(values: Mapping[str, np.ndarray], gains: list[str],
                          time_constants: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """``(gains, time constants)``, each ``(B, K)``, read from ``values`` under the
        parameter names ``gains`` and ``time_constants`` (one per relaxation)."""
        return named_pairs(values, gains, time_constants)

    def bench_defaults(self):
        """A reading 3 % high at first after a change, settling in 0.3 s (a second term
        4 % low, settling in 2 s)."""
        out = {gain_name(0): 0.03, time_constant_name(0): 0.3}
        if self.terms > 1:
            out.update({gain_name(1): -0.04, time_constant_name(1): 2.0})
        return out
