"""Chamber kind ``compliant``: a chamber whose volume grows with its pressure,
``V(p) = V_0 + C (p - P_atm)`` (a bellows, a test lung, a soft actuator).

Card keys: ``volume_m3`` (V_0, the volume at atmospheric pressure, tube included;
fitted as ``dead_volume_m3``) and ``compliance_m3_per_Pa`` (C; fitted as
``chamber_compliance_m3_per_Pa``), each known or a prior. With ``dV/dt = C dp/dt``
eq. 5 becomes ``dp/dt = n (Rs T mdot - p vdot) / (V + n p C)``
(:mod:`pneubayes.simulation.chamber`). Where C dominates (a lung: n p C is tens of
litres against one), the filling rate fixes the ratio of the valve's area to C, not
each: give one of them, or read the posterior's correlation.
"""

from __future__ import annotations

from pneubayes.rigcard.chamber_fixed import FixedChamber
from pneubayes.rigcard.component import register


@register
class CompliantChamber(FixedChamber):
    role, kind = "chamber", "compliant"
    quantities = (
        ("volume_m3", "m^3", "volume at atmospheric pressure, tube included", "positive"),
        ("compliance_m3_per_Pa", "m^3/Pa", "volume change per pascal", "positive"),
    )
    parameter_names_by_key = {"volume_m3": "dead_volume_m3",
                              "compliance_m3_per_Pa": "chamber_compliance_m3_per_Pa"}
    slots_written = ("volume_m3", "compliance_m3_per_Pa")

    def lower_all(self, values, rig):
        return {"volume_m3": values["volume_m3"],
                "compliance_m3_per_Pa": values["compliance_m3_per_Pa"]}
