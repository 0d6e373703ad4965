"""Supply kind ``constant``: a regulated supply at a known absolute pressure.

Card key: ``pressure_Pa`` (absolute, known). A supply column in the recording is kept
but does not drive the model (a ``supply_fluctuation`` effect would weigh it in).
"""

from __future__ import annotations

from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import real


@register
class ConstantSupply(RigComponent):
    role, kind = "supply", "constant"

    @classmethod
    def option_keys(cls):
        return ("pressure_Pa",)

    @classmethod
    def read_options(cls, table, where):
        return {"pressure_Pa": real(table.get("pressure_Pa"), f"{where} key 'pressure_Pa'",
                                    positive=True)}

    def metadata_defaults(self):
        return {"supply_pressure_Pa": self.extra["pressure_Pa"]}
