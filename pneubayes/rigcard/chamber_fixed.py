"""Chamber kind ``fixed``: a chamber of constant volume (a vessel, a blocked muscle).

Card key: ``volume_m3`` (tube included; known or a prior; fitted as the parameter
``dead_volume_m3``, the name every chamber's volume at its coordinate 0 has). A
recording may carry a position column only if it does not move.

The kernel's wall area (the convective heat-transfer form) is that of a cylinder as tall
as it is wide holding the volume's start value, whose diameter also stands in for the
bore and stroke of the recording's metadata.
"""

from __future__ import annotations

import math

import numpy as np

from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import Unknown


@register
class FixedChamber(RigComponent):
    role, kind = "chamber", "fixed"
    quantities = (("volume_m3", "m^3", "chamber volume, tube included", "positive"),)
    slots_written = ("volume_m3",)

    parameter_names_by_key = {"volume_m3": "dead_volume_m3"}

    def lower_all(self, values, rig):
        return {"volume_m3": values["volume_m3"]}

    def metadata_defaults(self):
        v = self.values["volume_m3"]
        vol = v.start_value() if isinstance(v, Unknown) else v
        d = (4.0 * vol / math.pi) ** (1.0 / 3.0)
        return {"bore_m": d, "stroke_m": d}

    def bind_columns(self, recording, where):
        x = recording.position_m
        if x is not None and np.ptp(x) > 0:
            raise RigCardError(f"{where}: chamber kind 'fixed' cannot move, but "
                               f"{recording.source}'s position column varies by "
                               f"{np.ptp(x):g} m; describe the chamber as 'piston' or "
                               "'polynomial'")
        return {"position_m": None} if x is not None else {}
