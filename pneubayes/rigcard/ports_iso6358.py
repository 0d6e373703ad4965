"""Ports kind ``iso6358``: the valve's flow paths as its datasheet rates them.

ISO 6358-1 rates each flow path of a pneumatic valve by a sonic conductance ``C`` and a
critical pressure ratio ``b`` (0.2-0.45 on most valves, against eq. 3's 0.528), and its
subsonic index ``m`` (1/2 on most). The valve kind's areas are the ports' choked areas
(:func:`choked_area_m2`: about 6.9e-6 m^2 per dm^3/(s bar) with eq. 3's discharge
coefficient 0.72); this table gives their laws: a port chokes down to its own ``b`` and
follows eq. 3's subsonic curve laid over ``[b, 1]``, its subsonic share raised to ``2
m`` (:mod:`pneubayes.effects.critical_ratio`, the same law as a fitted effect).

Card keys, each known or a prior (a datasheet's value, or a prior about it that the fit
narrows):

- ``inlet_critical_ratio`` (-, in (0, 1)): the supply-to-chamber path's ``b``
  (1 -> 2 on the datasheet);
- ``exhaust_critical_ratio`` (-, in (0, 1)): the chamber-to-exhaust path's ``b``
  (2 -> 3), of the valve's exhaust port or a separate ``[exhaust]`` valve;
- ``subsonic_index`` (-, in [0.2, 1]; default 1/2): ``m``, one for both paths.

A ratio left out keeps eq. 3 on that path; at least one is required. Fitted, they are
the parameters ``valve_inlet_critical_ratio``, ``valve_exhaust_critical_ratio`` and
``valve_subsonic_index``. With this table the loop does not propose the
``critical_ratio`` effect, and a model refuses it: both would write the same slots.
"""

from __future__ import annotations

from pneubayes.effects.critical_ratio import INDEX_BOUNDS
from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import Unknown

_RATIOS = ("inlet_critical_ratio", "exhaust_critical_ratio")
#: ISO 6358-1's reference (ANR) density of air, kg/m^3, at its reference temperature, K.
ISO_REFERENCE_DENSITY_KG_PER_M3 = 1.185
ISO_REFERENCE_TEMPERATURE_K = 293.15


def choked_area_m2(sonic_conductance_dm3_per_s_bar, gas=None) -> float:
    """The effective area whose choked flow by eq. 3 is the datasheet's, m^2.

    ISO 6358's choked mass flow is ``C rho_0 p_u sqrt(T_0 / T_u)``, eq. 3's ``A beta(T_u)
    p_u`` with ``beta`` proportional to ``1 / sqrt(T_u)``: ``A = C rho_0 / beta(T_0)``,
    the same at every upstream temperature. ``gas``: the
    :class:`~pneubayes.physics.gas.GasConstants` whose constants set ``beta`` (default
    the paper's, with its discharge coefficient 0.72: A is the area the valve kinds
    take, the effective area over 0.72)."""
    from dataclasses import replace

    from pneubayes.physics.gas import GasConstants

    c = float(sonic_conductance_dm3_per_s_bar)
    if not (c > 0.0 and c < float("inf")):
        raise ValueError(f"sonic_conductance_dm3_per_s_bar must be a positive number, got "
                         f"{sonic_conductance_dm3_per_s_bar!r}")
    at_t0 = replace(gas or GasConstants(), temperature_K=ISO_REFERENCE_TEMPERATURE_K)
    return c * 1e-8 * ISO_REFERENCE_DENSITY_KG_PER_M3 / at_t0.beta_s_per_m


@register
class Iso6358Ports(RigComponent):
    role, kind = "ports", "iso6358"
    quantities = (
        ("inlet_critical_ratio", "-", "the inlet path's critical pressure ratio (ISO "
         "6358's b)", "positive"),
        ("exhaust_critical_ratio", "-", "the exhaust path's critical pressure ratio (ISO "
         "6358's b)", "positive"),
        ("subsonic_index", "-", "the ports' subsonic index (ISO 6358's m)", "positive"),
    )
    parameter_names_by_key = {q[0]: f"valve_{q[0]}" for q in quantities}
    #: a ratio the card leaves out is None: that path keeps eq. 3
    defaults = {"inlet_critical_ratio": None, "exhaust_critical_ratio": None,
                "subsonic_index": 0.5}
    slots_written = (*_RATIOS, "port_subsonic_index")
    #: the catalogue effect whose slots this component writes (a model refuses both)
    covers_effects = ("critical_ratio",)

    def check(self, where):
        if all(self.values[k] is None for k in _RATIOS):
            raise RigCardError(f"{where}: give 'inlet_critical_ratio', "
                               "'exhaust_critical_ratio' or both (a path left out keeps "
                               "eq. 3's 0.528)")
        limits = {k: (0.0, 1.0) for k in _RATIOS}
        limits["subsonic_index"] = INDEX_BOUNDS
        for key, (lo, hi) in limits.items():
            v = self.values[key]
            span = ((v.lower, v.upper) if isinstance(v, Unknown) else
                    (v, v) if v is not None else None)
            if span is None:
                continue
            inside = (lo < span[0] and span[1] < hi if key in _RATIOS
                      else lo <= span[0] and span[1] <= hi)
            if not inside:
                what = "bounds" if isinstance(v, Unknown) else "value"
                rng = f"({lo}, {hi})" if key in _RATIOS else f"[{lo}, {hi}]"
                raise RigCardError(f"{where} key {key!r}: its {what} must lie in {rng}, "
                                   f"got {list(span) if isinstance(v, Unknown) else v!r}")

    def check_beside(self, parts, where):
        supply = parts["supply"].kind
        if supply in ("tank", "restricted"):
            raise RigCardError(f"{where}: a port's own critical ratio is stepped where the "
                               "valve meets the chamber; the simulator cannot combine it "
                               f"with a supply of kind {supply!r}")

    def to_table(self):
        out = super().to_table()
        return {k: v for k, v in out.items() if v is not None}

    def lower_all(self, values, rig):
        # 0 in a ratio's slot is eq. 3's law; the index is read only beside a ratio
        out = {k: (0.0 if self.values[k] is None else values[k]) for k in _RATIOS}
        out["port_subsonic_index"] = values["subsonic_index"]
        return out
