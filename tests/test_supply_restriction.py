"""A restriction upstream of the valve's inlet (effect ``supply_restriction``): the node's
mass balance, the compiled simulator against the scipy reference, limits and slopes."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import reference_errors, refit_planted
from conftest import tight_solver as _tight

from pneubayes.effects import SupplyRestriction, TubeDelay
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.model import Model
from pneubayes.physics.orifice import flow_function, flow_partials
from pneubayes.simulation import Inputs, simulate
from pneubayes.simulation.chamber import chamber_rhs
from pneubayes.simulation.reference import reference_simulate
from pneubayes.simulation.simulator import rig_constants
from pneubayes.simulation.supply_restriction import supply_node, supply_slopes

P_ATM, P_SUP = 101325.0, 551325.0


@pytest.fixture
def steps(sagging_steps):
    """(conftest's sagging_steps)"""
    return sagging_steps


def _slots(k, **extra):
    sl = np.zeros(max(SLOT_INDEX.values()) + 1)
    sl[SLOT_INDEX["volume_m3"]] = 2.4e-6
    sl[SLOT_INDEX["supply_restriction_inverse_area_per_m2"]] = k
    for name, v in extra.items():
        sl[SLOT_INDEX[name]] = v
    return sl


@pytest.mark.parametrize("x, a_in, k", [(2e5, 1.2e-6, 1e6), (5.3e5, 1.2e-6, 1e6),
                                        (1.2e5, 3e-7, 1e7), (1.5e5, 5e-6, 2e5),
                                        (6.2e5, 1e-6, 1e6)],
                         ids=["fill", "near_supply", "narrow_inlet", "narrow_supply",
                              "blow_back"])
def test_the_node_balances_the_restriction_against_the_inlet(rig, x, a_in, k):
    """``A_s f(p_s, n) = a_in f(n, x)`` at the node (both orifices choked or not; the
    inlet blowing back into the supply above it), between ``x`` and the supply, and
    the split two incompressible orifices would make where both are subsonic."""
    cs = rig_constants(rig)
    n = supply_node(P_SUP, x, a_in, k, cs)
    assert min(x, P_SUP) <= n <= max(x, P_SUP)
    lhs = flow_function(P_SUP, n, rig.gas) / k
    rhs = a_in * flow_function(n, x, rig.gas)
    assert lhs == pytest.approx(rhs, rel=1e-9)
    assert abs(lhs) > 0.0


def test_no_restriction_or_a_shut_inlet_sees_the_supply(rig):
    cs = rig_constants(rig)
    assert supply_node(P_SUP, 2e5, 1e-6, 0.0, cs) == P_SUP
    assert supply_node(P_SUP, 2e5, 0.0, 1e6, cs) == P_SUP
    assert supply_node(P_SUP, P_SUP, 1e-6, 1e6, cs) == P_SUP


@pytest.mark.parametrize("x, a_in, k", [(2e5, 1.2e-6, 1e6), (4.9e5, 1.2e-6, 1e6),
                                        (6.2e5, 1e-6, 1e6), (1.5e5, 5e-6, 2e5)])
def test_the_slopes_are_the_node_flows_derivatives(rig, x, a_in, k):
    """:func:`supply_slopes` against central differences of the inlet's flow with the
    node solved again: in the ports' pressure, in the supply's and in the inlet area."""
    cs = rig_constants(rig)

    def flow(p_sup, x, a):
        return flow_function(supply_node(p_sup, x, a, k, cs), x, rig.gas)

    n = supply_node(P_SUP, x, a_in, k, cs)
    f, d_n, d_x = flow_partials(n, x, rig.gas.alpha_s_per_m, rig.gas.beta_s_per_m,
                                rig.gas.theta, rig.gas.heat_capacity_ratio, 0.0)
    d_s, d_xx, share = supply_slopes(P_SUP, n, x, a_in, k, d_n, d_x, cs, 0.0)
    h = 1.0
    assert d_xx == pytest.approx((flow(P_SUP, x + h, a_in) - flow(P_SUP, x - h, a_in))
                                 / (2 * h), rel=1e-5)
    assert d_s == pytest.approx((flow(P_SUP + h, x, a_in) - flow(P_SUP - h, x, a_in))
                                / (2 * h), rel=1e-5)
    da = 1e-4 * a_in
    dq = ((a_in + da) * flow(P_SUP, x, a_in + da) - (a_in - da) * flow(P_SUP, x, a_in - da)) \
        / (2 * da)
    assert share * f == pytest.approx(dq, rel=1e-5)
    assert 0.0 < share < 1.0


@pytest.mark.parametrize("hot", [False, True])
def test_the_chamber_rate_and_its_jacobian_with_a_restriction(rig, hot):
    """chamber_rhs' dp/dt is the inlet's flow at the node in eq. 5 (the exhaust at the
    chamber), and its slope in p, its time derivative (the areas and the supply moving)
    and, with convective heat, its slope in T match central differences."""
    cs = rig_constants(rig)
    extra = {"heat_coefficient_W_per_m2_K": 30.0, "heat_coupling": 0.8} if hot else {}
    sl = _slots(1e6, **extra)
    temp = 310.0 if hot else rig.gas.temperature_K
    da_in, da_ex, dsup = 3e-5, -2e-5, 4e6
    for p, a_in, a_ex in ((2e5, 1.2e-6, 0.0), (4e5, 0.0, 1e-6), (5.35e5, 1.2e-6, 3e-7),
                          (5.8e5, 8e-7, 0.0)):

        def rhs(p, temp=temp, tt=0.0, a_in=a_in, a_ex=a_ex):
            return chamber_rhs(p, temp, a_in + tt * da_in, a_ex + tt * da_ex, 2.4e-6, 0.0,
                               P_SUP + tt * dsup, sl, cs, 1e-5, True, dsup, da_in, da_ex,
                               0.0, 0.0, 0.0, True)

        out = rhs(p)
        d = 1.0
        # (a choked restriction's flow does not see p: both 0 but for the node's
        # tolerance in the difference)
        assert out[1] == pytest.approx((rhs(p + d)[0] - rhs(p - d)[0]) / (2 * d), rel=1e-4,
                                       abs=1e-9 * abs(out[0]))
        h = 1e-7
        assert out[4] == pytest.approx((rhs(p, tt=h)[0] - rhs(p, tt=-h)[0]) / (2 * h),
                                       rel=1e-4, abs=1e-6 * abs(out[0]))
        n = supply_node(P_SUP, p, a_in, 1e6, cs)
        net = a_in * flow_function(n, p, rig.gas) - a_ex * flow_function(p, P_ATM, rig.gas)
        if not hot:
            kappa, rs = rig.gas.heat_capacity_ratio, rig.gas.specific_gas_constant_J_per_kg_K
            assert out[0] == pytest.approx(kappa * rs * rig.gas.temperature_K * net / 2.4e-6,
                                           rel=1e-12)
        else:
            dt = 1e-3
            assert out[5] == pytest.approx((rhs(p, temp + dt)[0] - rhs(p, temp - dt)[0])
                                           / (2 * dt), rel=1e-4)
            assert out[7] == pytest.approx((rhs(p, tt=h)[2] - rhs(p, tt=-h)[2]) / (2 * h),
                                           rel=1e-4, abs=1e-6 * abs(out[2]))


def test_a_narrow_restriction_sets_the_fill_whatever_the_inlet(rig):
    """A restriction a hundredth of the inlet's area: the fill is the restriction's own
    flow from the supply into the chamber (to 1e-3), whether the inlet opens to 50 or
    100 times it: a flow limit upstream."""
    cs = rig_constants(rig)
    sl = _slots(1e8)  # 0.01 mm^2
    kappa, rs = rig.gas.heat_capacity_ratio, rig.gas.specific_gas_constant_J_per_kg_K
    for p in (1.5e5, 3e5, 5e5):
        want = kappa * rs * rig.gas.temperature_K * 1e-8 * flow_function(
            P_SUP, p, rig.gas) / 2.4e-6
        for a_in in (5e-7, 1e-6):
            got = chamber_rhs(p, rig.gas.temperature_K, a_in, 0.0, 2.4e-6, 0.0, P_SUP, sl,
                              cs, 1e-5, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, True)[0]
            assert got == pytest.approx(want, rel=1e-3)


@pytest.mark.parametrize("others", [[], ["cylinder_leak"], ["heat_transfer"]])
def test_the_simulator_agrees_with_the_reference(rig, steps, valve_params, others):
    """The compiled simulator vs scipy Radau (rtol 1e-10, the node by Brent's method) on
    steps with a moving piston and a sagging supply, where the restriction moves the
    pressure by tens of kPa; the error falls with the tolerance."""
    model = Model([SupplyRestriction(), *others])
    params = dict(valve_params, supply_restriction=2e6)
    for other in others:
        params.update(model.effect(other).bench_defaults())
    ref, errs = reference_errors(model, params, steps, rig, 2e5)
    plain = simulate(Model(list(others)), {k: v for k, v in params.items()
                                          if k != "supply_restriction"},
                     steps, rig, 2e5, _tight()).pressure_Pa[0]
    assert np.max(np.abs(ref - plain)) > 1e4
    assert errs[1] < 0.5 and errs[1] < 0.2 * errs[0], errs


def test_beside_a_second_compartment_it_agrees_with_the_reference():
    """A ventilator's circuit and test lung (a two-compartment card, a switching valve of
    20 mm^2 from a 10-kPa supply) fed through 12 mm^2: the compiled two-state step
    against the reference, where the restriction slows the breath by hundreds of Pa."""
    from pneubayes.physics.gas import GasConstants
    from pneubayes.rig import Rig
    from pneubayes.rigcard import RigCard

    p_atm, p_sup = 101325.0, 111325.0
    card = RigCard.from_dict({
        "format": "pneubayes-rig/1", "name": "circuit and test lung",
        "atmospheric_pressure_Pa": p_atm, "temperature_K": 296.0,
        "command": {"unit": "duty", "range": [0.0, 1.0]},
        "chamber": {"kind": "two_compartment", "volume_m3": 5e-4, "lung_volume_m3": 1e-3,
                    "lung_compliance_m3_per_Pa": 2e-7, "resistance_Pa_s_per_m3": 2e6},
        "valve": {"kind": "switching", "open_area_m2": 2e-5, "exhaust_area_m2": 3e-5,
                  "opening_delay_s": 0.0, "opening_time_constant_s": 0.0},
        "supply": {"kind": "constant", "pressure_Pa": p_sup}}, "card.json")
    rig = Rig(0.05, p_atm, p_sup, gas=GasConstants(temperature_K=296.0))
    t = np.arange(751) * 2e-3
    inp = Inputs(t, ((t % 1.0) < 0.4).astype(float), np.zeros_like(t), np.full(t.size, p_sup))
    model = Model([SupplyRestriction()], rig_card=card)
    params = {"supply_restriction": 1.0 / 1.2e-5}
    ref = reference_simulate(model, params, inp, rig, p_atm + 500.0, method="Radau",
                             rtol=1e-10, atol=1e-6)
    got = simulate(model, params, inp, rig, p_atm + 500.0, _tight(1e-9)).pressure_Pa[0]
    free = simulate(model, {"supply_restriction": 0.0}, inp, rig, p_atm + 500.0,
                    _tight(1e-9)).pressure_Pa[0]
    assert np.max(np.abs(ref - free)) > 200.0
    assert np.max(np.abs(got - ref)) < 0.05


def test_limits_and_conservation(rig, valve_params):
    """With a restriction the full inlet still reaches the supply, the full exhaust the
    atmosphere as fast as without it; shut ports keep the pressure; no restriction is
    the plain model."""
    t = np.arange(10001) * 1e-3
    model = Model([SupplyRestriction()])
    params = dict(valve_params, supply_restriction=3e6)
    for u, p0, end in ((5.0, 2e5, P_SUP), (-5.0, 4e5, P_ATM)):
        inp = Inputs(t, np.full(t.size, u), np.full(t.size, 0.05), np.full(t.size, P_SUP))
        p = simulate(model, params, inp, rig, p0, _tight(1e-6)).pressure_Pa[0]
        plain = simulate(Model([]), valve_params, inp, rig, p0, _tight(1e-6)).pressure_Pa[0]
        # (the valve's other port leaks a little: both settle where the flows balance,
        # the restricted inlet's balance with the exhaust's leak a little lower)
        assert abs(p[-1] - end) < 2000.0
        if u > 0:
            assert plain[-1] - 1e3 < p[-1] < plain[-1]
            assert np.max(np.abs(p - plain)) > 1e4  # (the fill got there more slowly)
        else:
            assert 0.0 < plain[-1] - p[-1] < 20.0  # (measured 5.5 Pa)
            assert np.max(np.abs(p - plain)) < 1e3  # (the vent does not pass it)
    shut = chamber_rhs(3e5, rig.gas.temperature_K, 0.0, 0.0, 2.4e-6, 0.0, P_SUP, _slots(3e6),
                       rig_constants(rig), 1e-5, True, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, True)
    assert shut[0] == 0.0
    inp = Inputs(t[:301], np.sin(40 * t[:301]) * 3, np.full(301, 0.05), np.full(301, P_SUP))
    a = simulate(model, dict(valve_params, supply_restriction=0.0), inp, rig, 2e5,
                 _tight()).pressure_Pa[0]
    b = simulate(Model([]), valve_params, inp, rig, 2e5, _tight()).pressure_Pa[0]
    assert np.max(np.abs(a - b)) < 1e-6


def test_the_rates_along_a_path_are_the_simulator_s(rig, valve_params):
    """rate_terms (the least-squares fit on dp/dt, the open-form search's residual) feeds
    the inlet at the node as the simulator's chamber_rhs does."""
    from pneubayes.simulation.rates import port_areas, rate_terms

    model = Model([SupplyRestriction()])
    sl = model.lower(model.as_matrix(dict(valve_params, supply_restriction=2e6)), rig)[0]
    p = np.array([1.3e5, 2e5, 3e5, 4.5e5, 5.3e5])
    for spool in (3.0, 0.4, -3.0):
        got = rate_terms(sl, rig, p, np.full(p.size, spool), np.full(p.size, 0.02),
                         np.full(p.size, 0.01), np.full(p.size, P_SUP))
        total = got.inlet + got.exhaust + got.leak + got.volume + got.closure
        a_in, a_ex = port_areas(sl, np.array([spool]), None)
        vol = 2.4e-6 + rig.bore_area_m2 * 0.02
        for i, pi in enumerate(p):
            want = chamber_rhs(pi, rig.gas.temperature_K, a_in[0], a_ex[0], vol,
                               rig.bore_area_m2 * 0.01, P_SUP, sl, rig_constants(rig), 1e-5,
                               False, 0.0, 0.0, 0.0, spool, 0.0, 0.0, True)[0]
            assert total[i] == pytest.approx(want, rel=1e-9, abs=1e-6), (spool, pi)


@pytest.mark.parametrize("other, message", [
    (TubeDelay(form="wave"), "tube's acoustic line or wave line"),
    ("port_restriction", "restriction at the port")])
def test_refused_where_the_inlet_is_not_the_chambers(rig, valve_params, steps, other, message):
    model = Model([SupplyRestriction(), other])
    params = dict(valve_params, supply_restriction=1e6, tube_delay_s=0.005,
                  tube_diameter_m=0.004, port_restriction_fill=1e6, port_restriction_vent=0.0,
                  port_restriction_crack=0.0)
    params = {k: v for k, v in params.items() if k in model.parameter_names}
    with pytest.raises(ValueError, match=message):
        simulate(model, params, steps, rig, 2e5, _tight())


def test_a_planted_restriction_is_recovered_by_a_trajectory_fit(rig, valve_params):
    """Noise-free fills and vents through 0.4 mm^2 upstream of valve 1's inlet (about
    0.58 mm^2 open): the trajectory refinement of the restriction alone from 1 mm^2
    finds the planted inverse area within 1 %."""
    got = refit_planted(Model([SupplyRestriction()]),
                        dict(valve_params, supply_restriction=2.5e6), "supply_restriction",
                        1e6, seed=11)
    assert got == pytest.approx(2.5e6, rel=1e-2)


# ---------------------------------------------------------------- the rig card's kind
_CARD = {
    "format": "pneubayes-rig/1", "name": "a valve behind a supply hose",
    "atmospheric_pressure_Pa": P_ATM, "temperature_K": 296.0,
    "command": {"unit": "duty", "range": [0.0, 1.0]},
    "chamber": {"kind": "fixed", "volume_m3": 5e-5},
    "valve": {"kind": "gompertz", "inlet_offset_m2": 0.0, "inlet_a_m2": 2e-6,
              "inlet_b": 5.0, "inlet_c_per_V": 10.0, "inlet_d_V": -0.3,
              "exhaust_offset_m2": 0.0, "exhaust_a_m2": 3e-6, "exhaust_b": 5.0,
              "exhaust_c_per_V": -10.0, "exhaust_d_V": -0.7},
    "supply": {"kind": "restricted", "restriction_area_m2": 1e-6, "pressure_Pa": P_SUP},
}


def test_a_restricted_supply_card_is_the_effect_at_its_area():
    """Supply kind ``restricted`` lowers to the effect's slot at 1 / its area: the same
    pressures as the constant supply beside ``supply_restriction``; a prior on the area
    makes it the fitted ``supply_restriction_area_m2``; it round-trips."""
    import json

    from rig_helpers import edited_card

    from pneubayes.physics.gas import GasConstants
    from pneubayes.rig import Rig
    from pneubayes.rigcard import RigCard

    rig = Rig(0.01, P_ATM, P_SUP, gas=GasConstants(temperature_K=296.0))
    t = np.arange(301) * 1e-3
    inp = Inputs(t, 0.5 + 0.5 * np.sin(2 * np.pi * 5 * t), np.zeros_like(t),
                 np.full(t.size, P_SUP))
    c = edited_card(_CARD)
    assert RigCard.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    got = simulate(Model(rig_card=c), np.zeros((1, 0)), inp, rig, 2e5, _tight()).pressure_Pa[0]
    plain = edited_card(_CARD, supply={"kind": "constant", "pressure_Pa": P_SUP})
    want = simulate(Model([SupplyRestriction()], rig_card=plain), {"supply_restriction": 1e6},
                    inp, rig, 2e5, _tight()).pressure_Pa[0]
    free = simulate(Model(rig_card=plain), np.zeros((1, 0)), inp, rig, 2e5,
                    _tight()).pressure_Pa[0]
    np.testing.assert_array_equal(got, want)
    assert np.max(np.abs(got - free)) > 1e4
    fitted = edited_card(_CARD, supply__restriction_area_m2={"prior": "log-uniform",
                                                             "bounds": [1e-8, 1e-4]})
    assert Model(rig_card=fitted).parameter_names == ("supply_restriction_area_m2",)


@pytest.mark.parametrize("changes, words", [
    ({"supply__restriction_area_m2": -1e-6}, ["'restriction_area_m2'", "> 0"]),
    ({"supply__pressure_Pa": "gauge"}, ["'pressure_Pa'", "measured"]),
])
def test_a_bad_restricted_supply_names_the_key(changes, words):
    from rig_helpers import edited_card

    from pneubayes.errors import RigCardError

    with pytest.raises(RigCardError) as err:
        edited_card(_CARD, **changes)
    for w in words:
        assert w in str(err.value), (w, str(err.value))
