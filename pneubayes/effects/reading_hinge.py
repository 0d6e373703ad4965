"""An open-form term at the reading: a reading whose slope breaks at a pressure.

A transducer driven past its range bends into a rail (its bridge or its amplifier
saturates; an ADC clips at full scale), a gauge's spring stiffens at the end of its
travel, a board sensor's output stage compresses near its supply rail. Such a reading is
a static map of the pressure whose slope changes at a threshold: no relaxation, play or
curvature (:mod:`pneubayes.effects.sensor_nonlinearity`, a parabola over the whole
range) expresses a knee. This component reads the pressure through ``J`` hinges::

    r = z + sum_j c_j max(0, z - theta_j),

``c_j`` (``reading_hinge_gain_{j}``, -: the change of the reading's slope above the
knee; -1 is a flat rail) and ``theta_j`` (``reading_hinge_threshold_{j}``, Pa
absolute), ``z`` what the chamber's pressure reads through every other reading term. It
is the reading's last map (a rail clips what the sensor's dynamics and its pick-ups
deliver). Every gain 0 is the reading without the component, whatever the thresholds.
With ``below=True`` the knees bend the reading below them instead, ``r = z + sum_j c_j
min(0, z - theta_j)`` (a floor: a transducer whose output clips at its lower rail, a
gauge that reads nothing until its spring's preload is passed; -1 is flat below).

The chamber's physics is unchanged: the simulator reads each window through the hinges
after the kernel (:mod:`pneubayes.simulation.reading_hinge`) and starts the chamber at
the pressure that reads the window's first reading (the map inverted; a parameter set
whose map is not increasing everywhere fails, as a failed simulation does). The
discovery library never searches for it: the open-form stage at the reading
(:class:`~pneubayes.discovery.stages.reading_hinge_form.ReadingHingeForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.reading_closure import named_pairs
from pneubayes.rig import Rig

#: The most hinges one component carries.
HINGE_MAX_TERMS = 2
#: A gain's bounds (-): down to a reading whose slope above the knee is 1 % of the
#: slope below (a rail that still tells the pressure; a fit there is a rail, the
#: physics' limit, not a stand-in), up to one four times as steep.
HINGE_GAIN_BOUNDS = (-0.99, 3.0)
#: A threshold's bounds and start, Pa absolute.
HINGE_THRESHOLD_BOUNDS_PA = (5.0e4, 2.0e6)
HINGE_THRESHOLD_START_PA = 3.0e5


def hinge_gain_name(j: int) -> str:
    """Hinge ``j``'s gain parameter."""
    return f"reading_hinge_gain_{j}"


def hinge_threshold_name(j: int) -> str:
    """Hinge ``j``'s threshold parameter."""
    return f"reading_hinge_threshold_{j}"


class ReadingHinge(Effect):
    """``terms`` hinges of the reading, ``r = z + sum_j c_j max(0, z - theta_j)``
    (``reading_hinge_gain_{j}``, ``reading_hinge_threshold_{j}``)."""

    name = "reading_hinge"
    acts_on = ()  # (the simulator applies it after the kernel, on the windows' reading)
    library_searched = False
    cheap_forms = True
    relaxes_reading = True

    def __init__(self, terms: int = 1, below: bool = False):
        if isinstance(terms, bool) or not isinstance(terms, int) \
                or not 1 <= terms <= HINGE_MAX_TERMS:
            raise ValueError(f"reading_hinge: option 'terms' must be an integer in "
                             f"1..{HINGE_MAX_TERMS}, got {terms!r}")
        if not isinstance(below, bool):
            raise ValueError(f"reading_hinge: option 'below' must be True or False, got "
                             f"{below!r}")
        self.terms = terms
        self.below = below

    def options(self):
        return {"terms": self.terms, "below": self.below}

    def parameters(self):
        lo, hi = HINGE_THRESHOLD_BOUNDS_PA
        out = []
        for j in range(self.terms):
            out.append(Parameter(hinge_gain_name(j), "-", *HINGE_GAIN_BOUNDS, "uniform",
                                 f"reading hinge {j}: the change c of the reading's slope "
                                 f"{'below' if self.below else 'above'} its knee (-1: a "
                                 "flat rail)", neutral=0.0,
                                 limit="lower"))
            out.append(Parameter(hinge_threshold_name(j), "Pa", lo, hi, "uniform",
                                 f"reading hinge {j}: the reading's knee theta, Pa absolute "
                                 "(the term vanishes with its gain whatever its knee)",
                                 neutral=HINGE_THRESHOLD_START_PA))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {}  # (no slot of the kernel: see the module's docstring)

    def reading_hinges(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray]:
        """``(gains, thresholds Pa)``, each ``(B, terms)``, of a batch of values (knees
        below as their thresholds negated: :mod:`pneubayes.simulation.reading_hinge`)."""
        return self.hinges_named(values, [hinge_gain_name(j) for j in range(self.terms)],
                                 [hinge_threshold_name(j) for j in range(self.terms)],
                                 self.below)

    @staticmethod
    def hinges_named(values: Mapping[str, np.ndarray], gains: list[str],
                     thresholds: list[str], below: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
        """``(gains, thresholds)``, each ``(B, J)``, read from ``values`` under the
        parameter names ``gains`` and ``thresholds`` (one per hinge; with ``below``, knees
        that bend the reading below them, their thresholds negated)."""
        g, th = named_pairs(values, gains, thresholds)
        return g, -th if below else th

    def bench_defaults(self):
        """A reading that bends to a fifth of its slope above 3 bar (a second: to a
        twentieth above 3.5 bar)."""
        out = {hinge_gain_name(0): -0.8, hinge_threshold_name(0): 3.0e5}
        if self.terms > 1:
            out.update({hinge_gain_name(1): -0.15, hinge_threshold_name(1): 3.5e5})
        return out
