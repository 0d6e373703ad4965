"""Candidate models for a named group: the catalogue effect, its form(s) and start values.

A named group becomes the current model plus that group's catalogue effect, started at
the strength of the group's best library term. A leak is fitted in the graded laminar
form (an orifice leak is the exhaust port's own law, never missing); a heat exchange in
both its forms, one rate and a convective coefficient started at the same relaxation; a
tube in both its forms, the paper's transport delay and an acoustic line (2-mm bore to
start, the delay from the best term; outside tubes are lines, which lag and ring).
"""

from __future__ import annotations

import re

import numpy as np

from pneubayes.discovery.verification import StepFit
from pneubayes.effects import make_effect
from pneubayes.physics.cylinder import wall_area_m2
from pneubayes.rig import Rig


def _inside(model, name: str, value: float) -> float:
    """``value`` moved just inside the parameter's bounds (a refiner's start)."""
    p = model.parameter(name)
    margin = 1e-6 * (p.upper - p.lower)
    return float(np.clip(value, p.lower + margin, p.upper - margin))


def effect_candidates(fit: StepFit, group: str, evidence: dict, rig: Rig,
                      line_segments: int = 3):
    """``[(model, start), ...]``: the group's effect form(s) with start values from
    the group's best term."""
    compliant = _compliant(fit, rig)  # no temperature or line state beside it
    if group == "tube_delay":
        return _tube_candidates(fit, evidence, rig, 0 if compliant else line_segments)
    if group != "heat_transfer":
        return [effect_candidate(fit, group, evidence)]
    if _has_line(fit.model) or compliant:  # the acoustic line is isothermal
        return []
    rate_model, rate_start = effect_candidate(fit, group, evidence)
    rate = rate_start["heat_transfer_rate_per_s"]
    # the coefficient giving that rate, (kappa - 1) h (A_w / V) T / p = rate, at
    # mid-stroke and mid-range pressure
    gas = rig.gas
    vol = _dead_volume(fit.model, fit.params, rig) + rig.bore_area_m2 * 0.5 * (
        rig.stroke_m or 0.0)
    wall = float(wall_area_m2(vol, rig.bore_area_m2))
    p_mid = 0.5 * (rig.supply_pressure_Pa + rig.atmospheric_pressure_Pa)
    h = rate * p_mid * vol / ((gas.heat_capacity_ratio - 1.0) * gas.temperature_K * wall)
    conv_model, conv_start = effect_candidate(fit, group, evidence, form="convective")
    name = "heat_transfer_coefficient_W_per_m2_K"
    conv_start[name] = _inside(conv_model, name, h)
    return [(rate_model, rate_start), (conv_model, conv_start)]


def effect_candidate(fit: StepFit, group: str, evidence: dict, **options):
    """The effect object and its start values from the group's best term."""
    term = evidence.get("best_term") or ""
    num = [float(t) for t in re.findall(r"[-+]?\d*\.?\d+(?:[eE][-+]?\d+)?", term)]
    start = dict(fit.params)
    if group == "cylinder_leak":
        # the laminar law, graded along the stroke (a clearance whose seal engagement
        # varies; gradient 0 is the uniform gap): an orifice leak is never missing
        effect = make_effect("cylinder_leak", form="graded")
    else:  # the rig card's options (the tube's bore), then the form asked for
        effect = make_effect(group, **{**fit.model.effect_options(group), **options})
    model = fit.model.with_effect(effect)
    start.update(effect.neutral_values())
    pname = effect.parameter_names()[0]
    value = {"tube_delay": 1e-3 * num[0] if num else 0.003,
             "spool_lag": 1e-3 * num[0] if num else 0.003,
             "valve_deadzone": num[0] if num else 0.2,
             "supply_fluctuation": 1.0,
             "heat_transfer": num[0] if num else 5.0}.get(group)
    if group == "cylinder_leak":
        value = 0.3 * effect.bench_defaults()[pname]
    if value is not None:
        start[pname] = _inside(model, pname, value)
    return model, start


def first_free(model, group: str):
    """Parameters to refine on their own before all of them, or None.

    An acoustic line's step costs tens of times a plain one, and a refinement's
    Jacobian costs one simulation per free parameter: the line's two parameters and the
    dead volume it shares are fitted first (four simulations per Jacobian instead of a
    dozen), then everything from there.
    """
    if group == "tube_delay" and _has_line(model):
        return tuple(n for n in ("tube_delay_s", "tube_diameter_m", "dead_volume_m3")
                     if n in model.parameter_names)
    return None


def _compliant(fit: StepFit, rig: Rig) -> bool:
    """Whether the fitted model's chamber is compliant or has a second compartment, or
    its supply is a tank (a rig card's), which the simulator integrates without a
    temperature or line state: no heat transfer and no acoustic line beside them."""
    from pneubayes.effects.path import SLOT_INDEX

    slots = fit.model.lower(fit.model.vector(fit.params)[None, :], rig)
    return bool(slots[0, SLOT_INDEX["compliance_m3_per_Pa"]] > 0
                or slots[0, SLOT_INDEX["tank_volume_m3"]] > 0
                or slots[0, SLOT_INDEX["lung_volume_m3"]] > 0
                or slots[0, SLOT_INDEX["volume_table_points"]] > 0)


def _dead_volume(model, params: dict, rig: Rig) -> float:
    """The chamber's volume at position 0 (m^3), fitted or known to a rig card."""
    from pneubayes.effects.path import SLOT_INDEX

    slots = model.lower(model.vector(params)[None, :], rig)
    return float(slots[0, SLOT_INDEX["volume_m3"]])


def _has_line(model) -> bool:
    return model.has("tube_delay") and model.effect("tube_delay").form == "line"


def _tube_candidates(fit: StepFit, evidence: dict, rig: Rig, segments: int):
    """The tube as a transport delay (the paper's) and as an acoustic line of
    ``segments`` cells (none if 0; no line beside a heat model: it is isothermal)."""
    out = [effect_candidate(fit, "tube_delay", evidence)]
    if fit.model.has("heat_transfer") or segments == 0:
        return out
    model, start = effect_candidate(fit, "tube_delay", evidence, form="line", segments=segments)
    tube = model.effect("tube_delay")
    # the line's volume comes out of the fitted dead volume: keep it to half of that
    vol = float(tube.tube_volume_m3(start, rig))
    dead = _dead_volume(fit.model, fit.params, rig)
    if vol > 0.5 * dead:
        start["tube_delay_s"] = _inside(model, "tube_delay_s",
                                        start["tube_delay_s"] * 0.5 * dead / vol)
    out.append((model, start))
    return out
