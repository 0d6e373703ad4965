"""Heat transfer's ``forced`` form: a convective coefficient that grows with the fill's
inflow. Nested in the convective form, its slopes against differences, the compiled
simulator against the scipy reference, refusals."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_chamber_slopes, filling_rhs, heat_beside_line, reference_errors
from conftest import tight_solver as _tight

from pneubayes.effects import make_effect
from pneubayes.effects.path import JET_FLOW_REF_KG_PER_S, SLOT_INDEX
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, simulate
from pneubayes.simulation.chamber import wall_exchange
from pneubayes.simulation.simulator import rig_constants

P_SUP = 551325.0




@pytest.fixture
def steps():
    """Fills, holds and vents with a piston at 3 Hz: 0.2 s."""
    t = np.arange(201) * 1e-3
    u = np.select([t < 0.05, t < 0.09, t < 0.14, t < 0.17], [3.0, 0.0, -3.0, 1.0], -0.4)
    return Inputs(t, u, 0.05 + 0.01 * np.sin(2 * np.pi * 3 * t), np.full(t.size, P_SUP))


def _params(valve_params, jet, h=20.0):
    return dict(valve_params, heat_transfer_coefficient_W_per_m2_K=h,
                heat_transfer_jet_W_per_m2_K=jet, heat_transfer_coupling=1.0)


def test_no_jet_is_the_convective_form_to_the_bit(rig, valve_params, steps):
    forced = Model([make_effect("heat_transfer", form="forced")])
    conv = Model([make_effect("heat_transfer", form="convective")])
    a = simulate(forced, _params(valve_params, 0.0), steps, rig, 2e5, _tight()).pressure_Pa
    p = _params(valve_params, 0.0)
    p.pop("heat_transfer_jet_W_per_m2_K")
    b = simulate(conv, p, steps, rig, 2e5, _tight()).pressure_Pa
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("closure", [False, True])
def test_the_rate_its_jacobian_and_time_derivatives(rig, closure):
    """During a fill (and beside an inert closure term, whose body is a copy): the wall
    term is (kappa - 1) (h_0 + h_j m_in / 1 g/s) A_w (T_w - T) / V, and J_pp, v_p,
    J_pT, J_Tp, J_TT and v_T match central differences with the areas and the supply
    moving."""
    cs = rig_constants(rig)
    sl = np.zeros(max(SLOT_INDEX.values()) + 1)
    sl[SLOT_INDEX["volume_m3"]] = 2.4e-6
    sl[SLOT_INDEX["heat_coefficient_W_per_m2_K"]] = 20.0
    sl[SLOT_INDEX["heat_jet_coefficient_W_per_m2_K"]] = 300.0
    sl[SLOT_INDEX["heat_coupling"]] = 0.8
    if closure:  # (a constant of zero flow: the closure's body, the same rate)
        sl[SLOT_INDEX["closure_terms"]] = 1.0
        sl[SLOT_INDEX["closure_coefficient_0"]] = 0.0
    p, temp, a_in = 2.6e5, 340.0, 5e-7
    rhs = filling_rhs(sl, cs, P_SUP, a_in)
    out = rhs(p, temp)
    plain = sl.copy()
    plain[SLOT_INDEX["heat_jet_coefficient_W_per_m2_K"]] = 0.0
    base = filling_rhs(plain, cs, P_SUP, a_in)(p, temp)
    from pneubayes.physics.orifice import flow_function
    m_in = a_in * flow_function(P_SUP, p, rig.gas)
    t_w = rig.gas.temperature_K
    te = t_w + 0.8 * (temp - t_w)
    extra = wall_exchange(rig.gas.heat_capacity_ratio, 300.0 * m_in / JET_FLOW_REF_KG_PER_S,
                          rig.bore_area_m2, 2.4e-6)[0] * (t_w - te)
    assert out[0] - base[0] == pytest.approx(extra, rel=1e-9)
    assert abs(extra) > 0.02 * abs(base[0])  # (the jet matters here: 4.7 %)
    assert_chamber_slopes(rhs, p, temp)


def test_the_simulator_agrees_with_the_reference(rig, valve_params, steps):
    """Compiled vs scipy Radau (rtol 1e-10) where the jet moves the pressure by kPa; the
    error falls with the tolerance."""
    model = Model([make_effect("heat_transfer", form="forced")])
    params = _params(valve_params, 150.0)
    ref, errs = reference_errors(model, params, steps, rig, 2e5)
    still = simulate(model, _params(valve_params, 0.0), steps, rig, 2e5,
                     _tight()).pressure_Pa[0]
    assert np.max(np.abs(ref - still)) > 2e3
    assert errs[1] < 0.5 and errs[1] < 0.2 * errs[0], errs


def test_beside_the_acoustic_line_it_agrees_with_the_reference(rig, valve_params, steps):
    """Behind a 3-cell acoustic line the jet is the line's inflow into the chamber (a
    state of the line): compiled vs Radau over the fill, the hold and the vent's start,
    where the jet moves the pressure by kPa."""
    moved, err = heat_beside_line(make_effect("heat_transfer", form="forced"),
                                  _params(valve_params, 150.0), steps, rig,
                                  {"heat_transfer_jet_W_per_m2_K": 0.0})
    assert moved > 1e3
    assert err < 1.0


def test_the_forced_form_is_a_later_form_of_heat_transfer(rig):
    """It is offered beside the rate and convective forms, started at the convective
    coefficient and a jet that doubles it at 1 g/s."""
    from pneubayes.effects.discovery import CandidateContext

    heat = make_effect("heat_transfer")
    model = Model([])
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    ctx = CandidateContext(model=model, params=params, rig=rig, term_start=None,
                           second_state_free=True, line_segments=0, dead_volume_m3=2.4e-6)
    forms = heat.candidate_forms(ctx)
    assert [e.form for e, _ in forms] == ["rate", "convective", "forced"]
    conv, forced = forms[1][1], forms[2][1]
    assert forced["heat_transfer_coefficient_W_per_m2_K"] == \
        conv["heat_transfer_coefficient_W_per_m2_K"]
    assert forced["heat_transfer_jet_W_per_m2_K"] == pytest.approx(
        conv["heat_transfer_coefficient_W_per_m2_K"], rel=1e-6)
