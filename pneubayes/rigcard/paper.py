"""The paper's rigs as rig cards: a Table I cylinder (a piston chamber) with a Table II
valve (a Gompertz valve with the core's default priors, or its Table II maps as known
values), supplied at a constant pressure. A model on such a card is the thin-port model
(``Model()``) under other names: the same slots, the same simulation.
"""

from __future__ import annotations

from pneubayes.physics.cylinder import cylinder_preset
from pneubayes.physics.valve import valve_preset
from pneubayes.rigcard.card import RIG_FORMAT, RigCard


def paper_rig_card(cylinder: str, valve: str, supply_pressure_Pa: float = 551325.0,
                   atmospheric_pressure_Pa: float = 101325.0, temperature_K: float = 293.15,
                   valve_known: bool = False) -> RigCard:
    """The card of a Table I cylinder and a Table II valve (the valve's maps known when
    ``valve_known``, else fitted under the core's default priors)."""
    cyl = cylinder_preset(cylinder)
    valve_table = {"kind": "gompertz"}
    if valve_known:
        valve_table.update(valve_preset(valve).parameters())
    return RigCard.from_dict({
        "format": RIG_FORMAT, "name": f"{cylinder} + {valve} (the paper's Tables I-II)",
        "atmospheric_pressure_Pa": atmospheric_pressure_Pa, "temperature_K": temperature_K,
        "command": {"unit": "V", "range": [-5.0, 5.0]},
        "chamber": {"kind": "piston", "bore_m": cyl.bore_m, "stroke_m": cyl.stroke_m,
                    "dead_volume_m3": {"prior": "log-uniform", "bounds": [1e-8, 1e-4]}},
        "valve": valve_table,
        "supply": {"kind": "constant", "pressure_Pa": supply_pressure_Pa},
    }, f"paper rig {cylinder}+{valve}")
