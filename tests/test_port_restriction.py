"""A restriction in series at the chamber's port (effect ``port_restriction``): the node's
mass balance, the compiled simulator against the scipy reference, limits and slopes."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import discovery_settings, reference_errors, valve1_recordings
from conftest import tight_solver as _tight

from pneubayes.discovery.openform.port_restriction import (
    PortRestrictionProblem,
    PortRestrictionSearch,
)
from pneubayes.effects import PortRestriction, TubeDelay
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.physics.orifice import flow_function, flow_partials
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, SolverConfig, simulate
from pneubayes.simulation.chamber import chamber_rhs
from pneubayes.simulation.reference import reference_simulate
from pneubayes.simulation.restriction import (
    OPEN_AREA_M2,
    direction_area,
    node_pressure,
    series_slopes,
)
from pneubayes.simulation.simulator import rig_constants

P_ATM, P_SUP = 101325.0, 551325.0




@pytest.fixture
def steps(rig):
    """Steps between full inlet, closed, full exhaust and a half opening: 0.15 s."""
    t = np.arange(151) * 1e-3
    u = np.select([t < 0.04, t < 0.06, t < 0.1, t < 0.125], [3.0, 0.0, -3.0, 0.6], -0.6)
    return Inputs(t, u, np.full(t.size, 0.05), np.full(t.size, P_SUP))


@pytest.fixture
def long_steps(rig):
    """The same steps held longer: 0.3 s."""
    t = np.arange(301) * 1e-3
    u = np.select([t < 0.08, t < 0.12, t < 0.2, t < 0.25], [3.0, 0.0, -3.0, 0.6], -0.6)
    return Inputs(t, u, np.full(t.size, 0.05), np.full(t.size, P_SUP))


def _cs(rig):
    return rig_constants(rig)


@pytest.mark.parametrize("p, k_fill, k_vent, a_in, a_ex", [
    (2e5, 1e6, 5e6, 1.2e-6, 0.0),      # a fill through a 1 mm^2 restriction
    (4.5e5, 1e6, 5e6, 0.0, 1.0e-6),    # a vent through 0.2 mm^2
    (3e5, 2e6, 2e6, 0.6e-6, 0.4e-6),   # both ports open
    (1.2e5, 0.0, 1e7, 0.0, 0.8e-6),    # a vent near the atmosphere
    (5.4e5, 1e6, 0.0, 1.2e-6, 0.0),    # a fill near the supply
])
def test_the_node_balances_the_valve_against_the_restriction(rig, p, k_fill, k_vent, a_in,
                                                             a_ex):
    """The node's pressure: what the valve's ports pass equals what the restriction
    passes (eqs. 1-3 each, numpy's law), and it lies between the chamber and the source."""
    cs = _cs(rig)
    x = node_pressure(p, P_SUP, a_in, a_ex, k_fill, k_vent, 0.0, cs)
    g = rig.gas
    valve = (a_in * flow_function(P_SUP, x, g) - a_ex * flow_function(x, P_ATM, g))
    k = k_fill if x > p else k_vent
    through = flow_function(x, p, g) / k if k > 0 else valve
    assert valve == pytest.approx(through, rel=1e-9, abs=1e-15)
    plain = a_in * flow_function(P_SUP, p, g) - a_ex * flow_function(p, P_ATM, g)
    if k > 0:
        assert abs(valve) < abs(plain)  # the restriction slows the flow
        assert (x - p) * plain > 0  # the node sits on the source's side
    else:
        assert x == p


def test_no_restriction_in_a_direction_leaves_the_ports_at_the_chamber(rig):
    cs = _cs(rig)
    assert node_pressure(3e5, P_SUP, 1e-6, 0.0, 0.0, 1e6, 0.0, cs) == 3e5  # a fill, vent only
    assert node_pressure(3e5, P_SUP, 0.0, 1e-6, 1e6, 0.0, 0.0, cs) == 3e5  # a vent, fill only
    assert node_pressure(3e5, P_SUP, 0.0, 0.0, 1e6, 1e6, 0.0, cs) == 3e5  # nothing flows


def _slopes_against_differences(rig, p, a_in, a_ex, kf, kv, crack, rel, exhaust_share):
    """The net flow's slopes in p and p_s and the inlet's share (series_slopes), and with
    ``exhaust_share`` the exhaust's where the inlet is shut, against central differences
    of the node's solution, to ``rel``; returns the share."""
    cs = _cs(rig)
    g = rig.gas

    def net(pp, ps=P_SUP, ai=a_in, ae=a_ex):
        x = node_pressure(pp, ps, ai, ae, kf, kv, crack, cs)
        return ai * flow_function(ps, x, g) - ae * flow_function(x, P_ATM, g)

    x = node_pressure(p, P_SUP, a_in, a_ex, kf, kv, crack, cs)
    law = (g.alpha_s_per_m, g.beta_s_per_m, g.theta, g.heat_capacity_ratio, 0.0)
    _, din_s, din_x = flow_partials(P_SUP, x, *law)  # the ports' own slopes at the node
    _, dex_x, _ = flow_partials(x, P_ATM, *law)
    d_sup, d_in, d_ex, share = series_slopes(x, p, a_in, a_ex, kf, kv, crack, din_s, din_x,
                                             dex_x, cs, 0.0)
    dp, da = 1.0, 1e-10
    assert a_in * d_in - a_ex * d_ex == pytest.approx((net(p + dp) - net(p - dp)) / (2 * dp),
                                                      rel=rel)
    if a_in > 0:
        assert a_in * d_sup == pytest.approx(
            (net(p, P_SUP + dp) - net(p, P_SUP - dp)) / (2 * dp), rel=rel)
        assert share * flow_function(P_SUP, x, g) == pytest.approx(
            (net(p, ai=a_in + da) - net(p, ai=a_in - da)) / (2 * da), rel=rel)
    elif exhaust_share:
        assert a_ex > 0 and share * flow_function(x, P_ATM, g) == pytest.approx(
            (net(p, ae=a_ex - da) - net(p, ae=a_ex + da)) / (2 * da), rel=rel)
    return share


@pytest.mark.parametrize("p, a_in, a_ex", [(2e5, 1.2e-6, 0.0), (4.5e5, 0.0, 1e-6),
                                           (3e5, 0.6e-6, 0.4e-6)])
def test_the_slopes_are_the_node_flows_derivatives(rig, p, a_in, a_ex):
    """The net flow's slopes in p and p_s and an area's share, against central
    differences of the node's solution."""
    share = _slopes_against_differences(rig, p, a_in, a_ex, 1e6, 3e6, 0.0, 1e-5, False)
    assert 0.0 <= share < 1.0  # (0: the restriction chokes; its flow is its own)


@pytest.mark.parametrize("hot, crack", [(False, 0.0), (True, 0.0), (False, 1e4), (True, 1e4)])
def test_the_chamber_rate_and_its_jacobian_with_a_restriction(rig, hot, crack):
    """chamber_rhs' dp/dt beside a restriction (with and without a check valve on the
    fill) is the node's net flow in eq. 5, and its slope in p (and in T with convective
    heat) matches central differences."""
    cs = _cs(rig)
    sl = np.zeros(max(SLOT_INDEX.values()) + 1)
    sl[SLOT_INDEX["volume_m3"]] = 2.4e-6
    sl[SLOT_INDEX["restriction_fill_inverse_area_per_m2"]] = 1e6
    sl[SLOT_INDEX["restriction_vent_inverse_area_per_m2"]] = 4e6
    sl[SLOT_INDEX["restriction_crack_Pa"]] = crack
    if hot:
        sl[SLOT_INDEX["heat_coefficient_W_per_m2_K"]] = 30.0
        sl[SLOT_INDEX["heat_coupling"]] = 0.8
    temp = 310.0 if hot else rig.gas.temperature_K
    for p, a_in, a_ex in ((2e5, 1.2e-6, 0.0), (4e5, 0.0, 1e-6), (5.35e5, 1.2e-6, 0.0)):
        args = (a_in, a_ex, 2.4e-6, 0.0, P_SUP, sl, cs, 1e-5, True, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, True)
        out = chamber_rhs(p, temp, *args)
        d = 1.0
        up, dn = chamber_rhs(p + d, temp, *args), chamber_rhs(p - d, temp, *args)
        # (a choked restriction's flow does not see p: both 0 but for the node's
        # tolerance in the difference)
        assert out[1] == pytest.approx((up[0] - dn[0]) / (2 * d), rel=1e-4,
                                       abs=1e-9 * abs(out[0]))
        x = node_pressure(p, P_SUP, a_in, a_ex, 1e6, 4e6, crack, cs)
        net = a_in * flow_function(P_SUP, x, rig.gas) - a_ex * flow_function(x, P_ATM, rig.gas)
        if not hot:
            kappa, rs = rig.gas.heat_capacity_ratio, rig.gas.specific_gas_constant_J_per_kg_K
            assert out[0] == pytest.approx(kappa * rs * rig.gas.temperature_K * net / 2.4e-6,
                                           rel=1e-12)
        else:
            dt = 1e-3
            hot_, cold = chamber_rhs(p, temp + dt, *args), chamber_rhs(p, temp - dt, *args)
            assert out[5] == pytest.approx((hot_[0] - cold[0]) / (2 * dt), rel=1e-4,
                                           abs=1e-9 * abs(out[0]))


@pytest.mark.parametrize("crack", [0.0, 2e4])
def test_the_rates_along_a_path_are_the_simulator_s(rig, valve_params, crack):
    """rate_terms (the rates along a measured pressure: the least-squares fit on dp/dt,
    the open-form search's residual) passes the ports' flows at the node as the
    simulator's chamber_rhs does, where the restriction changes the rate several-fold
    (it once read them at the chamber: the restriction in the model was then part of
    the residual the search saw)."""
    from pneubayes.simulation.rates import port_areas, rate_terms

    model = Model([PortRestriction(), "cylinder_leak"])
    params = dict(valve_params, port_restriction_fill=2e6, port_restriction_vent=5e6,
                  port_restriction_crack=crack, **model.effect("cylinder_leak")
                  .bench_defaults())
    sl = model.lower(model.as_matrix(params), rig)[0]
    plain = Model(["cylinder_leak"])
    sl_plain = plain.lower(plain.as_matrix({k: v for k, v in params.items()
                                            if not k.startswith("port_")}), rig)[0]
    p = np.array([1.3e5, 2e5, 3e5, 4.5e5, 5.3e5])
    for spool in (3.0, 0.4, -0.5, -3.0):
        got = rate_terms(sl, rig, p, np.full(p.size, spool), np.full(p.size, 0.02),
                         np.full(p.size, 0.01), np.full(p.size, P_SUP))
        total = got.inlet + got.exhaust + got.leak + got.volume + got.closure
        a_in, a_ex = port_areas(sl, np.array([spool]), None)
        vol = 2.4e-6 + rig.bore_area_m2 * 0.02
        for i, pi in enumerate(p):
            want = chamber_rhs(pi, rig.gas.temperature_K, a_in[0], a_ex[0], vol,
                               rig.bore_area_m2 * 0.01, P_SUP, sl, _cs(rig), 1e-5, False,
                               0.0, 0.0, 0.0, spool, 0.0, 0.0, True)[0]
            assert total[i] == pytest.approx(want, rel=1e-9, abs=1e-6), (spool, pi)
        unrestricted = rate_terms(sl_plain, rig, p, np.full(p.size, spool),
                                  np.full(p.size, 0.02), np.full(p.size, 0.01),
                                  np.full(p.size, P_SUP))
        if spool == 3.0:  # the fill, slowed by the restriction at every pressure
            assert np.all(np.abs(got.inlet) < 0.8 * np.abs(unrestricted.inlet))
        # a batch's slot rows broadcast against the states (as the sensor point's
        # corners pass them), one row restricted and one not: each row's own rates
        both = np.stack([sl, sl.copy()])
        both[1, SLOT_INDEX["restriction_fill_inverse_area_per_m2"]] = 0.0
        both[1, SLOT_INDEX["restriction_vent_inverse_area_per_m2"]] = 0.0
        rows = rate_terms(both.T[:, :, None], rig, p[None, :], spool, 0.02, 0.01, P_SUP)
        np.testing.assert_allclose(rows.inlet[0], got.inlet, rtol=1e-12)
        unr = rate_terms(both[1], rig, p, spool, 0.02, 0.01, P_SUP)
        np.testing.assert_allclose(rows.inlet[1], unr.inlet, rtol=1e-12)


def test_the_search_s_path_signals_read_the_ports_at_the_node(rig, valve_params):
    """The open-form search's port flows along a recording (path_signals), beside a
    restriction in the model: each the valve's port at the node's pressure, the node
    solved at the sample's chamber pressure, supply and areas; the net flow's history
    (the flow lag's) the same flows."""
    from pneubayes.discovery.one_step import one_step_data
    from pneubayes.discovery.openform.signals import path_signals

    model = Model([PortRestriction()])
    params = dict(valve_params, port_restriction_fill=2e6, port_restriction_vent=5e6,
                  port_restriction_crack=1e4)
    (rec,) = valve1_recordings(model, params, "signals", 7, count=1, n=1501)
    sig = path_signals(model, params, rec, one_step_data(rec, 5))
    cs, g = _cs(rig), rig.gas
    moved = 0
    for i in range(0, rec.n_samples - 1, 37):
        p, ps = sig["pressure_Pa"][i], sig["supply_pressure_Pa"][i]
        a_in, a_ex = sig["inlet_area_m2"][i], sig["exhaust_area_m2"][i]
        x = node_pressure(p, ps, a_in, a_ex, 2e6, 5e6, 1e4, cs)
        assert sig["inlet_flow_kg_per_s"][i] == pytest.approx(
            a_in * flow_function(ps, x, g), rel=1e-12, abs=1e-15)
        assert sig["exhaust_flow_kg_per_s"][i] == pytest.approx(
            a_ex * flow_function(x, P_ATM, g), rel=1e-12, abs=1e-15)
        moved += abs(x - p) > 1e3
    assert moved > 5  # (the node differs from the chamber at many of the samples)
    net = sig["net_flow_history"]
    np.testing.assert_allclose(net.values, sig["inlet_flow_kg_per_s"]
                               - sig["exhaust_flow_kg_per_s"], rtol=1e-12)


@pytest.mark.parametrize("k_fill, k_vent", [(2e6, 5e6), (0.0, 3e6), (3e6, 0.0)])
def test_the_simulator_agrees_with_the_reference(rig, steps, valve_params, k_fill, k_vent):
    """The compiled simulator beside a restriction vs scipy Radau (rtol 1e-10, the node by
    Brent's method), where the restriction moves the pressure by tens of kPa."""
    model = Model([PortRestriction()])
    params = dict(valve_params, port_restriction_fill=k_fill, port_restriction_vent=k_vent,
                  port_restriction_crack=0.0)
    got = simulate(model, params, steps, rig, 2e5, _tight()).pressure_Pa[0]
    ref = reference_simulate(model, params, steps, rig, 2e5, rtol=1e-10)
    plain = simulate(Model([]), valve_params, steps, rig, 2e5, _tight()).pressure_Pa[0]
    assert np.max(np.abs(got - plain)) > 1e4
    assert np.max(np.abs(got - ref)) < 0.5


@pytest.mark.parametrize("other", ["cylinder_leak", "heat_transfer"])
def test_beside_a_leak_and_heat_it_agrees_with_the_reference(rig, steps, valve_params, other):
    """The cylinder's leak leaves the chamber itself, not through the node (it was once
    read at the node: 12.9 kPa off beside the orifice leak)."""
    model = Model([PortRestriction(), other])
    params = dict(valve_params, port_restriction_fill=2e6, port_restriction_vent=5e6,
                  port_restriction_crack=0.0)
    params.update(model.effect(other).bench_defaults())
    got = simulate(model, params, steps, rig, 2e5, _tight()).pressure_Pa[0]
    ref = reference_simulate(model, params, steps, rig, 2e5, rtol=1e-10)
    assert np.max(np.abs(got - ref)) < 1.0


def test_a_flow_lag_low_passes_the_flow_through_the_node(rig, long_steps, valve_params):
    """An open-form flow lag (``net_flow_lag``) low-passes the ports' net flow; beside a
    restriction the ports pass it at the node, and so does the lag (it once read the
    ports at the chamber's pressure)."""
    from pneubayes.effects import make_effect

    model = Model([PortRestriction(), make_effect("closure", terms="net_flow_lag")])
    params = dict(valve_params, port_restriction_fill=2e6, port_restriction_vent=5e6,
                  port_restriction_crack=0.0, closure_coefficient_0=0.5,
                  closure_threshold_0_a=0.02)
    steps = long_steps
    ref, errs = reference_errors(model, params, steps, rig, 2e5, (1e-4, 1e-8, 1e-10),
                                 ref_rtol=1e-11)
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[-1] < 5.0, errs  # (measured 2.8 Pa; 145 kPa when read at the chamber)
    alone = simulate(Model([PortRestriction()]), {
        k: v for k, v in params.items() if not k.startswith("closure")}, steps, rig, 2e5,
        _tight()).pressure_Pa[0]
    assert np.max(np.abs(ref - alone)) > 1e4  # the lag's own share is large


def test_a_piston_pushing_the_chamber_above_the_supply_agrees_with_the_reference(
        rig, valve_params):
    """A full inlet while the piston compresses the chamber past the supply: the node sits
    at the inlet's own square root (x near p_s), across which Newton's method bounced
    until it ran out of iterations (once 697 Pa off the reference here)."""
    t = np.arange(151) * 1e-3  # (past the supply from about 0.1 s)
    inputs = Inputs(t, np.full(t.size, 2.8), 0.015 + 0.005 * np.sin(2 * np.pi * 3 * t),
                    np.full(t.size, P_SUP))
    model = Model([PortRestriction()])
    params = dict(valve_params, port_restriction_fill=0.0, port_restriction_vent=5e6,
                  port_restriction_crack=0.0)
    got = simulate(model, params, inputs, rig, 4e5, _tight()).pressure_Pa[0]
    ref = reference_simulate(model, params, inputs, rig, 4e5, rtol=1e-10)
    assert np.max(ref) > P_SUP + 1e3
    assert np.max(np.abs(got - ref)) < 1.0


def test_limits_and_conservation(rig, valve_params):
    """With a restriction the full inlet still reaches the supply and the full exhaust
    the atmosphere; shut ports keep the pressure; no restriction is the plain model."""
    t = np.arange(10001) * 1e-3
    model = Model([PortRestriction()])
    params = dict(valve_params, port_restriction_fill=3e6, port_restriction_vent=3e6,
                  port_restriction_crack=0.0)
    for u, p0, end in ((5.0, 2e5, P_SUP), (-5.0, 4e5, P_ATM)):
        inp = Inputs(t, np.full(t.size, u), np.full(t.size, 0.05), np.full(t.size, P_SUP))
        p = simulate(model, params, inp, rig, p0, _tight(1e-6)).pressure_Pa[0]
        plain = simulate(Model([]), valve_params, inp, rig, p0, _tight(1e-6)).pressure_Pa[0]
        # (the valve's other port leaks a little: both settle where the flows balance)
        assert abs(p[-1] - end) < 2000.0 and abs(p[-1] - plain[-1]) < 1.0
        assert np.max(np.abs(p - plain)) > 1e4  # (it got there more slowly)
    sl = np.zeros(max(SLOT_INDEX.values()) + 1)
    sl[SLOT_INDEX["restriction_fill_inverse_area_per_m2"]] = 3e6
    sl[SLOT_INDEX["restriction_vent_inverse_area_per_m2"]] = 3e6
    shut = chamber_rhs(3e5, rig.gas.temperature_K, 0.0, 0.0, 2.4e-6, 0.0, P_SUP, sl,
                       _cs(rig), 1e-5, True, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, True)
    assert shut[0] == 0.0
    inp = Inputs(t[:301], np.sin(40 * t[:301]) * 3, np.full(301, 0.05), np.full(301, P_SUP))
    # (the general kernel's path with the restriction's slots at 0 is the plain one too)
    none = dict(valve_params, port_restriction_fill=0.0, port_restriction_vent=0.0,
                port_restriction_crack=0.0)
    a = simulate(model, none, inp, rig, 2e5, _tight()).pressure_Pa[0]
    b = simulate(Model([]), valve_params, inp, rig, 2e5, _tight()).pressure_Pa[0]
    assert np.max(np.abs(a - b)) < 1e-6


def test_refused_beside_the_tubes_lines(rig, valve_params, steps):
    model = Model([PortRestriction(), TubeDelay(form="wave")])
    params = dict(valve_params, port_restriction_fill=1e6, port_restriction_vent=1e6,
                  port_restriction_crack=0.0,
                  tube_delay_s=0.005, tube_diameter_m=0.004)
    with pytest.raises(ValueError, match="restriction at the chamber's port"):
        simulate(model, params, steps, rig, 2e5, _tight())



def test_the_search_proposes_no_effect_the_simulator_refuses_beside_it(rig, valve_params):
    """A port's own critical ratio is not stepped beside a restriction at the port: the
    search's library leaves it out there (it crashed the round after a restriction was
    named), and keeps it beside the plain model; the refusal's reason is the
    simulator's."""
    from pneubayes.discovery.library import steppable_beside
    from pneubayes.simulation import combination_error
    model = Model([PortRestriction()])
    params = dict(valve_params, port_restriction_fill=1e6, port_restriction_vent=1e6,
                  port_restriction_crack=0.0)
    assert not steppable_beside(model, params, "critical_ratio", rig)
    assert steppable_beside(model, params, "cylinder_leak", rig)
    assert steppable_beside(Model([]), valve_params, "critical_ratio", rig)
    both = Model([PortRestriction(), "critical_ratio"])
    reason = combination_error(both, {**both.neutral_values(), **params}, rig)
    assert "critical pressure ratio" in reason and "restriction at the port" in reason
    assert combination_error(model, params, rig) is None

# ---------------------------------------------------------------- the check valve
def test_the_check_valve_s_area_cracks_opens_and_is_smooth():
    """The wider direction passes the needle's area below the crack, its own above twice
    it, rising smoothly between; the narrower direction, and no crack, keep their own."""
    needle, check = 1.0 / 5e6, 1.0 / 5e5
    assert direction_area(9e3, 5e5, 5e6, 1e4) == (needle, 0.0)
    assert direction_area(2.1e4, 5e5, 5e6, 1e4) == (check, 0.0)
    assert direction_area(3e4, 0.0, 5e6, 1e4) == (OPEN_AREA_M2, 0.0)  # an open check
    assert direction_area(1.5e4, 5e6, 5e5, 1e4) == (needle, 0.0)  # the needle's side
    assert direction_area(1.5e4, 5e5, 5e6, 0.0) == (check, 0.0)
    assert direction_area(1.5e4, 5e5, 5e5, 1e4) == (check, 0.0)  # (alike: no check)
    drops = np.linspace(9e3, 2.1e4, 241)
    area = np.array([direction_area(d, 5e5, 5e6, 1e4)[0] for d in drops])
    slope = np.array([direction_area(d, 5e5, 5e6, 1e4)[1] for d in drops])
    assert np.all(np.diff(area) >= 0.0) and area[120] == pytest.approx(0.5 * (needle + check))
    # (its largest slope is 1.5 (check - needle) / crack; the differences straddle the
    # crack's and the full opening's corners at second order)
    np.testing.assert_allclose(slope[1:-1], (area[2:] - area[:-2]) / (drops[2] - drops[0]),
                               rtol=0, atol=1e-2 * (check - needle) / 1e4)
    assert slope.max() == pytest.approx(1.5 * (check - needle) / 1e4, rel=1e-3)


#: Chamber states and check valves whose node sits on the check's ramp (|x - p| between
#: the crack and twice it): ``(p, a_in, a_ex, k_fill, k_vent, crack)``.
ON_THE_RAMP = [
    (5.3e5, 1.2e-6, 0.0, 5e5, 5e6, 1.5e4),     # a fill near the supply, meter-out
    (4.5e5, 0.0, 1e-6, 5e6, 5e5, 1.5e4),       # a vent, meter-in
    (2e5, 1.2e-6, 0.0, 0.0, 5e6, 2e4),         # a fill through an open check
    (1.3e5, 0.0, 1e-6, 5e5, 5e6, 1.5e4),       # a vent near the atmosphere (the needle)
]


@pytest.mark.parametrize("p, a_in, a_ex, k_fill, k_vent, crack", ON_THE_RAMP)
def test_the_node_balances_through_the_check_valve(rig, p, a_in, a_ex, k_fill, k_vent,
                                                   crack):
    cs = _cs(rig)
    g = rig.gas
    x = node_pressure(p, P_SUP, a_in, a_ex, k_fill, k_vent, crack, cs)
    valve = a_in * flow_function(P_SUP, x, g) - a_ex * flow_function(x, P_ATM, g)
    own, other = (k_fill, k_vent) if x > p else (k_vent, k_fill)
    area = direction_area(abs(x - p), own, other, crack)[0]
    assert valve == pytest.approx(area * flow_function(x, p, g), rel=1e-9)
    if own < other:
        assert crack < abs(x - p) < 2.0 * crack  # (the case is on the ramp)
        assert 1.0 / other < area < (1.0 / own if own > 0 else OPEN_AREA_M2)


@pytest.mark.parametrize("p, a_in, a_ex, k_fill, k_vent, crack", ON_THE_RAMP)
def test_the_slopes_through_the_check_valve(rig, p, a_in, a_ex, k_fill, k_vent, crack):
    """The net flow's slopes in p and p_s, and an area's share, where the check's area
    moves with the drop, against central differences of the node's solution."""
    _slopes_against_differences(rig, p, a_in, a_ex, k_fill, k_vent, crack, 1e-4, True)


@pytest.mark.parametrize("k_fill, k_vent, crack", [(5e5, 5e6, 1.5e4), (5e6, 5e5, 1.5e4),
                                                   (0.0, 5e6, 2e4)])
def test_a_check_valve_agrees_with_the_reference(rig, steps, valve_params, k_fill, k_vent,
                                                 crack):
    """Meter-out and meter-in flow controls with their checks, and an open check beside a
    needle, against the reference (its own area law, the node by Brent's method); the
    crack moves the pressure by kPa."""
    model = Model([PortRestriction()])
    params = dict(valve_params, port_restriction_fill=k_fill, port_restriction_vent=k_vent,
                  port_restriction_crack=crack)
    got = simulate(model, params, steps, rig, 2e5, _tight()).pressure_Pa[0]
    ref = reference_simulate(model, params, steps, rig, 2e5, rtol=1e-10)
    uncracked = simulate(model, {**params, "port_restriction_crack": 0.0}, steps, rig, 2e5,
                         _tight()).pressure_Pa[0]
    assert np.max(np.abs(got - uncracked)) > 2e3
    assert np.max(np.abs(got - ref)) < 1.0


# ---------------------------------------------------------------- search and stage
#: A meter-out flow control planted on valve 1 (full ports about 0.58 mm^2): the fill
#: through 0.5 mm^2, the vent through 0.17 mm^2.
PLANTED = {"port_restriction_fill": 2e6, "port_restriction_vent": 6e6,
           "port_restriction_crack": 0.0}


@pytest.fixture(scope="module")
def restricted_recordings():
    """Four 8-s valve1 recordings (1 kHz, 200 Pa noise) through a planted meter-out
    restriction, and one of the plain valve."""
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    return (valve1_recordings(Model([PortRestriction()]), {**base, **PLANTED}, "restricted",
                              90, 4, 8001),
            valve1_recordings(Model(), base, "restricted", 90, 1), base)


def test_the_search_finds_a_planted_restriction_and_none_without(restricted_recordings):
    recs, plain, base = restricted_recordings
    solver = SolverConfig.standard()
    # (the valve's maps and dead volume as planted: the dead volume's scales held)
    search = PortRestrictionSearch(dead_volume_scales=(1.0,), refine_passes=4)
    found = search.fit(
        PortRestrictionProblem(WindowSet(recs[:1], 2.0, 2.0), Model(), base, solver))
    (term,) = found.terms_
    assert term.vent_per_m2 == pytest.approx(PLANTED["port_restriction_vent"], rel=0.3)
    assert term.fill_per_m2 == pytest.approx(PLANTED["port_restriction_fill"], rel=0.5)
    assert found.explained_fraction_ > 0.9 and "mm^2" in str(term)
    none = search.fit(
        PortRestrictionProblem(WindowSet(plain, 2.0, 2.0), Model(), base, solver))
    assert none.terms_ == [] and none.best_.explained < 0.02
    with pytest.raises(ValueError, match="already has a port restriction"):
        PortRestrictionSearch().fit(PortRestrictionProblem(
            WindowSet(recs[:1], 2.0, 2.0), Model([PortRestriction()]), {**base, **PLANTED},
            solver))
    with pytest.raises(ValueError, match="area_shares"):
        PortRestrictionSearch(area_shares=(-1.0,)).fit(object())
    with pytest.raises(ValueError, match="PortRestrictionProblem"):
        PortRestrictionSearch().fit(object())


def test_the_search_finds_a_check_valve_s_crack():
    """A meter-out flow control whose fill passes a check valve cracking at 20 kPa
    beside the needle: the search finds the crack, the needle and the check's area, and
    predicts within a few x the noise where, without a check valve, it cannot."""
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    planted = {"port_restriction_fill": 1e6, "port_restriction_vent": 6e6,
               "port_restriction_crack": 2e4}
    recs = valve1_recordings(Model([PortRestriction()]), {**base, **planted}, "checked", 90,
                             1, 8001)
    problem = PortRestrictionProblem(WindowSet(recs, 2.0, 2.0), Model(), base,
                                     SolverConfig.standard())

    def rmse(term):
        r = problem.window_residuals([[(term.fill_per_m2, term.vent_per_m2, term.crack_Pa)]])
        return float(np.sqrt(np.nanmean(r**2)))

    (term,) = PortRestrictionSearch(dead_volume_scales=(1.0,)).fit(problem).terms_
    assert term.crack_Pa == pytest.approx(2e4, rel=0.25) and "cracking" in str(term)
    assert term.vent_per_m2 == pytest.approx(6e6, rel=0.05)
    assert term.fill_per_m2 == pytest.approx(1e6, rel=0.3)
    plain = PortRestrictionSearch(dead_volume_scales=(1.0,), crack_shares=()).fit(problem)
    assert plain.best_.crack_Pa == 0.0
    assert rmse(term) < 3.0 * 200.0 < 0.5 * rmse(plain.best_)  # (200 Pa: the noise)
    with pytest.raises(ValueError, match="crack_shares"):
        PortRestrictionSearch(crack_shares=(0.0,)).fit(problem)


def test_the_stage_s_knobs_and_its_switch():
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import PortRestrictionForm, default_stages

    assert PortRestrictionForm().compete_below_gap_closed == 0.9
    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("ReadingFlowForm") < names.index("PortRestrictionForm") \
        < names.index("VolumeForm")
    off = default_stages(DiscoverySettings(
        stages=StageSettings(port_restriction_min_noise_ratio=0)))
    assert "PortRestrictionForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="port_restriction_min_noise_ratio"):
        StageSettings(port_restriction_min_noise_ratio=0.5)


@pytest.mark.slow
def test_discovery_finds_a_planted_restriction(restricted_recordings, tmp_path):
    """The loop with the port's stage: the restriction is found, verified on the held-out
    recordings, and the held-out error falls to about the noise floor; the report lists
    it as a term at the port."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery
    from pneubayes.discovery.stages import PortRestrictionForm

    recs, _, _ = restricted_recordings
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=print, stages=[PortRestrictionForm()]
                       ).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_port_terms"]
    assert term["term"] == "port restriction"
    # on a fixed piston only the areas over the dead volume are identified: the vent's
    # restriction against the valve's full exhaust (k_v a_ex) is the physics it finds
    got, true = result.final.params, {**valve_preset("valve1").parameters(), **PLANTED}

    def vent_over_exhaust(v):
        return v["port_restriction_vent"] * (v["exhaust_offset_m2"] + v["exhaust_a_m2"])

    assert vent_over_exhaust(got) == pytest.approx(vent_over_exhaust(true), rel=0.1)
    assert doc["effects"] == [] and doc["found_terms"] == [] and doc["stand_ins"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    # beside the restriction the next round's search leaves out what cannot join it
    searches = [e for e in doc["ledger"] if e["action"] == "search"]
    assert searches[0]["not_steppable"] == []
    assert searches[-1]["not_steppable"] == ["critical_ratio"]
    write_discovery(result, recs, tmp_path, figures=False)
    report = (tmp_path / "report.md").read_text()
    assert "port restriction" in report
    assert ("; not searched from round 2 on: the simulator cannot step it beside the "
            "model |") in report
    assert "PortRestriction()" in (tmp_path / "found_port.py").read_text()


@pytest.mark.slow
def test_discovery_finds_a_check_valve_s_crack(tmp_path):
    """The loop on a meter-out flow control whose fill passes a check valve cracking at
    20 kPa: the restriction is found with its crack and the held-out error falls to
    about the noise floor."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.stages import PortRestrictionForm

    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    planted = {"port_restriction_fill": 1e6, "port_restriction_vent": 6e6,
               "port_restriction_crack": 2e4}
    recs = valve1_recordings(Model([PortRestriction()]), {**base, **planted}, "checked", 91,
                             4, 8001)
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=print, stages=[PortRestrictionForm()]
                       ).fit(recs).result_
    doc = result.to_dict()
    assert [t["term"] for t in doc["found_port_terms"]] == ["port restriction"]
    assert result.final.params["port_restriction_crack"] == pytest.approx(2e4, rel=0.3)
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]


def test_a_found_restriction_becomes_an_effect_plug_in_a_user_can_name(rig, steps,
                                                                       valve_params):
    from pneubayes.discovery.openform.skeleton import port_effect_skeleton

    text = port_effect_skeleton(Model([PortRestriction()]), {**valve_params, **PLANTED},
                                "SpeedController", "speed_controller")
    namespace: dict = {}
    exec(compile(text, "speed_controller.py", "exec"), namespace)
    effect = namespace["SpeedController"]()
    assert effect.name == "speed_controller"
    assert "vent_inverse_area_per_m2" in effect.parameter_names()
    mine = simulate(Model([effect]), {**valve_params, **effect.bench_defaults()}, steps, rig,
                    2e5, _tight()).pressure_Pa[0]
    theirs = simulate(Model([PortRestriction()]), {**valve_params, **PLANTED}, steps, rig,
                      2e5, _tight()).pressure_Pa[0]
    np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-6)
