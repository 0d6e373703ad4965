"""Chamber kind ``piston``: the paper's cylinder, V = V_0 + A x (eq. 5, Fig. 5b).

Card keys: ``bore_m`` and ``stroke_m`` (known, m), ``dead_volume_m3`` (the volume at
position 0, tube included; known or a prior). The recording's ``position_m`` column (or
its fixed ``position_m`` key) is the piston position.
"""

from __future__ import annotations

from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import real


@register
class PistonChamber(RigComponent):
    role, kind = "chamber", "piston"
    quantities = (("dead_volume_m3", "m^3", "volume at position 0, tube included", "positive"),)
    slots_written = ("volume_m3",)

    @classmethod
    def option_keys(cls):
        return ("bore_m", "stroke_m")

    @classmethod
    def read_options(cls, table, where):
        return {k: real(table.get(k), f"{where} key {k!r}", positive=True)
                for k in cls.option_keys()}

    def lower_all(self, values, rig):
        return {"volume_m3": values["dead_volume_m3"]}

    def metadata_defaults(self):
        return {"bore_m": self.extra["bore_m"], "stroke_m": self.extra["stroke_m"]}

