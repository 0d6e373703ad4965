"""Supply kind ``restricted``: a supply that feeds the valve's inlet through a restriction.

A supply hose or a fitting, a regulator near its flow limit, a blower on its fan curve:
the inlet sees the pressure between the restriction and itself, ``A f(p_s, n) = a_in
f(n, x)`` (:mod:`pneubayes.simulation.supply_restriction`); the exhaust does not pass it.

Card keys: ``restriction_area_m2`` (> 0, known or a prior; fitted as the parameter
``supply_restriction_area_m2``) and ``pressure_Pa`` (absolute, upstream of the
restriction: a number, or ``"measured"``: the recording's supply column, gauged before
the restriction).
"""

from __future__ import annotations

from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import real


@register
class RestrictedSupply(RigComponent):
    role, kind = "supply", "restricted"
    quantities = (("restriction_area_m2", "m^2", "the supply restriction's area",
                   "positive"),)
    parameter_names_by_key = {"restriction_area_m2": "supply_restriction_area_m2"}
    slots_written = ("supply_restriction_inverse_area_per_m2", "supply_gain")

    @classmethod
    def option_keys(cls):
        return ("pressure_Pa",)

    @classmethod
    def read_options(cls, table, where):
        p = table.get("pressure_Pa")
        if p != "measured":
            p = real(p, f"{where} key 'pressure_Pa' (absolute Pa, or \"measured\")",
                     positive=True)
        return {"pressure_Pa": p}

    @property
    def measured(self) -> bool:
        return self.extra["pressure_Pa"] == "measured"

    def lower_all(self, values, rig):
        return {"supply_restriction_inverse_area_per_m2": 1.0 / values["restriction_area_m2"],
                "supply_gain": 1.0 if self.measured else 0.0}

    def metadata_defaults(self):
        return {} if self.measured else {"supply_pressure_Pa": self.extra["pressure_Pa"]}

    def bind_columns(self, recording, where):
        if self.measured and recording.supply_pressure_Pa is None:
            raise RigCardError(f"{where}: supply kind 'restricted' with pressure_Pa "
                               f"\"measured\" needs a supply pressure column; "
                               f"{recording.source} has none")
        return {}
