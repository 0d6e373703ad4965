"""The open form on the chamber's volume with inertia: a wall that carries a load (effect
``loaded_wall``), its simulation, its search in the prediction windows' residual and the
stage that adds it (issue 69: a volume that lags its pressure and rings)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import P_ATM, P_SUP, discovery_settings, random_steps, valve1_recordings
from scipy.linalg import expm

from pneubayes.discovery.openform.loaded_wall import LoadedWallProblem, LoadedWallSearch
from pneubayes.effects.loaded_wall import LoadedWall
from pneubayes.effects.volume_closure import VolumeClosure
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, SolverConfig, simulate, simulate_windows
from pneubayes.simulation.loaded_wall import wall_advance

RANGE = P_SUP - P_ATM
BASE = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
C_TRUE, F_TRUE, Z_TRUE = 2e-12, 12.0, 0.3  # 0.2 cm^3 per bar, ringing at 12 Hz
WALL = {"loaded_wall_compliance": C_TRUE, "loaded_wall_frequency": F_TRUE,
        "loaded_wall_damping": Z_TRUE}


def _inputs(seed, n, hold_s=(0.1, 0.6)):
    t = np.arange(n) * 1e-3
    u = random_steps(np.random.default_rng(seed), n, 1e-3, hold_s=hold_s)
    return Inputs(t, u, np.full(n, 0.015), np.full(n, P_SUP))


def _rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.mark.parametrize("zeta", [0.05, 0.7, 1.0, 1.0 + 1e-9, 4.0])
def test_the_wall_s_step_is_exact_under_a_linear_pressure(zeta):
    """Against the matrix exponential of the forced oscillator, the pressure ramp as a
    third state: under-, critically and overdamped, and at the series' seam."""
    w, h, x0, v0, y0, y1 = 2 * np.pi * 9.0, 0.013, 1.3e5, -2e6, 2.0e5, 2.6e5
    s = (y1 - y0) / h
    a = np.array([[0.0, 1.0, 0.0, 0.0], [-w * w, -2 * zeta * w, w * w, 0.0],
                  [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0]])
    want = expm(a * h) @ np.array([x0, v0, y0, s])
    got = wall_advance(x0, v0, y0, y1, h, w, zeta)
    assert got[0] == pytest.approx(want[0], rel=1e-10, abs=1e-6)
    assert got[1] == pytest.approx(want[1], rel=1e-9, abs=1e-4)
    assert wall_advance(x0, v0, y0, y1, 0.0, w, zeta) == (x0, v0)


def test_the_wall_agrees_with_the_plant_s_loaded_wall(rig):
    """Against the bench plant's own loaded wall (LSODA, written apart): within 0.01 % of
    the range for a ringing, a fast lightly damped and an overdamped wall, where the
    rigid chamber misses by over 10 %; the standard solver within 0.01 % of a 100 x
    tighter one."""
    from pneubayes.bench.forms.chamber import LoadedWall as PlantWall
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    inputs = _inputs(3, 2501)
    model, solver = Model([LoadedWall()]), SolverConfig.standard()
    rigid = simulate(Model(), BASE, inputs, rig, P_ATM, solver).pressure_Pa[0]
    for c, f, z in ((1e-11, 12.0, 0.3), (5e-12, 40.0, 0.1), (2e-11, 5.0, 3.0)):
        ref = simulate_plant(BASE, (PlantWall(c, f, z),), inputs, rig, P_ATM,
                             PlantConfig.reference()).pressure_Pa
        params = {**BASE, "loaded_wall_compliance": c, "loaded_wall_frequency": f,
                  "loaded_wall_damping": z}
        got = simulate(model, params, inputs, rig, P_ATM, solver).pressure_Pa[0]
        assert _rms(got, ref) < 1e-4 * RANGE
        assert _rms(rigid, ref) > 0.1 * RANGE
        tight = simulate(model, params, inputs, rig, P_ATM,
                         solver.tightened(100.0)).pressure_Pa[0]
        assert np.max(np.abs(got - tight)) < 1e-4 * RANGE


def test_the_wall_beside_a_moving_piston_agrees_with_the_plant(rig):
    """The wall's volume rate beside the piston's (3 Hz, 10 mm): within 0.01 % of the
    range of the plant, where the rigid chamber misses by over 10 %."""
    from pneubayes.bench.forms.chamber import LoadedWall as PlantWall
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    fixed = _inputs(3, 2501)
    t = fixed.time_s
    inputs = Inputs(t, fixed.command_V, 0.015 + 0.01 * np.sin(2 * np.pi * 3.0 * t),
                    fixed.supply_pressure_Pa)
    ref = simulate_plant(BASE, (PlantWall(1e-11, 12.0, 0.3),), inputs, rig, P_ATM,
                         PlantConfig.reference()).pressure_Pa
    params = {**BASE, "loaded_wall_compliance": 1e-11, "loaded_wall_frequency": 12.0,
              "loaded_wall_damping": 0.3}
    got = simulate(Model([LoadedWall()]), params, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    rigid = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert _rms(got, ref) < 1e-4 * RANGE
    assert _rms(rigid, ref) > 0.1 * RANGE


def test_the_wall_beside_heat_transfer_agrees_with_the_plant(rig):
    """With the chamber's temperature as a second state (convective heat transfer,
    30 W/m^2/K): within 0.01 % of the range of the plant's wall and heat, where the heat
    alone misses by over 10 %."""
    from pneubayes.bench.forms.catalogue import WallHeatTransfer
    from pneubayes.bench.forms.chamber import LoadedWall as PlantWall
    from pneubayes.bench.plant import PlantConfig, simulate_plant
    from pneubayes.effects import make_effect

    inputs = _inputs(3, 2501)
    ref = simulate_plant(BASE, (PlantWall(1e-11, 12.0, 0.3), WallHeatTransfer(30.0)), inputs,
                         rig, P_ATM, PlantConfig.reference()).pressure_Pa
    heat = Model([make_effect("heat_transfer", form="convective")])
    hot = {**BASE, "heat_transfer_coefficient_W_per_m2_K": 30.0, "heat_transfer_coupling": 1.0}
    got = simulate(heat.with_effect(LoadedWall()),
                   {**hot, "loaded_wall_compliance": 1e-11, "loaded_wall_frequency": 12.0,
                    "loaded_wall_damping": 0.3}, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    alone = simulate(heat, hot, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert _rms(got, ref) < 1e-4 * RANGE
    assert _rms(alone, ref) > 0.1 * RANGE


def test_a_wall_without_give_is_the_rigid_chamber(rig):
    inputs = _inputs(5, 1501)
    solver = SolverConfig.standard()
    rigid = simulate(Model(), BASE, inputs, rig, P_ATM, solver).pressure_Pa[0]
    none = simulate(Model([LoadedWall()]), {**BASE, **WALL, "loaded_wall_compliance": 0.0},
                    inputs, rig, P_ATM, solver).pressure_Pa[0]
    np.testing.assert_array_equal(none, rigid)


@pytest.mark.parametrize("ring", [{}, {"loaded_wall_frequency": 2.0,
                                        "loaded_wall_damping": 0.1}])
def test_windows_start_the_wall_where_the_recorded_reading_left_it(rig, ring):
    """Windows started from the recorded pressure, with the wall stepped over the
    reading's history, continue the one-window simulation; started at rest they do
    not. A slow ring (2 Hz, z 0.1: seconds of history) is read through a strided history
    as well."""
    inputs = _inputs(7, 4001)
    model, params = Model([LoadedWall()]), {**BASE, **WALL, **ring}
    whole = simulate(model, params, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    starts, length = np.arange(500, 3501, 500), 401
    idx = starts[:, None] + np.arange(length)
    rec = Inputs(inputs.time_s, inputs.command_V, inputs.position_m,
                 inputs.supply_pressure_Pa, reading_Pa=whole)
    got = simulate_windows(model, params, rec, rig, starts, length, whole[starts],
                           SolverConfig.standard())[0]
    assert np.max(np.abs(got - whole[idx])) < 2e-3 * RANGE
    fresh = simulate_windows(model, params, inputs, rig, starts, length, whole[starts],
                             SolverConfig.standard())[0]
    assert np.max(np.abs(fresh - whole[idx])) > 5.0 * np.max(np.abs(got - whole[idx]))


def test_a_wall_is_refused_beside_a_table_and_its_options_are_checked(rig):
    from pneubayes.simulation.reference import reference_simulate

    inputs = _inputs(1, 201)
    model = Model([LoadedWall(), VolumeClosure()])
    params = {**BASE, **WALL, **VolumeClosure().bench_defaults()}
    with pytest.raises(ValueError, match="loaded wall .* volume closure"):
        simulate(model, params, inputs, rig, 2e5, SolverConfig.standard())
    with pytest.raises(ValueError, match="loaded wall"):
        reference_simulate(Model([LoadedWall()]), {**BASE, **WALL}, inputs, rig, 2e5)
    for bad in (0, 2, True, 1.0):
        with pytest.raises(ValueError, match="terms"):
            LoadedWall(terms=bad)


def test_a_wall_behind_the_wave_tube_agrees_with_the_plant(rig):
    """A loaded wall behind a 1-m tube (the plant: 48-cell tube and its loaded wall,
    LSODA): the wave tube beside the wall within what the wave tube reaches into a rigid
    chamber, where the rigid chamber behind it misses by over ten times that."""
    from pneubayes.bench.forms import AcousticTube
    from pneubayes.bench.forms.chamber import LoadedWall as PlantWall
    from pneubayes.bench.plant import PlantConfig, simulate_plant
    from pneubayes.effects import make_effect

    dt = 1e-4
    t = np.arange(6001) * dt
    rng = np.random.default_rng(1)
    u, i = np.empty(t.size), 0
    while i < t.size:
        hold = int(rng.integers(300, 1501))
        u[i:i + hold] = rng.uniform(-5.0, 5.0)
        i += hold
    inputs = Inputs(t, u, np.full(t.size, 0.015), np.full(t.size, P_SUP))
    dead, c, f, z = 1.5e-7, 1e-12, 30.0, 0.2
    tube = AcousticTube(1.0, 0.002)
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": dead}
    ref = simulate_plant(base, (AcousticTube(1.0, 0.002, segments=48), PlantWall(c, f, z)),
                         inputs, rig, P_ATM, PlantConfig.reference()).pressure_Pa
    params = {**base, "dead_volume_m3": dead + tube.volume_m3,
              "tube_delay_s": tube.transit_time_s(rig.gas), "tube_diameter_m": 0.002}
    wave = Model([make_effect("tube_delay", form="wave", segments=8)])
    got = simulate(wave.with_effect(LoadedWall()),
                   {**params, "loaded_wall_compliance": c, "loaded_wall_frequency": f,
                    "loaded_wall_damping": z},
                   inputs, rig, P_ATM, SolverConfig.reference()).pressure_Pa[0]
    rigid = simulate(wave, params, inputs, rig, P_ATM, SolverConfig.reference()).pressure_Pa[0]
    rms = _rms(got, ref)
    assert rms < 400.0, f"wave + wall vs plant: {rms:.0f} Pa RMS"
    assert _rms(rigid, ref) > 10.0 * rms


@pytest.fixture(scope="module")
def wall_recordings():
    """Four 8-s valve1 recordings (1 kHz, 200 Pa noise) of a 2.4-cm^3 chamber with a
    loaded wall (1 cm^3 per bar at 12 Hz, damping ratio 0.3), and two of a rigid one."""
    return (valve1_recordings(Model([LoadedWall()]), {**BASE, **WALL}, "loaded", 80, 4, 8001),
            valve1_recordings(Model(), BASE, "loaded", 80, 2))


def test_the_search_finds_a_planted_wall_and_none_in_a_rigid_chamber():
    """The search on the fixture's first recordings, simulated alone (one 8-s of the
    wall, one 6-s of a rigid chamber)."""
    walls = valve1_recordings(Model([LoadedWall()]), {**BASE, **WALL}, "loaded", 80, 1, 8001)
    rigid = valve1_recordings(Model(), BASE, "loaded", 80, 1)
    solver = SolverConfig.standard()
    ws = WindowSet(walls[:1], 2.0, 2.0)
    found = LoadedWallSearch().fit(LoadedWallProblem(ws, Model(), BASE, solver))
    (term,) = found.terms_
    assert term.frequency_Hz == pytest.approx(F_TRUE, rel=0.15)
    assert 0.5 * C_TRUE <= term.compliance_m3_per_Pa <= 2.0 * C_TRUE
    assert 0.5 * Z_TRUE <= term.damping_ratio <= 2.0 * Z_TRUE
    assert found.explained_fraction_ > 0.9 and "Hz" in str(term)
    none = LoadedWallSearch().fit(LoadedWallProblem(WindowSet(rigid[:1], 2.0, 2.0),
                                                    Model(), BASE, solver))
    assert none.terms_ == [] and none.best_.explained < 0.02
    with pytest.raises(ValueError, match="already has a loaded wall"):
        LoadedWallSearch().fit(LoadedWallProblem(ws, Model([LoadedWall()]),
                                                 {**BASE, **WALL}, solver))
    with pytest.raises(ValueError, match="frequencies_Hz"):
        LoadedWallSearch(frequencies_Hz=(0.01,)).fit(LoadedWallProblem(ws, Model(), BASE,
                                                                       solver))
    with pytest.raises(ValueError, match="LoadedWallProblem"):
        LoadedWallSearch().fit(object())


def test_a_residual_that_asks_for_less_volume_proposes_no_wall():
    """Where every pair's wall would have to take volume away (the least squares give it
    a negative compliance), the screen keeps none and the search ends without a term."""

    class Shrinking(LoadedWallProblem):
        def check(self):
            pass

        def volume_scale_m3_per_Pa(self):
            return 1e-11

        @property
        def scales_dead_volume(self):
            return False

        def window_residuals(self, hinges, scales=None):
            base = np.linspace(1.0, 2.0, 40).reshape(4, 10)
            return np.stack([base if not h else 1.1 * base for h in hinges])

    probe = Shrinking(None, Model(), BASE, SolverConfig.standard())
    found = LoadedWallSearch(frequencies_Hz=(5.0, 10.0), damping_ratios=(0.3,)).fit(probe)
    assert found.terms_ == [] and found.best_ is None and found.explained_fraction_ == 0.0


def test_the_stage_s_knobs_and_its_switch():
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import LoadedWallForm, default_stages

    assert LoadedWallForm().compete_below_gap_closed == 0.9
    with pytest.raises(ValueError, match="min_noise_ratio"):
        LoadedWallForm(min_noise_ratio=0.5)
    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("VolumePlayForm") < names.index("LoadedWallForm") \
        < names.index("OpenForm")
    off = default_stages(DiscoverySettings(stages=StageSettings(loaded_wall_min_noise_ratio=0)))
    assert "LoadedWallForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="loaded_wall_min_noise_ratio"):
        StageSettings(loaded_wall_min_noise_ratio=0.5)


def test_a_found_wall_becomes_an_effect_plug_in_a_user_can_name(rig):
    from pneubayes.discovery.openform.skeleton import volume_effect_skeleton

    text = volume_effect_skeleton(Model([LoadedWall()]), {**BASE, **WALL}, "Payload",
                                  "payload")
    namespace: dict = {}
    exec(compile(text, "payload.py", "exec"), namespace)
    effect = namespace["Payload"]()
    assert effect.name == "payload" and "wall_frequency_Hz" in effect.parameter_names()
    inputs = _inputs(2, 801)
    mine = simulate(Model([effect]), {**BASE, **effect.bench_defaults()}, inputs, rig,
                    P_ATM, SolverConfig.standard()).pressure_Pa[0]
    theirs = simulate(Model([LoadedWall()]), {**BASE, **WALL}, inputs, rig, P_ATM,
                      SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_discovery_finds_a_planted_wall_where_relaxations_only_average_it(wall_recordings,
                                                                          tmp_path):
    """The loop with the volume's stages and the closure: the wall is found with its
    frequency, verified on the held-out recordings, and the held-out error falls to
    about the noise floor; the report lists it as a term on the chamber's volume."""
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.report import write_discovery
    from pneubayes.discovery.stages import LoadedWallForm, VolumeForm, VolumePlayForm

    recs, _ = wall_recordings
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 2})
    result = Discovery(settings, None, log=print,
                       stages=[VolumeForm(), VolumePlayForm(), LoadedWallForm()]
                       ).fit(recs).result_
    doc = result.to_dict()
    (term,) = doc["found_volume_terms"]
    assert term["term"] == "loaded wall 0"
    f = term["parameters"]["loaded_wall_frequency"]["estimate"]
    assert f == pytest.approx(F_TRUE, rel=0.05)
    assert doc["effects"] == [] and doc["found_terms"] == [] and doc["stand_ins"] == []
    assert doc["rmse_final_Pa"] < 1.5 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
    write_discovery(result, recs, tmp_path, figures=True)
    report = (tmp_path / "report.md").read_text()
    assert "figures/found_volume_terms.png" in report
    assert "LoadedWall()" in (tmp_path / "found_volume.py").read_text()
