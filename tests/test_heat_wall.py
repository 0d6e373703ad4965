"""Heat exchange with a wall warmer or colder than the supply (``wall_offset``): a closed
chamber's closed form, nesting (offset 0, coupling 0), slopes against differences, the
compiled simulator against the scipy reference, the discovery form chain and a planted
offset recovered."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import (
    assert_chamber_slopes,
    filling_rhs,
    heat_beside_line,
    reference_errors,
    refit_planted,
)
from conftest import tight_solver as _tight

from pneubayes.effects import make_effect
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, simulate
from pneubayes.simulation.simulator import rig_constants

P_SUP = 551325.0


def _heat(form="convective", offset=True):
    return make_effect("heat_transfer", form=form, wall_offset=offset)


@pytest.fixture
def steps():
    """Fills, holds and vents with a piston at 3 Hz: 0.2 s."""
    t = np.arange(201) * 1e-3
    u = np.select([t < 0.05, t < 0.09, t < 0.14, t < 0.17], [3.0, 0.0, -3.0, 1.0], -0.4)
    return Inputs(t, u, 0.05 + 0.01 * np.sin(2 * np.pi * 3 * t), np.full(t.size, P_SUP))


def _params(valve_params, offset, h=40.0, coupling=1.0):
    return dict(valve_params, heat_transfer_coefficient_W_per_m2_K=h,
                heat_transfer_coupling=coupling, heat_transfer_wall_offset_K=offset)


@pytest.mark.parametrize("form, strength", [
    ("convective", {"heat_transfer_coefficient_W_per_m2_K": 60.0}),
    ("rate", {"heat_transfer_rate_per_s": 20.0})])
def test_a_filled_and_shut_chamber_settles_at_its_walls_temperature(rig, form, strength):
    """A shut chamber at rest keeps its pressure whatever its wall's temperature (the
    gas starts at the wall's). Filled for 2 ms through a choked inlet (the same mass
    whatever the chamber's temperature) and shut, it settles where its gas is at the
    wall's: the rise over ``p0`` is ``(T_s + dT_w) / T_s`` times the rise with the wall
    at the supply's temperature."""
    from test_plant import CLOSABLE  # (ports whose areas vanish at command 0)

    t = np.arange(3001) * 1e-3
    model = Model([_heat(form)])
    params = {**CLOSABLE, "dead_volume_m3": 2.4e-6, **strength, "heat_transfer_coupling": 1.0}

    def run(u, offset):
        inputs = Inputs(t, u, np.full(t.size, 0.02), np.full(t.size, P_SUP), 0.0)
        return simulate(model, dict(params, heat_transfer_wall_offset_K=offset), inputs,
                        rig, 1.2e5, _tight(1e-10)).pressure_Pa[0]

    assert np.max(np.abs(run(np.zeros(t.size), 20.0) - 1.2e5)) < 1e-3
    fill = np.where(t < 0.0015, 5.0, 0.0)
    warm, plain = run(fill, 20.0), run(fill, 0.0)
    assert warm[2] < 0.5 * P_SUP  # (choked throughout the fill)
    t_s = rig.gas.temperature_K
    assert (warm[-1] - 1.2e5) / (plain[-1] - 1.2e5) == pytest.approx((t_s + 20.0) / t_s,
                                                                      rel=1e-5)
    assert plain[-1] - 1.2e5 > 2e4


def test_offset_zero_is_the_form_without_it_and_coupling_zero_is_eq_5(rig, valve_params,
                                                                       steps):
    without = Model([_heat(offset=False)])
    p = _params(valve_params, 0.0)
    a = simulate(Model([_heat()]), p, steps, rig, 2e5, _tight()).pressure_Pa
    p.pop("heat_transfer_wall_offset_K")
    b = simulate(without, p, steps, rig, 2e5, _tight()).pressure_Pa
    np.testing.assert_array_equal(a, b)
    eq5 = simulate(Model([]), valve_params, steps, rig, 2e5, _tight()).pressure_Pa
    cold = simulate(Model([_heat()]), _params(valve_params, 30.0, coupling=0.0), steps, rig,
                    2e5, _tight()).pressure_Pa
    np.testing.assert_array_equal(cold, eq5)


@pytest.mark.parametrize("form", ["convective", "forced", "rate"])
def test_the_slopes_match_differences_with_a_warm_wall(rig, form):
    """During a fill, J_pp, v_p, J_pT, J_Tp, J_TT and v_T against central differences,
    with the wall 25 K above the supply and the coupling at 0.7."""
    cs = rig_constants(rig)
    sl = np.zeros(max(SLOT_INDEX.values()) + 1)
    sl[SLOT_INDEX["volume_m3"]] = 2.4e-6
    if form == "rate":
        sl[SLOT_INDEX["heat_rate_per_s"]] = 15.0
    else:
        sl[SLOT_INDEX["heat_coefficient_W_per_m2_K"]] = 40.0
    if form == "forced":
        sl[SLOT_INDEX["heat_jet_coefficient_W_per_m2_K"]] = 200.0
    sl[SLOT_INDEX["heat_coupling"]] = 0.7
    sl[SLOT_INDEX["heat_wall_offset_K"]] = 25.0
    p, temp = 2.6e5, 330.0
    rhs = filling_rhs(sl, cs, P_SUP)
    cool = sl.copy()
    cool[SLOT_INDEX["heat_wall_offset_K"]] = 0.0
    assert rhs(p, temp)[0] - filling_rhs(cool, cs, P_SUP)(p, temp)[0] > 0.0  # (warmed)
    assert_chamber_slopes(rhs, p, temp)


@pytest.mark.parametrize("form", ["convective", "rate"])
def test_the_simulator_agrees_with_the_reference(rig, valve_params, steps, form):
    """Compiled vs scipy Radau (rtol 1e-10) with the wall 20 K above the supply, where
    the offset moves the pressure by kPa; the error falls with the tolerance."""
    model = Model([_heat(form)])
    params = _params(valve_params, 20.0)
    if form == "rate":
        params["heat_transfer_rate_per_s"] = params.pop("heat_transfer_coefficient_W_per_m2_K")
    ref, errs = reference_errors(model, params, steps, rig, 2e5)
    cool = simulate(model, dict(params, heat_transfer_wall_offset_K=0.0), steps, rig, 2e5,
                    _tight()).pressure_Pa[0]
    assert np.max(np.abs(ref - cool)) > 1e3
    assert errs[1] < 0.5 and errs[1] < 0.2 * errs[0], errs


def test_beside_the_acoustic_line_it_agrees_with_the_reference(rig, valve_params, steps):
    """Behind a 3-cell acoustic line (the temperature a state of the line): compiled vs
    Radau over the fill, the hold and the vent's start."""
    moved, err = heat_beside_line(_heat(), _params(valve_params, 20.0), steps, rig,
                                  {"heat_transfer_wall_offset_K": 0.0})
    assert moved > 500.0
    assert err < 1.0


def test_discovery_fits_the_offset_after_the_convective_and_forced_forms(rig):
    from pneubayes.effects.discovery import CandidateContext

    model = Model([])
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    ctx = CandidateContext(model=model, params=params, rig=rig, term_start=None,
                           second_state_free=True, line_segments=0, dead_volume_m3=2.4e-6)
    forms = make_effect("heat_transfer").candidate_forms(ctx)
    assert [e.options() for e, _ in forms] == [
        {"form": f} for f in ("rate", "convective", "forced")]
    nxt = [e.form_after_fit({}, ctx) for e, _ in forms]
    assert nxt[0] is None
    for (effect, start), form in zip(nxt[1:], ("convective", "forced")):
        assert effect.options() == {"form": form, "wall_offset": True}
        assert start == {"heat_transfer_wall_offset_K": 0.0}
        assert effect.form_after_fit({}, ctx) is None
    card = Model([nxt[1][0]]).to_card({**params, "heat_transfer_coefficient_W_per_m2_K": 9.0,
                                       "heat_transfer_coupling": 1.0,
                                       "heat_transfer_wall_offset_K": 12.0})
    back, values = Model.from_card(card)
    assert back.effect("heat_transfer").options() == {"form": "convective",
                                                      "wall_offset": True}
    assert values["heat_transfer_wall_offset_K"] == 12.0


def test_a_planted_offset_is_recovered(valve_params):
    """Noise-free fills and vents of valve 1 beside a convective wall 15 K above the
    supply: the offset alone refitted from 0 within 2 %."""
    model = Model([_heat()])
    truth = _params(valve_params, 15.0, h=60.0)
    got = refit_planted(model, truth, "heat_transfer_wall_offset_K", 0.0, seed=3)
    assert got == pytest.approx(15.0, rel=2e-2)
