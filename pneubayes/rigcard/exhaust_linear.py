"""Exhaust kind ``linear``: a separate exhaust valve whose area grows linearly with its
own command, ``A clip(v, 0, 1)`` (an on/off exhaust valve on a binary command, or a
proportional one on a duty).

Card keys: ``command`` (``{unit, range}``, required), ``column`` (default
``exhaust_command``) and ``open_area_m2`` (> 0, known or a prior; fitted, the parameter
``exhaust_valve_open_area_m2``).
"""

from __future__ import annotations

from pneubayes.rigcard.component import register
from pneubayes.rigcard.exhaust_common import SeparateExhaust


@register
class LinearExhaust(SeparateExhaust):
    role, kind = "exhaust", "linear"
    quantities = (("open_area_m2", "m^2", "area at command 1", "positive"),)
    parameter_names_by_key = {"open_area_m2": "exhaust_valve_open_area_m2"}
    slots_written = ("exhaust_open_area_m2", "exhaust_own_command")

    def lower_all(self, values, rig):
        return {"exhaust_open_area_m2": values["open_area_m2"], "exhaust_own_command": 1.0}
