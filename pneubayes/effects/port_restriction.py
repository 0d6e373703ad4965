"""An open-form term at the chamber's port: a restriction in series with the valve.

Between a valve and its chamber there is often one more orifice: a fitting or a quick
coupling, a speed controller's needle (a meter-out or meter-in flow control, with a
check valve that lets the other direction pass), a narrow port in the cylinder's cap.
The chamber's net flow passes it, and the valve's ports see the pressure between the
two, not the chamber's::

    a_in f(p_s, x) - a_ex f(x, P_atm) = A f(x, p),    A = A_f if x > p else A_v,

eqs. 1-3 for every orifice, the node between them holding no air of its own
(:mod:`pneubayes.simulation.restriction`). A fill then slows where the restriction is
narrower than the valve's inlet, a vent where it is narrower than its exhaust; a
one-way flow control restricts one direction only. The parameters are the
restriction's inverse areas, ``port_restriction_fill`` (flow into the chamber) and
``port_restriction_vent`` (out of it), in 1/m^2: 0 is no restriction, 1e6 an area of
1 mm^2; and ``port_restriction_crack`` (Pa), the cracking drop of a one-way flow
control's check valve: below it the wider direction passes only the narrower one's area
(the needle both share), from one to two times it the check opens to its own
(:func:`pneubayes.simulation.restriction.direction_area`); 0 is no check valve.

The simulator steps it beside heat transfer, a closure, a compliant chamber and the
valve's own dynamics; not beside the tube's acoustic or transmission line, a supply
tank or a second compartment. The discovery library never searches for it: the
open-form stage at the port
(:class:`~pneubayes.discovery.stages.port_restriction_form.PortRestrictionForm`)
proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig

#: The inverse areas' bounds, 1/m^2 (areas of 0.01 mm^2 and up).
INVERSE_AREA_BOUNDS_PER_M2 = (0.0, 1e8)
#: The check valve's cracking drop's bounds, Pa.
CRACK_BOUNDS_PA = (0.0, 1e5)

FILL = "port_restriction_fill"
VENT = "port_restriction_vent"
CRACK = "port_restriction_crack"


class PortRestriction(Effect):
    """A restriction in series at the chamber's port: inverse areas
    ``port_restriction_fill`` (into the chamber) and ``port_restriction_vent`` (out of
    it), 1/m^2, 0 none; its check valve's cracking drop ``port_restriction_crack``, Pa,
    0 none."""

    name = "port_restriction"
    acts_on = ("restriction_fill_inverse_area_per_m2", "restriction_vent_inverse_area_per_m2",
               "restriction_crack_Pa")
    library_searched = False
    cheap_forms = True
    beside_line = False

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) or terms != 1:
            raise ValueError(f"port_restriction: option 'terms' must be 1 (one restriction), "
                             f"got {terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def parameters(self):
        return (
            Parameter(FILL, "1/m^2", *INVERSE_AREA_BOUNDS_PER_M2, "uniform",
                      "port restriction: 1 / its area for flow into the chamber (0: none)",
                      neutral=0.0),
            Parameter(VENT, "1/m^2", *INVERSE_AREA_BOUNDS_PER_M2, "uniform",
                      "port restriction: 1 / its area for flow out of the chamber (0: none)",
                      neutral=0.0),
            Parameter(CRACK, "Pa", *CRACK_BOUNDS_PA, "uniform",
                      "port restriction: its check valve's cracking drop (the wider "
                      "direction's; 0: none)", neutral=0.0),
        )

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {"restriction_fill_inverse_area_per_m2": np.asarray(values[FILL], np.float64),
                "restriction_vent_inverse_area_per_m2": np.asarray(values[VENT], np.float64),
                "restriction_crack_Pa": np.asarray(values[CRACK], np.float64)}

    def bench_defaults(self):
        """A meter-out flow control: the fill through 2 mm^2, the vent through 0.2 mm^2,
        the check cracking at 10 kPa."""
        return {FILL: 5e5, VENT: 5e6, CRACK: 1e4}
