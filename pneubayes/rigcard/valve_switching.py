"""Valve kind ``switching``: an on/off valve driven by a 0/1 command.

Opening ``u`` follows the command after an opening delay and through a first-order
opening lag; the inlet area is ``A_open u`` and, on a 3/2 valve that vents when closed,
the exhaust area ``A_exhaust (1 - u)``
(:func:`pneubayes.physics.valve.switching_scalar`).

Card keys (each known or a prior): ``open_area_m2`` (> 0), ``exhaust_area_m2``
(>= 0; 0 for a 2/2 valve), ``opening_delay_s`` (>= 0) and ``opening_time_constant_s``
(>= 0). Fitted, they are the parameters ``valve_open_area_m2``, ... .
"""

from __future__ import annotations

from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register


@register
class SwitchingValve(RigComponent):
    role, kind = "valve", "switching"
    quantities = (
        ("open_area_m2", "m^2", "inlet area when fully open", "positive"),
        ("exhaust_area_m2", "m^2", "exhaust area when closed (0: a 2/2 valve)",
         "nonnegative"),
        ("opening_delay_s", "s", "dead time from command to opening", "nonnegative"),
        ("opening_time_constant_s", "s", "first-order opening time constant",
         "nonnegative"),
    )
    parameter_names_by_key = {q[0]: f"valve_{q[0]}" for q in quantities}
    slots_written = ("inlet_open_area_m2", "exhaust_open_area_m2", "command_delay_s",
                     "spool_time_constant_s")

    def without_exhaust(self, where):
        if self.values["exhaust_area_m2"] != 0.0:
            raise RigCardError(f"{where} key 'exhaust_area_m2': the rig's exhaust is a "
                               "separate valve (its [exhaust] table); set this to 0")
        return self

    def lower_all(self, values, rig):
        return {"inlet_open_area_m2": values["open_area_m2"],
                "exhaust_open_area_m2": values["exhaust_area_m2"],
                "command_delay_s": values["opening_delay_s"],
                "spool_time_constant_s": values["opening_time_constant_s"]}
