"""Rig cards (pneubayes-rig/1): reading, bad cards, the components' physics and binding."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from rig_helpers import edited_card

from pneubayes.errors import ModelCardError, RecordingError, RigCardError
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.rigcard import KINDS, RigCard, load_rig_card
from pneubayes.simulation import Inputs, SolverConfig, simulate
from pneubayes.simulation.reference import reference_simulate

ROOT = Path(__file__).resolve().parents[1]
GTD = ROOT / "data" / "real" / "gtdynamics"
P_ATM, P_SUP = 101325.0, 601325.0
TIGHT = SolverConfig(rtol=1e-8, atol_Pa=1e-3, atol_K=1e-4, max_step_s=1e-3,
                     min_step_s=1e-14, max_steps_per_s=5e7)

CARD = {
    "format": "pneubayes-rig/1", "name": "test rig",
    "atmospheric_pressure_Pa": P_ATM, "temperature_K": 293.15,
    "command": {"unit": "binary"},
    "chamber": {"kind": "fixed", "volume_m3": {"prior": "log-uniform",
                                              "bounds": [1e-6, 1e-3]}},
    "valve": {"kind": "switching", "open_area_m2": {"prior": "log-uniform",
                                                    "bounds": [1e-8, 1e-4]},
              "exhaust_area_m2": 0.0, "opening_delay_s": 0.0,
              "opening_time_constant_s": 0.0},
    "supply": {"kind": "constant", "pressure_Pa": P_SUP},
    "tube": {"length_m": 1.0, "inner_diameter_m": 0.004},
    "bounds": {"tube_delay_s": [0.0, 0.08]},
}


def card(**changes) -> RigCard:
    return edited_card(CARD, **changes)


# ---------------------------------------------------------------- reading
def test_card_round_trips_through_dict_json_and_toml(tmp_path):
    c = card()
    assert RigCard.from_dict(c.to_dict()) == c
    (tmp_path / "r.json").write_text(json.dumps(c.to_dict()))
    assert load_rig_card(tmp_path / "r.json") == c
    toml = """format = "pneubayes-rig/1"
name = "test rig"
atmospheric_pressure_Pa = 101325.0
temperature_K = 293.15
bounds = {tube_delay_s = [0.0, 0.08]}
[command]
unit = "binary"
[chamber]
kind = "fixed"
volume_m3 = {prior = "log-uniform", bounds = [1e-6, 1e-3]}
[valve]
kind = "switching"
open_area_m2 = {prior = "log-uniform", bounds = [1e-8, 1e-4]}
exhaust_area_m2 = 0.0
opening_delay_s = 0.0
opening_time_constant_s = 0.0
[supply]
kind = "constant"
pressure_Pa = 601325.0
[tube]
length_m = 1.0
inner_diameter_m = 0.004
"""
    (tmp_path / "r.toml").write_text(toml)
    assert load_rig_card(tmp_path / "r.toml") == c


def test_every_kind_is_registered_once_per_role():
    assert {("chamber", "fixed"), ("chamber", "piston"), ("chamber", "polynomial"),
            ("valve", "gompertz"), ("valve", "switching"), ("supply", "measured"),
            ("supply", "constant")} <= set(KINDS)


@pytest.mark.parametrize("changes, words", [
    ({"chamber__kind": "bellows"}, ["'chamber' -> 'kind'", "'bellows'", "fixed"]),
    ({"command": {"range": [0, 1]}}, ["'command' -> 'unit'"]),
    ({"command": None}, ["'command'", "missing"]),
    ({"chamber__volume_m3": -1e-4}, ["'volume_m3'", "> 0"]),
    ({"chamber__volume_m3": {"prior": "log-uniform", "bounds": [0.0, 1e-3]}},
     ["'volume_m3'", "lower must be > 0"]),
    ({"chamber__volume_m3": {"prior": "normal", "bounds": [1e-6, 1e-3]}},
     ["'volume_m3' -> 'prior'"]),
    ({"chamber__volume_m3": {"prior": "uniform", "bounds": [1e-3, 1e-6]}},
     ["'volume_m3' -> 'bounds'", "below"]),
    ({"valve__open_area_mm2": 1.0}, ["unknown key", "open_area_mm2"]),
    ({"valve__open_area_m2": "big"}, ["'open_area_m2'", "finite number"]),
    ({"temperature_K": 20.0}, ["temperature_K", "probably degrees C"]),
    ({"format": "pneubayes-rig/9"}, ["'format'"]),
    ({"tube": {"length_m": 1.0}}, ["'tube'"]),
    ({"bounds": {"tube_delay_s": [0.1, 0.0]}}, ["'bounds'", "tube_delay_s"]),
    ({"chamber": {"kind": "polynomial", "dead_volume_m3": 1e-4,
                  "coefficients_m3_per_m": [1e-3, -1.0], "coordinate_range_m": [0, 0.01]}},
     ["coefficients_m3_per_m", "must grow"]),
    ({"chamber": {"kind": "polynomial", "dead_volume_m3": 1e-4,
                  "coefficients_m3_per_m": [], "coordinate_range_m": [0, 0.01]}},
     ["coefficients_m3_per_m"]),
    ({"command": {"unit": "duty", "range": [0.5, 1.5]}}, ["'command' -> 'range'", "duty"]),
])
def test_bad_cards_are_errors_naming_the_key(changes, words):
    with pytest.raises(RigCardError) as err:
        card(**changes)
    for w in words:
        assert w in str(err.value), (w, str(err.value))
    assert "card.json" in str(err.value)


def test_unreadable_cards_name_the_file(tmp_path):
    with pytest.raises(RigCardError, match="cannot read"):
        load_rig_card(tmp_path / "absent.json")
    (tmp_path / "bad.toml").write_text("format = ")
    with pytest.raises(RigCardError, match="bad.toml: not valid TOML"):
        load_rig_card(tmp_path / "bad.toml")


# ---------------------------------------------------------------- model
def test_model_on_a_card_has_the_cards_unknowns_and_round_trips():
    c = card()
    m = Model(["tube_delay"], rig_card=c)
    assert m.parameter_names == ("valve_open_area_m2", "dead_volume_m3", "tube_delay_s")
    # the card's tube bore reaches the effect, its bounds the effect's parameter
    assert m.effect("tube_delay").tube_diameter_m == 0.004
    assert m.parameter("tube_delay_s").upper == 0.08
    values = {"valve_open_area_m2": 1e-6, "dead_volume_m3": 1e-4, "tube_delay_s": 0.01}
    m2, v2 = Model.from_card(json.loads(json.dumps(m.to_card(values))))
    assert m2 == m and v2 == values
    assert m.without("tube_delay").rig_card == c
    assert m.without("tube_delay").with_effect("tube_delay") == m
    assert Model(["tube_delay"]) != m


def test_model_card_with_a_broken_rig_names_it():
    m = Model(rig_card=card())
    doc = m.to_card({"valve_open_area_m2": 1e-6, "dead_volume_m3": 1e-4})
    doc["rig"]["chamber"]["kind"] = "balloon"
    with pytest.raises(ModelCardError, match="key 'rig' key 'chamber'"):
        Model.from_card(doc, "model.json")


def test_known_quantities_are_not_fitted():
    c = card(valve__open_area_m2=2e-6, chamber__volume_m3=1e-4)
    assert Model(rig_card=c).parameter_names == ()


# ---------------------------------------------------------------- physics
def _inputs(t, u, before=None, x=None):
    return Inputs(t, u, np.zeros_like(t) if x is None else x, np.full(t.shape, P_SUP), before)


def test_closed_switching_valve_keeps_the_pressure():
    c = card()
    m = Model(rig_card=c)
    t = np.arange(501) * 1e-3
    p = simulate(m, {"valve_open_area_m2": 1e-5, "dead_volume_m3": 1e-5}, _inputs(t, 0 * t),
                 _rig(c), 2.5e5, TIGHT).pressure_Pa[0]
    assert np.max(np.abs(p - 2.5e5)) < 1e-6


def _rig(c):
    from pneubayes.physics.gas import GasConstants
    from pneubayes.rig import Rig

    md = c.metadata_defaults()
    return Rig(md["bore_m"], c.atmospheric_pressure_Pa, P_SUP,
               GasConstants(temperature_K=c.temperature_K), stroke_m=md["stroke_m"])


def test_open_switching_valve_fills_to_supply_and_a_3_2_valve_vents_to_atmosphere():
    c = card(valve__exhaust_area_m2={"prior": "log-uniform", "bounds": [1e-8, 1e-4]})
    m = Model(rig_card=c)
    t = np.arange(2001) * 1e-3
    params = {"valve_open_area_m2": 2e-6, "valve_exhaust_area_m2": 2e-6,
              "dead_volume_m3": 1e-5}
    filled = simulate(m, params, _inputs(t, np.ones_like(t)), _rig(c), P_ATM,
                      TIGHT).pressure_Pa[0]
    vented = simulate(m, params, _inputs(t, np.zeros_like(t)), _rig(c), P_SUP,
                      TIGHT).pressure_Pa[0]
    assert abs(filled[-1] - P_SUP) < 1.0 and abs(vented[-1] - P_ATM) < 1.0
    # monotone to within the solver tolerance (atol 1e-3 Pa)
    assert np.all(np.diff(filled) >= -1e-2) and np.all(np.diff(vented) <= 1e-2)


@pytest.mark.parametrize("delay", [0.004, 0.0173])
def test_opening_delay_shifts_the_fill_and_sees_the_pre_trigger_command(delay):
    """A valve commanded open at the first sample, with a pre-trigger command of 0,
    fills exactly like one opened ``delay`` later (a step on the grid); without the
    pre-trigger command the delay could not show."""
    c = card(valve__opening_delay_s={"prior": "uniform", "bounds": [0.0, 0.05]})
    m = Model(rig_card=c)
    dt = 1e-4
    t = np.arange(1201) * dt
    params = {"valve_open_area_m2": 1e-6, "valve_opening_delay_s": delay,
              "dead_volume_m3": 2e-5}
    late = simulate(m, params, _inputs(t, np.ones_like(t), before=0.0), _rig(c), P_ATM,
                    TIGHT).pressure_Pa[0]
    k = int(round(delay / dt))
    u_shift = (np.arange(t.size) >= k).astype(float)
    shifted = simulate(m, {**params, "valve_opening_delay_s": 0.0},
                       _inputs(t, u_shift, before=0.0), _rig(c), P_ATM, TIGHT).pressure_Pa[0]
    np.testing.assert_allclose(late, shifted, atol=0.5)
    assert np.all(late[:k] == P_ATM) and late[-1] > P_ATM + 1e4
    unseen = simulate(m, params, _inputs(t, np.ones_like(t)), _rig(c), P_ATM,
                      TIGHT).pressure_Pa[0]
    assert unseen[k // 2] > P_ATM + 100.0  # no pre-trigger command: open since forever


def test_opening_lag_matches_the_reference_solver():
    c = card(valve__opening_time_constant_s=0.01)
    m = Model(rig_card=c)
    t = np.arange(121) * 1e-3
    u = ((t > 0.02) & (t < 0.08)).astype(float)
    params = {"valve_open_area_m2": 1e-6, "dead_volume_m3": 1e-5}
    inputs = _inputs(t, u)
    ours = simulate(m, params, inputs, _rig(c), 1.5e5, TIGHT).pressure_Pa[0]
    ref = reference_simulate(m, params, inputs, _rig(c), 1.5e5, method="DOP853", rtol=1e-8)
    assert np.max(np.abs(ours - ref)) < 20.0  # Pa, of a 400-kPa swing


def test_pre_trigger_command_and_delay_match_the_reference_solver():
    c = card(valve__opening_delay_s=0.0123, valve__opening_time_constant_s=0.004)
    m = Model(rig_card=c)
    t = np.arange(81) * 1e-3
    params = {"valve_open_area_m2": 1e-6, "dead_volume_m3": 1e-5}
    inputs = _inputs(t, (t < 0.04).astype(float), before=0.0)
    ours = simulate(m, params, inputs, _rig(c), 1.5e5, TIGHT).pressure_Pa[0]
    ref = reference_simulate(m, params, inputs, _rig(c), 1.5e5, method="DOP853", rtol=1e-8)
    assert np.all(ours[:12] == 1.5e5)
    assert np.max(np.abs(ours - ref)) < 20.0


def test_polynomial_chamber_closed_follows_the_polytropic_law():
    """A closed chamber whose volume follows V(s) = V0 + c1 s + c2 s^2 + c3 s^3 of a moving
    coordinate: p V^n is constant (eq. 5 with no flow)."""
    coeffs = [3.141e-3, -3.251e-2, 0.128]
    c = card(chamber={"kind": "polynomial", "dead_volume_m3": 6.6e-5,
                      "coefficients_m3_per_m": coeffs, "coordinate_range_m": [0.0, 0.03]})
    m = Model(rig_card=c)
    t = np.arange(1001) * 1e-3
    s = 0.015 * (1 - np.cos(2 * np.pi * t))  # 0 .. 0.03 m and back
    chamber = c.chamber
    x = chamber.equivalent_position_m(s)
    rig = _rig(c)
    assert math.isclose(rig.bore_area_m2, coeffs[0], rel_tol=1e-12)
    p = simulate(m, {"valve_open_area_m2": 1e-6}, _inputs(t, 0 * t, x=x), rig, 3e5,
                 TIGHT).pressure_Pa[0]
    vol = 6.6e-5 + np.polyval([*reversed(coeffs), 0.0], s)
    kappa = rig.gas.heat_capacity_ratio
    # the volume is linear between samples in x, as the kernel takes it: compare on samples
    np.testing.assert_allclose(p * vol ** kappa, 3e5 * vol[0] ** kappa, rtol=2e-4)


def test_polynomial_chamber_with_compliance_closed_keeps_p_v_to_the_n():
    """The muscle's optional compliance (its tendon stretching): V = V(s) + C (p - P_atm)
    of the moving coordinate and the pressure; closed, p V^n stays constant with V the
    whole volume (eq. 5 with dV/dt = c1 ds/dt + C dp/dt), and C = 0 is the plain kind."""
    coeffs = [3.141e-3, -3.251e-2, 0.128]
    chamber = {"kind": "polynomial", "dead_volume_m3": 6.6e-5,
               "coefficients_m3_per_m": coeffs, "coordinate_range_m": [0.0, 0.03]}
    t = np.arange(1001) * 1e-3
    s = 0.015 * (1 - np.cos(2 * np.pi * t))
    out = {}
    for compliance in (0.0, 1e-10):
        c = card(chamber={**chamber, "compliance_m3_per_Pa": compliance})
        m = Model(rig_card=c)
        x = c.chamber.equivalent_position_m(s)
        out[compliance] = simulate(m, {"valve_open_area_m2": 1e-6}, _inputs(t, 0 * t, x=x),
                                   _rig(c), 3e5, TIGHT).pressure_Pa[0]
    kappa = _rig(card()).gas.heat_capacity_ratio
    p = out[1e-10]
    vol = 6.6e-5 + np.polyval([*reversed(coeffs), 0.0], s) + 1e-10 * (p - P_ATM)
    np.testing.assert_allclose(p * vol ** kappa, p[0] * vol[0] ** kappa, rtol=2e-4)
    assert np.max(np.abs(p - out[0.0])) > 1e3  # the compliance matters here
    plain = card(chamber=chamber)
    assert Model(rig_card=plain).parameter_names == Model(
        rig_card=card(chamber={**chamber, "compliance_m3_per_Pa": 0.0})).parameter_names


# ---------------------------------------------------------------- recordings
def _write(tmp_path, rows, sidecar, name="rec"):
    (tmp_path / f"{name}.csv").write_text("time_s,command_V,pressure_Pa\n" + "".join(
        f"{t},{u},{p}\n" for t, u, p in rows))
    (tmp_path / f"{name}.json").write_text(json.dumps(sidecar))
    return tmp_path / f"{name}.csv"


def test_a_sidecar_naming_a_card_needs_no_bore_or_stroke(tmp_path):
    (tmp_path / "rig.json").write_text(json.dumps(CARD))
    rows = [(0.001 * i, 1 if i > 3 else 0, P_ATM + 100 * i) for i in range(50)]
    path = _write(tmp_path, rows, {"rig": "rig.json", "command_before_start": 0})
    rec = read_recording(path)
    assert rec.rig_card == card() and rec.command_before_start == 0.0
    assert rec.metadata.supply_pressure_Pa == P_SUP and rec.rig().bore_m > 0
    assert Inputs.from_recording(rec).command_before_start == 0.0


def test_a_command_outside_the_declared_range_names_the_row(tmp_path):
    (tmp_path / "rig.json").write_text(json.dumps(CARD))
    rows = [(0.001 * i, 0.5 if i == 7 else 0, P_ATM) for i in range(20)]
    path = _write(tmp_path, rows, {"rig": "rig.json"})
    with pytest.raises(RecordingError, match=r"row 8: command 0.5 is outside .*binary"):
        read_recording(path)


def test_a_broken_or_missing_card_is_a_problem_naming_the_key(tmp_path):
    rows = [(0.001 * i, 0, P_ATM) for i in range(20)]
    path = _write(tmp_path, rows, {"rig": "absent.json"})
    with pytest.raises(RecordingError, match="key 'rig'.*cannot read"):
        read_recording(path)
    bad = dict(CARD, chamber={"kind": "fixed", "volume_m3": -1.0})
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    path = _write(tmp_path, rows, {"rig": "bad.json"}, "rec2")
    with pytest.raises(RecordingError, match="volume_m3"):
        read_recording(path)


def test_a_fixed_chamber_refuses_a_moving_position(tmp_path):
    (tmp_path / "rig.json").write_text(json.dumps(CARD))
    (tmp_path / "m.csv").write_text("time_s,command_V,pressure_Pa,position_m\n" + "".join(
        f"{0.001 * i},0,{P_ATM},{0.001 * i}\n" for i in range(20)))
    (tmp_path / "m.json").write_text(json.dumps({"rig": "rig.json"}))
    with pytest.raises(RecordingError, match="'fixed' cannot move"):
        read_recording(tmp_path / "m.csv")


def test_a_muscles_contraction_is_checked_against_its_range_not_the_equivalent_stroke(
        tmp_path):
    """A polynomial chamber whose volume curve bends (c2 < 0) has an equivalent stroke
    shorter than its coordinate range: a 7-cm contraction inside a 0-12-cm range reads
    (the reader's stroke rule reads piston positions only), one past the range fails with
    the card's message, naming the row."""
    muscle = dict(CARD, chamber={"kind": "polynomial", "dead_volume_m3": 6.6e-5,
                                 "coefficients_m3_per_m": [3.141e-3, -3.251e-2, 0.128],
                                 "coordinate_range_m": [0.0, 0.12]})
    (tmp_path / "rig.json").write_text(json.dumps(muscle))
    stroke = load_rig_card(tmp_path / "rig.json").chamber.metadata_defaults()["stroke_m"]
    assert 1.5 * stroke + 5e-3 < 0.07  # the rule on the raw column would refuse 7 cm
    for name, top in (("in", 0.07), ("out", 0.14)):
        (tmp_path / f"{name}.csv").write_text("time_s,command_V,pressure_Pa,position_m\n"
                                              + "".join(f"{0.001 * i},0,{P_ATM},"
                                                        f"{top * i / 19}\n"
                                                        for i in range(20)))
        (tmp_path / f"{name}.json").write_text(json.dumps({"rig": "rig.json"}))
    rec = read_recording(tmp_path / "in.csv")
    np.testing.assert_allclose(rec.position_m,
                               rec.rig_card.chamber.equivalent_position_m(
                                   0.07 * np.arange(20) / 19), rtol=1e-12)
    with pytest.raises(RecordingError, match=r"row 19: coordinate 0.1326.* outside the rig "
                                             r"card's coordinate range \[0, 0.12\]"):
        read_recording(tmp_path / "out.csv")


def test_a_bound_recording_is_not_written_back(tmp_path):
    from pneubayes.io import write_recording

    (tmp_path / "rig.json").write_text(json.dumps(CARD))
    rows = [(0.001 * i, 0, P_ATM) for i in range(20)]
    rec = read_recording(_write(tmp_path, rows, {"rig": "rig.json"}))
    with pytest.raises(ValueError, match="bound to the rig card"):
        write_recording(rec, tmp_path / "copy")


@pytest.mark.skipif(not GTD.is_dir(), reason="shipped GTDynamics data absent")
def test_shipped_gtdynamics_recordings_read_with_their_card():
    paths = sorted(GTD.glob("*/*.csv"))
    assert len(paths) == 20
    recs = [read_recording(p) for p in paths]
    assert all(r.rig_card == recs[0].rig_card for r in recs)
    assert recs[0].rig_card.valve.kind == "switching"
    for r in recs:
        assert set(np.unique(r.command_V)) == {0.0, 1.0}
        assert r.command_before_start == 0.0
        assert r.supply_pressure_Pa is not None and r.time_s[-1] <= 0.33
        # gauge psi made absolute with the stated atmosphere: a muscle at rest reads
        # 2-5 psi gauge
        assert 110e3 < r.pressure_Pa[0] < 140e3


def test_compliant_chamber_filled_at_a_choked_constant_flow_follows_the_closed_form():
    """Choked inflow (supply far above the chamber) is a constant mass flow m; with
    V(p) = V0 + C (p - P_atm), dp/dt = n Rs T m / (V0 - C P_atm + C (1 + n) p), so
    (V0 - C P_atm) p + C (1 + n) p^2 / 2 grows linearly in time."""
    sup = 2e6
    c = card(chamber={"kind": "compliant", "volume_m3": 1e-3,
                      "compliance_m3_per_Pa": 2e-7},
             supply={"kind": "constant", "pressure_Pa": sup})
    m = Model(rig_card=c)
    rig = _rig(c)
    from dataclasses import replace
    rig = replace(rig, supply_pressure_Pa=sup)
    t = np.arange(401) * 1e-3
    area = 2e-6
    inputs = Inputs(t, np.ones_like(t), np.zeros_like(t), np.full(t.shape, sup))
    p = simulate(m, {"valve_open_area_m2": area}, inputs, rig, P_ATM, TIGHT).pressure_Pa[0]
    g = rig.gas
    kappa, rs_t = g.heat_capacity_ratio, g.specific_gas_constant_J_per_kg_K * g.temperature_K
    mdot = area * g.beta_s_per_m * sup
    a_, b_ = 1e-3 - 2e-7 * P_ATM, 2e-7 * (1 + kappa) / 2

    def lhs(x):
        return a_ * x + b_ * x * x
    target = lhs(P_ATM) + kappa * rs_t * mdot * t
    closed = (-a_ + np.sqrt(a_ * a_ + 4 * b_ * target)) / (2 * b_)
    assert p[-1] > P_ATM + 5e3  # a real fill, still choked (p << 0.53 x supply)
    np.testing.assert_allclose(p, closed, rtol=1e-6, atol=0.05)


def test_compliance_cannot_join_a_heat_or_line_model():
    c = card(chamber={"kind": "compliant", "volume_m3": 1e-3,
                      "compliance_m3_per_Pa": 2e-7})
    m = Model(["heat_transfer"], rig_card=c)
    t = np.arange(11) * 1e-3
    with pytest.raises(ValueError, match="compliant chamber"):
        simulate(m, {"valve_open_area_m2": 1e-7, "heat_transfer_rate_per_s": 5.0,
                     "heat_transfer_coupling": 1.0},
                 _inputs(t, 0 * t), _rig(c), P_ATM, TIGHT)


def test_discovery_proposes_no_heat_or_line_beside_a_compliant_chamber():
    """The simulator steps a compliant chamber with its pressure alone, so discovery
    offers neither heat transfer nor the tube's acoustic line there (the tube's
    transport delay has no state and stays)."""
    from pneubayes.discovery.candidates import effect_candidates
    from pneubayes.discovery.settings import FormSettings
    from pneubayes.discovery.verification import StepFit

    c = card(chamber={"kind": "compliant", "volume_m3": 1e-3,
                      "compliance_m3_per_Pa": 2e-7})
    fit = StepFit(Model(rig_card=c), {"valve_open_area_m2": 1e-7}, 1.0, 1.0, np.zeros(1),
                  np.zeros(1), 500.0, 0.0)
    heat = {"best_term_start": {"heat_transfer_rate_per_s": 10.0, "heat_transfer_coupling": 1.0}}
    line3 = FormSettings(tube_line_segments=3, tube_line_form="line")
    assert effect_candidates(fit, "heat_transfer", heat, _rig(c), line3) == []
    tube = {"best_term_start": {"tube_delay_s": 0.004}}
    assert [m.effect("tube_delay").form
            for m, _ in effect_candidates(fit, "tube_delay", tube, _rig(c), line3)] == [
        "transport"]


RW = ROOT / "data" / "real" / "respiraworks"


@pytest.mark.skipif(not RW.is_dir(), reason="shipped RespiraWorks data absent")
def test_shipped_respiraworks_recordings_read_with_their_cards():
    recs = {k: [read_recording(p) for p in sorted((RW / k).glob("*.csv"))]
            for k in ("AIR", "OXY")}
    assert len(recs["AIR"]) == len(recs["OXY"]) == 6
    for rs in recs.values():
        card_ = rs[0].rig_card
        assert card_.chamber.kind == "two_compartment" and card_.command.unit == "duty"
        assert card_.exhaust is not None and card_.exhaust.extra["column"] == "cmd_exh_valve"
        for r in rs:
            assert r.rig_card == card_
            assert 0.0 <= r.command_V.min() and r.command_V.max() <= 1.0
            # kPa gauge made absolute: a test lung at 0.3-3.7 kPa above the atmosphere
            gauge = r.pressure_Pa - 101325.0
            assert 200.0 < gauge.min() and gauge.max() < 4000.0
            assert "pc_setpoint_cmH2O" in r.extra_columns


def _fake_trial(root: Path, name="0p00_0p05_hipknee-65source_x") -> Path:
    d = root / name
    d.mkdir(parents=True)
    rows = []
    for i in range(1, 201):
        t = 0.002 * i
        p = 3.0 + (30.0 * min(max(t - 0.02, 0.0), 0.05) / 0.05)
        rows.append(f"{t:.3f}, 65.0, {p:.3f}, {p:.3f}, {p:.3f}, {p:.3f}")
    (d / "pressure_raw_psi.csv").write_text("\n".join(rows) + "\n")
    (d / "t_valve.csv").write_text("# knee_right, hip_right, hip_left, knee_left (seconds)\n"
                                   "0.00, 0.00, 0.00, 0.00\n0.05, 0.05, 0.05, 0.05\n")
    # the video: 250 fps from 10.0 s, each joint's angle a ramp from its own start
    frames = np.arange(120)
    (d / "vid_time_s.txt").write_text("".join(f"{10.0 + 0.004 * k:.4f}\n" for k in frames))
    (d / "angle_pre_rad.csv").write_text("".join(
        f"{2.8 - 0.5 * tk:.6f},{-2.5 + tk:.6f},{-2.5 + 2 * tk:.6f},{2.8 - 0.25 * tk:.6f}\n"
        for tk in 0.004 * frames))
    return d


def test_import_gtdynamics_writes_recordings_and_their_card(tmp_path, capsys):
    from pneubayes.cli import main

    trial = _fake_trial(tmp_path / "in")
    before = {p: p.read_bytes() for p in trial.iterdir()}
    assert main(["import", "gtdynamics", str(trial), "--out", str(tmp_path / "out")]) == 0
    assert {p: p.read_bytes() for p in trial.iterdir()} == before  # inputs untouched
    paths = sorted((tmp_path / "out").glob("*/*.csv"))
    assert [p.stem for p in paths] == ["hip_left", "hip_right", "knee_left", "knee_right"]
    rec = read_recording(paths[0])
    assert rec.rig_card.valve.kind == "switching" and rec.command_before_start == 0.0
    assert rec.time_s[-1] <= 0.33
    np.testing.assert_array_equal(rec.command_V, (rec.time_s < 0.05).astype(float))
    np.testing.assert_allclose(rec.pressure_Pa[0], 3.0 * 6894.757293168361 + 101325.0)
    # the cam's travel: its radius (0.045 m) times the cam angle's change, which grows
    # as a knee flexes and a hip extends (the ramps' rates 0.5, 1, 2, 0.25 rad/s)
    rate = {"knee_right": 0.5, "hip_right": 1.0, "hip_left": 2.0, "knee_left": 0.25}
    for p in paths:
        table = np.genfromtxt(p, delimiter=",", names=True)
        np.testing.assert_allclose(table["cam_travel_m"],
                                   0.045 * rate[p.stem] * table["time_s"], rtol=1e-6,
                                   atol=1e-12)
    assert "cam_travel_m" in rec.extra_columns and rec.position_m is None
    # a trial without its video imports without the column; with half of it, refused
    (trial / "vid_time_s.txt").rename(tmp_path / "vid_time_s.txt")
    assert main(["import", "gtdynamics", str(trial), "--out", str(tmp_path / "half")]) == 2
    assert "vid_time_s.txt is missing" in capsys.readouterr().err
    (trial / "angle_pre_rad.csv").rename(tmp_path / "angle_pre_rad.csv")
    assert main(["import", "gtdynamics", str(trial), "--out", str(tmp_path / "none")]) == 0
    plain = read_recording(sorted((tmp_path / "none").glob("*/*.csv"))[0])
    assert "cam_travel_m" not in plain.extra_columns
    np.testing.assert_array_equal(plain.pressure_Pa, rec.pressure_Pa)
    # a second import into the same folder needs --overwrite
    assert main(["import", "gtdynamics", str(trial), "--out", str(tmp_path / "out")]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_import_gtdynamics_of_staggered_valves_and_one_that_never_closes(tmp_path, capsys):
    """The source's staggered trial kind: each muscle's command follows its own open and
    close times; a close time of inf (not closed within the record) is a command held
    open to the end and a null close time in the sidecar, not an error or a guess."""
    from pneubayes.cli import main

    trial = _fake_trial(tmp_path / "in", "0p02_knee-0p09_inf-80source_x")
    (trial / "t_valve.csv").write_text("# knee_right, hip_right, hip_left, knee_left\n"
                                       "0.02, 0.00, 0.00, 0.02\ninf, 0.09, 0.09, inf\n")
    assert main(["import", "gtdynamics", str(trial), "--out", str(tmp_path / "out")]) == 0
    for path in sorted((tmp_path / "out").glob("*/*.csv")):
        rec = read_recording(path)
        knee = path.stem.startswith("knee")
        opened, closed = (0.02, np.inf) if knee else (0.0, 0.09)
        np.testing.assert_array_equal(
            rec.command_V, ((rec.time_s >= opened) & (rec.time_s < closed)).astype(float))
        meta = rec.metadata.extra["import"]
        assert meta["valve_open_s"] == opened
        assert meta["valve_close_s"] == (None if knee else 0.09)
    # a close before the open, or a time that is not a number, is named
    for rows, message in (("0, 0, 0, 0\n0.05, 0.05, -0.01, 0.05\n",
                           "hip_left closes at -0.01 s, before it opens at 0.0 s"),
                          ("0, nan, 0, 0\n0.05, 0.05, 0.05, 0.05\n",
                           "hip_right's open and close times must be numbers")):
        (trial / "t_valve.csv").write_text(rows)
        assert main(["import", "gtdynamics", str(trial), "--out",
                     str(tmp_path / "bad")]) == 2
        assert message in capsys.readouterr().err


def test_import_of_a_folder_that_is_no_trial_is_a_message(tmp_path, capsys):
    from pneubayes.cli import main

    (tmp_path / "empty").mkdir()
    assert main(["import", "gtdynamics", str(tmp_path / "empty"), "--out",
                 str(tmp_path / "o")]) == 2
    assert "not a GTDynamics trial folder" in capsys.readouterr().err


def test_a_delay_fitted_on_the_real_muscle_fills_matches_the_data():
    """The plain card model plus a command delay, refined on the fill phase (trigger to
    30 ms after the valve closes) of two real muscles, finds the dead time the data show
    (about 20 ms from the recorded open time to the rise)."""
    from pneubayes.inference.pipeline import FitSettings
    from pneubayes.inference.refine import TrajectoryRefiner
    from pneubayes.inference.windows import WindowSet

    if not GTD.is_dir():
        pytest.skip("shipped GTDynamics data absent")
    recs = []
    for p in sorted(GTD.glob("0p00_0p09_hipknee-80source*/*.csv"))[:2]:
        r = read_recording(p)
        recs.append(r.slice(0, int(np.searchsorted(r.time_s, 0.12, side="right"))))
    m = Model(["tube_delay"], rig_card=recs[0].rig_card)
    start = {**m.base_start_values(), "tube_delay_s": 0.01}
    ref = TrajectoryRefiner(m, FitSettings().refine_solver, max_nfev=60).fit(
        WindowSet(recs, 0.1, 0.1), start)
    assert 0.015 < ref.params_["tube_delay_s"] < 0.025
    assert ref.rmse_Pa_ < 0.5 * ref.start_rmse_Pa_


def test_cli_rig_option_and_a_fit_on_a_card(tmp_path, capsys):
    """fit builds the card's model and records the card; --rig gives a card."""
    from pneubayes.cli import main

    if not GTD.is_dir():
        pytest.skip("shipped GTDynamics data absent")
    paths = sorted(GTD.glob("0p00_0p09_hipknee-80source*/*.csv"))[:2]
    assert main(["fit", *map(str, paths), "--method", "refine", "--horizon", "0.3",
                 "--effects", "tube_delay", "--out", str(tmp_path / "fit")]) == 0
    card_ = json.loads((tmp_path / "fit" / "model.json").read_text())
    assert card_["rig"]["valve"]["kind"] == "switching"
    assert set(card_["parameters"]) == {"valve_open_area_m2", "dead_volume_m3",
                                        "tube_delay_s"}
    # the same recordings with their card given by --rig (and the sidecar's ignored)
    assert main(["check", "--rig", str(GTD / "gtdynamics-muscle.rig.json"),
                 str(paths[0])]) == 0
    with pytest.raises(SystemExit) as stop:  # an option error, before any work
        main(["check", "--rig", str(tmp_path / "absent.json"), str(paths[0])])
    assert stop.value.code == 2
    assert "cannot read the rig card" in capsys.readouterr().err


def test_fit_known_from_another_fit_refits_only_the_named_quantities(tmp_path, capsys):
    """fit --known-from RUN --refit NAME: the card's other fitted quantities are known at
    RUN's values (recorded in the new model card); a name the card does not fit, --refit
    alone and another rig's run are one-line errors."""
    from pneubayes.cli import main

    if not GTD.is_dir():
        pytest.skip("shipped GTDynamics data absent")
    paths = [str(p) for p in sorted(GTD.glob("0p00_0p09_hipknee-80source*/*.csv"))[:2]]
    first = tmp_path / "fit"
    assert main(["fit", *paths, "--method", "refine", "--horizon", "0.1", "--effects",
                 "tube_delay", "--out", str(first)]) == 0
    one = json.loads((first / "model.json").read_text())
    assert main(["fit", *paths, "--method", "refine", "--horizon", "0.1", "--effects",
                 "tube_delay", "--known-from", str(first), "--refit", "dead_volume_m3",
                 "--out", str(tmp_path / "again")]) == 0
    two = json.loads((tmp_path / "again" / "model.json").read_text())
    assert set(two["parameters"]) == {"dead_volume_m3", "tube_delay_s"}
    assert two["rig"]["valve"]["open_area_m2"] == pytest.approx(
        one["parameters"]["valve_open_area_m2"], rel=1e-12)
    capsys.readouterr()
    for extra, words in ((["--known-from", str(first), "--refit", "tank_volume_m3"],
                          "not fitted quantities"),
                         (["--refit", "dead_volume_m3"], "--refit needs --known-from")):
        assert main(["fit", *paths, "--method", "refine", "--horizon", "0.1", *extra,
                     "--out", str(tmp_path / "bad")]) == 2
        assert words in capsys.readouterr().err


def test_a_paper_rig_card_is_the_thin_port_model_under_other_names(rig, base_params, hand):
    """The paper's cylinder and valve as a card (piston chamber, Gompertz valve, constant
    supply) simulate exactly as the thin-port core: the plug-ins lower onto the same
    slots."""
    from pneubayes.rigcard.paper import paper_rig_card

    c = paper_rig_card("AIR37", "valve1", supply_pressure_Pa=rig.supply_pressure_Pa,
                       atmospheric_pressure_Pa=rig.atmospheric_pressure_Pa)
    core, on_card = Model(["tube_delay"]), Model(["tube_delay"], rig_card=c)
    assert set(on_card.parameter_names) == set(core.parameter_names)
    params = {**base_params, "tube_delay_s": 0.003}
    params.pop("leak_area_m2")
    t = np.arange(801) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), t.size, 1e-3, hold_s=(0.02, 0.08))
    inputs = Inputs(t, u, hand.moving_position(t, freq=2.0),
                    np.full(t.shape, rig.supply_pressure_Pa))
    a = simulate(core, params, inputs, rig, 2e5, TIGHT).pressure_Pa
    b = simulate(on_card, params, inputs, rig, 2e5, TIGHT).pressure_Pa
    np.testing.assert_array_equal(a, b)
    known = Model(rig_card=paper_rig_card("AIR37", "valve1", valve_known=True))
    assert known.parameter_names == ("dead_volume_m3",)


def test_the_shipped_paper_rig_cards_are_current():
    from pneubayes.physics.cylinder import CYLINDERS
    from pneubayes.physics.valve import VALVES
    from pneubayes.rigcard.paper import paper_rig_card

    for cyl in CYLINDERS:
        for valve in VALVES:
            shipped = load_rig_card(ROOT / "data" / "rigs" / f"{cyl}-{valve}.rig.json")
            assert shipped == paper_rig_card(cyl, valve)


def test_discovery_offers_a_compliant_chamber_only_forms_it_can_simulate():
    """Heat transfer and the acoustic line need states a compliant chamber's integration
    does not carry: discovery offers neither beside it (the transport delay it can)."""
    from pneubayes.discovery.candidates import effect_candidates
    from pneubayes.discovery.settings import FormSettings
    from pneubayes.discovery.verification import StepFit

    c = card(chamber={"kind": "compliant", "volume_m3": 1e-3,
                      "compliance_m3_per_Pa": {"prior": "log-uniform",
                                               "bounds": [1e-8, 1e-6]}})
    m = Model(rig_card=c)
    fit = StepFit(m, {"valve_open_area_m2": 1e-6, "chamber_compliance_m3_per_Pa": 2e-7},
                  1.0, 1.0, np.zeros(1), np.zeros(1), 1.0, 0.0)
    rig = _rig(c)
    assert effect_candidates(fit, "heat_transfer", {}, rig) == []
    tubes = effect_candidates(fit, "tube_delay", {"best_term_start": {"tube_delay_s": 0.004}},
                              rig, FormSettings(tube_line_form="line"))
    assert [mm.effect("tube_delay").form for mm, _ in tubes] == ["transport"]
    fixed = Model(rig_card=card())
    fit2 = StepFit(fixed, {"valve_open_area_m2": 1e-6, "dead_volume_m3": 1e-4},
                   1.0, 1.0, np.zeros(1), np.zeros(1), 1.0, 0.0)
    assert [mm.effect("heat_transfer").form for mm, _ in effect_candidates(
        fit2, "heat_transfer", {}, rig)] == ["rate", "convective", "forced"]


def test_components_compare_and_hash_by_their_tables():
    poly = {"kind": "polynomial", "dead_volume_m3": 1e-4,
            "coefficients_m3_per_m": [1e-3, 0.01], "coordinate_range_m": [0.0, 0.02]}
    a, b = card(chamber=poly).chamber, card(chamber=dict(poly)).chamber
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a != card().chamber


def test_the_documented_examples_are_valid_cards():
    """The README's and the card module's TOML examples read as cards."""
    import tomllib

    from pneubayes.rigcard import card as card_module

    guide = (ROOT / "docs" / "rig.md").read_text()
    block = guide[guide.index("## Rig cards"):].split("```toml\n", 1)[1].split("```")[0]
    assert RigCard.from_dict(tomllib.loads(block), "docs/rig.md").valve.kind == "switching"
    doc = card_module.__doc__.split("::\n\n", 1)[1].split("\n\n")[0]
    text = "\n".join(line[4:] for line in doc.splitlines())
    assert RigCard.from_dict(tomllib.loads(text), "card.py").chamber.kind == "polynomial"


def test_known_at_fixes_a_fits_values_and_keeps_the_named_unknowns():
    c = card(valve__opening_delay_s={"prior": "uniform", "bounds": [0.0, 0.05]})
    m = Model(rig_card=c)
    assert set(m.parameter_names) == {"valve_open_area_m2", "valve_opening_delay_s",
                                      "dead_volume_m3"}
    params = {"valve_open_area_m2": 2e-6, "valve_opening_delay_s": 0.01,
              "dead_volume_m3": 3e-5}
    k = c.known_at(params, keep_unknown=("dead_volume_m3",))
    assert Model(rig_card=k).parameter_names == ("dead_volume_m3",)
    assert k.valve.values["open_area_m2"] == 2e-6
    assert k.valve.values["opening_delay_s"] == 0.01
    t = np.arange(201) * 1e-3
    inp = _inputs(t, (t > 0.02).astype(float), before=0.0)
    a = simulate(m, params, inp, _rig(c), P_ATM, TIGHT).pressure_Pa[0]
    b = simulate(Model(rig_card=k), {"dead_volume_m3": 3e-5}, inp, _rig(c), P_ATM,
                 TIGHT).pressure_Pa[0]
    np.testing.assert_array_equal(a, b)
    with pytest.raises(RigCardError, match="'valve_opening_delay_s'"):
        c.known_at({"valve_open_area_m2": 2e-6, "dead_volume_m3": 3e-5})
