"""A separately commanded exhaust valve and a finite supply tank (rig card kinds
``exhaust: gompertz | linear`` and ``supply: tank``): closed forms, conservation, limits,
the reference solver, equivalences and bad cards."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from rig_helpers import assert_converges_to, edited_card

from pneubayes.errors import RecordingError, RigCardError
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.physics.gas import GasConstants
from pneubayes.rig import Rig
from pneubayes.rigcard import KINDS, RigCard
from pneubayes.simulation import Inputs, SolverConfig, simulate
from pneubayes.simulation.rates import port_areas
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_TANK = 101325.0, 601325.0
TIGHT = SolverConfig(rtol=1e-8, atol_Pa=1e-3, atol_K=1e-4, max_step_s=1e-3,
                     min_step_s=1e-14, max_steps_per_s=5e7)
GAS = GasConstants(temperature_K=296.0)
RIG = Rig(0.01, P_ATM, P_TANK, gas=GAS)

BASE = {
    "format": "pneubayes-rig/1", "name": "two valves and a tank",
    "atmospheric_pressure_Pa": P_ATM, "temperature_K": 296.0,
    "command": {"unit": "duty", "range": [0.0, 1.0]},
    "chamber": {"kind": "fixed", "volume_m3": 5e-5},
    "valve": {"kind": "gompertz", "inlet_offset_m2": 0.0, "inlet_a_m2": 2e-6,
              "inlet_b": 5.0, "inlet_c_per_V": 10.0, "inlet_d_V": -0.3},
    "exhaust": {"kind": "gompertz", "command": {"unit": "duty"}, "column": "cmd_exh",
                "offset_m2": 0.0, "a_m2": 3e-6, "b": 5.0, "c_per_V": 10.0, "d_V": -0.3},
    "supply": {"kind": "tank", "volume_m3": 2e-4, "initial_pressure_Pa": P_TANK},
}


def card(**changes) -> RigCard:
    return edited_card(BASE, **changes)


def inputs(t, u, ue):
    return Inputs(t, u, np.zeros_like(t), np.full(t.shape, P_TANK), None, ue)


def run(c, inp, p0, solver=TIGHT):
    return simulate(Model(rig_card=c), np.zeros((1, 0)), inp, RIG, p0, solver).pressure_Pa[0]


def test_the_new_kinds_are_registered():
    assert {("exhaust", "gompertz"), ("exhaust", "linear"), ("supply", "tank")} <= set(KINDS)


def test_card_with_exhaust_and_tank_round_trips_and_closes_the_valves_own_exhaust():
    c = card()
    assert RigCard.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    assert all(c.valve.values[k] == 0.0 for k in c.valve.values if k.startswith("exhaust_"))
    fitted = card(exhaust__a_m2={"prior": "log-uniform", "bounds": [1e-8, 1e-4]},
                  supply__volume_m3={"prior": "log-uniform", "bounds": [1e-5, 1e-2]})
    assert Model(rig_card=fitted).parameter_names == ("tank_volume_m3", "exhaust_valve_a_m2")


@pytest.mark.parametrize("changes, words", [
    ({"valve__exhaust_a_m2": 1e-6}, ["'valve'", "separate valve", "exhaust_a_m2"]),
    ({"exhaust": {"kind": "gompertz", "a_m2": 1e-6}}, ["'exhaust' -> 'command'", "missing"]),
    ({"exhaust": {"kind": "valve9", "command": {"unit": "duty"}}},
     ["'exhaust' -> 'kind'", "gompertz", "linear"]),
    ({"exhaust__c_per_V": -3.0}, ["'c_per_V'", "> 0"]),
    ({"exhaust__column": ""}, ["'column'"]),
    ({"supply__chambers_fed": 0}, ["'chambers_fed'", "integer >= 1"]),
    ({"supply__initial_pressure_Pa": "full"}, ["'initial_pressure_Pa'", "measured"]),
    ({"supply__volume_m3": -1.0}, ["'volume_m3'", "> 0"]),
])
def test_bad_exhaust_and_tank_tables_name_the_key(changes, words):
    with pytest.raises(RigCardError) as err:
        card(**changes)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_a_switching_valve_with_its_own_exhaust_area_refuses_a_separate_exhaust():
    d = copy.deepcopy(BASE)
    d["command"] = {"unit": "binary"}
    d["valve"] = {"kind": "switching", "open_area_m2": 1e-6, "exhaust_area_m2": 1e-6,
                  "opening_delay_s": 0.0, "opening_time_constant_s": 0.0}
    with pytest.raises(RigCardError, match="'exhaust_area_m2'.*set this to 0"):
        RigCard.from_dict(d, "card.json")
    d["valve"]["exhaust_area_m2"] = 0.0
    assert RigCard.from_dict(d, "card.json").exhaust.kind == "gompertz"


# ------------------------------------------------------------------ exhaust valve
def test_the_separate_exhaust_is_the_one_valves_exhaust_when_its_command_mirrors_it():
    """A one-valve exhaust map a(u) with c < 0 equals a separate map with c > 0 on the
    command -u (d -> -d): the same pressures from the same kernel."""
    one = copy.deepcopy(BASE)
    one.pop("exhaust")
    one["command"] = {"unit": "V", "range": [-1.0, 1.0]}
    one["supply"] = {"kind": "constant", "pressure_Pa": P_TANK}
    one["valve"].update({"exhaust_offset_m2": 1e-9, "exhaust_a_m2": 3e-6, "exhaust_b": 5.0,
                         "exhaust_c_per_V": -10.0, "exhaust_d_V": 0.2})
    sep = copy.deepcopy(one)
    sep["valve"] = {k: v for k, v in one["valve"].items() if not k.startswith("exhaust_")}
    sep["exhaust"] = {"kind": "gompertz", "command": {"unit": "V", "range": [-1.0, 1.0]},
                      "offset_m2": 1e-9, "a_m2": 3e-6, "b": 5.0, "c_per_V": 10.0,
                      "d_V": -0.2}
    t = np.arange(801) * 1e-3
    u = np.round(np.sin(2 * np.pi * 3 * t), 1)
    a = run(RigCard.from_dict(one), inputs(t, u, None), P_ATM)
    b = run(RigCard.from_dict(sep), inputs(t, u, -u), P_ATM)
    assert np.ptp(a) > 1e5
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-6)
    # the rates layer (discovery's equation error) agrees on the areas
    c_sep = RigCard.from_dict(sep)
    sl = Model(rig_card=c_sep).lower(np.zeros((1, 0)), RIG)[0]
    sl_one = Model(rig_card=RigCard.from_dict(one)).lower(np.zeros((1, 0)), RIG)[0]
    np.testing.assert_allclose(port_areas(sl, u, -u), port_areas(sl_one, u), rtol=1e-12)


def test_closed_valves_keep_the_pressure_and_an_open_exhaust_alone_vents_to_atmosphere():
    c = card(supply={"kind": "constant", "pressure_Pa": P_TANK},
             exhaust={"kind": "linear", "command": {"unit": "binary"}, "open_area_m2": 2e-6})
    t = np.arange(2001) * 1e-3
    zero = np.zeros_like(t)
    kept = run(c, inputs(t, zero, zero), 3e5)
    assert np.max(np.abs(kept - 3e5)) < 1e-6
    vented = run(c, inputs(t, zero, np.ones_like(t)), 3e5)
    assert abs(vented[-1] - P_ATM) < 1.0 and np.all(np.diff(vented) <= 1e-2)


def test_a_model_with_a_separate_exhaust_needs_the_exhaust_command():
    t = np.arange(11) * 1e-3
    with pytest.raises(ValueError, match="no exhaust command"):
        run(card(), inputs(t, 0 * t, None), P_ATM)


# ------------------------------------------------------------------ tank
def test_a_tank_feeding_a_closed_chamber_ends_at_the_shared_pressure():
    """Only the port exchanges air: V p + V_t P_t is conserved (eq. 5 in both volumes),
    so the two settle at (V p0 + V_t P_t0) / (V + V_t)."""
    c = card(exhaust={"kind": "linear", "command": {"unit": "duty"}, "open_area_m2": 1e-6})
    t = np.arange(3001) * 1e-3
    p = run(c, inputs(t, np.ones_like(t), np.zeros_like(t)), P_ATM)
    v, vt = 5e-5, 2e-4
    shared = (v * P_ATM + vt * P_TANK) / (v + vt)
    assert abs(p[-1] - shared) < 0.01  # and it stays there: no drift at balance
    assert np.all(np.diff(p) >= -1e-2)


def test_a_large_tank_is_a_constant_supply_and_chambers_fed_divides_the_volume():
    t = np.arange(601) * 1e-3
    inp = inputs(t, (t > 0.05) * 0.8, (t > 0.3) * 1.0)
    const = run(card(supply={"kind": "constant", "pressure_Pa": P_TANK}), inp, P_ATM)
    big = run(card(supply__volume_m3=1e3), inp, P_ATM)
    np.testing.assert_allclose(big, const, atol=0.05)
    four = run(card(supply__volume_m3=8e-4, supply__chambers_fed=4), inp, P_ATM)
    one = run(card(supply__volume_m3=2e-4), inp, P_ATM)
    np.testing.assert_allclose(four, one, atol=1e-6)
    assert np.max(const - one) > 1e4  # the small tank's drop is visible


def test_tank_and_separate_exhaust_match_the_reference_solver_and_converge():
    t = np.arange(251) * 2e-3
    u = (np.sin(2 * np.pi * 4 * t) > 0) * 0.8
    inp = inputs(t, u, 1.0 - u / 0.8)
    c = card()
    ref = reference_simulate(Model(rig_card=c), np.zeros(0), inp, RIG, P_ATM,
                             method="DOP853", rtol=1e-10, atol=1e-5)
    std = run(c, inp, P_ATM, SolverConfig.standard())
    tight = run(c, inp, P_ATM, SolverConfig.standard().tightened(100))
    # within the standard preset's 0.1 % floor, tenfold
    assert_converges_to(ref, std, tight, min_span=2e5, std_of_span=1e-4, shrink=0.5)


def test_a_tank_cannot_join_a_heat_or_line_model():
    m = Model(["heat_transfer"], rig_card=card())
    t = np.arange(11) * 1e-3
    params = {n: m.parameter(n).upper * 0.5 for n in m.parameter_names}
    with pytest.raises(ValueError, match="supply tank"):
        simulate(m, params, inputs(t, 0 * t, 0 * t), RIG, P_ATM, TIGHT)


def test_a_tank_starts_at_each_windows_measured_supply_or_carries_between_windows():
    from pneubayes.simulation import simulate_windows

    c = card(supply={"kind": "tank", "volume_m3": 2e-4, "initial_pressure_Pa": "measured"})
    t = np.arange(201) * 1e-3
    sup = np.linspace(P_TANK, 4e5, t.size)  # a gauge that is only read at window starts
    inp = Inputs(t, np.full(t.shape, 0.8), np.zeros_like(t), sup, None, np.zeros_like(t))
    m = Model(rig_card=c)
    # separate windows each start charged at the supply sample there
    sep = simulate_windows(m, np.zeros((1, 0)), inp, RIG, np.array([0, 50]), 100,
                           np.array([P_ATM, P_ATM]), TIGHT)[0]
    alone = simulate_windows(m, np.zeros((1, 0)), inp, RIG, np.array([50]), 100,
                             np.array([P_ATM]), TIGHT)[0, 0]
    np.testing.assert_allclose(sep[1], alone, atol=1e-6)
    # contiguous windows carry the tank: the same as one long window
    whole = simulate(m, np.zeros((1, 0)), inp, RIG, P_ATM, TIGHT).pressure_Pa[0]
    start2 = whole[100]
    chained = simulate_windows(m, np.zeros((1, 0)), inp, RIG, np.array([0, 100]), 101,
                               np.array([P_ATM, start2]), TIGHT)[0]
    np.testing.assert_allclose(chained[1], whole[100:], atol=1e-3)


SIDECAR = {"rig": "rig.json", "supply_pressure_Pa": P_TANK}


def test_a_tank_measured_at_start_needs_a_supply_column_and_the_exhaust_its_column(tmp_path):
    d = copy.deepcopy(BASE)
    d["supply"]["initial_pressure_Pa"] = "measured"
    (tmp_path / "rig.json").write_text(json.dumps(d))
    head = "time_s,command_V,pressure_Pa"
    rows = "".join(f"{0.001 * i},0.5,{P_ATM},{{}}\n" for i in range(20))
    (tmp_path / "a.csv").write_text(head + ",cmd_exh\n" + rows.replace("{}", "0.2"))
    (tmp_path / "a.json").write_text(json.dumps(SIDECAR))
    with pytest.raises(RecordingError, match="'tank'.*needs a supply pressure column"):
        read_recording(tmp_path / "a.csv")
    (tmp_path / "b.csv").write_text(head + ",supply_pressure_Pa\n"
                                    + rows.replace("{}", str(P_TANK)))
    (tmp_path / "b.json").write_text(json.dumps(SIDECAR))
    with pytest.raises(RecordingError, match="command column 'cmd_exh' is not in"):
        read_recording(tmp_path / "b.csv")
    (tmp_path / "c.csv").write_text(head + ",supply_pressure_Pa,cmd_exh\n" + "".join(
        f"{0.001 * i},0.5,{P_ATM},{P_TANK},{1.5 if i == 4 else 0.2}\n" for i in range(20)))
    (tmp_path / "c.json").write_text(json.dumps(SIDECAR))
    with pytest.raises(RecordingError, match=r"column 'cmd_exh' row 5: command 1.5"):
        read_recording(tmp_path / "c.csv")
    (tmp_path / "d.csv").write_text(head + ",supply_pressure_Pa,cmd_exh\n" + "".join(
        f"{0.001 * i},0.5,{P_ATM},{P_TANK},0.25\n" for i in range(20)))
    (tmp_path / "d.json").write_text(json.dumps(SIDECAR))
    rec = read_recording(tmp_path / "d.csv")
    assert np.all(Inputs.from_recording(rec).exhaust_command == 0.25)


def test_discovery_proposes_no_critical_ratio_beside_a_supply_tank():
    """A port's own critical ratio is not stepped beside a supply tank: the search's
    library leaves it out (the loop crashed in its first round), and keeps the effects
    the simulator steps there."""
    from pneubayes.discovery.library import steppable_beside
    model = Model(rig_card=card())
    assert not steppable_beside(model, {}, "critical_ratio", RIG)
    assert steppable_beside(model, {}, "cylinder_leak", RIG)
