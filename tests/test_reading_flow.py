"""The open form at the reading driven by the valve's port flows: terms of the inlet's and
the exhaust's mass flows added to the reading (effect ``reading_flow``), the simulator's
windows, against the reference solver, and their search in the windows' residual."""

from __future__ import annotations

import numpy as np
import pytest

from pneubayes.effects import ReadingFlow
from pneubayes.model import Model
from pneubayes.simulation.reading_flow import feature_values

GAIN = 1500.0  # Pa per (g/s)^2


def _setup(rig, hand, n=1201, features=("inlet_flow_square",), gains=(GAIN,)):
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs

    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    model = Model().with_effect(ReadingFlow(features))
    params = {**base, **{f"reading_flow_gain_{k}": g for k, g in enumerate(gains)}}
    return inputs, base, model, params


def _flows_by_hand(base, rig, spool, p):
    """The valve1 maps' port flows (kg/s) written out: eqs. 1-3 and 11, no dead band."""
    from pneubayes.physics.orifice import flow_function
    from pneubayes.physics.valve import gompertz_area

    a_in = gompertz_area(spool, *(base[f"inlet_{k}"] for k in ("offset_m2", "a_m2", "b",
                                                                 "c_per_V", "d_V")))
    a_ex = gompertz_area(spool, *(base[f"exhaust_{k}"] for k in ("offset_m2", "a_m2", "b",
                                                                   "c_per_V", "d_V")))
    return (a_in * flow_function(rig.supply_pressure_Pa, p, rig.gas),
            a_ex * flow_function(p, rig.atmospheric_pressure_Pa, rig.gas))


def test_the_features_are_the_flows_in_grams_per_second_and_their_signed_squares():
    q_in, q_ex = np.array([2e-3, -1e-3]), np.array([0.5e-3, 3e-3])
    np.testing.assert_allclose(feature_values("inlet_flow", q_in, q_ex), [2.0, -1.0])
    np.testing.assert_allclose(feature_values("exhaust_flow", q_in, q_ex), [0.5, 3.0])
    np.testing.assert_allclose(feature_values("inlet_flow_square", q_in, q_ex), [4.0, -1.0])
    np.testing.assert_allclose(feature_values("exhaust_flow_square", q_in, q_ex), [0.25, 9.0])
    with pytest.raises(ValueError, match="unknown feature 'net_flow'"):
        feature_values("net_flow", q_in, q_ex)


def test_the_components_options_and_parameters_are_checked():
    for bad in ((), ("inlet_flow",) * 2, ("jet",), ("inlet_flow", "exhaust_flow",
                                                    "inlet_flow_square")):
        with pytest.raises(ValueError, match="option 'features'"):
            ReadingFlow(bad)
    eff = ReadingFlow(["exhaust_flow", "inlet_flow_square"])
    assert eff.features == ("exhaust_flow", "inlet_flow_square") and eff.terms == 2
    assert eff.options() == {"features": ["exhaust_flow", "inlet_flow_square"]}
    units = [p.unit for p in eff.parameters()]
    assert units == ["Pa/(g/s)", "Pa/((g/s)^2)"]
    assert eff.relaxes_reading and not eff.library_searched
    assert ReadingFlow("inlet_flow").features == ("inlet_flow",)


def test_the_simulator_adds_the_flow_terms_along_the_chambers_own_pressure(rig, hand):
    """A model with the component predicts the plain model's pressure, started where the
    first reading less the terms there stands, plus c F along it, F the port flows of
    eqs. 1-3 at the samples (written out here); gain 0 is the plain model bit for bit;
    windows started mid-recording from the whole run's reading reproduce it."""
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, base, model, params = _setup(rig, hand)
    starts, solver, length = np.array([0, 300, 700]), SolverConfig.standard(), 500
    read = simulate_windows(model, params, inputs, rig, starts, length, 2e5, solver)[0]
    idx = starts[:, None] + np.arange(length)
    spool = inputs.command_V[idx]
    p0 = np.full(starts.size, 2e5)
    for _ in range(30):  # the chamber's start: p0 + c F(p0) reads 2e5
        q_in, _ = _flows_by_hand(base, rig, spool[:, 0], p0)
        p0 = 2e5 - GAIN * (q_in * 1e3) * np.abs(q_in * 1e3)
    plain = simulate_windows(Model(), base, inputs, rig, starts, length, p0, solver)[0]
    q_in, _ = _flows_by_hand(base, rig, spool, plain)
    want = plain + GAIN * (q_in * 1e3) * np.abs(q_in * 1e3)
    assert np.max(np.abs(want - plain)) > 400.0  # (the term matters: 0.55 g/s at most)
    np.testing.assert_allclose(read, want, rtol=0, atol=0.5)
    off = simulate_windows(model, {**params, "reading_flow_gain_0": 0.0}, inputs, rig,
                           starts, length, 2e5, solver)
    np.testing.assert_array_equal(off, simulate_windows(Model(), base, inputs, rig, starts,
                                                        length, 2e5, solver))
    n = inputs.time_s.size
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    again = simulate_windows(model, params, inputs, rig, starts[1:], length,
                             whole[starts[1:]], solver)[0]
    np.testing.assert_allclose(again, whole[starts[1:, None] + np.arange(length)], rtol=0,
                               atol=2.0)


def test_a_batch_moves_each_sets_start_and_its_sensitivity_follows(rig, hand):
    """In one batch, sets with other gains predict what each predicts alone (each set's
    chamber start and flows its own), and the reading's start sensitivity matches a
    finite difference of the start reading."""
    from pneubayes.simulation import SolverConfig, simulate_windows, simulate_windows_sensitivity

    inputs, _, model, params = _setup(rig, hand, features=("inlet_flow_square",
                                                           "exhaust_flow"),
                                      gains=(GAIN, -400.0))
    starts, solver, length = np.array([100, 600]), SolverConfig.standard(), 400
    sets = [params, {**params, "reading_flow_gain_0": 0.5 * GAIN},
            {**params, "reading_flow_gain_1": 300.0}]
    batch = simulate_windows(model, np.stack([model.vector(s) for s in sets]), inputs, rig,
                             starts, length, 2.5e5, solver)
    for b, s in enumerate(sets):
        alone = simulate_windows(model, s, inputs, rig, starts, length, 2.5e5, solver)[0]
        np.testing.assert_allclose(batch[b], alone, rtol=0, atol=20.0)
    p, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, length, 2.5e5,
                                           solver)
    dp = 50.0
    up = simulate_windows(model, params, inputs, rig, starts, length, 2.5e5 + dp, solver)
    fd = (up[0] - p[0]) / dp
    np.testing.assert_allclose(sens[0][:, 1:], fd[:, 1:], rtol=0, atol=0.05)


def test_a_flow_shifted_reading_agrees_with_the_reference_solver(rig, hand):
    """One window from the recording's first sample, two terms on a valve with a spool
    lag: the compiled simulator and the reference solver (its own flows, eqs. 1-3 and 11
    written apart, and its own spool state) agree as the plain model's do."""
    from pneubayes.effects import SpoolLag
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    inputs, base, _, _ = _setup(rig, hand, n=601)  # (five steps)
    model = Model([SpoolLag(), ReadingFlow(("inlet_flow_square", "exhaust_flow"))])
    params = {**base, "spool_time_constant_s": 4e-3, "reading_flow_gain_0": GAIN,
              "reading_flow_gain_1": -400.0}
    n, solver = inputs.time_s.size, SolverConfig.standard()
    sim = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8, atol=1e-5)
    plain = Model([SpoolLag()])
    bare = {k: params[k] for k in plain.parameter_names}
    p_sim = simulate_windows(plain, bare, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    p_ref = reference_simulate(plain, bare, inputs, rig, 2e5, rtol=1e-8, atol=1e-5)
    assert np.max(np.abs(sim - p_sim)) > 300.0
    assert np.max(np.abs(sim - ref)) < 2.0 * np.max(np.abs(p_sim - p_ref)) + 5.0
    with pytest.raises(ValueError, match="solved here only on the chamber's own reading"):
        reference_simulate(model.with_effect(__import__(
            "pneubayes.effects", fromlist=["SensorLag"]).SensorLag()),
            {**params, "sensor_time_constant_s": 1e-3}, inputs, rig, 2e5)


def _jet_recording(rig, hand, gain, seed=0, noise_Pa=100.0, n=6001):
    """``(recording, the true maps)``: a recording whose reading carries ``gain`` x the
    inlet flow's square, and noise."""
    from pneubayes.io.recording import Recording, RecordingMetadata
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    md = RecordingMetadata("AIR37", "valve1", rig.bore_m, 0.0375,
                           rig.atmospheric_pressure_Pa, rig.supply_pressure_Pa, 293.15,
                           position_m=0.015)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    u = hand.random_steps(rng, n, 1e-3, hold_s=(0.05, 0.3))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    truth = Model().with_effect(ReadingFlow())
    blank = Recording(md, t, u, np.full(n, 2e5))
    p = simulate(truth, {**base, "reading_flow_gain_0": gain}, Inputs.from_recording(blank),
                 blank.rig(), 2e5, SolverConfig.standard()).pressure_Pa[0]
    return Recording(md, t, u, p + rng.normal(0.0, noise_Pa, n), source="jet.csv"), base


def _flow_blocks(rig, hand, gain, seed=0):
    """:func:`_jet_recording` cut into 500-ms windows, read by the plain model at the true
    maps."""
    from pneubayes.discovery.openform.reading_flow import flow_windows
    from pneubayes.inference.windows import WindowSet
    from pneubayes.simulation import SolverConfig

    rec, base = _jet_recording(rig, hand, gain, seed)
    return flow_windows(WindowSet([rec], 0.5, 0.5), Model(), base, SolverConfig.standard())


def test_a_found_flow_terms_view_follows_what_the_model_misses_without_it(rig, hand,
                                                                           tmp_path):
    """The report's view of a port flow term at the planted gain: along its feature the
    term follows the binned reading the model misses without it, and it draws."""
    from pneubayes.discovery.openform.flow_view import flow_views
    from pneubayes.plotting import plot_found_reading_terms
    from pneubayes.simulation import SolverConfig

    rec, base = _jet_recording(rig, hand, 4.0 * GAIN)
    model = Model().with_effect(ReadingFlow())
    (view,) = flow_views(model, {**base, "reading_flow_gain_0": 4.0 * GAIN}, [rec], 0.5,
                         SolverConfig.standard())
    assert view["unit"] == "(g/s)^2" and view["explained_fraction"] > 0.8
    np.testing.assert_allclose(view["term_Pa"], view["missing_Pa"], rtol=0,
                               atol=4.0 * max(view["missing_sem_Pa"]) + 20.0)
    assert plot_found_reading_terms([view], tmp_path / "f.png").exists()
    with pytest.raises(ValueError, match="no reading flow component"):
        flow_views(Model(), base, [rec], 0.5, SolverConfig.standard())


def test_the_search_recovers_a_planted_flow_term_and_finds_none_in_noise(rig, hand):
    """A jet's share (the inlet flow's square) planted in a reading: the search keeps that
    feature with its gain; on the plain model's own recording it keeps nothing; bad
    settings are named."""
    from pneubayes.discovery.openform.reading_flow import FlowSearch

    blocks = _flow_blocks(rig, hand, 4.0 * GAIN)
    s = FlowSearch().fit(blocks)
    assert [t.feature for t in s.terms_][:1] == ["inlet_flow_square"], s.terms_
    assert s.terms_[0].gain == pytest.approx(4.0 * GAIN, rel=0.1)
    assert s.explained_fraction_ > 0.8
    null = FlowSearch().fit(_flow_blocks(rig, hand, 0.0, seed=1))
    assert null.terms_ == [] and null.best_ is not None and null.best_.explained < 0.02
    assert FlowSearch().get_params()["max_terms"] == 2
    with pytest.raises(ValueError, match="features must be distinct names"):
        FlowSearch(features=("jet",)).fit(blocks)
    with pytest.raises(ValueError, match="max_terms"):
        FlowSearch(max_terms=3).fit(blocks)
    with pytest.raises(ValueError, match="list of FlowWindows"):
        FlowSearch().fit(blocks[0])


def test_the_flow_stage_is_in_the_pipeline_and_its_terms_are_listed_apart():
    from types import SimpleNamespace

    from pneubayes.discovery.result import DiscoveryResult
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import default_stages

    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("ReadingFlowForm") == names.index("ReadingCommandForm") + 1
    off = default_stages(DiscoverySettings(stages=StageSettings(
        reading_flow_min_noise_ratio=0.0)))
    assert "ReadingFlowForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="reading_flow_min_noise_ratio"):
        StageSettings(reading_flow_min_noise_ratio=0.5)
    model = Model().with_effect(ReadingFlow(("exhaust_flow_square",)))
    params = {**{k: 1.0 for k in Model().parameter_names}, "reading_flow_gain_0": -800.0}
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=600.0)
    result = DiscoveryResult(settings=DiscoverySettings(), base=final, final=final,
                             accepted=(), ledger=(), maps=(), searches=(), params=params,
                             estimate="refined", noise_floor_Pa=500.0, range_Pa=4.5e5,
                             span_Pa=4e5)
    doc = result.to_dict()
    assert doc["effects"] == [] and doc["found_terms"] == []
    (term,) = doc["found_reading_terms"]
    assert term["term"] == "port flow term 0"
    assert term["formula"].startswith("r = p + c_0 F_0, F_0 = exhaust_flow_square ((g/s)^2")
    assert term["parameters"]["reading_flow_gain_0"] == {"unit": "Pa/((g/s)^2)",
                                                         "estimate": -800.0}


def test_found_flow_terms_become_an_effect_plug_in_a_user_can_name(rig, hand, tmp_path):
    """The terms' skeleton is Python that defines an effect of the user's name: a model
    with it simulates exactly as the model with the found component; a model card with
    the component reads back the same; a model without one is named."""
    from pneubayes.discovery.openform.skeleton import flow_effect_skeleton
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, base, model, params = _setup(rig, hand, n=601,
                                         features=("inlet_flow_square", "exhaust_flow"),
                                         gains=(GAIN, -400.0))
    text = flow_effect_skeleton(model, params, "JetAtSensor", "jet_at_sensor")
    assert f"c_0 = {GAIN:g} Pa per (g/s)^2" in text and "F_1 = exhaust_flow (g/s)" in text
    ns: dict = {}
    exec(compile(text, "found_reading_flow.py", "exec"), ns)  # noqa: S102
    eff = ns["JetAtSensor"]()
    assert eff.name == "jet_at_sensor" and eff.relaxes_reading
    assert eff.bench_defaults() == {"inlet_flow_square_gain": GAIN,
                                    "exhaust_flow_gain": -400.0}
    mine = Model([eff])
    starts, solver = np.array([0, 300]), SolverConfig.standard()
    theirs = simulate_windows(model, params, inputs, rig, starts, 300, 2e5, solver)
    ours = simulate_windows(mine, {**base, **eff.bench_defaults()}, inputs, rig, starts, 300,
                            2e5, solver)
    np.testing.assert_array_equal(ours, theirs)
    model.save_card(params, tmp_path / "model.json")
    back, values = Model.load_card(tmp_path / "model.json")
    assert back.effect("reading_flow").features == ("inlet_flow_square", "exhaust_flow")
    np.testing.assert_array_equal(
        simulate_windows(back, values, inputs, rig, starts, 300, 2e5, solver), theirs)
    with pytest.raises(ValueError, match="no reading flow component"):
        flow_effect_skeleton(Model(), {})


@pytest.mark.slow
def test_discovery_finds_a_planted_jet_in_the_reading(tmp_path):
    """The loop with the flow stage alone, on four 8-s valve1 recordings whose reading
    carries a share of the inlet's jet: the term is found with its feature and gain,
    verified on held-out windows, the held-out error falls to about the noise floor, and
    the report lists it with the reading's terms and writes its plug-in."""
    from conftest import BORE, P_ATM, P_SUP, STROKE, discovery_settings, random_steps

    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery
    from pneubayes.discovery.stages import ReadingFlowForm
    from pneubayes.io.recording import Recording, RecordingMetadata
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    truth_model = Model().with_effect(ReadingFlow())
    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
             "reading_flow_gain_0": 10.0 * GAIN}
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    recs, n = [], 8001
    for seed in range(4):
        rng = np.random.default_rng(10 + seed)
        t = np.arange(n) * 1e-3
        u = random_steps(rng, n, 1e-3, hold_s=(0.1, 0.6))
        blank = Recording(md, t, u, np.full(n, P_ATM))
        p = simulate(truth_model, truth, Inputs.from_recording(blank), blank.rig(), P_ATM,
                     SolverConfig.standard()).pressure_Pa[0]
        recs.append(Recording(md, t, u, p + rng.normal(0.0, 200.0, n),
                              source=f"jet_{seed}.csv"))
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=None,
                       stages=[ReadingFlowForm()]).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_reading_terms"]
    assert term["formula"].startswith("r = p + c_0 F_0, F_0 = inlet_flow_square")
    c = term["parameters"]["reading_flow_gain_0"]["estimate"]
    # the gain trades against the inlet map's scale (the term is c (A_in f)^2): the
    # shift at the full inflow from the atmosphere is what the data fix
    from pneubayes.physics.orifice import flow_function
    from pneubayes.physics.valve import gompertz_area

    def shift(values, gain):
        a = gompertz_area(5.0, *(values[f"inlet_{k}"] for k in ("offset_m2", "a_m2", "b",
                                                                  "c_per_V", "d_V")))
        q = a * flow_function(P_SUP, P_ATM, blank.rig().gas) * 1e3
        return gain * q * q
    assert shift(result.params, c) == pytest.approx(shift(truth, 10.0 * GAIN), rel=0.1)
    assert c == pytest.approx(10.0 * GAIN, rel=0.3)
    assert doc["effects"] == [] and doc["found_terms"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    write_discovery(result, recs, tmp_path)
    assert (tmp_path / "found_reading_flow.py").exists()
    assert (tmp_path / "figures" / "found_reading_terms.png").exists()
