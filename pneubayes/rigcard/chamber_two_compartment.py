"""Chamber kind ``two_compartment``: the measured compartment feeds a second, compliant
one through a laminar resistance (a ventilator's circuit and its test lung behind the
airway resistance; a valve manifold and a bellows behind a hose).

The sensor reads the first compartment, of fixed volume ``volume_m3``. The second holds
``V_L = lung_volume_m3 + lung_compliance_m3_per_Pa (p_L - P_atm)`` and fills through
the resistance ``resistance_Pa_s_per_m3`` (R: pressure drop per volume flow), with the
mass flow ``rho q = (p + p_L) / (2 Rs T) (p - p_L) / R = (p^2 - p_L^2) / (2 Rs T R)``
(isothermal laminar flow at the mean density;
:mod:`pneubayes.simulation.lung`). With R -> 0 the two are one compliant chamber; with
R -> infinity the second is cut off.

Card keys, each known or a prior: ``volume_m3`` (fitted as ``dead_volume_m3``),
``lung_volume_m3``, ``lung_compliance_m3_per_Pa`` and ``resistance_Pa_s_per_m3``
(a QuickLung's Rp5, Rp20 and Rp50 are 4.9e5, 2.0e6 and 4.9e6 Pa s/m^3). The second
compartment's pressure is a state the recording does not measure: each recording's
first window starts it at the measured pressure (no flow), contiguous windows carry it.
Not combinable with heat transfer, the tube's acoustic line or a supply tank.
"""

from __future__ import annotations

from pneubayes.rigcard.chamber_fixed import FixedChamber
from pneubayes.rigcard.component import register


@register
class TwoCompartmentChamber(FixedChamber):
    role, kind = "chamber", "two_compartment"
    quantities = (
        ("volume_m3", "m^3", "the measured compartment's volume, tube included", "positive"),
        ("lung_volume_m3", "m^3", "the second compartment's volume at atmospheric pressure",
         "positive"),
        ("lung_compliance_m3_per_Pa", "m^3/Pa", "the second compartment's compliance",
         "positive"),
        ("resistance_Pa_s_per_m3", "Pa s/m^3", "laminar resistance between the two",
         "positive"),
    )
    parameter_names_by_key = {"volume_m3": "dead_volume_m3"}
    slots_written = ("volume_m3", "lung_volume_m3", "lung_compliance_m3_per_Pa",
                     "lung_conductance_kg_per_s_Pa2")

    def lower_all(self, values, rig):
        rs_t = rig.gas.specific_gas_constant_J_per_kg_K * rig.gas.temperature_K
        return {"volume_m3": values["volume_m3"], "lung_volume_m3": values["lung_volume_m3"],
                "lung_compliance_m3_per_Pa": values["lung_compliance_m3_per_Pa"],
                "lung_conductance_kg_per_s_Pa2":
                    1.0 / (2.0 * rs_t * values["resistance_Pa_s_per_m3"])}
