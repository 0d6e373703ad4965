"""An open-form term on the chamber's volume: a chamber that grows with its pressure
above a threshold.

The open-form closure (:mod:`pneubayes.effects.closure`) adds mass to the chamber; the
reading closure (:mod:`pneubayes.effects.reading_closure`) changes what the sensor
reports. Some of what a rig carries changes how much gas the chamber holds at a
pressure: a gas-charged accumulator that takes gas above its precharge, a bladder or a
hose wall that yields, a muscle that swells. This component adds to the chamber's
volume ``K`` hinges of its pressure::

    V(p) = V_0 + sum_k C_k max(0, p - theta_k),

``C_k`` (``volume_closure_compliance_{k}``, m^3/Pa) and ``theta_k``
(``volume_closure_threshold_{k}``, Pa absolute). A negative second hinge above a positive
first makes the volume's growth saturate (an accumulator's gas spring, stiffening as it
is compressed); where the compliances summed up to a hinge fall below 0 the volume stays
flat above it (a chamber does not shrink as its pressure rises). Eq. 5 then reads ``dp/dt = n (Rs T
mdot - p vdot) / (V(p) + n p dV/dp)``. Every compliance 0 is the chamber without the
component, whatever the thresholds.

It lowers onto the compiled simulator's tabulated volume (slots ``volume_table_*``,
:func:`pneubayes.simulation.chamber.compliant_volume`): a chamber stepped with its
pressure as its only state, so it cannot be combined with heat transfer, the tube's
acoustic line (form ``"line"``; its transmission line, ``"wave"``, carries it), a supply
tank or a second compartment, nor with a rig card whose chamber is already compliant.
The discovery library never searches for it: the open-form stage on the volume
(:class:`~pneubayes.discovery.stages.volume_form.VolumeForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.path import TABLE_MAX_POINTS
from pneubayes.rig import Rig

#: The most hinges one volume closure carries.
VOLUME_MAX_TERMS = 2
#: A compliance's bounds, m^3/Pa (up to 100 cm^3 per bar either way: far beyond any
#: chamber's dead volume per bar on the benches and rigs the toolkit serves).
COMPLIANCE_BOUNDS_M3_PER_PA = (-1e-9, 1e-9)
#: A threshold's bounds and start, Pa absolute.
THRESHOLD_BOUNDS_PA = (2e4, 3e6)
THRESHOLD_START_PA = 101325.0
#: How far the table's outer points lie beyond the hinges, Pa (the end segments are
#: extended: below the first hinge the volume is flat, above the last it grows with the
#: sum of the compliances).
TABLE_MARGIN_PA = 1e4
#: Two hinges this close (Pa) share one table point.
MIN_HINGE_GAP_PA = 1.0


def compliance_name(k: int) -> str:
    """Hinge ``k``'s compliance parameter."""
    return f"volume_closure_compliance_{k}"


def threshold_name(k: int) -> str:
    """Hinge ``k``'s threshold parameter."""
    return f"volume_closure_threshold_{k}"


_TABLE_SLOTS = ("volume_table_points",
                *(f"volume_table_pressure_Pa_{k}" for k in range(TABLE_MAX_POINTS)),
                *(f"volume_table_volume_m3_{k}" for k in range(TABLE_MAX_POINTS)))


def hinge_table(compliances, thresholds) -> tuple[np.ndarray, np.ndarray]:
    """The tabulated volume change of ``sum_k C_k max(0, p - theta_k)``: ``(pressures,
    volumes)``, each ``(B, K + 2)`` (Pa, increasing; m^3), from ``compliances`` and
    ``thresholds`` ``(B, K)``: a point below the lowest hinge, one at each hinge, one
    above the highest. Where the compliances summed up to a hinge fall below 0 the
    volume stays flat above it instead."""
    c = np.atleast_2d(np.asarray(compliances, dtype=np.float64))
    th = np.atleast_2d(np.asarray(thresholds, dtype=np.float64))
    c, th = np.broadcast_arrays(c, th)
    order = np.argsort(th, axis=1)
    th = np.take_along_axis(th, order, axis=1)
    c = np.take_along_axis(c, order, axis=1)
    # strictly increasing points: a hinge within MIN_HINGE_GAP_PA of the one before
    # moves up to it (the volume's change over that gap is below a micro-litre)
    for k in range(1, th.shape[1]):
        th[:, k] = np.maximum(th[:, k], th[:, k - 1] + MIN_HINGE_GAP_PA)
    pts = np.concatenate([th[:, :1] - TABLE_MARGIN_PA, th,
                          th[:, -1:] + TABLE_MARGIN_PA], axis=1)
    # the slope above each hinge, never below 0: a chamber's volume does not shrink as
    # its pressure rises (a negative hinge saturates the growth, down to none)
    slopes = np.maximum(0.0, np.cumsum(c, axis=1))
    vol = np.zeros_like(pts)
    for j in range(2, pts.shape[1]):  # the volume at each point, segment by segment
        vol[:, j] = vol[:, j - 1] + slopes[:, j - 2] * (pts[:, j] - pts[:, j - 1])
    return pts, vol


class VolumeClosure(Effect):
    """``terms`` hinges of the chamber's volume in its pressure, ``V(p) = V_0 + sum_k C_k
    max(0, p - theta_k)`` (``volume_closure_compliance_{k}``,
    ``volume_closure_threshold_{k}``)."""

    name = "volume_closure"
    acts_on = _TABLE_SLOTS
    library_searched = False
    cheap_forms = True
    beside_line = False

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) \
                or not 1 <= terms <= VOLUME_MAX_TERMS:
            raise ValueError(f"volume_closure: option 'terms' must be an integer in "
                             f"1..{VOLUME_MAX_TERMS}, got {terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def beside_tube(self, form: str) -> bool:
        """The transmission-line tube (``"wave"``) steps a compliant chamber; the
        acoustic line's cells (``"line"``) do not."""
        return form == "wave"

    def parameters(self):
        out = []
        for k in range(self.terms):
            out.append(Parameter(compliance_name(k), "m^3/Pa", *COMPLIANCE_BOUNDS_M3_PER_PA,
                                 "uniform", f"volume hinge {k}: the chamber's added volume "
                                 "per pascal above its threshold (negative: less growth)",
                                 neutral=0.0))
            out.append(Parameter(threshold_name(k), "Pa", *THRESHOLD_BOUNDS_PA, "uniform",
                                 f"volume hinge {k}: the absolute pressure above which the "
                                 "chamber grows (the term vanishes with its compliance "
                                 "whatever its threshold)", neutral=THRESHOLD_START_PA))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        c = np.stack([np.atleast_1d(np.asarray(values[compliance_name(k)], np.float64))
                      for k in range(self.terms)], axis=-1)
        th = np.stack([np.atleast_1d(np.asarray(values[threshold_name(k)], np.float64))
                       for k in range(self.terms)], axis=-1)
        pts, vol = hinge_table(c, th)
        # every compliance 0: no table (the rigid chamber's path, exactly the base model)
        on = np.any(c != 0.0, axis=1)
        out = {"volume_table_points": np.where(on, float(pts.shape[1]), 0.0)}
        for j in range(pts.shape[1]):
            out[f"volume_table_pressure_Pa_{j}"] = np.where(on, pts[:, j], 0.0)
            out[f"volume_table_volume_m3_{j}"] = np.where(on, vol[:, j], 0.0)
        return out

    def bench_defaults(self):
        """A chamber that takes 2 cm^3 per bar above 3 bar absolute (a second hinge: 1
        cm^3 per bar more above 4.5 bar)."""
        out = {compliance_name(0): 2e-11, threshold_name(0): 3e5}
        if self.terms > 1:
            out.update({compliance_name(1): 1e-11, threshold_name(1): 4.5e5})
        return out
