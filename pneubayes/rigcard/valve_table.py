"""Valve kind ``table``: a tabulated command -> area map (a lab's measured flow table).

The port areas are linear between the table's points and held flat beyond its ends
(:func:`pneubayes.physics.valve.table_scalar`), of the command after any delay, lag and
dead band, like the Gompertz map of eq. 11 they replace.

Card keys:

- ``command`` ([c_0, c_1, ...], the card command's unit, strictly increasing, 2 to
  :data:`pneubayes.effects.path.TABLE_MAX_POINTS` points);
- ``inlet_area_m2`` (the inlet area at each point, m^2, >= 0, non-decreasing: the inlet
  opens as the command grows);
- ``exhaust_area_m2`` (optional, the exhaust area at each point, m^2, >= 0,
  non-increasing: a 3/2 or 5/3 valve's exhaust opens as the command falls; left out or
  all 0 for a 2/2 valve or beside a separate ``[exhaust]`` valve);
- ``inlet_scale`` and ``exhaust_scale`` (optional, > 0, known or a prior; default 1):
  factors on the tabulated areas, for a table whose shape is trusted but whose size is
  not (a flow table measured at another supply, a discharge coefficient). Fitted, they
  are the parameters ``valve_inlet_scale`` and ``valve_exhaust_scale``.
"""

from __future__ import annotations

from pneubayes.effects.path import TABLE_MAX_POINTS
from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import table_column


@register
class TableValve(RigComponent):
    role, kind = "valve", "table"
    quantities = (
        ("inlet_scale", "-", "factor on the tabulated inlet areas", "positive"),
        ("exhaust_scale", "-", "factor on the tabulated exhaust areas", "positive"),
    )
    parameter_names_by_key = {q[0]: f"valve_{q[0]}" for q in quantities}
    slots_written = ("table_points",
                     *(f"table_command_{k}" for k in range(TABLE_MAX_POINTS)),
                     *(f"table_inlet_m2_{k}" for k in range(TABLE_MAX_POINTS)),
                     *(f"table_exhaust_m2_{k}" for k in range(TABLE_MAX_POINTS)))

    defaults = {"inlet_scale": 1.0, "exhaust_scale": 1.0}

    @classmethod
    def option_keys(cls):
        return ("command", "inlet_area_m2", "exhaust_area_m2")

    @classmethod
    def read_options(cls, table, where):
        cmd = table_column(table, "command", where, order="increasing",
                           max_points=TABLE_MAX_POINTS)
        n = len(cmd)
        inlet = table_column(table, "inlet_area_m2", where, order="non-decreasing",
                             length=n, per="command point", nonnegative=True)
        exhaust = (table_column(table, "exhaust_area_m2", where, order="non-increasing",
                                length=n, per="command point", nonnegative=True)
                   if "exhaust_area_m2" in table else [0.0] * n)
        if not any(a > 0 for a in inlet):
            raise RigCardError(f"{where} key 'inlet_area_m2': the inlet never opens (all 0)")
        return {"command": cmd, "inlet_area_m2": inlet, "exhaust_area_m2": exhaust}

    def check(self, where):
        if self.values["exhaust_scale"] != 1.0 and not any(self.extra["exhaust_area_m2"]):
            raise RigCardError(f"{where} key 'exhaust_scale': the table has no exhaust "
                               "areas to scale")

    def without_exhaust(self, where):
        if any(a != 0.0 for a in self.extra["exhaust_area_m2"]):
            raise RigCardError(f"{where} key 'exhaust_area_m2': the rig's exhaust is a "
                               "separate valve (its [exhaust] table); leave this out (or "
                               "all 0)")
        return self

    def lower_all(self, values, rig):
        cmd = self.extra["command"]
        out = {"table_points": float(len(cmd))}
        for k, c in enumerate(cmd):
            out[f"table_command_{k}"] = c
            out[f"table_inlet_m2_{k}"] = values["inlet_scale"] * self.extra["inlet_area_m2"][k]
            out[f"table_exhaust_m2_{k}"] = (values["exhaust_scale"]
                                            * self.extra["exhaust_area_m2"][k])
        return out
