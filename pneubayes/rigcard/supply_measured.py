"""Supply kind ``measured``: the recording's supply column drives the inlet (eqs. 1-3).

Card key: ``nominal_pressure_Pa`` (absolute, optional; the recording's
``supply_pressure_Pa`` otherwise), the reference a ``supply_fluctuation`` effect's gain
scales deviations from. The base model uses the measured column as it is (gain 1).
"""

from __future__ import annotations

from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import real


@register
class MeasuredSupply(RigComponent):
    role, kind = "supply", "measured"
    slots_written = ("supply_gain",)

    @classmethod
    def option_keys(cls):
        return ("nominal_pressure_Pa",)

    @classmethod
    def read_options(cls, table, where):
        if "nominal_pressure_Pa" not in table:
            return {}
        return {"nominal_pressure_Pa": real(table["nominal_pressure_Pa"],
                                            f"{where} key 'nominal_pressure_Pa'",
                                            positive=True)}

    def lower_all(self, values, rig):
        return {"supply_gain": 1.0}

    def metadata_defaults(self):
        if "nominal_pressure_Pa" in self.extra:
            return {"supply_pressure_Pa": self.extra["nominal_pressure_Pa"]}
        return {}

    def bind_columns(self, recording, where):
        if recording.supply_pressure_Pa is None:
            raise RigCardError(f"{where}: supply kind 'measured' needs a supply pressure "
                               f"column; {recording.source} has none")
        return {}
