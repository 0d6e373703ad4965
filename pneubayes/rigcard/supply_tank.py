"""Supply kind ``tank``: a finite tank, charged before the run and drained by the valves
it feeds (not refilled).

Its pressure is a state of the simulation: it starts at ``initial_pressure_Pa`` and falls
as the inlet draws from it, ``dP/dt = -n Rs T m_in / (V / N)`` (polytropic index n as
the chamber's, air at the card's temperature), with N the number of identical chambers
the tank feeds at once (``chambers_fed``; each recording models one of them). Contiguous
windows carry the tank's pressure; each separate window (a trial) starts charged.

Card keys: ``volume_m3`` (> 0, known or a prior; fitted, the parameter
``tank_volume_m3``), ``initial_pressure_Pa`` (absolute: a number, or ``"measured"``: the
recording's supply column at each window's start, a charge gauge read before the run;
later samples of the column are not used) and ``chambers_fed`` (an integer >= 1,
default 1).
"""

from __future__ import annotations

from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import real


@register
class TankSupply(RigComponent):
    role, kind = "supply", "tank"
    quantities = (("volume_m3", "m^3", "tank volume", "positive"),)
    parameter_names_by_key = {"volume_m3": "tank_volume_m3"}
    slots_written = ("tank_volume_m3", "supply_gain")

    @classmethod
    def option_keys(cls):
        return ("initial_pressure_Pa", "chambers_fed")

    @classmethod
    def read_options(cls, table, where):
        init = table.get("initial_pressure_Pa")
        if init != "measured":
            init = real(init, f"{where} key 'initial_pressure_Pa' (absolute Pa, or "
                              "\"measured\")", positive=True)
        fed = table.get("chambers_fed", 1)
        if isinstance(fed, bool) or not isinstance(fed, int) or fed < 1:
            raise RigCardError(f"{where} key 'chambers_fed': must be an integer >= 1, got "
                               f"{fed!r}")
        return {"initial_pressure_Pa": init, "chambers_fed": fed}

    @property
    def measured_start(self) -> bool:
        return self.extra["initial_pressure_Pa"] == "measured"

    def lower_all(self, values, rig):
        # the kernel starts the tank at the supply it would use at the window's start:
        # the measured column (gain 1) or the nominal pressure (gain 0)
        return {"tank_volume_m3": values["volume_m3"] / self.extra["chambers_fed"],
                "supply_gain": 1.0 if self.measured_start else 0.0}

    def metadata_defaults(self):
        if self.measured_start:
            return {}
        return {"supply_pressure_Pa": self.extra["initial_pressure_Pa"]}

    def bind_columns(self, recording, where):
        if self.measured_start and recording.supply_pressure_Pa is None:
            raise RigCardError(f"{where}: supply kind 'tank' with initial_pressure_Pa "
                               f"\"measured\" needs a supply pressure column; "
                               f"{recording.source} has none")
        return {}
