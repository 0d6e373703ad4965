"""A rig card's ``[ports]`` table: the valve's ISO 6358 rating (critical ratios ``b``,
subsonic index ``m``) stated from a datasheet or as priors a fit narrows."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import tight_solver
from rig_helpers import edited_card

from pneubayes.effects.critical_ratio import CriticalRatio
from pneubayes.errors import FormCombinationError, RigCardError
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.rigcard import RigCard, load_rig_card
from pneubayes.simulation import Inputs, simulate
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 601325.0
CARD = {
    "format": "pneubayes-rig/1", "name": "datasheet valve",
    "atmospheric_pressure_Pa": P_ATM, "temperature_K": 293.15,
    "command": {"unit": "binary"},
    "chamber": {"kind": "fixed", "volume_m3": 2e-5},
    "valve": {"kind": "switching", "open_area_m2": 1e-6, "exhaust_area_m2": 1.4e-6,
              "opening_delay_s": 0.0, "opening_time_constant_s": 0.0},
    "supply": {"kind": "constant", "pressure_Pa": P_SUP},
    "ports": {"kind": "iso6358", "inlet_critical_ratio": 0.3,
              "exhaust_critical_ratio": 0.25, "subsonic_index": 0.45},
}


def card(**changes) -> RigCard:
    return edited_card(CARD, **changes)


def _drive(seconds=0.6, hold_s=0.05):
    """Fills and vents of a 3/2 valve: the binary command toggled every ``hold_s``."""
    t = np.arange(int(round(seconds / 1e-3)) + 1) * 1e-3
    u = (np.floor(t / hold_s) % 2 == 0).astype(float)
    return Inputs(t, u, np.zeros_like(t), np.full(t.shape, P_SUP), 0.0)


def _rig(c):
    from pneubayes.physics.gas import GasConstants
    from pneubayes.rig import Rig

    md = c.metadata_defaults()
    return Rig(md["bore_m"], c.atmospheric_pressure_Pa, P_SUP,
               GasConstants(temperature_K=c.temperature_K), stroke_m=md["stroke_m"])


# ---------------------------------------------------------------- reading
def test_the_ports_table_round_trips_through_dict_json_and_toml(tmp_path):
    prior = {"prior": "uniform", "bounds": [0.2, 0.45]}
    c = card(ports={"kind": "iso6358", "exhaust_critical_ratio": prior})
    d = c.to_dict()
    assert d["ports"] == {"kind": "iso6358", "exhaust_critical_ratio": prior,
                          "subsonic_index": 0.5}
    assert RigCard.from_dict(d) == c
    (tmp_path / "rig.json").write_text(json.dumps(d))
    assert load_rig_card(tmp_path / "rig.json") == c
    (tmp_path / "rig.toml").write_text(
        'format = "pneubayes-rig/1"\nname = "datasheet valve"\n'
        f"atmospheric_pressure_Pa = {P_ATM}\ntemperature_K = 293.15\n"
        '[command]\nunit = "binary"\n[chamber]\nkind = "fixed"\nvolume_m3 = 2e-5\n'
        '[valve]\nkind = "switching"\nopen_area_m2 = 1e-6\nexhaust_area_m2 = 1.4e-6\n'
        "opening_delay_s = 0.0\nopening_time_constant_s = 0.0\n"
        f'[supply]\nkind = "constant"\npressure_Pa = {P_SUP}\n'
        '[ports]\nkind = "iso6358"\n'
        'exhaust_critical_ratio = {prior = "uniform", bounds = [0.2, 0.45]}\n')
    assert load_rig_card(tmp_path / "rig.toml") == c
    m = Model(rig_card=c)
    assert m.parameter_names == ("valve_exhaust_critical_ratio",)
    back, values = Model.from_card(m.to_card({"valve_exhaust_critical_ratio": 0.3}))
    assert back == m and values == {"valve_exhaust_critical_ratio": 0.3}


@pytest.mark.parametrize("ports, words", [
    ({"kind": "iso6358"}, "give 'inlet_critical_ratio'"),
    ({"kind": "iso6358", "subsonic_index": 0.4}, "give 'inlet_critical_ratio'"),
    ({"kind": "iso6358", "inlet_critical_ratio": 1.0}, "must lie in (0.0, 1.0)"),
    ({"kind": "iso6358", "inlet_critical_ratio": -0.3}, "inlet_critical_ratio"),
    ({"kind": "iso6358", "exhaust_critical_ratio": {"prior": "uniform",
                                                    "bounds": [0.2, 1.2]}},
     "its bounds must lie in (0.0, 1.0)"),
    ({"kind": "iso6358", "inlet_critical_ratio": 0.3, "subsonic_index": 1.5},
     "'subsonic_index': its value must lie in [0.2, 1.0]"),
    ({"kind": "iso6358", "inlet_critical_ratio": 0.3, "sonic_conductance": 2.0},
     "unknown key(s) ['sonic_conductance']"),
    ({"kind": "ellipse", "inlet_critical_ratio": 0.3}, "unknown ports kind 'ellipse'"),
])
def test_a_bad_ports_table_is_an_error_naming_the_key(ports, words):
    with pytest.raises(RigCardError) as err:
        card(ports=ports)
    assert "card.json key 'ports'" in str(err.value) and words in str(err.value)


@pytest.mark.parametrize("supply", [
    {"kind": "tank", "volume_m3": 1e-3, "initial_pressure_Pa": "measured"},
    {"kind": "restricted", "restriction_area_m2": 2e-6, "pressure_Pa": "measured"}],
    ids=["tank", "restricted"])
def test_a_rating_beside_a_supply_the_ratio_cannot_join_is_refused(supply):
    with pytest.raises(RigCardError,
                       match=f"key 'ports'.*supply of kind '{supply['kind']}'"):
        card(supply=supply)


# ---------------------------------------------------------------- physics
def test_a_datasheets_conductance_gives_the_area_of_the_same_choked_flow():
    """ISO 6358's choked flow ``C rho_0 p_u sqrt(T_0 / T_u)`` equals eq. 3's through
    :func:`choked_area_m2` at every upstream temperature."""
    from pneubayes.physics.gas import GasConstants
    from pneubayes.rigcard.ports_iso6358 import choked_area_m2

    c_dm3 = 1.7
    area = choked_area_m2(c_dm3)
    for temp in (260.0, 293.15, 340.0):
        iso = c_dm3 * 1e-8 * 1.185 * 5e5 * np.sqrt(293.15 / temp)
        eq3 = area * GasConstants(temperature_K=temp).beta_s_per_m * 5e5
        assert eq3 == pytest.approx(iso, rel=1e-12)
    with pytest.raises(ValueError, match="sonic_conductance_dm3_per_s_bar"):
        choked_area_m2(0.0)


def test_the_stated_rating_is_the_critical_ratio_effect_at_those_values():
    """The card's rating writes the slots the effect writes: the same trajectory as the
    card without it beside ``critical_ratio`` (form ``iso6358``) at the same values,
    and it differs from eq. 3's by kPa."""
    c, plain = card(), card(ports=None)
    inputs, rig = _drive(), _rig(c)
    rated = simulate(Model(rig_card=c), {}, inputs, rig, P_ATM,
                     tight_solver(1e-8)).pressure_Pa[0]
    effect = simulate(Model([CriticalRatio("iso6358")], rig_card=plain),
                      {"inlet_critical_ratio": 0.3, "exhaust_critical_ratio": 0.25,
                       "subsonic_index": 0.45}, inputs, rig, P_ATM,
                      tight_solver(1e-8)).pressure_Pa[0]
    eq3 = simulate(Model(rig_card=plain), {}, inputs, rig, P_ATM,
                   tight_solver(1e-8)).pressure_Pa[0]
    np.testing.assert_array_equal(rated, effect)
    assert np.max(np.abs(rated - eq3)) > 5e3


def test_the_rated_valve_agrees_with_the_reference_solver():
    c = card()
    m, inputs = Model(rig_card=c), _drive(0.3)
    ours = simulate(m, {}, inputs, _rig(c), P_ATM, tight_solver(1e-9)).pressure_Pa[0]
    ref = reference_simulate(m, {}, inputs, _rig(c), P_ATM, method="Radau", rtol=1e-10)
    assert np.ptp(ref) > 2e5
    assert np.max(np.abs(ours - ref)) < 5.0  # Pa


def test_one_path_rated_leaves_the_other_on_eq_3():
    """A card rating the exhaust alone fills as eq. 3's valve does and vents otherwise."""
    c = card(ports={"kind": "iso6358", "exhaust_critical_ratio": 0.25})
    plain = card(ports=None)
    t = np.arange(301) * 1e-3
    rig = _rig(c)

    def run(cc, u, p0):
        inputs = Inputs(t, u, np.zeros_like(t), np.full(t.shape, P_SUP), u[0])
        return simulate(Model(rig_card=cc), {}, inputs, rig, p0,
                        tight_solver(1e-8)).pressure_Pa[0]

    fill, vent = np.ones_like(t), np.zeros_like(t)
    np.testing.assert_array_equal(run(c, fill, P_ATM), run(plain, fill, P_ATM))
    assert np.max(np.abs(run(c, vent, P_SUP) - run(plain, vent, P_SUP))) > 5e3


# ---------------------------------------------------------------- fitting and discovery
def test_a_model_refuses_the_effect_beside_the_rating_and_discovery_leaves_it_out():
    m = Model(rig_card=card())
    assert m.covers("critical_ratio") and not m.has("critical_ratio")
    assert not m.covers("tube_delay")
    assert not Model(rig_card=card(ports=None)).covers("critical_ratio")
    with pytest.raises(FormCombinationError, match="states what effect 'critical_ratio'"):
        m.with_effect("critical_ratio")


def test_a_datasheet_prior_is_narrowed_to_the_planted_ratios(tmp_path):
    """Noise-free fills and vents recorded from a valve rated b = 0.3 (inlet) and 0.25
    (exhaust): a card giving both as priors over ISO's 0.2-0.45 recovers them within 1 %
    by the trajectory refinement, from the priors' middle."""
    from pneubayes.inference.refine import TrajectoryRefiner

    truth, inputs = card(), _drive(1.0)
    p = simulate(Model(rig_card=truth), {}, inputs, _rig(truth), P_ATM,
                 tight_solver(1e-9)).pressure_Pa[0]
    prior = {"prior": "uniform", "bounds": [0.2, 0.45]}
    fitted = card(ports={"kind": "iso6358", "inlet_critical_ratio": prior,
                         "exhaust_critical_ratio": prior, "subsonic_index": 0.45})
    (tmp_path / "rig.json").write_text(json.dumps(fitted.to_dict()))
    (tmp_path / "rec.csv").write_text("time_s,command_V,pressure_Pa\n" + "".join(
        f"{t:.4f},{u:g},{q:.3f}\n" for t, u, q in zip(inputs.time_s, inputs.command_V, p)))
    (tmp_path / "rec.json").write_text(json.dumps({"rig": "rig.json",
                                                   "command_before_start": 0}))
    rec = read_recording(tmp_path / "rec.csv")
    model = Model(rig_card=rec.rig_card)
    fit = TrajectoryRefiner(model, tight_solver(1e-7), 0.5, 0.5, max_nfev=40,
                            uncertainty=False).fit(
        [rec], {"valve_inlet_critical_ratio": 0.33, "valve_exhaust_critical_ratio": 0.33})
    assert fit.params_["valve_inlet_critical_ratio"] == pytest.approx(0.3, rel=1e-2)
    assert fit.params_["valve_exhaust_critical_ratio"] == pytest.approx(0.25, rel=1e-2)
