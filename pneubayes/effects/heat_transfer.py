"""Heat exchange between the chamber air and its wall (Richer & Hurmuzlu 2000), in three forms.

Eq. 5 is isentropic with the temperature fixed at the supply's. Every form makes the
chamber temperature T a state, with the wall at the supply temperature T_w:

- ``dp/dt = kappa / V (Rs (T_w m_in - T m_out) - p dV/dt) + (kappa - 1) Q / V``: eq. 5
  with the air that leaves carrying the chamber's temperature (inflow at the supply's),
  plus the wall heat flow Q;
- ``dT/dt = T (dp/dt / p + dV/dt / V - Rs T mdot / (p V))`` (ideal gas, mass balance).

``form="rate"``: ``Q = m c_v (T_w - T) / tau``, i.e. ``(kappa - 1) Q / V = p (T_w - T) /
(T tau)``, with the exchange rate ``heat_transfer_rate_per_s`` = 1/tau. The orifice mass
flows keep the paper's supply temperature (no sqrt(T_w / T) on eq. 1), so this form is a
first-order correction to eq. 5 with one time constant for every pressure and volume.

``form="convective"``: Newton's law on the chamber's wall, ``Q = h A_w (T_w - T)`` with
``A_w = 2 A + pi D V / A`` (two end caps and the barrel of a cylinder of bore D, section
A, holding volume V), and orifice flows leaving the chamber scaled by sqrt(T_w / T)
(eq. 1's upstream temperature). Its parameter is the coefficient
``heat_transfer_coefficient_W_per_m2_K`` h. The relaxation rate it implies,
``(kappa - 1) h A_w T / (p V)``, is fastest in small volumes and at low pressure, as in
real chambers; the rate form cannot change its rate along a stroke.

``form="forced"``: the convective form with ``h = h_0 + h_j m_in / (1 g/s)``
(``heat_transfer_jet_W_per_m2_K`` h_j; ``m_in`` the valve's inflow): a fill's jet stirs
the gas (forced convection), more exchange while it fills. ``h_j = 0`` is convective.

Every form has a coupling ``heat_transfer_coupling`` c in [0, 1]: the pressure equation
reads ``T_w + c (T - T_w)`` wherever it reads T (the outflow's enthalpy, the wall's heat
and the outflows' sqrt(T_w / T)); T itself follows the gas law. c = 1 is the energy
equation above; c = 0 is eq. 5 exactly, so a fit of the effect contains the fit without
it (the exchange alone cannot: as the rate or h falls to 0 at c = 1 the chamber becomes
*adiabatic*, not eq. 5). A nonuniform gas or exchange in the valve's body sit between.

Option ``wall_offset`` adds ``heat_transfer_wall_offset_K`` dT_w: the wall at ``T_s +
dT_w`` (a valve body or a room warmer or colder than the supply's air), the gas starting
there at rest; the pressure equation reads ``T_s + c dT_w`` for the wall, so c = 0 is eq.
5 and dT_w = 0 the form without it. Discovery fits it after the convective and forced
forms, from their fit.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, RelaxationTerm
from pneubayes.physics.cylinder import wall_area_m2
from pneubayes.rig import Rig

_FORMS = ("rate", "convective", "forced")
#: The wall offset's bounds, K (either side of the supply's temperature).
WALL_OFFSET_K = 50.0


class HeatTransfer(Effect):
    """Chamber temperature as a state, exchanging heat with the wall."""

    name = "heat_transfer"
    #: The forms (``form`` option) this effect has; the first is the default.
    forms = _FORMS
    cheap_forms = True
    acts_on = ("heat_rate_per_s", "heat_coefficient_W_per_m2_K", "heat_coupling",
               "heat_jet_coefficient_W_per_m2_K", "heat_wall_offset_K")
    #: the chamber temperature: a state no recording measures
    needs_warmup = True

    option_variants = ({"form": "convective", "wall_offset": True},)

    def __init__(self, form: str = "rate", wall_offset: bool = False):
        self.form = form
        self.wall_offset = bool(wall_offset)

    def options(self):
        return {"form": self.form, **({"wall_offset": True} if self.wall_offset else {})}

    @classmethod
    def card_defaults(cls, params):
        """A card from before the coupling meant the energy equation at any exchange > 0
        and eq. 5 at 0."""
        strength = params.get("heat_transfer_rate_per_s",
                              params.get("heat_transfer_coefficient_W_per_m2_K"))
        if "heat_transfer_coupling" in params or not isinstance(strength, (int, float)):
            return {}
        return {"heat_transfer_coupling": 1.0 if strength > 0 else 0.0}

    def parameters(self):
        self._check()
        coupling = Parameter("heat_transfer_coupling", "1", 0.0, 1.0, "uniform",
                             "share of the chamber temperature's departure from the wall's "
                             "that the pressure feels (0: eq. 5, 1: the energy equation)",
                             neutral=0.0, limit="upper")
        wall = (Parameter("heat_transfer_wall_offset_K", "K", -WALL_OFFSET_K, WALL_OFFSET_K,
                          "uniform", "the wall's temperature above the supply's",
                          neutral=0.0),) if self.wall_offset else ()
        if self.form == "rate":
            return (Parameter("heat_transfer_rate_per_s", "1/s", 0.0, 100.0, "uniform",
                              "wall heat-exchange rate, 1 / wall time constant", neutral=0.0),
                    coupling) + wall
        h = Parameter("heat_transfer_coefficient_W_per_m2_K", "W/(m^2 K)", 0.0, 1000.0,
                      "uniform", "convective heat-transfer coefficient to the wall",
                      neutral=0.0)
        if self.form == "convective":
            return (h, coupling) + wall
        return (h, Parameter("heat_transfer_jet_W_per_m2_K", "W/(m^2 K)", 0.0, 1000.0,
                             "uniform", "the coefficient's growth at an inflow of 1 g/s "
                             "(forced convection by the fill's jet)", neutral=0.0),
                coupling) + wall

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        out = {"heat_coupling": np.asarray(values["heat_transfer_coupling"], np.float64)}
        if self.wall_offset:
            out["heat_wall_offset_K"] = np.asarray(values["heat_transfer_wall_offset_K"],
                                                   np.float64)
        if self.form == "rate":
            out["heat_rate_per_s"] = np.asarray(values["heat_transfer_rate_per_s"],
                                                np.float64)
            return out
        out["heat_coefficient_W_per_m2_K"] = np.asarray(
            values["heat_transfer_coefficient_W_per_m2_K"], dtype=np.float64)
        if self.form == "forced":
            out["heat_jet_coefficient_W_per_m2_K"] = np.asarray(
                values["heat_transfer_jet_W_per_m2_K"], dtype=np.float64)
        return out

    # ------------------------------------------------------------------ discovery
    library_strengths = (1.0, 3.0, 10.0, 30.0, 100.0)
    discovery_fallback = {"heat_transfer_rate_per_s": 5.0, "heat_transfer_coupling": 1.0}

    def library_terms(self, strengths):
        """A one-step prediction starts at the wall temperature, so it cannot show heat
        transfer: after a fill or a vent the air relaxes to the wall temperature and, to
        first order, the pressure error is a high-passed pressure at each trial rate
        (1/s)."""
        return tuple(RelaxationTerm(f"heat {r:g}/s", {"heat_transfer_rate_per_s": r,
                                                     "heat_transfer_coupling": 1.0},
                                    rate_per_s=r) for r in strengths)

    def candidate_forms(self, ctx: CandidateContext):
        """Every form, the rate at the best term's and the convective coefficient giving
        that rate, ``(kappa - 1) h (A_w / V) T / p = rate``, at mid-stroke and mid-range
        pressure, so neither starts handicapped; the forced form at that coefficient
        and a jet that doubles it at 1 g/s. None where the model has no room for
        the temperature state (a rig card's compliant chamber, tank or second
        compartment, or a transmission-line tube); beside an acoustic line the
        temperature joins the line's state."""
        if not ctx.second_state_free or ctx.slot("wave_length_m") > 0:
            return []
        rate_form = HeatTransfer(**{**self.options(), "form": "rate"})
        # (a start may name only some of them: the other form's fitted coupling)
        start = {**self.discovery_fallback, **self.candidate_start(ctx.term_start)}
        rate = ctx.inside(rate_form, "heat_transfer_rate_per_s",
                          start["heat_transfer_rate_per_s"])
        coupling = ctx.inside(rate_form, "heat_transfer_coupling",
                              start["heat_transfer_coupling"])
        rig = ctx.rig
        vol = ctx.dead_volume_m3 + rig.bore_area_m2 * 0.5 * (rig.stroke_m or 0.0)
        wall = float(wall_area_m2(vol, rig.bore_area_m2))
        p_mid = 0.5 * (rig.supply_pressure_Pa + rig.atmospheric_pressure_Pa)
        gas = rig.gas
        h = rate * p_mid * vol / ((gas.heat_capacity_ratio - 1.0) * gas.temperature_K * wall)
        conv = HeatTransfer(**{**self.options(), "form": "convective"})
        forced = HeatTransfer(**{**self.options(), "form": "forced"})
        h = ctx.inside(conv, "heat_transfer_coefficient_W_per_m2_K", h)
        return [(rate_form, {"heat_transfer_rate_per_s": rate,
                             "heat_transfer_coupling": coupling}),
                (conv, {"heat_transfer_coefficient_W_per_m2_K": h,
                        "heat_transfer_coupling": coupling}),
                (forced, {"heat_transfer_coefficient_W_per_m2_K": h,
                          "heat_transfer_jet_W_per_m2_K": ctx.inside(
                              forced, "heat_transfer_jet_W_per_m2_K", h),
                          "heat_transfer_coupling": coupling})]

    def form_after_fit(self, params, ctx):
        """The convective or forced form with the wall's offset, from its fit (the offset
        at 0: the fitted form itself)."""
        if self.wall_offset or self.form == "rate":
            return None
        return (HeatTransfer(form=self.form, wall_offset=True),
                {"heat_transfer_wall_offset_K": 0.0})

    def bench_defaults(self):
        # (with the offset: a wall 15 K above the supply, a valve body or a warm room;
        # the bench's plant steps the rate form's, its WallHeatTransfer the others')
        wall = {"heat_transfer_wall_offset_K": 15.0} if self.wall_offset else {}
        if self.form == "rate":
            # a wall time constant of 0.2 s, typical of small cylinders
            return {"heat_transfer_rate_per_s": 5.0, "heat_transfer_coupling": 1.0, **wall}
        if self.form == "forced":  # still air, and a fill's jet of 1 g/s: 4 x
            return {"heat_transfer_coefficient_W_per_m2_K": 20.0,
                    "heat_transfer_jet_W_per_m2_K": 60.0, "heat_transfer_coupling": 1.0,
                    **wall}
        # natural to weakly forced convection in a small cylinder
        return {"heat_transfer_coefficient_W_per_m2_K": 30.0, "heat_transfer_coupling": 1.0,
                **wall}
