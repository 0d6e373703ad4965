"""The open form at the reading, rate-independent: plays (backlash) of the reading
(effect ``reading_play``), the simulator's windows read through them, against the
reference solver, and their search in the windows' residual."""

from __future__ import annotations

import numpy as np
import pytest

from pneubayes.effects import ReadingPlay
from pneubayes.model import Model
from pneubayes.simulation.reading_play import history_play, play_rows, played_reading

WIDTH, GAIN = 6000.0, -0.6


def _naive_play(x, w, y):
    out = []
    for v in x:
        y = min(v + w, max(v - w, y))
        out.append(y)
    return np.array(out)


def test_a_play_lags_a_reversal_by_its_width_whatever_the_rate():
    """A triangle wave through a play: after each reversal the play stands still until
    the input has come back 2 w, then follows it w behind; the same on a wave ten times
    slower (rate-independent); its slope in the start follows the input's only while it
    moves; the history's play is the same recursion from the first finite sample."""
    tri = np.concatenate([np.linspace(1e5, 3e5, 101), np.linspace(3e5, 1.5e5, 76)[1:],
                          np.linspace(1.5e5, 2.5e5, 51)[1:]])
    w = 1e4
    y, dy = play_rows(tri[None], np.ones((1, tri.size)), w, np.array([1e5]))
    np.testing.assert_allclose(y[0], _naive_play(tri, w, 1e5))
    top = 100  # the reversal at 3e5: the play holds 2.9e5 until the input is 2.8e5
    assert y[0, top] == pytest.approx(2.9e5)
    held = (tri[top:top + 76] > 2.8e5)
    assert np.all(y[0, top:top + 76][held] == pytest.approx(2.9e5))
    falling = np.arange(top, top + 76)[tri[top:top + 76] < 2.8e5]
    np.testing.assert_allclose(y[0, falling], tri[falling] + w)
    assert np.all(dy[0, falling] == 1.0)
    slow = np.interp(np.linspace(0, tri.size - 1, 10 * tri.size), np.arange(tri.size), tri)
    ys, _ = play_rows(slow[None], np.ones((1, slow.size)), w, np.array([1e5]))
    assert ys[0].min() == pytest.approx(y[0].min()) and ys[0].max() == pytest.approx(y[0].max())
    # its slope: 0 from a fixed start until the input drags it
    s = np.linspace(1.0, 0.5, tri.size)[None]
    _, d0 = play_rows(tri[None], s, w, np.array([2e5]))
    moving = np.abs(_naive_play(tri, w, 2e5) - np.r_[2e5, _naive_play(tri, w, 2e5)[:-1]]) > 0
    first = int(np.argmax(moving))
    assert np.all(d0[0, :first] == 0.0) and d0[0, first] == s[0, first]
    reading = np.r_[np.nan, tri, np.nan, tri[::-1]]
    starts = np.array([1 + top, tri.size + 2 + 50])
    h = history_play(reading, np.array([[w]]), starts)[0, 0]
    assert h[0] == pytest.approx(_naive_play(tri, w, tri[0])[top])
    assert h[1] == pytest.approx(_naive_play(tri[::-1], w, tri[-1])[50])


def test_zero_gain_reads_the_pressure_and_a_bad_width_is_named():
    p = np.random.default_rng(0).uniform(1e5, 5e5, (2, 3, 40))
    part, slope = played_reading(p, np.ones_like(p), np.array([[0.0], [GAIN]]),
                                 np.array([[WIDTH], [WIDTH]]), p[:, None, :, 0])
    assert np.all(part[0] == 0.0) and np.any(part[1] != 0.0)
    with pytest.raises(ValueError, match="half-width 0 of parameter set 1"):
        played_reading(p, np.ones_like(p), np.array([[0.0], [GAIN]]),
                       np.array([[WIDTH], [0.0]]), p[:, None, :, 0])


def _setup(rig, hand, n=1201):
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs

    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    params = {**base, "reading_play_gain_0": GAIN, "reading_play_width_0": WIDTH}
    return inputs, base, params


def test_the_simulator_reads_windows_through_the_play(rig, hand):
    """A model with a reading play predicts the plain model's pressure plus h (p - y), y
    from rest at each window's start; windows that start from a recorded reading start
    the play where the recording's own reading put it (exactly, for one play), where
    windows started at rest miss; a reading that the gains leave unable to tell the
    pressure fails as a set, or is named."""
    from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

    inputs, base, params = _setup(rig, hand)
    model = Model().with_effect(ReadingPlay())
    starts = np.array([0, 300, 700])
    solver = SolverConfig.standard()
    plain = simulate_windows(Model(), base, inputs, rig, starts, 500, 2e5, solver)
    read = simulate_windows(model, params, inputs, rig, starts, 500, 2e5, solver)
    expect = np.stack([p + GAIN * (p - _naive_play(p, WIDTH, p[0])) for p in plain[0]])
    np.testing.assert_allclose(read[0], expect, rtol=0, atol=1e-6)
    assert np.max(np.abs(read - plain)) > 2000.0
    n = inputs.time_s.size
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    recorded = Inputs(inputs.time_s, inputs.command_V, inputs.position_m,
                      inputs.supply_pressure_Pa, reading_Pa=whole)
    warm = simulate_windows(model, params, recorded, rig, starts[1:], 500, whole[starts[1:]],
                            solver)
    rest = simulate_windows(model, params, inputs, rig, starts[1:], 500, whole[starts[1:]],
                            solver)
    truth = whole[starts[1:, None] + np.arange(500)]
    err_warm = np.max(np.abs(warm[0] - truth))
    assert err_warm < 1.0 < 0.05 * np.max(np.abs(rest[0] - truth))
    bad = {**params, "reading_play_gain_0": -1.2}
    both = np.stack([model.vector(params), model.vector(bad)])
    out = simulate_windows(model, both, inputs, rig, starts, 500, 2e5, solver,
                           check_bounds=False, on_failure="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1]))
    with pytest.raises(ValueError, match="sum to more than -1"):
        simulate_windows(model, bad, inputs, rig, starts, 500, 2e5, solver,
                         check_bounds=False)


def test_a_played_reading_agrees_with_the_reference_solver(rig, hand):
    """One window from the recording's first sample: the compiled simulator with a play
    against the reference solver (scipy at rtol 1e-8, its play a plain loop over the
    samples), over 0.4 s and three steps."""
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    inputs, _, params = _setup(rig, hand, n=401)
    model = Model().with_effect(ReadingPlay(terms=2))
    params = {**params, "reading_play_gain_1": 0.3, "reading_play_width_1": 1500.0}
    ours = simulate_windows(model, params, inputs, rig, np.array([0]), 401, 2e5,
                            SolverConfig.standard())[0, 0]
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    span = np.ptp(ref)
    assert np.max(np.abs(ours - ref)) < 1e-3 * span
    plain = reference_simulate(Model(), {k: v for k, v in params.items()
                                         if not k.startswith("reading_play")}, inputs, rig, 2e5,
                               rtol=1e-8)
    assert np.max(np.abs(ref - plain)) > 2000.0


def _windows(gain, width, seed, noise_Pa=400.0, w=30, length=1500):
    """Step-like pressure windows (a chamber's first-order response to random levels),
    their reading through a play plus noise: ``(t, p, residual)``."""
    from pneubayes.simulation.reading_closure import relaxed_reading

    rng = np.random.default_rng(seed)
    t = np.arange(w * length).reshape(w, length) * 1e-3
    steps = np.empty((w, length))
    for i in range(w):
        levels = rng.uniform(1.2e5, 5e5, 6)
        at = np.sort(rng.integers(0, length, 5))
        steps[i] = levels[np.searchsorted(at, np.arange(length), side="right")]
    p = relaxed_reading(t, steps[None], np.array([[-1.0]]), np.array([[0.02]]))[0]
    y, _ = play_rows(p, np.zeros_like(p), width, p[:, 0])
    measured = p + gain * (p - y)
    return t, p, (measured + rng.normal(0.0, noise_Pa, p.shape) - p)[:, 1:]


def test_the_search_recovers_a_planted_play_and_finds_none_in_noise():
    """A play of the reading planted in windows' residual: the play search recovers its
    gain and half-width; in noise alone it keeps nothing; a relaxation's search does
    not mistake the play for itself as well as the play's does; bad settings named."""
    from pneubayes.discovery.openform.reading import ReadingSearch, ReadingWindows
    from pneubayes.discovery.openform.reading_play import PlaySearch

    t, p, resid = _windows(GAIN, WIDTH, 0)
    s = PlaySearch().fit([ReadingWindows(t, p, resid)])
    assert len(s.terms_) == 1, s.terms_
    assert s.terms_[0].gain == pytest.approx(GAIN, rel=0.05)
    assert s.terms_[0].width_Pa == pytest.approx(WIDTH, rel=0.05)
    assert s.explained_fraction_ > 0.8
    relax = ReadingSearch().fit([ReadingWindows(t, p, resid)])
    assert relax.explained_fraction_ < s.explained_fraction_ - 0.1
    rng = np.random.default_rng(3)
    null = PlaySearch().fit([ReadingWindows(t, p, rng.normal(0.0, 400.0, resid.shape))])
    assert null.terms_ == [] and null.best_ is not None and null.best_.explained < 0.02
    with pytest.raises(ValueError, match="widths_Pa"):
        PlaySearch(widths_Pa=(100.0, 50.0, 1e3)).fit([ReadingWindows(t, p, resid)])
    with pytest.raises(ValueError, match="max_terms"):
        PlaySearch(max_terms=3).fit([ReadingWindows(t, p, resid)])


def test_the_play_stage_is_in_the_pipeline_and_its_terms_are_listed_apart():
    from types import SimpleNamespace

    from pneubayes.discovery.result import DiscoveryResult
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import ReadingPlayForm, default_stages

    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("ReadingPlayForm") == names.index("ReadingForm") + 1
    off = default_stages(DiscoverySettings(stages=StageSettings(
        reading_play_min_noise_ratio=0.0)))
    assert "ReadingPlayForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="reading_play_min_noise_ratio"):
        StageSettings(reading_play_min_noise_ratio=0.5)
    far = SimpleNamespace(heldout_rmse_Pa=2500.0, model=Model().with_effect(ReadingPlay()))
    from pneubayes.discovery.state import RoundState

    state = RoundState(number=1, current=far, search=None, supported=[], tentative=[],
                       started_far=True, gap_ratio=2.0, noise_Pa=500.0, search_step=0,
                       counts={}, passing=[])
    assert ReadingPlayForm()._applies(state, 500.0)[0] is False  # (it has one already)
    model = Model().with_effect(ReadingPlay())
    params = {**{k: 1.0 for k in Model().parameter_names}, "reading_play_gain_0": GAIN,
              "reading_play_width_0": WIDTH}
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=600.0)
    result = DiscoveryResult(settings=DiscoverySettings(), base=final, final=final,
                             accepted=(), ledger=(), maps=(), searches=(), params=params,
                             estimate="refined", noise_floor_Pa=500.0, range_Pa=4.5e5,
                             span_Pa=4e5)
    doc = result.to_dict()
    assert doc["effects"] == [] and doc["found_terms"] == []
    (term,) = doc["found_reading_terms"]
    assert term["term"] == "play 0" and term["formula"].startswith("r = p + h_0 (p - y_0)")
    assert term["parameters"]["reading_play_width_0"] == {"unit": "Pa", "estimate": WIDTH}


def test_found_plays_become_an_effect_plug_in_beside_a_relaxation(rig, hand):
    """The play's skeleton is Python that defines an effect of the user's name: a model
    with it simulates exactly as the model with the found reading play; beside a
    relaxation of the reading both act (the reference solver agrees); a model without a
    play is named."""
    from pneubayes.discovery.openform.skeleton import play_effect_skeleton
    from pneubayes.effects import ReadingClosure
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    inputs, base, params = _setup(rig, hand, n=601)
    model = Model().with_effect(ReadingPlay())
    text = play_effect_skeleton(model, params, "GaugePlay", "gauge_play")
    assert f"h_0 = {GAIN:g}, w_0 = {WIDTH:g} Pa" in text
    ns: dict = {}
    exec(compile(text, "found_reading_play.py", "exec"), ns)  # noqa: S102
    eff = ns["GaugePlay"]()
    assert eff.name == "gauge_play" and eff.relaxes_reading
    assert eff.bench_defaults() == {"play0_gain": GAIN, "play0_half_width_Pa": WIDTH}
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
    with pytest.raises(ValueError, match="no reading play"):
        play_effect_skeleton(Model(), {})


def test_a_controllers_prediction_starts_the_play_where_the_readings_left_it(rig, hand):
    """PressurePredictor with the readings before now predicts a recording read through
    a play from mid-recording as the recording's own simulation does; without them it
    starts the play at rest and misses by part of the width."""
    from pneubayes.inference.predictive import PressurePredictor
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, _, params = _setup(rig, hand)
    n, now, horizon = inputs.time_s.size, 600, 400
    u = inputs.command_V
    model = Model().with_effect(ReadingPlay())
    solver = SolverConfig.standard()
    whole = simulate_windows(model, params, inputs, rig, np.array([0]), n, 2e5, solver)[0, 0]
    predictor = PressurePredictor(model, model.vector(params)[None], rig, solver)
    args = (whole[now], u[now:now + horizon], 0.015, 1e-3)
    warm = predictor.predict_draws(*args, command_history_V=u[:now],
                                   reading_history_Pa=whole[:now])[0, 0]
    rest = predictor.predict_draws(*args, command_history_V=u[:now])[0, 0]
    truth = whole[now:now + horizon + 1]
    assert np.max(np.abs(warm - truth)) < 50.0 < 0.2 * np.max(np.abs(rest - truth))


@pytest.mark.slow
def test_discovery_finds_a_planted_play_of_the_reading(tmp_path):
    """The loop with the play stage alone, on four 8-s valve1 recordings read through a
    play: the play is found with its gain and half-width, verified on held-out windows,
    the held-out error falls to about the noise floor, and the report lists it with the
    reading's terms and writes its plug-in."""
    from conftest import BORE, P_ATM, P_SUP, STROKE, discovery_settings, random_steps

    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery
    from pneubayes.discovery.stages import ReadingPlayForm
    from pneubayes.io.recording import Recording, RecordingMetadata
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    truth_model = Model().with_effect(ReadingPlay())
    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
             "reading_play_gain_0": GAIN, "reading_play_width_0": WIDTH}
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
                              source=f"playing_{seed}.csv"))
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=None, stages=[ReadingPlayForm()]).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_reading_terms"]
    h = term["parameters"]["reading_play_gain_0"]["estimate"]
    w = term["parameters"]["reading_play_width_0"]["estimate"]
    assert h == pytest.approx(GAIN, rel=0.1) and w == pytest.approx(WIDTH, rel=0.1)
    assert doc["effects"] == [] and doc["found_terms"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    write_discovery(result, recs, tmp_path)
    assert "terms at the reading found" in (tmp_path / "report.md").read_text()
    assert (tmp_path / "found_reading_play.py").exists()
