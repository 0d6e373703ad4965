"""The open form at the reading driven by the command: lags of the command's magnitude
added to the reading (effect ``reading_command``), the simulator's windows, against the
reference solver, and their search in the windows' residual."""

from __future__ import annotations

import numpy as np
import pytest

from pneubayes.effects import ReadingCommand
from pneubayes.model import Model
from pneubayes.simulation.reading_command import command_lag

GAIN, TAU = 700.0, 4e-3


def _setup(rig, hand, n=1201):
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs

    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    params = {**base, "reading_command_gain_0": GAIN,
              "reading_command_time_constant_0": TAU}
    return inputs, base, params


def test_a_command_lag_steps_exactly_under_a_held_command():
    """|u| held between samples: the lag after a step is 1 - exp(-(t - t_step) / tau) of
    it at every sample, on a uniform grid and an uneven one alike; it starts at its
    steady value under the command before the first sample; a bad time constant is
    named."""
    t = np.arange(200) * 1e-3
    u = np.where(t >= 0.05 - 1e-12, -4.0, 1.0)
    want = np.where(t >= 0.05 - 1e-12, 4.0 - 3.0 * np.exp(-(t - 0.05) / 0.01), 1.0)
    np.testing.assert_allclose(command_lag(t, u, 0.01), want, rtol=0, atol=1e-12)
    uneven = np.sort(np.r_[t, t[:-1] + 3e-4])
    held = np.where(uneven >= 0.05 - 1e-12, -4.0, 1.0)
    np.testing.assert_allclose(command_lag(uneven, held, 0.01)[::2], want, rtol=0,
                               atol=1e-12)
    before = command_lag(t, u, 0.01, before=3.0)
    np.testing.assert_allclose(before[:50], 1.0 + 2.0 * np.exp(-t[:50] / 0.01), atol=1e-12)
    with pytest.raises(ValueError, match="time constant must be finite and > 0"):
        command_lag(t, u, 0.0)


def test_the_simulator_adds_the_lags_to_the_reading_warm_from_the_recording(rig, hand):
    """A model with the component predicts the plain model's pressure (started at the
    first reading less the shift there) plus c l(t), the lag warm from the recording's
    start; windows started mid-recording from the whole run's reading reproduce it;
    gain 0 is the plain model bit for bit."""
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, base, params = _setup(rig, hand)
    model = Model().with_effect(ReadingCommand())
    starts = np.array([0, 300, 700])
    solver = SolverConfig.standard()
    lag = command_lag(inputs.time_s, inputs.command_V, TAU)
    shift = GAIN * lag[starts[:, None] + np.arange(500)]
    read = simulate_windows(model, params, inputs, rig, starts, 500, 2e5, solver)[0]
    plain = simulate_windows(Model(), base, inputs, rig, starts, 500, 2e5 - shift[:, 0],
                             solver)[0]
    np.testing.assert_allclose(read, plain + shift, rtol=0, atol=1e-6)
    assert np.max(np.abs(shift)) > 2000.0
    n = inputs.time_s.size
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    again = simulate_windows(model, params, inputs, rig, starts[1:], 500, whole[starts[1:]],
                             solver)[0]
    np.testing.assert_allclose(again, whole[starts[1:, None] + np.arange(500)], rtol=0,
                               atol=1.0)
    off = simulate_windows(model, {**params, "reading_command_gain_0": 0.0}, inputs, rig,
                           starts, 500, 2e5, solver)
    np.testing.assert_array_equal(off, simulate_windows(Model(), base, inputs, rig, starts,
                                                        500, 2e5, solver))


def test_a_command_shifted_reading_agrees_with_the_reference_solver(rig, hand):
    """One window from the recording's first sample, two lags: the compiled simulator
    against the reference solver (scipy at rtol 1e-8; its lags a plain loop over the
    samples), over 0.4 s and three steps."""
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    inputs, _, params = _setup(rig, hand, n=401)
    model = Model().with_effect(ReadingCommand(terms=2))
    params = {**params, "reading_command_gain_1": -300.0,
              "reading_command_time_constant_1": 0.2}
    ours = simulate_windows(model, params, inputs, rig, np.array([0]), 401, 2e5,
                            SolverConfig.standard())[0, 0]
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    assert np.max(np.abs(ours - ref)) < 1e-3 * np.ptp(ref)
    plain = reference_simulate(Model(), {k: v for k, v in params.items()
                                         if not k.startswith("reading_command")},
                               inputs, rig, 2e5 - GAIN * abs(inputs.command_V[0]) + 300.0
                               * abs(inputs.command_V[0]), rtol=1e-8)
    assert np.max(np.abs(ref - plain)) > 2000.0


def test_the_components_options_and_parameters_are_checked():
    with pytest.raises(ValueError, match="'terms' must be an integer in 1..2"):
        ReadingCommand(terms=3)
    names = Model().with_effect(ReadingCommand(terms=2)).parameter_names
    assert {"reading_command_gain_1", "reading_command_time_constant_1"} <= set(names)
    assert ReadingCommand().relaxes_reading and not ReadingCommand().library_searched


def _windows(gain, tau, seed, noise_Pa=400.0, w=30, length=1500):
    """Windows of a recording whose command steps at random: step-like pressures, and
    their reading shifted by ``gain`` x the lag of |u| plus noise: ``(blocks, lag)``."""
    from pneubayes.discovery.openform.reading import ReadingWindows

    rng = np.random.default_rng(seed)
    n = w * length
    t = np.arange(n) * 1e-3
    u = np.repeat(rng.uniform(-5.0, 5.0, n // 100), 100)
    lag = command_lag(t, u, tau)
    p = 1.2e5 + 3e5 * np.abs(np.sin(t / 0.7))
    starts = np.arange(w) * length
    idx = starts[:, None] + np.arange(length)
    # (each window starts from its measured reading: the chamber at it less the shift)
    resid = gain * (lag[idx] - lag[idx][:, :1]) + rng.normal(0.0, noise_Pa, idx.shape)
    block = ReadingWindows(t[idx], p[idx], resid[:, 1:], np.ones(idx.shape), None,
                           (t, u, None, starts))
    return [block], lag


def test_the_search_recovers_a_planted_command_lag_and_finds_none_in_noise():
    """A lag of |u| planted in windows' residual: the search recovers its gain and time
    constant; in noise alone it keeps nothing; a relaxation's search, which sees only
    the pressure, explains little of it; bad settings are named."""
    from pneubayes.discovery.openform.reading import ReadingSearch, ReadingWindows
    from pneubayes.discovery.openform.reading_command import CommandLagSearch

    blocks, _ = _windows(GAIN, 0.02, 0)
    s = CommandLagSearch().fit(blocks)
    assert len(s.terms_) == 1, s.terms_
    assert s.terms_[0].gain == pytest.approx(GAIN, rel=0.05)
    assert s.terms_[0].time_constant_s == pytest.approx(0.02, rel=0.1)
    assert s.explained_fraction_ > 0.8
    b = blocks[0]
    relax = ReadingSearch().fit([ReadingWindows(b.time_s, b.predicted_Pa, b.residual_Pa,
                                                b.sensitivity)])
    assert relax.explained_fraction_ < 0.3
    rng = np.random.default_rng(3)
    null = CommandLagSearch().fit([ReadingWindows(
        b.time_s, b.predicted_Pa, rng.normal(0.0, 400.0, b.residual_Pa.shape),
        b.sensitivity, None, b.command)])
    assert null.terms_ == [] and null.best_ is not None and null.best_.explained < 0.02
    with pytest.raises(ValueError, match="time_constants_s"):
        CommandLagSearch(time_constants_s=(1e-2, 5e-3, 1.0)).fit(blocks)
    with pytest.raises(ValueError, match="max_terms"):
        CommandLagSearch(max_terms=3).fit(blocks)


def test_the_command_stage_is_in_the_pipeline_and_its_terms_are_listed_apart():
    from types import SimpleNamespace

    from pneubayes.discovery.result import DiscoveryResult
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import default_stages

    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("ReadingCommandForm") == names.index("ReadingPlayForm") + 1
    off = default_stages(DiscoverySettings(stages=StageSettings(
        reading_command_min_noise_ratio=0.0)))
    assert "ReadingCommandForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="reading_command_min_noise_ratio"):
        StageSettings(reading_command_min_noise_ratio=0.5)
    model = Model().with_effect(ReadingCommand())
    params = {**{k: 1.0 for k in Model().parameter_names}, "reading_command_gain_0": GAIN,
              "reading_command_time_constant_0": TAU}
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=600.0)
    result = DiscoveryResult(settings=DiscoverySettings(), base=final, final=final,
                             accepted=(), ledger=(), maps=(), searches=(), params=params,
                             estimate="refined", noise_floor_Pa=500.0, range_Pa=4.5e5,
                             span_Pa=4e5)
    doc = result.to_dict()
    assert doc["effects"] == [] and doc["found_terms"] == []
    (term,) = doc["found_reading_terms"]
    assert term["term"] == "command lag 0" and term["formula"].startswith("r = p + c_0 l_0")
    assert term["parameters"]["reading_command_time_constant_0"] == {"unit": "s",
                                                                      "estimate": TAU}


def test_found_command_lags_become_an_effect_plug_in_beside_a_relaxation(rig, hand):
    """The lags' skeleton is Python that defines an effect of the user's name: a model
    with it simulates exactly as the model with the found component; beside a relaxation
    of the reading both act (the reference solver agrees); a model without one is
    named."""
    from pneubayes.discovery.openform.skeleton import command_effect_skeleton
    from pneubayes.effects import ReadingClosure
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    inputs, base, params = _setup(rig, hand, n=601)
    model = Model().with_effect(ReadingCommand())
    text = command_effect_skeleton(model, params, "GroundShift", "ground_shift")
    assert f"c_0 = {GAIN:g} Pa per command unit, tau_0 = {TAU:g} s" in text
    ns: dict = {}
    exec(compile(text, "found_reading_command.py", "exec"), ns)  # noqa: S102
    eff = ns["GroundShift"]()
    assert eff.name == "ground_shift" and eff.relaxes_reading
    assert eff.bench_defaults() == {"command0_gain_Pa": GAIN, "command0_time_constant_s": TAU}
    mine = Model([eff])
    mine_params = {**base, **eff.bench_defaults()}
    starts, solver = np.array([0, 300]), SolverConfig.standard()
    theirs = simulate_windows(model, params, inputs, rig, starts, 300, 2e5, solver)
    ours = simulate_windows(mine, mine_params, inputs, rig, starts, 300, 2e5, solver)
    np.testing.assert_array_equal(ours, theirs)
    both = Model().with_effect(ReadingClosure()).with_effect(eff)
    both_params = {**mine_params, "reading_closure_gain_0": 0.05,
                   "reading_closure_time_constant_0": 0.2}
    n = 601
    sim = simulate_windows(both, both_params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    ref = reference_simulate(both, both_params, inputs, rig, 2e5, rtol=1e-8, atol=1e-5)
    alone = simulate_windows(mine, mine_params, inputs, rig, np.array([0]), n, 2e5,
                             solver)[0, 0]
    assert np.max(np.abs(sim - ref)) < 20.0 < np.max(np.abs(sim - alone))
    with pytest.raises(ValueError, match="no reading command lag"):
        command_effect_skeleton(Model(), {})


@pytest.mark.slow
def test_discovery_finds_a_planted_command_lag_in_the_reading(tmp_path):
    """The loop with the command stage alone, on four 8-s valve1 recordings whose
    reading shifts with the command: the lag is found with its gain and time constant,
    verified on held-out windows, the held-out error falls to about the noise floor,
    and the report lists it with the reading's terms and writes its plug-in."""
    from conftest import BORE, P_ATM, P_SUP, STROKE, discovery_settings, random_steps

    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery
    from pneubayes.discovery.stages import ReadingCommandForm
    from pneubayes.io.recording import Recording, RecordingMetadata
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    truth_model = Model().with_effect(ReadingCommand())
    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
             "reading_command_gain_0": GAIN, "reading_command_time_constant_0": 0.02}
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    recs, n = [], 8001
    for seed in range(4):
        rng = np.random.default_rng(10 + seed)
        t = np.arange(n) * 1e-3
        u = random_steps(rng, n, 1e-3, hold_s=(0.1, 0.6))
        blank = Recording(md, t, u, np.full(n, P_ATM))
        p = simulate(truth_model, truth, Inputs.from_recording(blank), blank.rig(),
                     P_ATM + GAIN * abs(u[0]), SolverConfig.standard()).pressure_Pa[0]
        recs.append(Recording(md, t, u, p + rng.normal(0.0, 200.0, n),
                              source=f"shifted_{seed}.csv"))
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=None,
                       stages=[ReadingCommandForm()]).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_reading_terms"]
    c = term["parameters"]["reading_command_gain_0"]["estimate"]
    tau = term["parameters"]["reading_command_time_constant_0"]["estimate"]
    assert c == pytest.approx(GAIN, rel=0.1) and tau == pytest.approx(0.02, rel=0.1)
    assert doc["effects"] == [] and doc["found_terms"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    write_discovery(result, recs, tmp_path)
    assert "terms at the reading found" in (tmp_path / "report.md").read_text()
    assert (tmp_path / "found_reading_command.py").exists()


def test_a_controllers_prediction_carries_the_lag_from_the_command_history(rig, hand):
    """PressurePredictor given the commands before now predicts a shifted recording from
    mid-recording as the recording's own simulation does (the lag warm from them);
    without them the lag starts settled at the first command and misses."""
    from pneubayes.inference.predictive import PressurePredictor
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, _, params = _setup(rig, hand)
    params = {**params, "reading_command_time_constant_0": 0.05}
    n, now, horizon = inputs.time_s.size, 600, 400
    u = inputs.command_V
    model = Model().with_effect(ReadingCommand())
    solver = SolverConfig.standard()
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    predictor = PressurePredictor(model, model.vector(params)[None], rig, solver)
    args = (whole[now], u[now:now + horizon], 0.015, 1e-3)
    warm = predictor.predict_draws(*args, command_history_V=u[:now])[0, 0]
    cold = predictor.predict_draws(*args)[0, 0]
    truth = whole[now:now + horizon + 1]
    assert np.max(np.abs(warm - truth)) < 50.0 < np.max(np.abs(cold - truth))
