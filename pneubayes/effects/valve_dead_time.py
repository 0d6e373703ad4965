"""A valve's dead time that depends on the supply pressure it switches.

An on/off or proportional valve acts some milliseconds after its command: a coil's
current builds, then the armature, a pilot's poppet or the main stage moves. The force
that moves it, and so its travel time, depends on the pressure across the valve: a
pilot-operated valve's main stage is driven by the supply and opens sooner at a higher
supply; a direct-acting poppet is held shut by it and opens later. Between runs at
different supply pressures the dead time changes, which a fixed delay of the command
averages over. This effect delays the command by::

    d = d_ref ((p_ref - P_atm) / (p_s - P_atm))^n

``d_ref`` (``valve_dead_time_s``) the dead time at the reference gauge supply
``p_ref - P_atm`` (option ``reference_gauge_Pa``, 5 bar: it only says where d_ref is
read), ``p_s`` the recording's nominal supply (its rig's), ``n``
(``valve_dead_time_exponent``): 1/2 for a part moved from rest over a fixed travel by a
force proportional to the pressure (``t = sqrt(2 x m / F)``), below 0 for a valve held
shut by the pressure, 0 a fixed dead time (a pure delay of the command, as the rig
card's ``opening_delay_s``). The delay adds to the command's other delays and acts on
rises and falls alike. It is one per recording: a recording whose supply moves between
switches (a draining tank) carries the dead time of its nominal supply.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig

#: A dead time's bounds, s.
DEAD_TIME_BOUNDS_S = (0.0, 0.05)
#: The exponent's bounds (a travel time against the force's power).
EXPONENT_BOUNDS = (-3.0, 3.0)


class ValveDeadTime(Effect):
    """The command delayed by ``valve_dead_time_s`` at the reference supply, scaled by
    the gauge supply's ratio to it to the power ``valve_dead_time_exponent``."""

    name = "valve_dead_time"
    acts_on = ("command_delay_s",)
    library_searched = False

    def __init__(self, reference_gauge_Pa: float = 5e5):
        if isinstance(reference_gauge_Pa, bool) or not reference_gauge_Pa > 0:
            raise ValueError(f"ValveDeadTime.reference_gauge_Pa must be a number > 0, got "
                             f"{reference_gauge_Pa!r}")
        self.reference_gauge_Pa = float(reference_gauge_Pa)

    def options(self):
        return {} if self.reference_gauge_Pa == 5e5 else \
            {"reference_gauge_Pa": self.reference_gauge_Pa}

    def parameters(self):
        return (Parameter("valve_dead_time_s", "s", *DEAD_TIME_BOUNDS_S, "uniform",
                          "the valve's dead time at the reference gauge supply",
                          neutral=0.0),
                Parameter("valve_dead_time_exponent", "-", *EXPONENT_BOUNDS, "uniform",
                          "the dead time's power law in the reference over the gauge "
                          "supply", neutral=0.0))

    def dead_time_s(self, values: Mapping[str, np.ndarray], rig: Rig) -> np.ndarray:
        """The dead time (s) on ``rig`` (its nominal supply)."""
        # (a Rig's supply is above its atmosphere)
        gauge = rig.supply_pressure_Pa - rig.atmospheric_pressure_Pa
        ratio = self.reference_gauge_Pa / gauge
        return (np.asarray(values["valve_dead_time_s"], dtype=np.float64)
                * ratio ** np.asarray(values["valve_dead_time_exponent"], dtype=np.float64))

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {"command_delay_s": self.dead_time_s(values, rig)}

    def bench_defaults(self):
        """A pilot-operated valve: 15 ms at 5 bar, its main stage driven by the supply."""
        return {"valve_dead_time_s": 0.015, "valve_dead_time_exponent": 0.5}
