"""The transmission-line tube (``tube_delay`` form ``"wave"``, pneubayes.simulation.wave).

Against an independent reference (the plant's finely lumped acoustic tube, LSODA), the
lossless front's arrival time, the limits (full inlet, full exhaust), conservation with
the valve shut, step halving, the carried state of contiguous windows, the start
sensitivity and the errors for what it cannot be combined with.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pneubayes.bench.forms import AcousticTube
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.effects import make_effect
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import (
    Inputs,
    SolverConfig,
    simulate,
    simulate_windows,
    simulate_windows_sensitivity,
)

P_ATM, P_SUP = 101_325.0, 551_325.0


def _wave(segments=8, **kw):
    return Model([make_effect("tube_delay", form="wave", segments=segments, **kw)])


def _params(rig, length_m, dia_m, dead_m3=1.5e-7, valve=None):
    """Valve 1 (or ``valve``) and a tube of ``length_m`` x ``dia_m``; the dead volume
    includes the tube's, as the recording format defines it."""
    tube = AcousticTube(length_m=length_m, diameter_m=dia_m)
    params = dict(valve or valve_preset("valve1").parameters(),
                  tube_delay_s=tube.transit_time_s(rig.gas), tube_diameter_m=dia_m)
    params["dead_volume_m3"] = dead_m3 + tube.volume_m3
    return params, tube


def _steps(seed, n, dt):
    rng = np.random.default_rng(seed)
    u, i = np.empty(n), 0
    while i < n:
        hold = int(round(rng.integers(30, 151) * 1e-3 / dt))
        u[i:i + hold] = rng.uniform(-5.0, 5.0)
        i += hold
    return u


@pytest.mark.parametrize("length_m, dia_m, most_Pa", [(1.0, 0.002, 250.0),
                                                      (2.9, 0.00183, 400.0)])
def test_the_wave_tube_agrees_with_the_plants_finely_lumped_tube(rig, length_m, dia_m,
                                                                 most_Pa):
    """The plant's acoustic tube in 48 cells (LSODA, written apart) approaches the
    continuous line; the wave form's 8 elements carry its waves exactly and lump its
    friction at their junctions. A 1-m and a 2.9-m tube under random 5-V steps agree to
    a few hundred Pa RMS, against 3-12 kPa without the tube (with its volume)."""
    dt = 1e-4
    t = np.arange(6001) * dt
    x = 0.01875 + 0.01 * np.sin(2 * np.pi * 3.0 * t)
    inputs = Inputs(t, _steps(1, t.size, dt), x, np.full(t.size, P_SUP))
    base = dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)
    params, _ = _params(rig, length_m, dia_m)
    ref = simulate_plant(base, (AcousticTube(length_m, dia_m, segments=48),), inputs, rig,
                         P_ATM, PlantConfig.reference()).pressure_Pa
    wave = simulate(_wave(), params, inputs, rig, P_ATM,
                    SolverConfig.reference()).pressure_Pa[0]
    bare = simulate(Model(), dict(base, dead_volume_m3=params["dead_volume_m3"]), inputs,
                    rig, P_ATM, SolverConfig.reference()).pressure_Pa[0]
    rms = float(np.sqrt(np.mean((wave - ref) ** 2)))
    rms_bare = float(np.sqrt(np.mean((bare - ref) ** 2)))
    assert rms < most_Pa, f"wave vs plant: {rms:.0f} Pa RMS"
    assert rms_bare > 10.0 * rms, (rms_bare, rms)
    # one element lumps the friction at the two ends only: worse
    one = simulate(_wave(1), params, inputs, rig, P_ATM, SolverConfig.reference()).pressure_Pa[0]
    assert float(np.sqrt(np.mean((one - ref) ** 2))) > 2.0 * rms


@pytest.fixture(scope="module")
def shut_fill(rig):
    """An on/off fill of a 1.88-m x 4-mm line into 4.2e-5 m^3 from 6.5 bar, shut at 60
    ms so the line rings: the inputs, the model's parameters and the plant's 48-cell
    tube with and without Zielke's unsteady shear (Schohl's five exponentials)."""
    from test_plant import CLOSABLE

    p_sup = P_ATM + 80 * 6895.0
    frig = Rig(rig.bore_m, P_ATM, p_sup)
    t = np.arange(1501) * 1e-4
    base = dict(CLOSABLE, inlet_a_m2=3e-6, dead_volume_m3=4.24e-5)
    inputs = Inputs(t, np.where(t < 0.06, 5.0, 0.0), np.full(t.size, 0.01),
                    np.full(t.size, p_sup))
    ref = {w: simulate_plant(base, (AcousticTube(1.88, 0.004, segments=48,
                                                 unsteady_friction=w),), inputs, frig,
                             P_ATM + 2e4, PlantConfig.reference()).pressure_Pa
           for w in (0.0, 1.0)}
    tube = AcousticTube(1.88, 0.004)
    params = dict(base, tube_delay_s=tube.transit_time_s(frig.gas), tube_diameter_m=0.004,
                  dead_volume_m3=base["dead_volume_m3"] + tube.volume_m3)
    return frig, inputs, params, ref


def _unsteady_run(shut_fill, weight):
    frig, inputs, params, _ = shut_fill
    return simulate(_wave(unsteady_friction=True), dict(params, tube_unsteady_friction=weight),
                    inputs, frig, P_ATM + 2e4, SolverConfig.reference()).pressure_Pa[0]


def test_the_wave_tubes_unsteady_shear_agrees_with_the_plants(shut_fill):
    """The wave tube's unsteady shear (Trikha's three exponentials at its junctions) and
    the plant's (Schohl's five in each of 48 cells), written apart: with it the two agree
    as closely as the quasi-steady pair do, and several times closer than the
    quasi-steady wave tube does to the unsteady line (the ring after the shut damps
    faster)."""
    ref = shut_fill[3]
    rms = {w: {v: float(np.sqrt(np.mean((_unsteady_run(shut_fill, w) - ref[v]) ** 2)))
               for v in ref} for w in (0.0, 1.0)}
    assert np.sqrt(np.mean((ref[1.0] - ref[0.0]) ** 2)) > 1000.0  # the shear matters here
    assert rms[0.0][0.0] < 500.0 and rms[1.0][1.0] < 500.0, rms
    assert rms[1.0][1.0] < 0.3 * rms[0.0][1.0], rms


def test_the_unsteady_shears_weight_is_recovered_from_the_plants_line(shut_fill):
    """Fitted alone on the plant's pressure, the weight comes out near 1 on the unsteady
    line and near 0 on the quasi-steady one."""
    from scipy.optimize import minimize_scalar

    ref = shut_fill[3]
    for truth in (0.0, 1.0):
        fit = minimize_scalar(lambda w, tr=truth: float(np.mean(
            (_unsteady_run(shut_fill, w) - ref[tr]) ** 2)), bounds=(0.0, 3.0),
            method="bounded", options={"xatol": 1e-3})
        assert abs(fit.x - truth) < 0.25, (truth, fit.x)


@pytest.mark.parametrize("grid_s", [1e-3, 5e-4])
def test_a_switch_is_not_late_by_the_grid(rig, make_inputs, grid_s):
    """A valve switched 5 ms into a window (exhaust to inlet, a 1-m tube into
    1.5e-5 m^3, one element): on a coarse grid the response matches a 1/16-ms grid's
    without a lag, the best-fitting time shift under 5 % of the grid step (a ramp that
    began at the switch lagged it by 0.27 ms on the 1-ms grid), and the step-halving
    error falls with the grid."""
    params, _ = _params(rig, 1.0, 0.002, dead_m3=1.5e-5)
    dt = 1e-3
    t = np.arange(81) * dt
    inputs = make_inputs(t, np.where(t >= 0.005, 4.5, -5.0))

    def run(g):
        return simulate(_wave(1, grid_s=g), params, inputs, rig, P_ATM,
                        SolverConfig.reference()).pressure_Pa[0]

    fine = run(6.25e-5)
    rate = np.gradient(fine, dt)
    err = run(grid_s) - fine
    lag = -float(np.sum(err * rate) / np.sum(rate ** 2))  # err ~ -lag * dp/dt
    assert abs(lag) < 0.05 * grid_s, lag
    finer = run(grid_s / 2) - fine
    assert np.sqrt(np.mean(finer ** 2)) < 0.7 * np.sqrt(np.mean(err ** 2))


def test_a_valve_step_reaches_the_chamber_after_the_transit_time(rig, make_inputs,
                                                                 closable_params):
    """The shut valve opened at 10 ms on a 2-m tube (5.8 ms): the chamber does not move
    before 10 + 5.8 ms less 0.4 ms (the valve's switch ramps over a grid step, 0.1 ms,
    either side of it, and the reads between grid points spread a front by about another),
    half its rise is reached within 0.25 ms after the transit time (a 48-cell lumped tube:
    0.18 ms after; this form: 0.11 ms), and it rises right after."""
    params, tube = _params(rig, 2.0, 0.002, valve=closable_params)
    dt = 1e-5
    t = np.arange(3001) * dt
    u = np.where(t >= 0.01, 5.0, 0.0)
    p = simulate(_wave(), params, make_inputs(t, u), rig, 3e5,
                 SolverConfig.reference()).pressure_Pa[0]
    arrive = 0.01 + tube.transit_time_s(rig.gas)
    assert np.max(np.abs(p[t < arrive - 4e-4] - 3e5)) < 1.0
    rise = p[np.searchsorted(t, arrive + 1e-3)] - 3e5
    half = t[np.argmax(p - 3e5 > 0.5 * rise)]
    assert arrive - 1e-4 <= half <= arrive + 2.5e-4, (half - arrive) * 1e3
    assert p[np.searchsorted(t, arrive + 3e-4)] - 3e5 > 1e3


def test_a_valve_switch_between_grid_points_moves_the_front_by_as_much(
        rig, make_inputs, closable_params):
    """A switch 33 us after a grid point (an irregular time base) reaches the valve end
    as a ramp from its own time: the front's half-rise comes 33 us later, not at the
    next grid point (100 us later) as a switch read only on the grid would."""
    params, tube = _params(rig, 2.0, 0.002, valve=closable_params)
    t = np.arange(3001) * 1e-5

    def half_rise(t_switch):
        tt = np.unique(np.append(t, t_switch))
        u = np.where(tt >= t_switch, 5.0, 0.0)
        p = simulate(_wave(), params, make_inputs(tt, u), rig, 3e5,
                     SolverConfig.reference()).pressure_Pa[0] - 3e5
        level = 0.5 * p[np.searchsorted(tt, t_switch + tube.transit_time_s(rig.gas) + 1e-3)]
        i = int(np.argmax(p > level))
        return tt[i - 1] + (level - p[i - 1]) / (p[i] - p[i - 1]) * (tt[i] - tt[i - 1])

    shift = half_rise(0.010033) - half_rise(0.01)
    assert shift == pytest.approx(33e-6, abs=8e-6), shift * 1e6


@pytest.mark.parametrize("command, p0, supply_side", [(5.0, P_ATM, True),
                                                      (-5.0, P_SUP, False)])
def test_through_the_wave_tube_the_chamber_settles_at_the_bare_chambers_balance(
        rig, make_inputs, hand, command, p0, supply_side):
    """Held full inlet or full exhaust for 3 s: without a leak the settled tube passes
    no flow and drops no pressure, so the chamber ends at the bare chamber's flow
    balance (eqs. 4/9; the valve's offsets leak from inlet to exhaust)."""
    params, _ = _params(rig, 2.0, 0.002)
    bare = {k: v for k, v in params.items() if not k.startswith("tube_")}
    t = np.arange(3001) * 1e-3
    p = simulate(_wave(), params, make_inputs(t, np.full(t.size, command)), rig, p0,
                 SolverConfig.standard()).pressure_Pa[0]
    assert p[-1] == pytest.approx(hand.equilibrium(bare, u=command), abs=5.0)
    assert (p[-1] > 0.95 * P_SUP) if supply_side else (p[-1] < 1.05 * P_ATM)


@pytest.mark.parametrize("unsteady", [False, True])
def test_a_shut_valve_and_no_leak_keep_the_pressure(rig, make_inputs, closable_params,
                                                    unsteady):
    """Both ports shut (command 0 on the closable valve), no leak, tube at rest: nothing
    moves, to rounding (with the unsteady shear too)."""
    params, _ = _params(rig, 1.0, 0.002, valve=closable_params)
    model = _wave(unsteady_friction=True) if unsteady else _wave()
    if unsteady:
        params["tube_unsteady_friction"] = 1.0
    t = np.arange(2001) * 1e-3
    p = simulate(model, params, make_inputs(t, np.zeros(t.size)), rig, 3.3e5,
                 SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(p - 3.3e5)) < 1e-6


def test_the_wave_tube_converges_under_step_halving(rig, make_inputs):
    """The standard preset is within 0.1 % of the range of a far tighter tolerance. (The
    waves move on a fixed grid, and between grid points the chamber's forcing is linear,
    which the exponential step integrates exactly: the tolerance has little left to
    control.)"""
    params, _ = _params(rig, 1.5, 0.002)
    dt = 1e-3
    t = np.arange(1501) * dt
    inputs = make_inputs(t, _steps(3, t.size, dt), position=0.015)

    def run(rtol):
        cfg = SolverConfig(rtol=rtol, atol_Pa=rtol * 3e5, atol_K=0.01, max_step_s=0.02,
                           min_step_s=1e-12, max_steps_per_s=1e7)
        return simulate(_wave(), params, inputs, rig, P_ATM, cfg).pressure_Pa[0]

    tight = run(1e-9)
    errs = [float(np.max(np.abs(run(r) - tight))) for r in (3e-5, 1e-7)]
    assert errs[0] < 1e-3 * (P_SUP - P_ATM), errs
    assert errs[1] <= errs[0] + 1e-6, errs
    assert np.ptp(tight) > 0.5 * (P_SUP - P_ATM)  # the range is exercised


@pytest.mark.parametrize("grid", [{}, {"grid_s": 1.5e-4}], ids=["0.1 ms", "0.15 ms"])
def test_the_output_moves_smoothly_with_the_transit_time(rig, make_inputs, grid):
    """A fit moves the transit time T in small steps: the output must follow it
    continuously. On a 1-kHz recording of a 0.61-m tube, T x (1, 1.001, ..., 1.008)
    changes the output by nearly the same RMS each step, and by no more than three times
    what it changes the 3-cell lumped line's (a grid that divided an element's transit
    time into a whole number of steps moved the wave tube in jumps of 96-216 Pa per step,
    the line 8 Pa), on the default grid and a coarser one."""
    tube = AcousticTube(length_m=0.61, diameter_m=0.00195)
    dt = 1e-3
    t = np.arange(1201) * dt
    inputs = make_inputs(t, _steps(3, t.size, dt), position=0.01875)
    params = dict(valve_preset("valve1").parameters(), tube_diameter_m=0.00195,
                  dead_volume_m3=1.5e-7 + tube.volume_m3)
    t0 = tube.transit_time_s(rig.gas)

    def moves(model):
        outs = [simulate(model, dict(params, tube_delay_s=t0 * f), inputs, rig, P_ATM,
                         SolverConfig.standard()).pressure_Pa[0]
                for f in 1.0 + 1e-3 * np.arange(9)]
        return np.sqrt(np.mean(np.diff(outs, axis=0) ** 2, axis=1))

    wave = moves(_wave(**grid))
    line = moves(Model([make_effect("tube_delay", form="line", segments=3)]))
    assert np.all(wave > 0.5), wave
    assert wave.max() < 1.5 * np.median(wave), wave
    assert wave.max() < 3.0 * np.median(line), (wave, line)


@pytest.mark.parametrize("unsteady", [False, True])
def test_contiguous_windows_carry_the_waves(rig, make_inputs, unsteady):
    """The tube's waves are a state no recording measures: contiguous windows restarted
    from the full run's own pressures reproduce it (to the carried state's resampling)
    only because each starts from the waves the previous one left (and the unsteady
    shear's memories); apart, each starts with the tube at rest and misses by kPa."""
    params, _ = _params(rig, 2.0, 0.002)
    model = _wave(unsteady_friction=True) if unsteady else _wave()
    if unsteady:
        params["tube_unsteady_friction"] = 1.0
    n = 1201
    t = np.arange(n) * 1e-3
    inputs = make_inputs(t, _steps(5, n, 1e-3), position=0.015)
    cfg = SolverConfig.reference()
    full = simulate(model, params, inputs, rig, 2e5, cfg).pressure_Pa[0]
    length = 301
    starts = np.arange(0, n - length + 1, length - 1)
    win = simulate_windows(model, params, inputs, rig, starts, length, full[starts], cfg)[0]
    apart = np.array([simulate_windows(model, params, inputs, rig, starts[w:w + 1], length,
                                       full[starts[w:w + 1]], cfg)[0, 0]
                      for w in range(starts.size)])
    err = max(float(np.max(np.abs(win[w] - full[s:s + length])))
              for w, s in enumerate(starts))
    err_apart = max(float(np.max(np.abs(apart[w] - full[s:s + length])))
                    for w, s in enumerate(starts) if w > 0)
    assert err < 300.0, err
    assert err_apart > 5.0 * err, (err, err_apart)


@pytest.mark.parametrize("unsteady", [False, True])
def test_start_sensitivity_through_the_wave_tube_matches_finite_differences(rig, hand,
                                                                            unsteady):
    params, _ = _params(rig, 1.0, 0.002, dead_m3=5e-7)
    model = _wave(unsteady_friction=True) if unsteady else _wave()
    if unsteady:
        params["tube_unsteady_friction"] = 1.0
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(4), n, 1e-3,
                                         levels=(-1.0, 1.0)),
                    np.full(n, 0.01), np.full(n, 6.0e5))
    starts = np.array([0, 400])
    p0 = np.array([2.0e5, 4.0e5])
    cfg = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=0.01, max_step_s=0.02,
                       min_step_s=1e-12, max_steps_per_s=1e7)
    out, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 400, p0,
                                             cfg)
    d = 20.0
    up = simulate_windows(model, params, inputs, rig, starts, 400, p0 + d, cfg)
    dn = simulate_windows(model, params, inputs, rig, starts, 400, p0 - d, cfg)
    fd = (up - dn) / (2 * d)
    assert np.all(sens[..., 0] == 1.0)
    # (the unsteady shear's memories carry no derivative in p0: about 0.026 with them
    # here, 0.007 without)
    assert np.max(np.abs(sens - fd)) < 0.03
    assert np.max(np.abs(fd)) > 0.5  # the start matters over the window's first part


def test_what_the_wave_tube_cannot_be_combined_with_is_an_error(rig, make_inputs):
    params, _ = _params(rig, 1.0, 0.002)
    model = _wave().with_effect(make_effect("heat_transfer"))
    params["heat_transfer_rate_per_s"] = 20.0
    params["heat_transfer_coupling"] = 1.0
    t = np.arange(11) * 1e-3
    with pytest.raises(ValueError, match="tube_delay form 'wave'.*heat_transfer"):
        simulate(model, params, make_inputs(t, np.zeros(t.size)), rig, P_ATM,
                 SolverConfig.standard())
    with pytest.raises(ValueError, match="segments must be an integer in 1..16"):
        make_effect("tube_delay", form="wave", segments=17).parameters()


def test_a_lagged_reading_behind_the_tube_warms_up_5_settling_times_not_the_pretrigger(
        rig):
    """A triggered recording's pre-trigger command is held from 10 s before its first
    sample; a lagged reading's warm-up reached back to it, and the tube's 0.1-ms grid
    stepped through all 10 s (the loop's sensor-lag trials beside a wave tube failed on
    real fills at the step budget). The warm-up starts 5 settling times before the
    window: the result is the same as with the pre-trigger command held from only
    50 ms before, and it stays within the standard step budget."""
    params, _ = _params(rig, 1.5, 0.003, dead_m3=2e-5)
    params["sensor_time_constant_s"] = 5e-4
    model = _wave().with_effect(make_effect("sensor_lag"))
    n = 60
    t = 0.002 * np.arange(n)
    u = np.where(t < 0.06, 5.0, -5.0)
    x, sup = np.full(n, 0.01), np.full(n, P_SUP)
    triggered = Inputs(t, u, x, sup, command_before_start=-5.0)
    # the same drive with the pre-trigger sample 50 ms before the first (no declared
    # pre-trigger command: the first sample's, -5 V, is held before it)
    t2 = np.concatenate(([t[0] - 0.05], t))
    near = Inputs(t2, np.concatenate(([-5.0], u)), np.concatenate(([0.01], x)),
                  np.concatenate(([P_SUP], sup)))
    cfg = SolverConfig.standard()
    a = simulate_windows(model, params, triggered, rig, np.array([0]), n, np.array([1.2e5]),
                         cfg)[0, 0]
    b = simulate_windows(model, params, near, rig, np.array([1]), n, np.array([1.2e5]),
                         cfg)[0, 0]
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6 * P_SUP)
    assert a.max() > 2e5  # it ran the fill


GTD = Path(__file__).resolve().parents[1] / "data" / "real" / "gtdynamics"


@pytest.mark.skipif(not GTD.is_dir(), reason="shipped GTDynamics data absent")
def test_friction_at_the_step_keeps_a_valve_wider_than_the_tube_from_ringing():
    """GTDynamics' muscles at the loop's fitted point: an on/off valve of 95 mm^2 in front
    of a 3.3-mm tube (8.5 mm^2) with an 18.4-ms transit. Where friction dominates the
    tube's impedance, a junction resistance taken from the last step's flow rang: a
    transit 10 us longer took the worst 44-ms fill window from 16.5 to 299 kPa RMS (the
    chamber at 1.2 MPa on a 0.56-MPa supply). With the friction solved at the step, the
    worst window moves by under 1 kPa over 0-50 us and the output by under 1 kPa RMS."""
    import json

    from pneubayes.inference.windows import WindowSet
    from pneubayes.io import read_recording

    recs = []
    for path in sorted(GTD.glob("*/*.csv")):
        rec = read_recording(path)
        close = float(rec.metadata.extra["import"]["valve_close_s"])
        recs.append(rec.slice(0, int(np.searchsorted(rec.time_s, close + 0.03, "right"))))
    ws = WindowSet(recs, 0.044, 0.044)
    card = {"format": "pneubayes-model/1", "effects": ["tube_delay"],
            "effect_options": {"tube_delay": {"tube_diameter_m": 0.0040005,
                                              "air_viscosity_Pa_s": 1.81e-05,
                                              "form": "wave", "segments": 8}},
            "parameters": {"valve_open_area_m2": 9.4904e-05, "dead_volume_m3": 1.2375e-04,
                           "tube_delay_s": 0.0183997, "tube_diameter_m": 0.0032914},
            "rig": json.loads((GTD / "gtdynamics-muscle.rig.json").read_text())}
    model, params = Model.from_card(card)
    j = list(model.parameter_names).index("tube_delay_s")
    theta = np.tile(model.vector(params), (5, 1))
    theta[:, j] += np.array([0.0, 1e-6, 1e-5, 2e-5, 5e-5])
    sim = ws.simulate(model, theta, SolverConfig.standard())
    worst = np.sqrt(np.mean((sim - ws.measured) ** 2, axis=-1)).max(axis=1)
    assert np.ptp(worst) < 1e3, worst
    assert np.all(np.sqrt(np.mean((sim - sim[0]) ** 2, axis=(1, 2))) < 1e3)
    assert np.all(sim < 1.1 * recs[0].supply_pressure_Pa.max())


def test_a_closure_beside_the_wave_tube_adds_its_mass_flow(rig, make_inputs, closable_params):
    """A closure that reads no port of the valve sits beside the wave tube: a constant
    inflow c into the shut chamber raises the pressure at n Rs T c / V once the tube's
    waves have settled (the tube's gas, compressed adiabatically as the waves carry it,
    adds its volume to the chamber's); one that reads a port is refused, naming it."""
    params, _ = _params(rig, 1.0, 0.002, valve=closable_params)
    c = 3e-6  # kg/s
    model = Model([make_effect("tube_delay", form="wave", segments=8),
                   make_effect("closure", terms="one")])
    t = np.arange(1001) * 1e-3
    p = simulate(model, dict(params, closure_coefficient_0=c), make_inputs(t, np.zeros(t.size)),
                 rig, 3.3e5, SolverConfig.reference()).pressure_Pa[0]
    g = rig.gas
    rate = (g.heat_capacity_ratio * g.specific_gas_constant_J_per_kg_K * g.temperature_K * c
            / params["dead_volume_m3"])
    late = t > 0.2
    slope = np.polyfit(t[late], p[late], 1)[0]
    assert abs(slope / rate - 1.0) < 0.01, (slope, rate)
    ported = Model([make_effect("tube_delay", form="wave", segments=8),
                    make_effect("closure", terms="inlet_flow")])
    with pytest.raises(ValueError, match="inlet_flow"):
        simulate(ported, dict(params, closure_coefficient_0=0.1),
                 make_inputs(t, np.zeros(t.size)), rig, 3.3e5, SolverConfig.reference())


# ---------------------------------------------------------------- a compliant chamber
def _bladder_card(rig, dead_m3, dv_max_m3, scale_Pa, points=16):
    """A rig card of valve 1 and a ``compliant_table`` chamber tabulating the plant's
    BladderVolume at ``points`` pressures (its own formula, written apart)."""
    from pneubayes.rigcard import RigCard

    p = np.linspace(P_ATM - 2e4, P_SUP + 2e4, points)
    y = (p - P_ATM) / scale_Pa
    dv = np.where(y >= 0, dv_max_m3 * (1 - np.exp(-y)), dv_max_m3 * y / (1 - 4 * y))
    card = {"format": "pneubayes-rig/1", "name": "valve 1, tube and bladder",
            "atmospheric_pressure_Pa": P_ATM, "temperature_K": rig.gas.temperature_K,
            "command": {"unit": "V", "range": [-5.0, 5.0]},
            "chamber": {"kind": "compliant_table", "dead_volume_m3": dead_m3,
                        "pressure_Pa": p.tolist(), "volume_change_m3": dv.tolist()},
            "valve": {"kind": "gompertz", **{k: v for k, v in valve_preset(
                "valve1").parameters().items() if k != "dead_volume_m3"}},
            "supply": {"kind": "constant", "pressure_Pa": P_SUP}}
    return RigCard.from_dict(card, "card.json")


def test_a_compliant_chamber_behind_the_wave_tube_agrees_with_the_plants_bladder(rig):
    """A bladder that takes 1.5 cm^3 as it fills (the plant's BladderVolume, 48-cell tube,
    LSODA) behind a 1-m tube: the wave tube beside the card's tabulated V(p) agrees to a
    few hundred Pa RMS (as the rigid chamber does), where the wave tube into a rigid
    chamber misses by tens of kPa."""
    from pneubayes.bench.forms import BladderVolume

    dt = 1e-4
    t = np.arange(6001) * dt
    inputs = Inputs(t, _steps(1, t.size, dt), np.full(t.size, 0.01875), np.full(t.size, P_SUP))
    base = dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)
    bladder = BladderVolume(dV_max_m3=1.5e-6, pressure_scale_Pa=1.5e5)
    ref = simulate_plant(base, (AcousticTube(1.0, 0.002, segments=48), bladder), inputs, rig,
                         P_ATM, PlantConfig.reference()).pressure_Pa
    params, _ = _params(rig, 1.0, 0.002)
    card = _bladder_card(rig, params["dead_volume_m3"], 1.5e-6, 1.5e5)
    tube = {k: params[k] for k in ("tube_delay_s", "tube_diameter_m")}
    model = Model([make_effect("tube_delay", form="wave", segments=8)], rig_card=card)
    got = simulate(model, tube, inputs, rig, P_ATM, SolverConfig.reference()).pressure_Pa[0]
    rigid = simulate(_wave(), params, inputs, rig, P_ATM,
                     SolverConfig.reference()).pressure_Pa[0]
    rms = float(np.sqrt(np.mean((got - ref) ** 2)))
    assert rms < 250.0, f"wave + bladder vs plant: {rms:.0f} Pa RMS"
    assert float(np.sqrt(np.mean((rigid - ref) ** 2))) > 20.0 * rms
    assert np.ptp(ref) > 0.5 * (P_SUP - P_ATM)


def _hinged(rig, compliance=2e-11, threshold=3.0e5):
    from pneubayes.effects.volume_closure import VolumeClosure

    params, _ = _params(rig, 1.5, 0.002)
    params.update(volume_closure_compliance_0=compliance,
                  volume_closure_threshold_0=threshold)
    return _wave().with_effect(VolumeClosure()), params


def test_a_volume_hinge_behind_the_wave_tube_converges_and_keeps_a_shut_chamber(
        rig, make_inputs, closable_params):
    """Step halving as for the rigid chamber; with the valve shut and no leak a
    compliant chamber behind the tube keeps its pressure; compliance 0 is the rigid
    wave tube exactly."""
    model, params = _hinged(rig)
    dt = 1e-3
    t = np.arange(1501) * dt
    inputs = make_inputs(t, _steps(3, t.size, dt), position=0.015)

    def run(rtol, values=params, m=model):
        cfg = SolverConfig(rtol=rtol, atol_Pa=rtol * 3e5, atol_K=0.01, max_step_s=0.02,
                           min_step_s=1e-12, max_steps_per_s=1e7)
        return simulate(m, values, inputs, rig, P_ATM, cfg).pressure_Pa[0]

    tight = run(1e-9)
    errs = [float(np.max(np.abs(run(r) - tight))) for r in (3e-5, 1e-7)]
    assert errs[0] < 1e-3 * (P_SUP - P_ATM) and errs[1] <= errs[0] + 1e-6, errs
    rigid = run(1e-9, {**params, "volume_closure_compliance_0": 0.0})
    np.testing.assert_array_equal(rigid, run(1e-9, {k: v for k, v in params.items()
                                                    if "closure" not in k}, _wave()))
    assert np.max(np.abs(rigid - tight)) > 5e3  # the hinge matters above 3 bar
    shut = {**_params(rig, 1.5, 0.002, valve=closable_params)[0],
            **{k: v for k, v in params.items() if "closure" in k}}
    p = simulate(model, shut, make_inputs(t, np.zeros(t.size)), rig, 3.6e5,
                 SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(p - 3.6e5)) < 1e-6


def test_start_sensitivity_through_the_wave_tube_into_a_compliant_chamber(rig, hand):
    model, params = _hinged(rig, compliance=1e-11, threshold=2.5e5)
    n = 801
    t = np.arange(n) * 1e-3
    inputs = Inputs(t, hand.random_steps(np.random.default_rng(4), n, 1e-3,
                                         levels=(-1.0, 1.0)),
                    np.full(n, 0.01), np.full(n, 6.0e5))
    starts, p0 = np.array([0, 400]), np.array([2.0e5, 4.0e5])
    cfg = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=0.01, max_step_s=0.02,
                       min_step_s=1e-12, max_steps_per_s=1e7)
    _, sens = simulate_windows_sensitivity(model, params, inputs, rig, starts, 400, p0, cfg)
    d = 20.0
    fd = (simulate_windows(model, params, inputs, rig, starts, 400, p0 + d, cfg)
          - simulate_windows(model, params, inputs, rig, starts, 400, p0 - d, cfg)) / (2 * d)
    assert np.max(np.abs(sens - fd)) < 0.03
    assert np.max(np.abs(fd)) > 0.5



# ---------------------------------------------------------------- the grid
def test_a_coarser_grid_converges_to_the_fine_one_and_stays_near_the_plant(rig):
    """The grid (``grid_s``) trades accuracy for cost: on a 2.9-m tube (element transit
    1.06 ms) the error against a far finer grid falls as the grid is refined, and a
    0.25-ms grid stays within 0.15 % of the range of the plant's 48-cell tube (0.08 % on
    the default 0.1-ms grid; measured 0.10 %); the default is the 0.1-ms grid."""
    assert make_effect("tube_delay", form="wave").options()["grid_s"] == 1e-4
    dt = 1e-4
    t = np.arange(6001) * dt
    x = 0.01875 + 0.01 * np.sin(2 * np.pi * 3.0 * t)
    inputs = Inputs(t, _steps(1, t.size, dt), x, np.full(t.size, P_SUP))
    params, _ = _params(rig, 2.9, 0.00183)

    def run(grid_s):
        return simulate(_wave(grid_s=grid_s), params, inputs, rig, P_ATM,
                        SolverConfig.standard()).pressure_Pa[0]

    fine = run(2.5e-5)
    errs = [float(np.sqrt(np.mean((run(g) - fine) ** 2))) for g in (1e-3, 5e-4, 2.5e-4)]
    assert errs[0] > errs[1] > errs[2] > 0.0, errs
    base = dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)
    ref = simulate_plant(base, (AcousticTube(2.9, 0.00183, segments=48),), inputs, rig,
                         P_ATM, PlantConfig.reference()).pressure_Pa
    rms = float(np.sqrt(np.mean((run(2.5e-4) - ref) ** 2)))
    assert rms < 1.5e-3 * np.ptp(ref), (rms, np.ptp(ref))


@pytest.mark.parametrize("grid_s", [0.0, 0.1, "1e-4"])
def test_a_bad_grid_names_the_option(grid_s):
    with pytest.raises(ValueError, match="grid_s"):
        make_effect("tube_delay", form="wave", grid_s=grid_s).parameters()


def test_the_discovery_setting_fixes_the_wave_candidates_grid_from_its_start(rig):
    """``forms.tube_wave_grid_*``: the transmission line the loop proposes gets a fixed
    grid, its start's element transit over the count, between 0.1 ms and the step; the
    defaults keep 0.1 ms."""
    from types import SimpleNamespace

    from pneubayes.discovery.candidates import effect_candidates
    from pneubayes.discovery.settings import FormSettings

    fit = SimpleNamespace(model=Model(), params=dict(valve_preset("valve1").parameters(),
                                                     dead_volume_m3=2.4e-6))

    def grid(forms, delay_s):
        cands = effect_candidates(fit, "tube_delay",
                                  {"best_term_start": {"tube_delay_s": delay_s}}, rig, forms)
        return [m.effect("tube_delay").grid_s for m, _ in cands
                if m.effect("tube_delay").form == "wave"]

    coarse = FormSettings(tube_wave_grid_s=5e-4, tube_wave_grid_per_element=4)
    assert grid(coarse, 4e-3) == [pytest.approx(1.25e-4)]  # 0.5-ms elements over 4
    assert grid(coarse, 0.02) == [5e-4]  # at most the step
    assert grid(coarse, 1e-3) == [1e-4]  # at least 0.1 ms
    assert grid(FormSettings(), 0.02) == [1e-4]
    with pytest.raises(ValueError, match="tube_wave_grid_per_element"):
        FormSettings(tube_wave_grid_per_element=0)


def test_the_discovery_setting_lets_the_wave_candidate_fit_the_unsteady_shear(rig):
    """``forms.tube_wave_unsteady``: the loop's transmission line carries the unsteady
    shear's weight as a parameter, started at 0 (the quasi-steady tube it nests); by
    default it does not."""
    from types import SimpleNamespace

    from pneubayes.discovery.candidates import effect_candidates
    from pneubayes.discovery.settings import FormSettings

    fit = SimpleNamespace(model=Model(), params=dict(valve_preset("valve1").parameters(),
                                                     dead_volume_m3=2.4e-6))

    def wave(forms):
        cands = effect_candidates(fit, "tube_delay",
                                  {"best_term_start": {"tube_delay_s": 4e-3}}, rig, forms)
        return [(m, start) for m, start in cands if m.effect("tube_delay").form == "wave"]

    [(model, start)] = wave(FormSettings(tube_wave_unsteady=True))
    assert "tube_unsteady_friction" in model.parameter_names
    assert start.get("tube_unsteady_friction", 0.0) == 0.0
    [(model, _)] = wave(FormSettings())
    assert "tube_unsteady_friction" not in model.parameter_names
    with pytest.raises(ValueError, match="tube_wave_unsteady must be true or false"):
        FormSettings(tube_wave_unsteady=1)
    with pytest.raises(ValueError, match="an option of the 'wave' form"):
        make_effect("tube_delay", form="line", unsteady_friction=True).parameters()
