"""The open form at the reading that breaks its slope: hinges read last (effect
``reading_hinge``), their map and its inverse, the simulator's windows, the reference
solver, and their search in the windows' residual."""

from __future__ import annotations

import numpy as np
import pytest

from pneubayes.effects import ReadingHinge
from pneubayes.model import Model
from pneubayes.simulation.reading_hinge import (
    hinged_reading,
    hinges_readable,
    unhinged_reading,
)

GAIN, KNEE = -0.7, 3.0e5


def _setup(rig, hand, n=1201):
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import Inputs

    t = np.arange(n) * 1e-3
    u = hand.random_steps(np.random.default_rng(5), n, 1e-3, hold_s=(0.05, 0.2))
    inputs = Inputs(t, u, np.full(n, 0.015), np.full(n, rig.supply_pressure_Pa))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    params = {**base, "reading_hinge_gain_0": GAIN, "reading_hinge_threshold_0": KNEE}
    return inputs, base, params


def test_the_map_its_slope_and_its_inverse_by_hand():
    """Two knees, written out piece by piece; the inverse is exact on every piece; a map
    that turns down somewhere is unreadable and inverts to NaN; the knees' order in the
    parameters does not matter."""
    g = np.array([[-0.5, 0.25], [0.25, -0.5], [-0.8, -0.3]])
    th = np.array([[2e5, 4e5], [4e5, 2e5], [2e5, 4e5]])
    z = np.array([1.5e5, 2e5, 3e5, 4e5, 5e5])[None].repeat(3, axis=0)
    r, s = hinged_reading(z, g, th)
    want = np.array([1.5e5, 2e5, 2e5 + 0.5e5, 2e5 + 1e5, 3e5 + 0.75e5])
    np.testing.assert_allclose(r[0], want, rtol=0, atol=1e-6)
    np.testing.assert_allclose(r[1], want, rtol=0, atol=1e-6)
    np.testing.assert_allclose(s[0], [1.0, 0.5, 0.5, 0.75, 0.75])
    assert hinges_readable(g, th).tolist() == [True, True, False]
    back = unhinged_reading(r, g, th)
    np.testing.assert_allclose(back[:2], z[:2], rtol=0, atol=1e-6)
    assert np.all(np.isnan(back[2]))
    dense = np.linspace(1e5, 6e5, 2001)[None].repeat(2, axis=0)
    np.testing.assert_allclose(unhinged_reading(hinged_reading(dense, g[:2], th[:2])[0],
                                                g[:2], th[:2]), dense, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match=r"must both be \(B, J\)"):
        hinges_readable(g, th[:, :1])


def test_knees_below_bend_the_reading_under_them_and_invert():
    """A knee below (its threshold negated in the map's arrays): ``min(0, z - theta)``,
    written out piece by piece beside a knee above; the inverse is exact on every piece;
    a floor steeper than flat is unreadable; the effect's option negates its
    thresholds."""
    g = np.array([[-0.6, 0.5], [-1.2, 0.0]])
    th = np.array([[-2e5, 4e5], [-2e5, 4e5]])
    z = np.array([1.0e5, 2e5, 3e5, 4e5, 5e5])[None].repeat(2, axis=0)
    r, s = hinged_reading(z, g, th)
    want = [1e5 - 0.6 * (1e5 - 2e5), 2e5, 3e5, 4e5, 5e5 + 0.5e5]
    np.testing.assert_allclose(r[0], want, rtol=0, atol=1e-6)
    np.testing.assert_allclose(s[0], [0.4, 1.0, 1.0, 1.5, 1.5])
    assert hinges_readable(g, th).tolist() == [True, False]
    dense = np.linspace(1.05e5, 6e5, 2001)[None]
    np.testing.assert_allclose(unhinged_reading(hinged_reading(dense, g[:1], th[:1])[0],
                                                g[:1], th[:1]), dense, rtol=0, atol=1e-6)
    assert np.all(np.isnan(unhinged_reading(r[1:], g[1:], th[1:])))
    floor = ReadingHinge(below=True)
    gains, knees = floor.reading_hinges({"reading_hinge_gain_0": np.array([-0.5]),
                                         "reading_hinge_threshold_0": np.array([2e5])})
    assert gains.tolist() == [[-0.5]] and knees.tolist() == [[-2e5]]
    assert floor.options() == {"terms": 1, "below": True}
    with pytest.raises(ValueError, match="'below' must be True or False"):
        ReadingHinge(below=1)


def test_the_simulator_reads_the_plain_pressure_through_the_knee(rig, hand):
    """A model with the component predicts H of the plain model's pressure started at
    H^-1 of the first reading, on windows that cross the knee; its start sensitivity is
    H'(p) dp/dp0 / H'(p0), the plain model's carried through the map; gain 0 is the
    plain model bit for bit."""
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.simulator import simulate_windows_sensitivity

    inputs, base, params = _setup(rig, hand)
    model = Model().with_effect(ReadingHinge())
    starts = np.array([0, 300, 700])
    solver = SolverConfig.standard()
    g, th = np.array([[GAIN]]), np.array([[KNEE]])
    r0 = np.array([2e5, 3.5e5, 4e5])
    z0 = unhinged_reading(r0[None], g, th)[0]
    assert z0[2] > r0[2] + 1e5  # (a start above the knee reads far below the chamber)
    read = simulate_windows(model, params, inputs, rig, starts, 500, r0, solver)[0]
    plain = simulate_windows(Model(), base, inputs, rig, starts, 500, z0, solver)[0]
    assert plain.min() < KNEE < plain.max()
    np.testing.assert_allclose(read, hinged_reading(plain[None], g, th)[0][0], rtol=0,
                               atol=1e-6)
    off = simulate_windows(model, {**params, "reading_hinge_gain_0": 0.0}, inputs, rig,
                           starts, 500, r0, solver)
    np.testing.assert_array_equal(off, simulate_windows(Model(), base, inputs, rig, starts,
                                                        500, r0, solver))
    _, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 500, r0,
                                           solver)
    _, plain_sens = simulate_windows_sensitivity(Model(), base, inputs, rig, starts, 500,
                                                 z0, solver)
    slope = hinged_reading(plain[None], g, th)[1][0]
    np.testing.assert_allclose(sens[0], slope * plain_sens[0] / slope[:, :1], rtol=1e-9,
                               atol=1e-12)
    assert np.ptp(slope) > 0.5  # (both pieces are read)


def test_a_hinged_reading_agrees_with_the_reference_solver(rig, hand):
    """One window from the recording's first sample, two knees: the compiled simulator
    against the reference solver (scipy at rtol 1e-8; the map applied to its samples),
    over 0.4 s and three steps that cross both knees."""
    from pneubayes.simulation import SolverConfig, simulate_windows
    from pneubayes.simulation.reference import reference_simulate

    inputs, _, params = _setup(rig, hand, n=401)
    model = Model().with_effect(ReadingHinge(terms=2))
    params = {**params, "reading_hinge_gain_1": 0.5, "reading_hinge_threshold_1": 2.0e5}
    ours = simulate_windows(model, params, inputs, rig, np.array([0]), 401, 2.5e5,
                            SolverConfig.standard())[0, 0]
    ref = reference_simulate(model, params, inputs, rig, 2.5e5, rtol=1e-8)
    assert np.max(np.abs(ours - ref)) < 1e-3 * np.ptp(ref)
    plain = reference_simulate(Model(), {k: v for k, v in params.items()
                                         if not k.startswith("reading_hinge")},
                               inputs, rig, 2.5e5, rtol=1e-8)
    assert np.max(np.abs(ref - plain)) > 5000.0


def test_an_unreadable_map_fails_as_a_set(rig, hand):
    """Two knees whose gains sum below -1: the set is named on raise and NaN on 'nan',
    its neighbour in the batch unaffected."""
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, _, params = _setup(rig, hand, n=401)
    model = Model().with_effect(ReadingHinge(terms=2))
    good = {**params, "reading_hinge_gain_1": -0.2, "reading_hinge_threshold_1": 3.5e5}
    bad = {**good, "reading_hinge_gain_1": -0.5}
    theta = np.stack([model.vector(good), model.vector(bad)])
    with pytest.raises(ValueError, match="parameter set 1's map is not increasing"):
        simulate_windows(model, theta, inputs, rig, np.array([0]), 400, 2e5,
                         SolverConfig.standard())
    out = simulate_windows(model, theta, inputs, rig, np.array([0]), 400, 2e5,
                           SolverConfig.standard(), on_failure="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1]))


def test_the_components_options_and_parameters_are_checked():
    with pytest.raises(ValueError, match="'terms' must be an integer in 1..2"):
        ReadingHinge(terms=3)
    names = Model().with_effect(ReadingHinge(terms=2)).parameter_names
    assert {"reading_hinge_gain_1", "reading_hinge_threshold_1"} <= set(names)
    assert ReadingHinge().relaxes_reading and not ReadingHinge().library_searched
    defaults = ReadingHinge(terms=2).bench_defaults()
    assert hinges_readable(np.array([[defaults["reading_hinge_gain_0"],
                                      defaults["reading_hinge_gain_1"]]]),
                           np.array([[defaults["reading_hinge_threshold_0"],
                                      defaults["reading_hinge_threshold_1"]]]))[0]


def _windows(gain, knee, seed, noise_Pa=300.0, w=30, length=1500):
    """Windows of pressures that rise and fall through ``knee``, their residual the
    knee's first-order effect (its start moved along a decaying sensitivity) plus
    noise: one block."""
    from pneubayes.discovery.openform.reading import ReadingWindows

    rng = np.random.default_rng(seed)
    n = w * length
    t = np.arange(n) * 1e-3
    p = 1.2e5 + 3e5 * np.abs(np.sin(t / 0.7 + rng.uniform(0, 0.2)))
    starts = np.arange(w) * length
    idx = starts[:, None] + np.arange(length)
    sens = np.exp(-(t[idx] - t[idx][:, :1]) / 0.05)
    hinge = np.maximum(p[idx] - knee, 0.0)
    resid = gain * (hinge - sens * hinge[:, :1]) + rng.normal(0.0, noise_Pa, idx.shape)
    return [ReadingWindows(t[idx], p[idx], resid[:, 1:], sens)]


def test_the_search_recovers_a_planted_knee_and_finds_none_in_noise():
    """A knee planted in windows' residual: the search recovers its gain and threshold
    on the grid it spreads over the predicted pressures; two knees are told apart; in
    noise alone it keeps nothing; bad settings are named."""
    from pneubayes.discovery.openform.reading import ReadingWindows
    from pneubayes.discovery.openform.reading_hinge import HingeSearch

    blocks = _windows(-0.3, 3.2e5, 0)
    s = HingeSearch().fit(blocks)
    assert s.terms_ and s.terms_[0].gain == pytest.approx(-0.3, rel=0.05)
    assert s.terms_[0].threshold_Pa == pytest.approx(3.2e5, rel=0.01)
    assert s.explained_fraction_ > 0.9
    assert s.thresholds_searched_[0] > 1.2e5 and s.thresholds_searched_[-1] < 4.2e5
    b = blocks[0]
    two = _windows(-0.8, 3.4e5, 1)[0]  # (a rail above a stiffening: opposite bends)
    second = 0.4 * (np.maximum(two.predicted_Pa - 2.0e5, 0.0)
                    - two.sensitivity * np.maximum(two.predicted_Pa[:, :1] - 2.0e5, 0.0))
    s2 = HingeSearch().fit([ReadingWindows(two.time_s, two.predicted_Pa,
                                           two.residual_Pa + second[:, 1:], two.sensitivity)])
    knees = sorted((t.threshold_Pa, t.gain) for t in s2.terms_)
    assert len(knees) == 2
    assert knees[0][0] == pytest.approx(2.0e5, rel=0.02) and knees[0][1] == pytest.approx(
        0.4, rel=0.1)
    assert knees[1][0] == pytest.approx(3.4e5, rel=0.02) and knees[1][1] == pytest.approx(
        -0.8, rel=0.1)
    rng = np.random.default_rng(3)
    null = HingeSearch().fit([ReadingWindows(b.time_s, b.predicted_Pa,
                                             rng.normal(0.0, 300.0, b.residual_Pa.shape),
                                             b.sensitivity)])
    assert null.terms_ == [] and null.best_ is not None and null.best_.explained < 0.02
    flat = HingeSearch().fit([ReadingWindows(b.time_s, np.full_like(b.predicted_Pa, 2e5),
                                             b.residual_Pa, b.sensitivity)])
    assert flat.terms_ == [] and flat.thresholds_searched_.size == 0
    with pytest.raises(ValueError, match="thresholds_Pa"):
        HingeSearch(thresholds_Pa=(3e5, 2e5, 4e5)).fit(blocks)
    with pytest.raises(ValueError, match="n_thresholds"):
        HingeSearch(n_thresholds=2).fit(blocks)
    with pytest.raises(ValueError, match="list of ReadingWindows"):
        HingeSearch().fit([object()])


def test_the_search_tells_a_floor_from_a_knee_above():
    """A floor planted in the windows' residual (a knee below: ``min(0, p - theta)``) is
    found as a knee below with its gain and threshold; searching knees above only, the
    search explains less of it."""
    from pneubayes.discovery.openform.reading import ReadingWindows
    from pneubayes.discovery.openform.reading_hinge import HingeSearch

    (b,) = _windows(0.0, 3.2e5, 4)
    floor = np.minimum(b.predicted_Pa - 2.2e5, 0.0) \
        - b.sensitivity * np.minimum(b.predicted_Pa[:, :1] - 2.2e5, 0.0)
    blocks = [ReadingWindows(b.time_s, b.predicted_Pa, b.residual_Pa - 0.6 * floor[:, 1:],
                             b.sensitivity)]
    s = HingeSearch(max_terms=1).fit(blocks)
    (term,) = s.terms_
    assert term.below and "min(0" in str(term)
    assert term.gain == pytest.approx(-0.6, rel=0.05)
    assert term.threshold_Pa == pytest.approx(2.2e5, rel=0.01)
    above = HingeSearch(max_terms=1, sides=("above",)).fit(blocks)
    assert above.explained_fraction_ < s.explained_fraction_ - 0.05
    with pytest.raises(ValueError, match="sides"):
        HingeSearch(sides=("left",)).fit(blocks)


def test_the_hinge_stage_competes_with_the_catalogues_curvature():
    """A curvature of the reading that closes most of the gap does not keep the stage
    from running (its rival: the knees replace it only by beating it); another effect
    that closes as much does."""
    from types import SimpleNamespace

    from pneubayes.discovery.stages import ReadingHingeForm
    from pneubayes.discovery.state import RoundState

    def state(passing):
        far = SimpleNamespace(heldout_rmse_Pa=2500.0, model=Model())
        return RoundState(number=1, current=far, search=None, supported=[], tentative=[],
                          started_far=True, gap_ratio=5.0, noise_Pa=500.0, search_step=0,
                          counts={}, passing=list(passing))
    stage = ReadingHingeForm()
    curved = (800.0, "sensor_nonlinearity", None, 1.0, 0.001)
    assert stage._applies(state([curved]), 500.0) == (True, curved)
    leak = (800.0, "cylinder_leak", None, 1.0, 0.001)
    assert stage._applies(state([leak]), 500.0)[0] is False
    assert stage._applies(state([]), 500.0) == (True, None)


def test_the_hinge_stage_is_in_the_pipeline_and_its_knees_are_listed_apart():
    from types import SimpleNamespace

    from pneubayes.discovery.result import DiscoveryResult
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import default_stages

    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("ReadingHingeForm") == names.index("ReadingForm") - 1
    off = default_stages(DiscoverySettings(stages=StageSettings(
        reading_hinge_min_noise_ratio=0.0)))
    assert "ReadingHingeForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="reading_hinge_min_noise_ratio"):
        StageSettings(reading_hinge_min_noise_ratio=0.5)
    model = Model().with_effect(ReadingHinge())
    params = {**{k: 1.0 for k in Model().parameter_names}, "reading_hinge_gain_0": GAIN,
              "reading_hinge_threshold_0": KNEE}
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=600.0)
    result = DiscoveryResult(settings=DiscoverySettings(), base=final, final=final,
                             accepted=(), ledger=(), maps=(), searches=(), params=params,
                             estimate="refined", noise_floor_Pa=500.0, range_Pa=4.5e5,
                             span_Pa=4e5)
    doc = result.to_dict()
    assert doc["effects"] == [] and doc["found_terms"] == []
    (term,) = doc["found_reading_terms"]
    assert term["term"] == "knee 0" and term["formula"].startswith("r = z + c_0 max(0,")
    assert term["parameters"]["reading_hinge_threshold_0"] == {"unit": "Pa",
                                                                "estimate": KNEE}


def test_found_knees_become_an_effect_plug_in(rig, hand):
    """The knees' skeleton is Python that defines an effect of the user's name: a model
    with it simulates exactly as the model with the found component; a model without
    one is named."""
    from pneubayes.discovery.openform.skeleton import hinge_effect_skeleton
    from pneubayes.simulation import SolverConfig, simulate_windows

    inputs, base, params = _setup(rig, hand, n=601)
    model = Model().with_effect(ReadingHinge())
    text = hinge_effect_skeleton(model, params, "TransducerRail", "transducer_rail")
    assert f"c_0 = {GAIN:g}, theta_0 = {KNEE:g} Pa" in text
    ns: dict = {}
    exec(compile(text, "found_reading_hinge.py", "exec"), ns)  # noqa: S102
    eff = ns["TransducerRail"]()
    assert eff.name == "transducer_rail" and eff.relaxes_reading
    assert eff.bench_defaults() == {"knee0_gain": GAIN, "knee0_threshold_Pa": KNEE}
    mine = Model([eff])
    starts, solver = np.array([0, 300]), SolverConfig.standard()
    theirs = simulate_windows(model, params, inputs, rig, starts, 300, 3.5e5, solver)
    ours = simulate_windows(mine, {**base, **eff.bench_defaults()}, inputs, rig, starts,
                            300, 3.5e5, solver)
    np.testing.assert_array_equal(ours, theirs)
    with pytest.raises(ValueError, match="no reading hinge"):
        hinge_effect_skeleton(Model(), {})
    floor = Model().with_effect(ReadingHinge(below=True))  # a floor's plug-in reads below
    text = hinge_effect_skeleton(floor, params, "Floor", "floor")
    assert "min(0, z - theta_0)" in text
    ns = {}
    exec(compile(text, "floor.py", "exec"), ns)  # noqa: S102
    eff = ns["Floor"]()
    np.testing.assert_array_equal(
        simulate_windows(Model([eff]), {**base, **eff.bench_defaults()}, inputs, rig, starts,
                         300, 3.5e5, solver),
        simulate_windows(floor, params, inputs, rig, starts, 300, 3.5e5, solver))


def _valve1_runs(model, params, name, read=None):
    """Four 8-s valve1 recordings (fixed piston, random command steps) of ``model`` at
    ``params`` from the atmosphere, each reading passed through ``read`` (None: as it
    is) with 200 Pa of noise; and the loop's settings for them (two held out, no
    posterior, at most two additions)."""
    from conftest import discovery_settings, valve1_recordings

    recs = valve1_recordings(model, params, name, 10, 4, 8001, read)
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    return recs, settings


@pytest.mark.slow
def test_discovery_finds_a_planted_rail_in_the_reading(tmp_path):
    """The loop with the hinge stage alone, on four 8-s valve1 recordings read through a
    transducer that bends to a fifth of its slope above 3 bar: the knee is found with
    its gain and threshold, verified on held-out windows, the held-out error falls to
    about the noise floor, and the report lists it, draws it and writes its plug-in."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery
    from pneubayes.discovery.stages import ReadingHingeForm
    from pneubayes.physics.valve import valve_preset

    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
             "reading_hinge_gain_0": -0.8, "reading_hinge_threshold_0": 3.0e5}
    recs, settings = _valve1_runs(Model().with_effect(ReadingHinge()), truth, "railed")
    result = Discovery(settings, None, log=None,
                       stages=[ReadingHingeForm()]).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_reading_terms"]
    c = term["parameters"]["reading_hinge_gain_0"]["estimate"]
    theta = term["parameters"]["reading_hinge_threshold_0"]["estimate"]
    assert c == pytest.approx(-0.8, abs=0.05) and theta == pytest.approx(3.0e5, rel=0.02)
    assert doc["effects"] == [] and doc["found_terms"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    write_discovery(result, recs, tmp_path)
    assert "terms at the reading found" in (tmp_path / "report.md").read_text()
    assert (tmp_path / "found_reading_hinge.py").exists()
    assert (tmp_path / "figures" / "found_reading_terms.png").exists()


@pytest.mark.slow
def test_discovery_finds_a_planted_floor_in_the_reading():
    """The loop with the hinge stage alone, on four valve1 recordings read through a
    transducer that reads half its slope below 2 bar (a floor): the knee is found below,
    with its gain and threshold, and the held-out error falls to about the noise
    floor."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.stages import ReadingHingeForm
    from pneubayes.physics.valve import valve_preset

    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    recs, settings = _valve1_runs(  # (the chamber from the atmosphere, read through it)
        Model(), truth, "floored",
        read=lambda p: hinged_reading(p[None], [[-0.5]], [[-2.0e5]])[0][0])
    result = Discovery(settings, None, log=None,
                       stages=[ReadingHingeForm()]).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_reading_terms"]
    assert "min(0, z - theta_0)" in term["formula"]
    c = term["parameters"]["reading_hinge_gain_0"]["estimate"]
    theta = term["parameters"]["reading_hinge_threshold_0"]["estimate"]
    assert c == pytest.approx(-0.5, abs=0.03) and theta == pytest.approx(2.0e5, rel=0.02)
    assert doc["effects"] == [] and doc["found_terms"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]


@pytest.mark.slow
def test_a_true_curvature_is_kept_against_its_rival_knees():
    """The rival rule's other side: four valve1 recordings read through the catalogue's
    curvature (-8 kPa at 1 bar gauge). The curvature passes; the knee stage runs beside
    it (its rival), loses to it on the held-out windows, and the curvature is named."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.effects import make_effect
    from pneubayes.physics.valve import valve_preset

    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
             "reading_curvature_Pa": -8000.0}
    recs, settings = _valve1_runs(Model([make_effect("sensor_nonlinearity")]), truth,
                                  "curved")
    result = Discovery(settings, None, log=None).fit(recs).result_
    doc = result.to_dict()
    assert [e["name"] for e in doc["effects"]] == ["sensor_nonlinearity"]
    assert doc["found_reading_terms"] == []
    rejected = [e for e in doc["ledger"] if e["action"] == "reading hinge form reject"]
    assert rejected  # (it ran beside the curvature and lost)
    assert doc["rmse_final_Pa"] < 1.2 * doc["noise_floor_Pa"]


def test_a_knee_flat_as_a_rail_is_a_limit_not_a_stand_in():
    """The knee's gain at its lower bound (a rail) is the physics' limit: a fit there is
    not counted at a bound, while its threshold at a bound still is; a bad limit is
    named."""
    from types import SimpleNamespace

    from pneubayes.discovery.openform.closure_model import newly_at_bounds
    from pneubayes.effects.base import Parameter
    from pneubayes.effects.reading_hinge import HINGE_GAIN_BOUNDS, HINGE_THRESHOLD_BOUNDS_PA

    model = Model().with_effect(ReadingHinge())
    base = {n: 1.0 for n in Model().parameter_names}
    current = SimpleNamespace(params=base)
    rail = SimpleNamespace(model=model, params={**base, "reading_hinge_gain_0":
                                                HINGE_GAIN_BOUNDS[0],
                                                "reading_hinge_threshold_0": 3e5})
    assert newly_at_bounds(rail, current) == []
    edge = SimpleNamespace(model=model, params={**rail.params, "reading_hinge_threshold_0":
                                                HINGE_THRESHOLD_BOUNDS_PA[1]})
    assert newly_at_bounds(edge, current) == ["reading_hinge_threshold_0"]
    steep = SimpleNamespace(model=model, params={**rail.params, "reading_hinge_gain_0":
                                                 HINGE_GAIN_BOUNDS[1]})
    assert newly_at_bounds(steep, current) == ["reading_hinge_gain_0"]
    with pytest.raises(ValueError, match="limit must be"):
        Parameter("x", "-", 0.0, 1.0, "uniform", "x", limit="both")


@pytest.mark.slow
def test_discovery_names_a_hard_clip_as_a_knee_at_its_limit():
    """Four valve1 recordings whose reading is clipped flat at 3 bar (an ADC's full
    scale; no map of the library is exactly flat): the knee is named at its gain's limit
    (a rail), not rejected as a stand-in, near 3 bar; the held-out error falls from
    ~140 kPa to within 2.5 x the noise floor (a window that starts on the rail cannot
    tell its chamber's pressure)."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.stages import ReadingHingeForm
    from pneubayes.effects.reading_hinge import HINGE_GAIN_BOUNDS
    from pneubayes.physics.valve import valve_preset

    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    recs, settings = _valve1_runs(Model(), truth, "clipped",
                                  read=lambda p: np.minimum(p, 3.0e5))
    doc = Discovery(settings, None, log=None,
                    stages=[ReadingHingeForm()]).fit(recs).result_.to_dict()
    (term,) = doc["found_reading_terms"]
    c = term["parameters"]["reading_hinge_gain_0"]["estimate"]
    theta = term["parameters"]["reading_hinge_threshold_0"]["estimate"]
    assert c == pytest.approx(HINGE_GAIN_BOUNDS[0], abs=1e-3)
    assert theta == pytest.approx(3.0e5, rel=0.02)
    assert doc["rmse_final_Pa"] < 2.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"] / 100
