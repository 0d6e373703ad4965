"""The open form at the reading: relaxations of the reading (effect ``reading_closure``),
their search in the windows' residual and the stage that adds them."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import discovery_settings

from pneubayes.discovery.openform.reading import (
    ReadingSearch,
    ReadingWindows,
    relaxation_columns,
)
from pneubayes.discovery.settings import DiscoverySettings, StageSettings
from pneubayes.discovery.stages import ReadingForm, default_stages
from pneubayes.discovery.state import RoundState
from pneubayes.effects.reading_closure import ReadingClosure
from pneubayes.model import Model
from pneubayes.simulation.reading_closure import relaxed_reading

GAIN, TAU = 0.04, 0.35


def test_a_ramps_relaxation_is_its_closed_form_on_any_time_grid():
    """p = a t from rest: p - p_bar = a tau (1 - exp(-t / tau)), exactly, on a uniform
    grid (one linear filter) and an uneven one (the recursion); the first sample is the
    pressure; a zero gain reads the pressure; the map is applied per parameter set."""
    a, tau = 2e5, 0.05
    uniform = np.arange(200) * 1e-3
    uneven = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(2e-4, 2e-3, 199)])
    for t in (uniform, uneven):
        p = np.stack([1e5 + a * t, 3e5 + a * t])[None]  # one set, two windows
        r = relaxed_reading(np.stack([t, t]), p, np.array([[0.1, 0.0]]),
                            np.array([[tau, 1.0]]))
        expect = p + 0.1 * a * tau * (1.0 - np.exp(-t / tau))
        np.testing.assert_allclose(r, expect, rtol=0, atol=1e-6)
        assert np.all(r[..., 0] == p[..., 0])
    p = np.random.default_rng(1).uniform(1e5, 5e5, (3, 2, 50))
    t = np.stack([uniform[:50]] * 2)
    g = np.array([[0.0], [0.2], [-0.3]])
    r = relaxed_reading(t, p, g, np.full((3, 1), 0.01))
    assert np.array_equal(r[0], p[0])
    one = relaxed_reading(t, p[1:2], g[1:2], np.full((1, 1), 0.01))
    np.testing.assert_array_equal(r[1], one[0])
    p[2, 0, 7] = np.nan  # a failed set's rows stay as they are
    assert np.isnan(relaxed_reading(t, p, g, np.full((3, 1), 0.01))[2, 0, 7])
    with pytest.raises(ValueError, match=r"\(B, W, L\)"):
        relaxed_reading(t, p[0], g, g)
    with pytest.raises(ValueError, match="time constant 0 of parameter set 1"):
        relaxed_reading(t, p, g, np.array([[1.0], [0.0], [1.0]]))


def test_the_simulator_reads_windows_through_the_relaxation(rig, hand):
    """A model with a reading closure predicts the plain model's pressure plus g (p -
    p_bar), p_bar from each window's start; the carried simulation refuses it."""
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate_windows
    from pneubayes.simulation.simulator import fresh_carry, simulate_carried

    n = 1201
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    model = Model().with_effect(ReadingClosure())
    params = {**base, "reading_closure_gain_0": GAIN, "reading_closure_time_constant_0": TAU}
    starts = np.array([0, 300, 700])
    solver = SolverConfig.standard()
    plain = simulate_windows(Model(), base, inputs, rig, starts, 500, 2e5, solver)
    read = simulate_windows(model, params, inputs, rig, starts, 500, 2e5, solver)
    tw = t[starts[:, None] + np.arange(500)]
    expect = relaxed_reading(tw, plain, np.array([[GAIN]]), np.array([[TAU]]))
    np.testing.assert_allclose(read, expect, rtol=0, atol=1e-6)
    assert np.max(np.abs(read - plain)) > 1000.0
    # windows that start from a recorded reading start its relaxation warm: they read
    # the recording's own reading (a simulation of it from its first sample) to the
    # second order in the gain, where windows started at rest miss by the transient
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    recorded = Inputs(t, u, inputs.position_m, inputs.supply_pressure_Pa, reading_Pa=whole)
    warm = simulate_windows(model, params, recorded, rig, starts, 500, whole[starts], solver)
    rest = simulate_windows(model, params, inputs, rig, starts, 500, whole[starts], solver)
    truth = whole[starts[:, None] + np.arange(500)]
    err_warm = np.max(np.abs(warm[0] - truth))
    assert err_warm < 0.05 * np.max(np.abs(rest[0] - truth)) and err_warm < 100.0
    with pytest.raises(ValueError, match="reading closure"):
        simulate_carried(model, params, inputs, rig, np.array([0, 100]), 2e5, fresh_carry(1, rig),
                         np.full(n, 2e5), 0.0, solver)


def _windows(gain, tau, seed, noise_Pa=400.0, w=30, length=1500):
    """Step-like pressure windows, their reading through a relaxation plus noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(w * length).reshape(w, length) * 1e-3
    steps = np.empty((w, length))
    for i in range(w):
        levels = rng.uniform(1.2e5, 5e5, 6)
        at = np.sort(rng.integers(0, length, 5))
        steps[i] = levels[np.searchsorted(at, np.arange(length), side="right")]
    # a chamber's first-order response to the steps (a relaxation of gain -1 is p_bar)
    p = relaxed_reading(t, steps[None], np.array([[-1.0]]), np.array([[0.02]]))[0]
    measured = relaxed_reading(t, p[None], np.array([[gain]]), np.array([[tau]]))[0]
    return t, p, (measured + rng.normal(0.0, noise_Pa, p.shape) - p)[:, 1:]


def test_the_search_recovers_a_planted_relaxation_and_finds_none_in_noise():
    t, p, resid = _windows(GAIN, TAU, 0)
    s = ReadingSearch().fit([ReadingWindows(t, p, resid)])
    assert len(s.terms_) == 1, s.terms_
    assert s.terms_[0].gain == pytest.approx(GAIN, rel=0.03)
    assert s.terms_[0].time_constant_s == pytest.approx(TAU, rel=0.05)
    assert s.explained_fraction_ > 0.8
    # two blocks give the same answer as one
    two = ReadingSearch().fit([ReadingWindows(t[:10], p[:10], resid[:10]),
                               ReadingWindows(t[10:], p[10:], resid[10:])])
    assert two.terms_[0].gain == pytest.approx(s.terms_[0].gain, rel=1e-6)
    # noise alone: no term, though the best column is reported
    rng = np.random.default_rng(3)
    null = ReadingSearch().fit([ReadingWindows(t, p, rng.normal(0.0, 400.0, resid.shape))])
    assert null.terms_ == [] and null.best_ is not None and null.best_.explained < 0.02
    # two relaxations of opposite sign, far apart in time: both found
    second = relaxed_reading(t, p[None], np.array([[-0.05]]), np.array([[2.0]]))[0] - p
    both = ReadingSearch().fit([ReadingWindows(t, p, resid + second[:, 1:])])
    taus = sorted(x.time_constant_s for x in both.terms_)
    assert len(taus) == 2 and taus[0] == pytest.approx(TAU, rel=0.2) \
        and taus[1] == pytest.approx(2.0, rel=0.3), both.terms_
    col = relaxation_columns([ReadingWindows(t, p, resid)], TAU)
    assert col.shape == resid.reshape(-1).shape


def test_the_search_names_bad_settings_and_shapes():
    t, p, resid = _windows(GAIN, TAU, 0, w=3, length=50)
    good = [ReadingWindows(t, p, resid)]
    with pytest.raises(ValueError, match="time_constants_s"):
        ReadingSearch(time_constants_s=(0.1, 0.05, 1.0)).fit(good)
    with pytest.raises(ValueError, match="max_terms"):
        ReadingSearch(max_terms=3).fit(good)
    with pytest.raises(ValueError, match=r"block 0: times .* residual"):
        ReadingSearch().fit([ReadingWindows(t, p, resid[:, 1:])])
    with pytest.raises(ValueError, match="a list of ReadingWindows"):
        ReadingSearch().fit(good[0])


def _state(current, passing=()):
    return RoundState(number=1, current=current, search=None, supported=[], tentative=[],
                      started_far=True, gap_ratio=2.0, noise_Pa=500.0, search_step=0,
                      counts={}, passing=list(passing))


def test_the_stage_runs_above_its_noise_ratio_once_and_beside_a_weak_trial():
    stage = ReadingForm(min_noise_ratio=1.5, compete_below_gap_closed=0.5)
    near = SimpleNamespace(heldout_rmse_Pa=700.0, model=Model())
    assert stage._applies(_state(near), 500.0) == (False, None)
    far = SimpleNamespace(heldout_rmse_Pa=2500.0, model=Model())
    assert stage._applies(_state(far), 500.0) == (True, None)
    strong = (1000.0, "cylinder_leak", None, 1.0, 0.001)
    assert stage._applies(_state(far, [strong]), 500.0)[0] is False
    weak = (2000.0, "closure", None, 1.0, 0.001)
    assert stage._applies(_state(far, [weak]), 500.0) == (True, weak)
    has = SimpleNamespace(heldout_rmse_Pa=2500.0, model=Model().with_effect(ReadingClosure()))
    assert stage._applies(_state(has), 500.0)[0] is False
    with pytest.raises(ValueError, match="min_noise_ratio"):
        ReadingForm(min_noise_ratio=0.5)
    with pytest.raises(ValueError, match="compete_below_gap_closed"):
        ReadingForm(compete_below_gap_closed=2.0)
    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names[-10:] == ["ReadingHingeForm", "ReadingForm", "ReadingPlayForm",
                           "ReadingCommandForm", "ReadingFlowForm", "PortRestrictionForm",
                           "VolumeForm", "VolumePlayForm", "LoadedWallForm", "OpenForm"]
    off = default_stages(DiscoverySettings(stages=StageSettings(
        reading_form_min_noise_ratio=0.0)))
    assert "ReadingForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="reading_form_min_noise_ratio"):
        StageSettings(reading_form_min_noise_ratio=0.5)


def test_found_relaxations_are_listed_apart_with_their_formula():
    from pneubayes.discovery.result import DiscoveryResult

    model = Model().with_effect(ReadingClosure())
    params = {**{k: 1.0 for k in Model().parameter_names}, "reading_closure_gain_0": GAIN,
              "reading_closure_time_constant_0": TAU}
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=600.0)
    result = DiscoveryResult(settings=DiscoverySettings(), base=final, final=final,
                             accepted=(), ledger=(), maps=(), searches=(), params=params,
                             estimate="refined", noise_floor_Pa=500.0, range_Pa=4.5e5,
                             span_Pa=4e5)
    doc = result.to_dict()
    assert doc["found_terms"] == [] and doc["effects"] == []
    (term,) = doc["found_reading_terms"]
    assert term["acts_on"] == "the pressure reading (Pa)"
    assert term["formula"].startswith("r = p + g_0 (p - p_bar_0)")
    assert term["parameters"]["reading_closure_time_constant_0"] == {"unit": "s",
                                                                     "estimate": TAU}


@pytest.fixture(scope="module")
def relaxing_recordings():
    """Four 8-s valve1 recordings (1 kHz, 200 Pa noise) read through a sensor that
    reads a change 4 % high at first and settles in 0.35 s."""
    return _relaxing(4, 8001)


def _relaxing(count, n):
    from conftest import BORE, P_ATM, P_SUP, STROKE, random_steps

    from pneubayes.io.recording import Recording, RecordingMetadata
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    truth_model = Model().with_effect(ReadingClosure())
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    truth = {**base, "reading_closure_gain_0": GAIN, "reading_closure_time_constant_0": TAU}
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    recs = []
    for seed in range(count):
        rng = np.random.default_rng(10 + seed)
        dt = 1e-3
        t = np.arange(n) * dt
        u = random_steps(rng, n, dt, hold_s=(0.1, 0.6))
        blank = Recording(md, t, u, np.full(n, P_ATM))
        p = simulate(truth_model, truth, Inputs.from_recording(blank), blank.rig(), P_ATM,
                     SolverConfig.standard()).pressure_Pa[0]
        recs.append(Recording(md, t, u, p + rng.normal(0.0, 200.0, n),
                              source=f"relaxing_{seed}.csv"))
    return recs, truth


@pytest.mark.slow
def test_discovery_finds_a_planted_relaxation_of_the_reading(relaxing_recordings, tmp_path):
    """The loop with the reading stage alone: the relaxation is found with its gain and
    time constant, verified on held-out windows, and the held-out error falls to about
    the noise floor; the report lists it apart from named effects."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery

    recs, truth = relaxing_recordings
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=None, stages=[ReadingForm()]).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_reading_terms"]
    g = term["parameters"]["reading_closure_gain_0"]["estimate"]
    tau = term["parameters"]["reading_closure_time_constant_0"]["estimate"]
    assert g == pytest.approx(GAIN, rel=0.1) and tau == pytest.approx(TAU, rel=0.15)
    assert doc["effects"] == [] and doc["found_terms"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    write_discovery(result, recs, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "terms at the reading found (relaxations, plays" in report
    assert "![found relaxations](figures/found_reading_terms.png)" in report
    assert (tmp_path / "figures" / "found_reading_terms.png").stat().st_size > 0
    assert (tmp_path / "found_reading.py").exists()
    assert json.loads((tmp_path / "discovery.json").read_text())["found_reading_effect"] \
        == "found_reading.py"


def test_a_true_relaxation_follows_the_reading_the_model_misses_without_it():
    """The report's view: on recordings read through a relaxation, the truth's term
    explains nearly all of the reading the model misses without it, bin by bin."""
    from pneubayes.discovery.openform.reading_view import reading_views
    from pneubayes.simulation import SolverConfig

    recs, truth = _relaxing(2, 3001)
    model = Model().with_effect(ReadingClosure())
    (view,) = reading_views(model, truth, recs, 1.0, SolverConfig.standard())
    assert view["explained_fraction"] > 0.95
    np.testing.assert_allclose(view["term_Pa"], GAIN * np.asarray(view["bin_centre"]),
                               rtol=0.2, atol=50.0)
    np.testing.assert_allclose(view["missing_Pa"], view["term_Pa"], rtol=0, atol=300.0)
    with pytest.raises(ValueError, match="no reading closure"):
        reading_views(Model(), truth, recs, 1.0, SolverConfig.standard())


def test_a_controllers_prediction_starts_the_relaxation_warm_from_the_readings(rig, hand):
    """PressurePredictor with the readings before now predicts a recording read through
    a relaxation from mid-transient as the recording's own simulation does; without them
    it starts the relaxation at rest and misses by the transient."""
    from pneubayes.inference.predictive import PressurePredictor
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

    n, now, horizon = 1201, 600, 400
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    model = Model().with_effect(ReadingClosure())
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
              "reading_closure_gain_0": GAIN, "reading_closure_time_constant_0": TAU}
    solver = SolverConfig.standard()
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    predictor = PressurePredictor(model, model.vector(params)[None], rig, solver)
    args = (whole[now], u[now:now + horizon], 0.015, 1e-3)
    warm = predictor.predict_draws(*args, command_history_V=u[:now],
                                   reading_history_Pa=whole[:now])[0, 0]
    rest = predictor.predict_draws(*args, command_history_V=u[:now])[0, 0]
    truth = whole[now:now + horizon + 1]
    assert np.max(np.abs(warm - truth)) < 50.0 < 0.05 * np.max(np.abs(rest - truth))
    with pytest.raises(ValueError, match="reading_history_Pa"):
        predictor.predict_draws(*args, reading_history_Pa=[np.nan])


def test_the_gains_keep_a_reading_that_moves_with_the_pressure(rig):
    """A relaxation of gain -1 reads only the low-pass (a pure lag, sensor_lag's): the
    bounds keep the gains' sum above -1, and the simulator names a set below it."""
    from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

    two = ReadingClosure(terms=2)
    lows = [p.lower for p in two.parameters() if p.name.startswith("reading_closure_gain")]
    assert len(lows) == 2 and 1.0 + sum(lows) > 0.0
    n = 50
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, np.full(n, 5.0), np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    model = Model().with_effect(ReadingClosure())
    from pneubayes.physics.valve import valve_preset

    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
              "reading_closure_gain_0": -1.0, "reading_closure_time_constant_0": TAU}
    with pytest.raises(ValueError, match="sum to more than -1"):
        simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5,
                         SolverConfig.standard(), check_bounds=False)


def test_found_relaxations_become_an_effect_plug_in_a_user_can_name(rig, hand):
    """The reading's skeleton is Python that defines an effect of the user's name
    that relaxes the reading: a model with it simulates exactly as the model with the
    found reading closure, beside a second such effect the relaxations add up, and the
    reference solver agrees."""
    from pneubayes.discovery.openform.skeleton import reading_effect_skeleton
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    model = Model().with_effect(ReadingClosure(terms=2))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    params = {**base, "reading_closure_gain_0": 0.05, "reading_closure_time_constant_0": 0.3,
              "reading_closure_gain_1": -0.03, "reading_closure_time_constant_1": 0.02}
    text = reading_effect_skeleton(model, params, "DiaphragmWarming", "diaphragm_warming")
    assert "g_0 = 0.05, tau_0 = 0.3 s" in text
    ns: dict = {}
    exec(compile(text, "found_reading.py", "exec"), ns)  # noqa: S102
    eff = ns["DiaphragmWarming"]()
    assert eff.name == "diaphragm_warming" and eff.relaxes_reading
    assert eff.bench_defaults() == {"relaxation0_gain": 0.05, "relaxation0_time_constant_s": 0.3,
                                    "relaxation1_gain": -0.03,
                                    "relaxation1_time_constant_s": 0.02}
    units = {p.name: (p.unit, p.prior) for p in eff.parameters()}
    assert units["relaxation1_time_constant_s"] == ("s", "log-uniform")
    mine = Model([eff])
    mine_params = {**base, **eff.bench_defaults()}

    n = 1201
    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(7), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    starts, solver = np.array([0, 400]), SolverConfig.standard()
    theirs = simulate_windows(model, params, inputs, rig, starts, 600, 2e5, solver)
    ours = simulate_windows(mine, mine_params, inputs, rig, starts, 600, 2e5, solver)
    np.testing.assert_array_equal(ours, theirs)
    plain = simulate_windows(Model(), base, inputs, rig, starts, 600, 2e5, solver)
    assert np.max(np.abs(ours - plain)) > 1000.0
    # two effects that relax the reading: their relaxations side by side
    one = Model().with_effect(ReadingClosure(terms=1))
    both = one.with_effect(ns["DiaphragmWarming"]())
    both_params = {**mine_params, "reading_closure_gain_0": 0.02,
                   "reading_closure_time_constant_0": 1.0}
    g, tau = both.reading_relaxations(both_params)
    np.testing.assert_array_equal(g, [[0.02, 0.05, -0.03]])
    np.testing.assert_array_equal(tau, [[1.0, 0.3, 0.02]])
    sim = simulate_windows(both, both_params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    ref = reference_simulate(both, both_params, inputs, rig, 2e5, rtol=1e-9, atol=1e-6)
    assert np.max(np.abs(sim - ref)) < 20.0
    with pytest.raises(ValueError, match="no reading closure"):
        reading_effect_skeleton(Model(), {})
