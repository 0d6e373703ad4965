"""Chamber kind ``table``: a volume tabulated against a measured coordinate,
``V(s) = V_dead + dV(s)`` with ``dV`` linear between the table's points (a McKibben
muscle's volume against its contraction, measured rather than fitted by a polynomial).

Card keys: ``dead_volume_m3`` (V_dead, tube included; known or a prior),
``coordinate_m`` ([s_0, s_1, ...], m, strictly increasing, at least 2 points) and
``volume_change_m3`` (dV at each point, m^3, strictly increasing: the volume grows with
the coordinate). Beyond the table's ends the end segments are extended (the reader
refuses a coordinate more than 5 % of the table's span outside it). The recording's
``position_m`` column carries the coordinate.

As the ``polynomial`` kind, the chamber is lowered as an equivalent piston: the area
``A = (dV_n - dV_0) / (s_n - s_0)`` at the position ``x = dV(s) / A``, so
``V_dead + A x = V(s)`` exactly and eq. 5's volume and dV/dt terms carry it unchanged.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from pneubayes.rigcard.chamber_polynomial import PolynomialChamber
from pneubayes.rigcard.component import register
from pneubayes.rigcard.values import table_column


@register
class TableChamber(PolynomialChamber):
    role, kind = "chamber", "table"
    quantities = (("dead_volume_m3", "m^3", "volume where the table's dV is 0, tube "
                   "included", "positive"),)
    slots_written = ("volume_m3",)
    defaults: ClassVar[dict] = {}
    parameter_names_by_key: ClassVar[dict[str, str]] = {}

    def lower_all(self, values, rig):
        return {"volume_m3": values["dead_volume_m3"]}

    @classmethod
    def option_keys(cls):
        return ("coordinate_m", "volume_change_m3")

    @classmethod
    def read_options(cls, table, where):
        s = table_column(table, "coordinate_m", where, order="increasing")
        dv = table_column(table, "volume_change_m3", where, order="increasing",
                          length=len(s), per="coordinate")
        return {"coordinate_m": s, "volume_change_m3": dv}

    def check(self, where):
        pass  # read_options checks the order of both columns

    @property
    def area_m2(self) -> float:
        s, dv = self.extra["coordinate_m"], self.extra["volume_change_m3"]
        return (dv[-1] - dv[0]) / (s[-1] - s[0])

    def coordinate_range(self) -> tuple[float, float]:
        s = self.extra["coordinate_m"]
        return s[0], s[-1]

    def equivalent_position_m(self, coordinate_m) -> np.ndarray:
        """``dV(s) / A``, m: linear between points, the end segments extended."""
        s = np.asarray(self.extra["coordinate_m"])
        dv = np.asarray(self.extra["volume_change_m3"])
        c = np.asarray(coordinate_m, dtype=np.float64)
        v = np.interp(c, s, dv)
        lo_slope = (dv[1] - dv[0]) / (s[1] - s[0])
        hi_slope = (dv[-1] - dv[-2]) / (s[-1] - s[-2])
        v = np.where(c < s[0], dv[0] + lo_slope * (c - s[0]), v)
        v = np.where(c > s[-1], dv[-1] + hi_slope * (c - s[-1]), v)
        return v / self.area_m2

    def metadata_defaults(self):
        return {"bore_m": math.sqrt(4.0 * self.area_m2 / math.pi),
                "stroke_m": float(self.equivalent_position_m(self.coordinate_range()[1]))}
