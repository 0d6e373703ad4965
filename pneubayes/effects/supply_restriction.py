"""A restriction upstream of the valve's inlet: a supply that cannot deliver any flow.

Between the supply whose pressure is known (the regulator's setting, a logged header, a
blower's rated pressure) and the valve's inlet there is often one more orifice: a supply
hose or a fitting, a regulator near its flow limit, a blower on its fan curve, a manifold
shared through one port. The inlet's flow passes it, and the inlet sees the pressure
between the two, not the supply's::

    A_s f(p_s, n) = a_in f(n, x),

eqs. 1-3 for both orifices, the node between them holding no air of its own
(:mod:`pneubayes.simulation.supply_restriction`). Where the valve opens wider than the
restriction the fill's flow stops growing with the command (a flow limit upstream);
the exhaust and the leak do not pass it, so the vent is unchanged. The parameter is the
restriction's inverse area ``supply_restriction`` (1/m^2): 0 is no restriction, 1e6 an
area of 1 mm^2. Where the supply is measured behind the restriction (a gauge at the
valve), the restriction is already in the measurement: do not add it.

The simulator steps it beside heat transfer, a closure, a compliant chamber, a second
compartment and the valve's own dynamics; not beside the tube's acoustic or
transmission line, a supply tank or a restriction at the chamber's port.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig

#: The inverse area's bounds, 1/m^2 (areas of 0.01 mm^2 and up).
INVERSE_AREA_BOUNDS_PER_M2 = (0.0, 1e8)

SUPPLY = "supply_restriction"


class SupplyRestriction(Effect):
    """A restriction in series upstream of the valve's inlet: inverse area
    ``supply_restriction``, 1/m^2, 0 none."""

    name = "supply_restriction"
    acts_on = ("supply_restriction_inverse_area_per_m2",)
    library_searched = False
    cheap_forms = True
    beside_line = False

    def parameters(self):
        return (Parameter(SUPPLY, "1/m^2", *INVERSE_AREA_BOUNDS_PER_M2, "uniform",
                          "supply restriction: 1 / its area upstream of the valve's inlet "
                          "(0: none)", neutral=0.0),)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {"supply_restriction_inverse_area_per_m2":
                np.asarray(values[SUPPLY], np.float64)}

    def bench_defaults(self):
        """A supply hose's fitting of 0.5 mm^2 (the bench valves' inlets open to about
        0.6 mm^2)."""
        return {SUPPLY: 2e6}
