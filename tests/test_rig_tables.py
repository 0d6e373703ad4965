"""Tabulated rig card kinds: a valve's command -> area table (valve kind ``table``) and a
chamber's volume against a measured coordinate (chamber kind ``table``): equivalences,
conservation, limits, the reference solver, planted-parameter recovery and bad cards."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from rig_helpers import assert_converges_to, edited_card

from pneubayes.effects.path import TABLE_MAX_POINTS
from pneubayes.errors import RigCardError
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.valve import gompertz_area
from pneubayes.rig import Rig
from pneubayes.rigcard import KINDS, RigCard
from pneubayes.simulation import Inputs, SolverConfig, simulate
from pneubayes.simulation.rates import port_areas
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 601325.0
TIGHT = SolverConfig(rtol=1e-8, atol_Pa=1e-3, atol_K=1e-4, max_step_s=1e-3,
                     min_step_s=1e-14, max_steps_per_s=5e7)
GAS = GasConstants(temperature_K=296.0)
RIG = Rig(0.01, P_ATM, P_SUP, gas=GAS)

BASE = {
    "format": "pneubayes-rig/1", "name": "tabulated valve",
    "atmospheric_pressure_Pa": P_ATM, "temperature_K": 296.0,
    "command": {"unit": "V", "range": [-5.0, 5.0]},
    "chamber": {"kind": "fixed", "volume_m3": 3e-5},
    "valve": {"kind": "table", "command": [-2.0, -1.0, 0.0, 1.0, 2.0],
              "inlet_area_m2": [0.0, 0.0, 1e-8, 4e-7, 1e-6],
              "exhaust_area_m2": [1.2e-6, 5e-7, 1e-8, 0.0, 0.0]},
    "supply": {"kind": "constant", "pressure_Pa": P_SUP},
}


def card(**changes) -> RigCard:
    return edited_card(BASE, **changes)


def inputs(t, u, x=None):
    return Inputs(t, u, np.zeros_like(t) if x is None else x, np.full(t.shape, P_SUP))


def run(c, inp, p0, params=None, effects=(), solver=TIGHT):
    m = Model(list(effects), rig_card=c)
    return simulate(m, params if params is not None else np.zeros((1, 0)), inp, RIG, p0,
                    solver).pressure_Pa[0]


def test_the_table_kinds_are_registered_and_round_trip():
    assert {("valve", "table"), ("chamber", "table")} <= set(KINDS)
    c = card(valve__inlet_scale={"prior": "log-uniform", "bounds": [0.1, 10.0]})
    assert RigCard.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    assert Model(rig_card=c).parameter_names == ("valve_inlet_scale",)


def test_the_tables_areas_are_linear_between_points_and_flat_beyond():
    c = card(valve__inlet_scale=2.0)
    sl = Model(rig_card=c).lower(np.zeros((1, 0)), RIG)[0]
    u = np.array([-3.0, -1.5, 0.5, 1.5, 2.0, 4.0])
    a_in, a_ex = port_areas(sl, u)
    np.testing.assert_allclose(a_in, 2.0 * np.array([0, 0, 2.05e-7, 7e-7, 1e-6, 1e-6]),
                               rtol=1e-12)
    np.testing.assert_allclose(a_ex, [1.2e-6, 8.5e-7, 5e-9, 0, 0, 0], rtol=1e-12, atol=1e-20)


def test_a_two_point_table_is_the_switching_valve():
    """A table [0, 1] -> inlet [0, A], exhaust [B, 0] is a switching valve of open area A
    and exhaust area B, also while its opening lags (the areas' rates agree)."""
    table = card(command={"unit": "duty", "range": [0.0, 1.0]},
                 valve={"kind": "table", "command": [0.0, 1.0],
                        "inlet_area_m2": [0.0, 1e-6], "exhaust_area_m2": [8e-7, 0.0]})
    switching = card(command={"unit": "duty", "range": [0.0, 1.0]},
                     valve={"kind": "switching", "open_area_m2": 1e-6,
                            "exhaust_area_m2": 8e-7, "opening_delay_s": 0.0,
                            "opening_time_constant_s": 0.0})
    t = np.arange(601) * 1e-3
    u = np.round(0.5 + 0.5 * np.sin(2 * np.pi * 3 * t), 1)
    for effects, params in (((), None), (("spool_lag",), {"spool_time_constant_s": 0.006})):
        a = run(table, inputs(t, u), 2e5, params, effects)
        b = run(switching, inputs(t, u), 2e5, params, effects)
        assert np.ptp(a) > 1e5
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)


def test_a_closed_table_valve_keeps_the_pressure_and_its_limits_are_supply_and_atmosphere():
    c = card(valve__inlet_area_m2=[0.0, 0.0, 0.0, 4e-7, 1e-6],
             valve__exhaust_area_m2=[1.2e-6, 5e-7, 0.0, 0.0, 0.0])
    t = np.arange(2001) * 1e-3
    kept = run(c, inputs(t, np.zeros_like(t)), 3e5)
    assert np.max(np.abs(kept - 3e5)) < 1e-6
    filled = run(c, inputs(t, np.full_like(t, 5.0)), P_ATM)
    vented = run(c, inputs(t, np.full_like(t, -5.0)), P_SUP)
    assert abs(filled[-1] - P_SUP) < 1.0 and abs(vented[-1] - P_ATM) < 1.0
    assert np.all(np.diff(filled) >= -1e-2) and np.all(np.diff(vented) <= 1e-2)


def test_a_lagging_table_valve_matches_the_reference_solver():
    c = card()
    t = np.arange(301) * 1e-3
    u = 2.5 * np.sin(2 * np.pi * 4 * t) + 0.3 * np.sin(2 * np.pi * 23 * t)
    params = {"spool_time_constant_s": 0.004}
    m = Model(["spool_lag"], rig_card=c)
    ref = reference_simulate(m, params, inputs(t, u), RIG, 2e5, method="DOP853",
                             rtol=1e-10, atol=1e-5)
    std = run(c, inputs(t, u), 2e5, params, ("spool_lag",), SolverConfig.standard())
    tight = run(c, inputs(t, u), 2e5, params, ("spool_lag",),
                SolverConfig.standard().tightened(100))
    assert_converges_to(ref, std, tight, min_span=1e5, std_of_span=1e-3, shrink=0.5)


def test_a_fine_table_of_a_gompertz_map_simulates_as_the_map():
    """Sixteen points of the paper's valve 1 (eq. 11, Table II) reproduce its fills to
    within the table's interpolation error."""
    from pneubayes.physics.valve import VALVES

    v = VALVES["valve1"]
    cmd = np.linspace(-5.0, 5.0, TABLE_MAX_POINTS)
    tab = card(valve={"kind": "table", "command": cmd.tolist(),
                      "inlet_area_m2": v.inlet.area(cmd).tolist(),
                      "exhaust_area_m2": v.exhaust.area(cmd).tolist()})
    gom = card(valve={"kind": "gompertz", **v.parameters()})
    t = np.arange(1001) * 1e-3
    u = np.repeat([1.5, -0.8, 3.0, -2.5, 0.4], 200)[: t.size]
    u = np.concatenate([u, [u[-1]]])
    a, b = run(tab, inputs(t, u), 2e5), run(gom, inputs(t, u), 2e5)
    # a chord of eq. 11 over a 0.67 V interval differs from it by a few percent of area
    assert np.sqrt(np.mean((a - b) ** 2)) < 0.03 * np.ptp(b)
    fine = np.linspace(-5, 5, 401)
    lin = np.interp(fine, cmd, v.inlet.area(cmd))
    assert np.max(np.abs(lin - gompertz_area(fine, *list(v.parameters().values())[:5]))) > 0


def _recording(tmp_path, card_dict, t, u, p, name):
    (tmp_path / "rig.json").write_text(json.dumps(card_dict))
    rows = "".join(f"{a:.17g},{b:.17g},{c:.17g}\n" for a, b, c in zip(t, u, p))
    (tmp_path / f"{name}.csv").write_text("time_s,command_V,pressure_Pa\n" + rows)
    (tmp_path / f"{name}.json").write_text(json.dumps({"rig": "rig.json"}))
    return read_recording(tmp_path / f"{name}.csv")


def test_a_planted_inlet_scale_is_recovered_by_least_squares(tmp_path):
    from pneubayes.inference.pipeline import FitSettings
    from pneubayes.inference.refine import TrajectoryRefiner
    from pneubayes.inference.windows import WindowSet

    d = copy.deepcopy(BASE)
    d["valve"]["inlet_scale"] = {"prior": "log-uniform", "bounds": [0.1, 10.0]}
    d["valve"]["exhaust_scale"] = {"prior": "log-uniform", "bounds": [0.1, 10.0]}
    c = RigCard.from_dict(d, "card.json")
    m = Model(rig_card=c)
    rng = np.random.default_rng(11)  # seed recorded here
    recs = []
    for k in range(2):
        t = np.arange(1000) * 1e-3
        u = np.repeat(rng.uniform(-2.5, 2.5, 10), 100)
        p = simulate(m, {"valve_inlet_scale": 1.7, "valve_exhaust_scale": 0.6},
                     inputs(t, u), RIG, P_ATM + 5e4, TIGHT).pressure_Pa[0]
        p = p + rng.normal(0.0, 300.0, p.size)
        recs.append(_recording(tmp_path, d, t, u, p, f"r{k}"))
    ref = TrajectoryRefiner(m, FitSettings().refine_solver, max_nfev=60).fit(
        WindowSet(recs, 0.5, 0.5), {"valve_inlet_scale": 1.0, "valve_exhaust_scale": 1.0})
    assert math.isclose(ref.params_["valve_inlet_scale"], 1.7, rel_tol=0.02)
    assert math.isclose(ref.params_["valve_exhaust_scale"], 0.6, rel_tol=0.02)


# ---------------------------------------------------------------- chamber table
def test_a_chamber_table_is_the_polynomial_chamber_on_its_points():
    """A table sampled from a polynomial V(s) and the polynomial itself give the same
    equivalent piston at the table's points, and a closed chamber keeps p V^n."""
    coeffs = [3.141e-3, -3.251e-2, 0.128]
    s_pts = np.linspace(0.0, 0.03, 7)
    dv = np.polyval([*reversed(coeffs), 0.0], s_pts)
    tab = card(chamber={"kind": "table", "dead_volume_m3": 6.6e-5,
                        "coordinate_m": s_pts.tolist(), "volume_change_m3": dv.tolist()},
               valve__inlet_area_m2=[0.0, 0.0, 0.0, 4e-7, 1e-6],
               valve__exhaust_area_m2=[1.2e-6, 5e-7, 0.0, 0.0, 0.0])  # closed at 0
    ch = tab.chamber
    np.testing.assert_allclose(ch.area_m2 * ch.equivalent_position_m(s_pts), dv, rtol=1e-12)
    md = tab.metadata_defaults()
    rig = Rig(md["bore_m"], P_ATM, P_SUP, GAS, stroke_m=md["stroke_m"])
    t = np.arange(1001) * 1e-3
    s = 0.015 * (1 - np.cos(2 * np.pi * t))
    x = ch.equivalent_position_m(s)
    p = simulate(Model(rig_card=tab), np.zeros((1, 0)), inputs(t, 0 * t, x), rig, 3e5,
                 TIGHT).pressure_Pa[0]
    vol = 6.6e-5 + ch.area_m2 * x
    kappa = GAS.heat_capacity_ratio
    np.testing.assert_allclose(p * vol ** kappa, 3e5 * vol[0] ** kappa, rtol=2e-4)
    # beyond the ends the end segments are extended
    slope = (dv[-1] - dv[-2]) / (s_pts[-1] - s_pts[-2])
    assert math.isclose(ch.area_m2 * float(ch.equivalent_position_m(0.031)),
                        dv[-1] + slope * 0.001, rel_tol=1e-12)


# ---------------------------------------------------------------- bad cards
@pytest.mark.parametrize("changes, words", [
    ({"valve__inlet_area_m2": [0.0, 1e-7, 5e-8, 4e-7, 1e-6]},
     ["'inlet_area_m2' [2]", "non-decreasing"]),
    ({"valve__exhaust_area_m2": [1.2e-6, 5e-7, 6e-7, 0.0, 0.0]},
     ["'exhaust_area_m2' [2]", "non-increasing"]),
    ({"valve__command": [-2.0, -1.0, -1.0, 1.0, 2.0]}, ["'command' [2]", "strictly"]),
    ({"valve__command": [-2.0, -1.0, 0.0, 1.0]}, ["'inlet_area_m2'", "one value per"]),
    ({"valve__inlet_area_m2": [0.0, -1e-9, 1e-8, 4e-7, 1e-6]}, ["[1]", ">= 0"]),
    ({"valve__command": list(range(TABLE_MAX_POINTS + 1))}, ["'command'", "2 to 16"]),
    ({"valve__inlet_area_m2": [0.0] * 5}, ["never opens"]),
    ({"valve__exhaust_area_m2": [0.0] * 5, "valve__exhaust_scale": 2.0},
     ["'exhaust_scale'", "no exhaust"]),
    ({"valve__inlet_scale": -1.0}, ["'inlet_scale'", "> 0"]),
    ({"valve__area_m2": [1, 2]}, ["unknown key", "'area_m2'"]),
    ({"exhaust": {"kind": "linear", "command": {"unit": "binary"}, "open_area_m2": 1e-6}},
     ["'exhaust_area_m2'", "separate valve"]),
    ({"chamber": {"kind": "table", "dead_volume_m3": 1e-5, "coordinate_m": [0.0, 0.01],
                  "volume_change_m3": [0.0, 0.0]}}, ["'volume_change_m3' [1]", "strictly"]),
    ({"chamber": {"kind": "table", "dead_volume_m3": 1e-5, "coordinate_m": [0.0],
                  "volume_change_m3": [0.0]}}, ["'coordinate_m'", "at least 2"]),
])
def test_bad_tables_name_the_key_and_the_point(changes, words):
    with pytest.raises(RigCardError) as err:
        card(**changes)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_a_table_valve_without_exhaust_works_beside_a_separate_exhaust():
    c = card(valve__exhaust_area_m2=[0.0] * 5, valve__inlet_area_m2=[0.0, 0.0, 0.0, 4e-7, 1e-6],
             exhaust={"kind": "linear", "command": {"unit": "binary"}, "open_area_m2": 1e-6})
    t = np.arange(1001) * 1e-3
    inp = Inputs(t, np.zeros_like(t), np.zeros_like(t), np.full(t.shape, P_SUP), None,
                 np.ones_like(t))
    p = run(c, inp, 3e5)
    assert abs(p[-1] - P_ATM) < 10.0
