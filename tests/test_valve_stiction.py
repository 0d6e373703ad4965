"""Valve stiction (effect ``valve_stiction``): the transform's closed forms, the bench's
independent SpoolStiction, the simulator against the same model fed the transformed
command and against the reference solver, mixed batches, the open-form signals, the
bench's plant and a planted band recovered through the simulator."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fluctuating_supply, moving_position, valve1_params

from pneubayes.bench.forms import SpoolStiction
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.effects import make_effect
from pneubayes.effects.discovery import CandidateContext
from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.io import Recording, RecordingMetadata
from pneubayes.model import Model
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    fresh_carry,
    simulate,
    simulate_carried,
    simulate_windows,
)
from pneubayes.simulation.reference import reference_simulate
from pneubayes.simulation.spool_path import spool_at
from pneubayes.simulation.stiction import stuck_command, valve_commands

P_ATM, P_SUP = 101325.0, 551325.0
RANGE = P_SUP - P_ATM
PLAY = make_effect("valve_stiction")
SLIP = make_effect("valve_stiction", form="stick_slip")


def wandering_command(seed: int, n: int, dt: float) -> np.ndarray:
    """A command that wanders in steps of 0.01-0.6 V held 5-30 ms (small steps a
    sticking valve ignores, large ones it follows), within +-3 V."""
    rng = np.random.default_rng(seed)
    u, i, level = np.empty(n), 0, 0.0
    while i < n:
        hold = max(1, int(round(rng.uniform(0.005, 0.03) / dt)))
        level = float(np.clip(level + rng.choice([-1, 1]) * rng.uniform(0.01, 0.6), -3, 3))
        u[i:i + hold] = level
        i += hold
    return u


def wandering_inputs(seed: int, n: int, dt: float) -> Inputs:
    t = np.arange(n) * dt
    return Inputs(t, wandering_command(seed, n, dt), moving_position(t, freq=3.0),
                  fluctuating_supply(t))


# ---------------------------------------------------------------- the transform
def test_play_trails_a_ramp_by_its_band_and_ignores_small_reversals():
    up = np.linspace(0.0, 1.0, 101)
    out = stuck_command(up, 0.0, 0.2, 0.0)
    assert np.all(out[:20] == 0.0)  # within the band from where it rests
    np.testing.assert_allclose(out[20:], up[20:] - 0.2, atol=1e-12)
    back = np.concatenate([up, 1.0 - np.linspace(0.0, 0.15, 16)])  # reverse by < band
    out = stuck_command(back, 0.0, 0.2, 0.0)
    assert np.all(out[101:] == pytest.approx(0.8))


def test_stick_slip_jumps_onto_the_command_and_a_zero_band_is_the_command():
    u = np.array([0.0, 0.05, 0.1, 0.3, 0.32, 0.1, 0.05])
    assert stuck_command(u, 0.0, 0.25, 1.0).tolist() == [0.0, 0.0, 0.0, 0.3, 0.3, 0.3, 0.05]
    assert stuck_command(u, 0.0, 0.25, 0.6).tolist() == pytest.approx(
        [0.0, 0.0, 0.0, 0.2, 0.2, 0.2, 0.2])
    assert np.array_equal(stuck_command(u, 0.0, 0.0, 0.5), u)


@pytest.mark.parametrize("breakaway,stop", [(0.1, 0.0), (0.3, 0.1), (0.2, 0.2)])
def test_the_transform_is_the_benchs_independent_sticking_spool(breakaway, stop):
    u = wandering_command(3, 3000, 1e-3)
    bench = np.array(SpoolStiction(breakaway_V=breakaway, stop_V=stop).targets(u))
    got = stuck_command(u, u[0], breakaway, 1.0 - stop / breakaway)
    np.testing.assert_allclose(got, bench, atol=1e-12)
    assert np.max(np.abs(got - u)) > 0.5 * breakaway  # it did stick


def test_parameter_sets_group_by_the_command_their_valve_sees():
    model = Model([SLIP])
    theta = np.array([model.vector(valve1_params(stiction_band_V=b, stiction_slip_fraction=f))
                      for b, f in ((0.0, 0.3), (0.2, 0.5), (0.0, 0.9), (0.2, 0.5),
                                   (0.1, 0.5))])
    u = wandering_command(1, 500, 1e-3)
    groups = valve_commands(model.lower(theta, None), u, u[0])
    rows = sorted(tuple(r.tolist()) for r, _ in groups)
    assert rows == [(0, 2), (1, 3), (4,)]  # a free valve whatever its slip
    for r, uu in groups:
        if 0 in r:
            assert uu is u


# ---------------------------------------------------------------- the simulator
def test_a_sticking_valve_simulates_as_the_free_one_fed_its_commands(rig):
    """Bit for bit: the model with stiction is the model without it on the command the
    valve sees, in a mixed batch too (sets without stiction in the same call)."""
    inputs = wandering_inputs(2, 801, 1e-3)
    model = Model(["spool_lag", SLIP])
    sets = [valve1_params(spool_time_constant_s=2e-3, stiction_band_V=b,
                          stiction_slip_fraction=f)
            for b, f in ((0.25, 0.4), (0.0, 0.0), (0.1, 1.0))]
    got = simulate(model, np.array([model.vector(s) for s in sets]), inputs, rig, 2e5,
                   SolverConfig.standard()).pressure_Pa
    free = Model(["spool_lag"])
    for row, s in zip(got, sets):
        uu = stuck_command(inputs.command_V, inputs.command_V[0], s["stiction_band_V"],
                           s["stiction_slip_fraction"])
        want = simulate(free, valve1_params(spool_time_constant_s=2e-3),
                        inputs.with_command(uu), rig, 2e5,
                        SolverConfig.standard()).pressure_Pa[0]
        assert np.array_equal(row, want)
    assert np.max(np.abs(got[0] - got[1])) > 0.02 * RANGE  # and stiction matters here


def test_windows_and_carried_chunks_see_the_whole_history(rig):
    """A window that starts late sees where the valve stuck long before it; the carried
    chunks of a mixed batch agree with whole-record windows."""
    inputs = wandering_inputs(4, 1201, 1e-3)
    model = Model([PLAY])
    sets = np.array([model.vector(valve1_params(stiction_band_V=b)) for b in (0.3, 0.0, 0.15)])
    whole = simulate(model, sets, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa
    starts = np.array([400, 800])
    # each window restarts from the set's own pressure (one p0 per window): set by set
    for b in range(3):
        one = simulate_windows(model, sets[b:b + 1], inputs, rig, starts, 201,
                               whole[b, starts], SolverConfig.standard())[0]
        for w, s in enumerate(starts):
            np.testing.assert_allclose(one[w], whole[b, s:s + 201], atol=2e-4 * RANGE)
    carry = fresh_carry(3, rig)
    out, _ = simulate_carried(model, sets, inputs, rig, np.array([0, 400, 800, 1200]), 2e5,
                              carry, whole[0], 0.0, SolverConfig.standard())
    np.testing.assert_allclose(out, whole, atol=2e-4 * RANGE)


def test_against_the_reference_solver(rig):
    inputs = wandering_inputs(5, 301, 1e-3)
    model = Model(["tube_delay", "spool_lag", SLIP])
    params = valve1_params(2e-5, tube_delay_s=0.0013, spool_time_constant_s=2e-3,
                           stiction_band_V=0.2, stiction_slip_fraction=0.7)
    ref = reference_simulate(model, params, inputs, rig, 2e5, rtol=1e-8)
    got = simulate(model, params, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - ref)) <= 1e-3 * RANGE
    free = simulate(Model(["tube_delay", "spool_lag"]), valve1_params(
        2e-5, tube_delay_s=0.0013, spool_time_constant_s=2e-3), inputs, rig, 2e5,
        SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(free - ref)) > 10 * np.max(np.abs(got - ref))


def test_the_open_form_signals_see_the_stuck_spool(rig):
    inputs = wandering_inputs(6, 400, 1e-3)
    model = Model(["tube_delay", PLAY])
    row = model.lower(model.as_matrix(valve1_params(tube_delay_s=0.002,
                                                    stiction_band_V=0.2)), rig)[0]
    times = np.linspace(0.01, 0.39, 77)
    uu = stuck_command(inputs.command_V, inputs.command_V[0], 0.2, 0.0)
    free = row.copy()
    free[S["stiction_band_V"]] = 0.0
    np.testing.assert_array_equal(spool_at(times, inputs, row),
                                  spool_at(times, inputs.with_command(uu), free))


def test_lowering_forms_and_one_sticking_valve_in_the_plant(rig):
    assert PLAY.parameter_names() == ("stiction_band_V",)
    assert SLIP.parameter_names() == ("stiction_band_V", "stiction_slip_fraction")
    off = Model([SLIP]).lower(Model([SLIP]).as_matrix(valve1_params(
        stiction_band_V=0.0, stiction_slip_fraction=0.0)), None)
    assert np.array_equal(off, Model().lower(Model().as_matrix(valve1_params()), None))
    with pytest.raises(ValueError, match="form must be one of"):
        make_effect("valve_stiction", form="sticky").parameters()
    ctx = CandidateContext(model=Model(), params=valve1_params(), rig=rig,
                           term_start={"stiction_band_V": 0.3}, second_state_free=True,
                           line_segments=0, line_cutoff_Hz=0.0, dead_volume_m3=2.4e-6)
    forms = PLAY.candidate_forms(ctx)
    assert [(e.form, s) for e, s in forms] == [
        ("play", {"stiction_band_V": 0.3}),
        ("stick_slip", {"stiction_band_V": 0.3, "stiction_slip_fraction": 0.5})]
    inputs = wandering_inputs(7, 50, 1e-3)
    with pytest.raises(ValueError, match="plant one of them"):
        simulate_plant(valve1_params(stiction_band_V=0.1), [SpoolStiction(0.1, 0.05)],
                       inputs, rig, 2e5, PlantConfig.reference(), effects=[PLAY])


def test_the_bench_plants_the_catalogue_effect_with_its_own_form(rig):
    """The bench steps the catalogue's sticking valve with its own SpoolStiction (an
    independent implementation): its plant agrees with the simulator's model, and a
    free valve differs far more."""
    inputs = wandering_inputs(8, 601, 1e-3)
    params = valve1_params(2e-5, stiction_band_V=0.2, stiction_slip_fraction=0.7)
    plant = simulate_plant(params, [], inputs, rig, 2e5, PlantConfig.reference(),
                           effects=[SLIP]).pressure_Pa
    got = simulate(Model([SLIP]), params, inputs, rig, 2e5,
                   SolverConfig.standard()).pressure_Pa[0]
    free = simulate(Model(), valve1_params(2e-5), inputs, rig, 2e5,
                    SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - plant)) <= 2e-3 * RANGE
    assert np.max(np.abs(free - plant)) > 10 * np.max(np.abs(got - plant))


def _sticking_records(rig, model, truth, seed0):
    """Four noisy 1-s records (300 Pa) of ``model`` at ``truth`` on wandering commands."""
    rng = np.random.default_rng(seed0)
    recs = []
    for seed in range(4):
        inputs = wandering_inputs(seed0 + seed, 1001, 1e-3)
        p = simulate(model, truth, inputs, rig, 2e5, SolverConfig.standard()).pressure_Pa[0]
        md = RecordingMetadata("AIR37", "valve1", rig.bore_m, rig.stroke_m, P_ATM, P_SUP,
                               rig.gas.temperature_K)
        recs.append(Recording(md, inputs.time_s, inputs.command_V,
                              p + rng.normal(0, 300, p.size), inputs.supply_pressure_Pa,
                              inputs.position_m))
    return WindowSet(recs, 0.1, 0.1)


def test_a_planted_play_is_recovered_through_the_simulator(rig):
    """Play is continuous in its band (the valve moves by |u - s| - B past the band), so
    the trajectory refiner's finite differences see it: from the library's fallback
    start (0.1 V) it finds a planted 0.25 V within 0.01 V."""
    model = Model([PLAY])
    ws = _sticking_records(rig, model, valve1_params(stiction_band_V=0.25), 20)
    fit = TrajectoryRefiner(model, SolverConfig.standard(), horizon_s=0.1, max_nfev=60,
                            free=["stiction_band_V"]).fit(
        ws, {**valve1_params(), "stiction_band_V": 0.1})
    assert fit.params_["stiction_band_V"] == pytest.approx(0.25, abs=0.01)
    assert fit.rmse_Pa_ < 330.0  # the noise (300 Pa), no misfit left


def test_a_planted_stick_slip_is_the_best_on_a_grid(rig):
    """Stick-slip jumps, so its error is a staircase in the band; on a grid of bands
    (the true slip 0.6) the smallest error is at the planted 0.25 V."""
    model = Model([SLIP])
    ws = _sticking_records(rig, model, valve1_params(stiction_band_V=0.25,
                                                     stiction_slip_fraction=0.6), 40)
    bands = np.arange(0.05, 0.51, 0.05)
    theta = np.array([model.vector(valve1_params(stiction_band_V=b,
                                                 stiction_slip_fraction=0.6))
                      for b in bands])
    rmse = np.sqrt(np.mean(ws.residuals(model, theta, SolverConfig.standard()) ** 2,
                           axis=(1, 2)))
    assert bands[np.argmin(rmse)] == pytest.approx(0.25)
    assert rmse.min() < 330.0 and np.sort(rmse)[1] > 1.2 * rmse.min()
