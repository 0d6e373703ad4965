"""Chamber kind ``compliant_table``: a chamber whose volume grows with its pressure along a
measured table, ``V(p) = V_dead + dV(p)`` (a test lung's or a bellows' pressure-volume
curve, stiffening as it fills), linear between the table's points with the end
segments extended.

Card keys: ``dead_volume_m3`` (V_dead, the volume where the table's dV is 0, tube
included; known or a prior), ``pressure_Pa`` ([p_0, p_1, ...], absolute, strictly
increasing, 2 to 16 points) and ``volume_change_m3`` (dV at each point, m^3,
non-decreasing). The compliance ``dV/dp`` is the table's slope, so eq. 5 becomes
``dp/dt = n (Rs T mdot - p vdot) / (V(p) + n p dV/dp)``
(:func:`pneubayes.simulation.chamber.compliant_volume`). A table of two points is the
``compliant`` kind with ``C`` its slope. The compliance jumps where the pressure crosses
a point, which the integrator's error estimate does not see: at the standard solver
preset a three-segment table's error was 0.4 % of the pressure span against a reference
solver (0.1 % without the kinks); tighten the solver, or give more, finer points.
"""

from __future__ import annotations

import math

from pneubayes.effects.path import TABLE_MAX_POINTS
from pneubayes.errors import RigCardError
from pneubayes.rigcard.chamber_fixed import FixedChamber
from pneubayes.rigcard.component import register
from pneubayes.rigcard.values import table_column


@register
class CompliantTableChamber(FixedChamber):
    role, kind = "chamber", "compliant_table"
    quantities = (("dead_volume_m3", "m^3", "volume where the table's dV is 0, tube "
                   "included", "positive"),)
    parameter_names_by_key = {}
    slots_written = ("volume_m3", "volume_table_points",
                     *(f"volume_table_pressure_Pa_{k}" for k in range(TABLE_MAX_POINTS)),
                     *(f"volume_table_volume_m3_{k}" for k in range(TABLE_MAX_POINTS)))

    @classmethod
    def option_keys(cls):
        return ("pressure_Pa", "volume_change_m3")

    @classmethod
    def read_options(cls, table, where):
        p = table_column(table, "pressure_Pa", where, order="increasing",
                         max_points=TABLE_MAX_POINTS)
        if not p[0] > 0:
            raise RigCardError(f"{where} key 'pressure_Pa' [0]: pressures are absolute "
                               f"(> 0 Pa), got {p[0]!r}")
        dv = table_column(table, "volume_change_m3", where, order="non-decreasing",
                          length=len(p), per="pressure point")
        return {"pressure_Pa": p, "volume_change_m3": dv}

    def lower_all(self, values, rig):
        out = {"volume_m3": values["dead_volume_m3"],
               "volume_table_points": float(len(self.extra["pressure_Pa"]))}
        for k, (p, dv) in enumerate(zip(self.extra["pressure_Pa"],
                                        self.extra["volume_change_m3"])):
            out[f"volume_table_pressure_Pa_{k}"] = p
            out[f"volume_table_volume_m3_{k}"] = dv
        return out

    def metadata_defaults(self):
        v = self.values["dead_volume_m3"]
        vol = v.start_value() if hasattr(v, "start_value") else v
        d = (4.0 * vol / math.pi) ** (1.0 / 3.0)
        return {"bore_m": d, "stroke_m": d}
