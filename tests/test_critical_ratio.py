"""Ports that choke at their own critical pressure ratio (effect ``critical_ratio``,
ISO 6358's ``b``): the flow law against its closed forms and ISO 6358's ellipse, the
compiled simulator against the scipy reference and the plant's tube, limits, refusals
and a planted ratio recovered."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import reference_errors, refit_planted
from conftest import tight_solver as _tight

from pneubayes.effects import CriticalRatio, make_effect
from pneubayes.effects.critical_ratio import ISENTROPIC_RATIO
from pneubayes.errors import FormCombinationError
from pneubayes.model import Model
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.orifice import flow_function, flow_partials
from pneubayes.simulation import Inputs, SolverConfig, simulate
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 551325.0


@pytest.fixture
def steps(sagging_steps):
    """(conftest's sagging_steps)"""
    return sagging_steps


GAS = GasConstants()




def _iso6358(r, b, m=0.5):
    """ISO 6358's subsonic curve at index ``m``, per unit of the choked flow."""
    return np.where(r <= b, 1.0, np.clip(1.0 - ((r - b) / (1.0 - b)) ** 2, 0, None) ** m)


# ---------------------------------------------------------------- the law
def test_at_eq_3s_ratio_the_law_is_eq_3():
    assert ISENTROPIC_RATIO == pytest.approx(1.0 / GAS.theta, rel=1e-12)
    r = np.linspace(0.02, 1.0, 301)
    plain = flow_function(6e5, 6e5 * r, GAS)
    assert np.max(np.abs(flow_function(6e5, 6e5 * r, GAS, ISENTROPIC_RATIO) - plain)) \
        <= 1e-12 * plain.max()


@pytest.mark.parametrize("b", [0.15, 0.3, 0.45, 0.7])
def test_choked_below_the_ratio_and_iso_6358s_ellipse_above(b):
    """Choked (eq. 3's ``beta p_u``) at ratios below ``b``, continuous there, zero at
    equal pressures, within 0.5 % of ISO 6358's ellipse (index 1/2) at every ratio."""
    p_u = 6e5
    r = np.linspace(0.01, 0.999, 500)
    f = flow_function(p_u, p_u * r, GAS, b)
    choked = GAS.beta_s_per_m * p_u
    assert np.allclose(f[r < b], choked, rtol=1e-12)
    assert flow_function(p_u, p_u * (b + 1e-9), GAS, b) == pytest.approx(choked, rel=1e-6)
    assert flow_function(p_u, p_u, GAS, b) == 0.0
    assert np.all(np.diff(f) <= 1e-9 * choked)  # falls as the ratio rises
    iso = _iso6358(r, b) * choked
    assert np.max(np.abs(f - iso)) < 5e-3 * choked


@pytest.mark.parametrize("b, m", [(0.3, 0.35), (0.3, 0.75), (0.45, 0.6)])
def test_the_subsonic_index_is_iso_6358s(b, m):
    """With a subsonic index the curve is ISO 6358's at that index to 0.5 % of the
    choked flow; at 1/2 it is the index-free curve to rounding."""
    p_u = 6e5
    r = np.linspace(0.01, 0.999, 500)
    choked = GAS.beta_s_per_m * p_u
    f = flow_function(p_u, p_u * r, GAS, b, m)
    assert np.max(np.abs(f - _iso6358(r, b, m) * choked)) < 5e-3 * choked
    assert np.allclose(flow_function(p_u, p_u * r, GAS, b, 0.5),
                       flow_function(p_u, p_u * r, GAS, b), rtol=1e-13, atol=0.0)


def test_a_lower_ratio_keeps_the_port_choked_longer():
    """At a ratio between b and 0.528 the port passes less than eq. 3's choked flow."""
    p_u, r = 6e5, 0.45
    assert flow_function(p_u, p_u * r, GAS) == pytest.approx(GAS.beta_s_per_m * p_u)
    assert flow_function(p_u, p_u * r, GAS, 0.3) < 0.99 * GAS.beta_s_per_m * p_u


@pytest.mark.parametrize("b, r, m", [(0.3, 0.5, 0.0), (0.3, 0.8, 0.0), (0.3, 0.97, 0.0),
                                     (0.6, 0.7, 0.0), (0.3, 1.4, 0.0), (0.3, 3.0, 0.0),
                                     (0.3, 0.8, 0.35), (0.3, 0.97, 0.8), (0.3, 2.0, 0.65)])
def test_the_slopes_are_the_flows_derivatives(b, r, m):
    """:func:`flow_partials` against central differences, forward and reversed."""
    a, be, th, k = GAS.alpha_s_per_m, GAS.beta_s_per_m, GAS.theta, GAS.heat_capacity_ratio
    p_u = 4e5
    _, du, dd = flow_partials(p_u, r * p_u, a, be, th, k, 0.0, b, m)
    h = 0.5

    def f(up, down):
        return flow_function(up, down, GAS, b, m)

    fdu = (f(p_u + h, r * p_u) - f(p_u - h, r * p_u)) / (2 * h)
    fdd = (f(p_u, r * p_u + h) - f(p_u, r * p_u - h)) / (2 * h)
    assert du == pytest.approx(fdu, rel=1e-6, abs=1e-12)
    assert dd == pytest.approx(fdd, rel=1e-6, abs=1e-12)


def test_reversed_flow_swaps_the_ends():
    assert flow_function(2e5, 5e5, GAS, 0.3) == pytest.approx(-flow_function(5e5, 2e5, GAS, 0.3))


@pytest.mark.parametrize("bad", [-0.1, 1.0, 1.5, np.nan])
def test_a_ratio_outside_0_1_is_an_error(bad):
    with pytest.raises(ValueError, match="critical_ratio"):
        flow_function(5e5, 2e5, GAS, bad)
    with pytest.raises(ValueError, match="subsonic_index"):
        flow_function(5e5, 2e5, GAS, 0.3, -abs(bad) - 0.1 if np.isfinite(bad) else bad)


# ---------------------------------------------------------------- the simulator
def test_at_eq_3s_ratio_the_simulation_is_the_models_without_it(rig, steps, valve_params):
    plain = simulate(Model(), valve_params, steps, rig, 2e5, _tight()).pressure_Pa[0]
    for form in CriticalRatio.forms:
        effect = CriticalRatio(form=form)
        got = simulate(Model([effect]), dict(valve_params, **effect.neutral_values()), steps,
                       rig, 2e5, _tight()).pressure_Pa[0]
        assert np.max(np.abs(got - plain)) < 1e-6


_VALUES = {"shared": {"critical_ratio": 0.3},
           "ports": {"inlet_critical_ratio": 0.25, "exhaust_critical_ratio": 0.4},
           "iso6358": {"inlet_critical_ratio": 0.25, "exhaust_critical_ratio": 0.4,
                       "subsonic_index": 0.7}}


@pytest.mark.parametrize("others", [[], ["cylinder_leak"], ["heat_transfer"]])
@pytest.mark.parametrize("form", CriticalRatio.forms)
def test_the_simulator_agrees_with_the_reference(rig, steps, valve_params, others, form):
    """Compiled vs scipy Radau (rtol 1e-10) where the ratio moves the pressure by tens of
    kPa; the error falls with the tolerance."""
    model = Model([CriticalRatio(form=form), *others])
    params = dict(valve_params, **_VALUES[form])
    for other in others:
        params.update(model.effect(other).bench_defaults())
    ref, errs = reference_errors(model, params, steps, rig, 2e5)
    plain = simulate(Model(list(others)), {k: v for k, v in params.items()
                                          if k not in _VALUES[form]},
                     steps, rig, 2e5, _tight()).pressure_Pa[0]
    assert np.max(np.abs(ref - plain)) > 1e4
    assert errs[1] < 0.5 and errs[1] < 0.2 * errs[0], errs


def test_beside_the_acoustic_line_it_agrees_with_the_reference(rig, steps, valve_params):
    model = Model([CriticalRatio(form="iso6358"),
                   make_effect("tube_delay", form="line", segments=3)])
    params = dict(valve_params, **_VALUES["iso6358"], tube_delay_s=1.5e-3,
                  tube_diameter_m=0.003, dead_volume_m3=2.4e-6 + 7.07e-6 * 0.51)
    ref = reference_simulate(model, params, steps, rig, 2e5, rtol=1e-10)
    got = simulate(model, params, steps, rig, 2e5, _tight(1e-9)).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) < 1.0


@pytest.mark.parametrize("b", [0.3, 0.5])
def test_full_inlet_reaches_the_supply_and_full_exhaust_the_atmosphere(rig, b):
    from test_plant import CLOSABLE

    t = np.arange(3001) * 1e-3
    model = Model([CriticalRatio()])
    params = dict(CLOSABLE, dead_volume_m3=2.4e-6, critical_ratio=b)
    for u, p0, end in ((5.0, P_ATM, P_SUP), (-5.0, P_SUP, P_ATM)):
        inp = Inputs(t, np.full(t.size, u), np.full(t.size, 0.02), np.full(t.size, P_SUP))
        p = simulate(model, params, inp, rig, p0, SolverConfig.reference()).pressure_Pa[0]
        assert p[-1] == pytest.approx(end, abs=20.0)


def test_a_shut_valve_and_no_leak_keep_the_pressure(rig):
    from test_plant import CLOSABLE

    t = np.arange(501) * 1e-3
    inp = Inputs(t, np.zeros(t.size), np.full(t.size, 0.02), np.full(t.size, P_SUP))
    params = dict(CLOSABLE, dead_volume_m3=2.4e-6, critical_ratio=0.3)
    p = simulate(Model([CriticalRatio()]), params, inp, rig, 3e5,
                 SolverConfig.reference()).pressure_Pa[0]
    assert np.max(np.abs(p - 3e5)) < 1e-6


def test_behind_the_wave_tube_it_agrees_with_the_plants_iso_6358_valve(rig):
    """The plant's 48-cell tube behind ISO 6358 ports (b = 0.3, index 0.7; written apart,
    LSODA) against the wave tube with the effect at those values: as close as the wave
    tube is to the plant's tube with eq. 3's ports (the test of ``test_wave.py``), many
    times closer than the wave tube with eq. 3's ports."""
    from test_wave import _params, _steps

    from pneubayes.bench.forms import AcousticTube, Iso6358Ports
    from pneubayes.bench.plant import PlantConfig, simulate_plant
    from pneubayes.physics.valve import valve_preset

    dt = 1e-4
    t = np.arange(6001) * dt
    x = 0.01875 + 0.01 * np.sin(2 * np.pi * 3.0 * t)
    inputs = Inputs(t, _steps(1, t.size, dt), x, np.full(t.size, P_SUP))
    base = dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)
    params, _ = _params(rig, 1.0, 0.002)
    ref = simulate_plant(base, (AcousticTube(1.0, 0.002, segments=48),
                                Iso6358Ports(critical_pressure_ratio=0.3,
                                             subsonic_index=0.7)), inputs, rig,
                         P_ATM, PlantConfig.reference()).pressure_Pa
    wave = make_effect("tube_delay", form="wave", segments=8)
    got = simulate(Model([wave, CriticalRatio(form="iso6358")]),
                   dict(params, inlet_critical_ratio=0.3, exhaust_critical_ratio=0.3,
                        subsonic_index=0.7),
                   inputs, rig, P_ATM, SolverConfig.reference()).pressure_Pa[0]
    eq3 = simulate(Model([wave]), params, inputs, rig, P_ATM,
                   SolverConfig.reference()).pressure_Pa[0]
    rms = float(np.sqrt(np.mean((got - ref) ** 2)))
    rms_eq3 = float(np.sqrt(np.mean((eq3 - ref) ** 2)))
    assert rms < 300.0, rms
    assert rms_eq3 > 3.0 * rms, (rms_eq3, rms)


def test_beside_a_restriction_or_a_tank_it_is_refused(rig, steps, valve_params):
    for other, extra in (("supply_restriction", {"supply_restriction": 2e6}),
                         ("port_restriction", None)):
        model = Model([CriticalRatio(), other])
        params = dict(valve_params, critical_ratio=0.3,
                      **(extra or model.effect(other).bench_defaults()))
        with pytest.raises(FormCombinationError, match="critical_ratio"):
            simulate(model, params, steps, rig, 2e5, _tight())


# ---------------------------------------------------------------- discovery's forms
def test_each_later_form_starts_from_the_last_ones_fit():
    """shared -> ports -> iso6358, each started at the last fit's ratios with every new
    parameter given (the follow-up's start is the fit's values and these)."""
    nxt, start = CriticalRatio().form_after_fit({"critical_ratio": 0.33}, None)
    assert nxt.form == "ports" and start == {"inlet_critical_ratio": 0.33,
                                             "exhaust_critical_ratio": 0.33}
    last, start2 = nxt.form_after_fit({"inlet_critical_ratio": 0.31,
                                       "exhaust_critical_ratio": 0.36}, None)
    assert last.form == "iso6358" and set(start2) == set(last.parameter_names())
    assert start2["subsonic_index"] == last.neutral_values()["subsonic_index"] == 0.5
    assert last.form_after_fit(start2, None) is None


# ---------------------------------------------------------------- a fit
def test_a_planted_ratio_is_recovered_by_a_trajectory_fit(rig, valve_params):
    """Noise-free fills and vents of valve 1 at b = 0.32: the trajectory refinement of the
    ratio alone from eq. 3's finds it within 1 %."""
    model = Model([CriticalRatio()])
    got = refit_planted(model, dict(valve_params, critical_ratio=0.32), "critical_ratio",
                        0.5, seed=12)
    assert got == pytest.approx(0.32, rel=1e-2)
