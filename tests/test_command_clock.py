"""The open form on the command: a valve driver on its own clock (effect
``command_clock``), its simulation against the bench plant's drivers, its search in the
prediction windows' residual and the stage that adds it (issue 69)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from conftest import P_ATM, P_SUP, random_steps

from pneubayes.effects import make_effect
from pneubayes.effects.command_clock import CommandClock
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, SolverConfig, simulate, simulate_windows
from pneubayes.simulation.reference import reference_simulate

RANGE = P_SUP - P_ATM
BASE = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}


def _inputs(seed, n, hold_s=(0.1, 0.6)):
    t = np.arange(n) * 1e-3
    u = random_steps(np.random.default_rng(seed), n, 1e-3, hold_s=hold_s)
    return Inputs(t, u, np.full(n, 0.015), np.full(n, P_SUP))


def _hold(period, phase, latency):
    return {**BASE, "command_clock_period": period, "command_clock_phase": phase,
            "command_clock_latency": latency}


def _rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.mark.parametrize("period, latency, phase", [(0.0123, 0.003, 0.37),
                                                    (0.004, 0.0, 0.0),
                                                    (0.025, 0.0071, 0.9)])
def test_a_holding_driver_agrees_with_the_plant_s_sampling_driver(rig, period, latency,
                                                                 phase):
    """Against the bench plant's ZohDriver (its switch times built apart, LSODA): within
    1e-5 of the range where the valve without it misses by over 0.3 %."""
    from pneubayes.bench.forms.valve import ZohDriver
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    inputs = _inputs(3, 2501)
    ref = simulate_plant(BASE, (ZohDriver(period, latency, phase),), inputs, rig, P_ATM,
                         PlantConfig.reference()).pressure_Pa
    got = simulate(Model([CommandClock()]), _hold(period, phase, latency), inputs, rig,
                   P_ATM, SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert _rms(got, ref) < 1e-5 * RANGE
    assert _rms(plain, ref) > 3e-3 * RANGE


@pytest.mark.parametrize("frequency_Hz, opening_s, closing_s, alignment",
                         [(50.0, 3e-3, 2e-3, 0.0), (20.0, 1e-3, 1e-3, 0.0),
                          (50.0, 3e-3, 2e-3, 0.5), (27.7, 1.7e-3, 2.1e-3, 0.25)])
def test_a_modulating_driver_agrees_with_the_plant_s_pwm_valve(rig, frequency_Hz, opening_s,
                                                              closing_s, alignment):
    """Against the bench plant's PwmValve (solenoid delays on its pulses, LSODA): the
    pulses' latency is the opening delay, their trim the opening less the closing delay
    and their alignment the driver's (from the period's start, centred, between); within
    1e-5 of the range where the proportional valve, and a driver aligned otherwise, miss
    by over 5 % and 0.5 %."""
    from pneubayes.bench.forms.valve import PwmValve
    from pneubayes.bench.plant import PlantConfig, simulate_plant

    inputs = _inputs(3, 2501)
    # shut over the first 50 ms: the plant's driver starts at the first sample, the
    # model's has ticked before it (a pulse ending at the next tick would reach into it)
    inputs = Inputs(inputs.time_s, np.where(inputs.time_s < 0.05, 0.0, inputs.command_V),
                    inputs.position_m, inputs.supply_pressure_Pa)
    ref = simulate_plant(BASE, (PwmValve(frequency_Hz, opening_s, closing_s, 5.0, alignment),),
                         inputs, rig, P_ATM, PlantConfig.reference()).pressure_Pa
    params = {**_hold(1.0 / frequency_Hz, 0.0, opening_s), "command_clock_full_command": 5.0,
              "command_clock_pulse_trim": opening_s - closing_s,
              "command_clock_pulse_alignment": alignment}
    model = Model([CommandClock("pwm")])
    got = simulate(model, params, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    other = simulate(model, {**params, "command_clock_pulse_alignment": 0.5 - alignment / 1.6},
                     inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert _rms(got, ref) < 1e-5 * RANGE
    assert _rms(plain, ref) > 0.05 * RANGE
    assert _rms(other, ref) > 0.005 * RANGE


def test_windows_continue_the_run_and_the_step_halves(rig):
    """Windows started mid-recording from the run's own pressure take the driver's ticks
    on the recording's clock (they continue the one-window run); a 100 x tighter solver
    moves the run by under 0.05 % of the range; no period is the valve without it,
    exactly."""
    inputs = _inputs(7, 4001, hold_s=(0.02, 0.2))
    model, params = Model([CommandClock()]), _hold(0.0173, 0.61, 0.004)
    whole = simulate(model, params, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    starts, length = np.arange(500, 3501, 497), 401
    got = simulate_windows(model, params, inputs, rig, starts, length, whole[starts],
                           SolverConfig.standard())[0]
    assert np.max(np.abs(got - whole[starts[:, None] + np.arange(length)])) < 2e-3 * RANGE
    tight = simulate(model, params, inputs, rig, P_ATM,
                     SolverConfig.standard().tightened(100.0)).pressure_Pa[0]
    assert np.max(np.abs(whole - tight)) < 5e-4 * RANGE
    off = simulate(model, {**params, "command_clock_period": 0.0,
                           "command_clock_latency": 0.0}, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_array_equal(off, plain)
    fast = simulate(model, {**params, "command_clock_period": 5e-5,
                            "command_clock_latency": 0.0}, inputs, rig, P_ATM,
                    SolverConfig.standard()).pressure_Pa[0]  # (faster than 10 kHz)
    np.testing.assert_array_equal(fast, plain)
    # with no clock the latency (4 ms) is a pure delay: the command recorded 4 samples late
    late = simulate(model, {**params, "command_clock_period": 0.0}, inputs, rig, P_ATM,
                    SolverConfig.standard()).pressure_Pa[0]
    u = np.concatenate([np.full(4, inputs.command_V[0]), inputs.command_V[:-4]])
    shifted = Inputs(inputs.time_s, u, inputs.position_m, inputs.supply_pressure_Pa)
    delayed = simulate(Model(), BASE, shifted, rig, P_ATM,
                       SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(late, delayed, rtol=0, atol=1e-6 * RANGE)
    windows = simulate_windows(model, {**params, "command_clock_period": 0.0}, inputs, rig,
                               starts, length, late[starts], SolverConfig.standard())[0]
    assert np.max(np.abs(windows - late[starts[:, None] + np.arange(length)])) < 2e-3 * RANGE


def test_the_driver_is_refused_by_the_ode_reference_and_checks_its_form(rig):
    with pytest.raises(ValueError, match="plant's driver"):
        reference_simulate(Model([CommandClock()]), _hold(0.01, 0.0, 0.0), _inputs(1, 201),
                           rig, 2e5)
    with pytest.raises(ValueError, match="form"):
        CommandClock("square")
    assert "command_clock_full_command" not in CommandClock().parameter_names()
    assert "command_clock_pulse_trim" in CommandClock("pwm").parameter_names()


def test_a_full_duty_pulse_holds_the_valve_open_and_none_shuts_it(rig):
    """At the full command the PWM valve is the proportional valve at full command from
    the first tick (no gap between periods, wherever its pulses are aligned); at 0 it is
    shut."""
    n = 801
    t = np.arange(n) * 1e-3
    full = Inputs(t, np.full(n, 5.0), np.full(n, 0.015), np.full(n, P_SUP))
    params = {**_hold(0.02, 0.0, 0.0), "command_clock_full_command": 5.0,
              "command_clock_pulse_trim": 0.002, "command_clock_pulse_alignment": 0.4}
    pwm = simulate(Model([CommandClock("pwm")]), params, full, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), BASE, full, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(pwm, plain, rtol=0, atol=1e-6 * RANGE)
    shut = Inputs(t, np.zeros(n), np.full(n, 0.015), np.full(n, P_SUP))
    closed = simulate(Model([CommandClock("pwm")]), params, shut, rig, 3e5,
                      SolverConfig.standard()).pressure_Pa[0]
    at_zero = simulate(Model(), BASE, shut, rig, 3e5, SolverConfig.standard()).pressure_Pa[0]
    np.testing.assert_allclose(closed, at_zero, rtol=0, atol=1e-6 * RANGE)


def _plant_recordings(form, count=2, n=8001):
    """``count`` recordings (1 kHz, 200 Pa noise) of valve 1 on a 2.4-cm^3 chamber
    behind the bench plant's driver ``form`` (None: none); each simulated once per
    module (the tests share them)."""
    return [_plant_recording(form, seed, n) for seed in range(count)]


@functools.cache
def _plant_recording(form, seed, n):
    from conftest import BORE, STROKE

    from pneubayes.bench.plant import PlantConfig, simulate_plant
    from pneubayes.io.recording import Recording, RecordingMetadata
    from pneubayes.rig import Rig

    rig = Rig(BORE, P_ATM, P_SUP, stroke_m=STROKE)
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    rng = np.random.default_rng(60 + seed)
    inputs = _inputs(60 + seed, n)
    p = simulate_plant(BASE, () if form is None else (form,), inputs, rig, P_ATM,
                       PlantConfig.reference()).pressure_Pa
    return Recording(md, inputs.time_s, inputs.command_V, p + rng.normal(0.0, 200.0, n),
                     source=f"driver_{seed}.csv")


def _clock_search(form, model=None, params=BASE, count=2, **kw):
    """The search on ``count`` 8-s recordings behind ``form``."""
    from pneubayes.discovery.openform.command_clock import (
        CommandClockProblem,
        CommandClockSearch,
    )
    from pneubayes.inference.windows import WindowSet

    ws = WindowSet(_plant_recordings(form, count), 2.0, 2.0)
    return CommandClockSearch(**kw).fit(CommandClockProblem(
        ws, Model() if model is None else model, params, SolverConfig.standard()))


def test_the_search_reads_a_planted_sampling_driver():
    """A sampling driver (12.3 ms, 3 ms late) from the bench plant: the period to 1e-4,
    the driver's form, nearly all of the residual (one refinement pass: the further
    passes move nothing here; none leaves it at 88 %); beside a transport delay, the
    driver's latency carries it."""
    from pneubayes.bench.forms.valve import ZohDriver

    zoh = _clock_search(ZohDriver(0.0123, 0.003, 0.37), refine_passes=1)
    (term,) = zoh.terms_
    assert term.form == "hold" and term.period_s == pytest.approx(0.0123, rel=1e-4)
    assert term.explained > 0.95 and zoh.coherence_ > 0.9
    # the ticks plus the latency where the plant has them, to a tenth of a millisecond
    offset = (term.phase * term.period_s + term.latency_s) % term.period_s
    assert abs(offset - (0.37 * 0.0123 + 0.003)) < 1e-4
    # beside a transport delay fitted for the waits' mean the driver's latency carries
    # the delay (the search cannot read negative waits), and its term clears the tube's
    # (the holding driver only: the form is read above)
    tube = Model([make_effect("tube_delay", form="transport")])
    late = _clock_search(ZohDriver(0.0123, 0.003, 0.37), tube,
                         {**BASE, **tube.neutral_values(), "tube_delay_s": 0.009},
                         forms=("hold",), refine_passes=1)
    (term,) = late.terms_
    assert term.period_s == pytest.approx(0.0123, rel=1e-4) and term.explained > 0.9
    assert term.values()["tube_delay_s"] == 0.0


def test_the_search_reads_a_planted_pwm_valve():
    """A PWM valve (50 Hz, its solenoid 3 ms to open, 2 ms to close) from the bench
    plant: the period to 1e-4, the driver's form, nearly all of the residual (one
    refinement pass, as above)."""
    from pneubayes.bench.forms.valve import PwmValve

    pwm = _clock_search(PwmValve(50.0, 3e-3, 2e-3, 5.0), refine_passes=1)
    (term,) = pwm.terms_
    assert term.form == "pwm" and term.period_s == pytest.approx(0.02, rel=1e-4)
    assert term.explained > 0.95 and "PWM" in str(term)


def test_the_search_reads_no_clock_from_a_valve_without_one():
    """A valve without a driver, one 8-s recording (the default search, both forms; a
    spurious driver has fewer windows to fit): none kept, the best far below the gate
    (it adds error)."""
    from pneubayes.discovery.openform.command_clock import CommandClockSearch

    none = _clock_search(None, count=1)
    assert none.terms_ == [] and none.best_.explained < 0.02
    with pytest.raises(ValueError, match="forms"):
        _clock_search(None, forms=("square",))
    with pytest.raises(ValueError, match="CommandClockProblem"):
        CommandClockSearch().fit(object())


def test_the_stage_runs_first_among_the_open_forms_and_can_be_switched_off():
    from pneubayes.discovery.settings import DiscoverySettings, StageSettings
    from pneubayes.discovery.stages import CommandClockForm, default_stages

    assert CommandClockForm().compete_below_gap_closed == 0.9
    names = [type(s).__name__ for s in default_stages(DiscoverySettings())]
    assert names.index("OtherForms") < names.index("CommandClockForm") \
        < names.index("ReadingForm")
    off = default_stages(DiscoverySettings(stages=StageSettings(
        command_clock_min_noise_ratio=0)))
    assert "CommandClockForm" not in [type(s).__name__ for s in off]
    with pytest.raises(ValueError, match="command_clock_min_noise_ratio"):
        StageSettings(command_clock_min_noise_ratio=0.5)


@pytest.mark.slow
def test_the_loop_finds_a_sampling_driver_beside_maps_fitted_without_it():
    """The loop on four recordings behind the plant's sampling driver, its base model
    fitted without it (the valve maps bend to take part of the waits): the stage reads
    the planted period from that model's windows (the changes' onsets in phase at
    1e-3 chance), fits the driver, reads it again beside the refitted maps and refits,
    until the held-out windows are predicted to the noise floor (the first fit alone
    stood at 50 x it)."""
    from conftest import discovery_settings

    from pneubayes.bench.forms.valve import ZohDriver
    from pneubayes.discovery.loop import Discovery
    from pneubayes.discovery.stages import CommandClockForm

    recs = _plant_recordings(ZohDriver(0.0123, 0.003, 0.37), count=4)
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 1})
    result = Discovery(settings, None, log=None,
                       stages=[CommandClockForm()]).fit(recs).result_
    ledger = list(result.ledger)
    (search, *_) = [e for e in ledger if e["action"] == "command clock form search"]
    (term,) = search["terms"]
    assert term["form"] == "hold" and term["period_s"] == pytest.approx(0.0123, rel=1e-4)
    assert [a["name"] for a in result.accepted] == ["command_clock"]
    p = result.final.params
    assert result.final.heldout_rmse_Pa < 1.2 * result.noise_floor_Pa
    assert p["command_clock_period"] == pytest.approx(0.0123, rel=2e-5)
    # the valve switches where the plant's driver does, to a tenth of a millisecond
    offset = (p["command_clock_phase"] * 0.0123 + p["command_clock_latency"]) % 0.0123
    assert abs(offset - (0.37 * 0.0123 + 0.003)) < 1e-4


def test_the_ticks_are_centred_between_the_changes_they_take():
    """The ticks move to the middle of the span that keeps every change at its tick, the
    latency the other way (the switches stay put); clipped at the latency's bounds; a
    clock without changes or period as given."""
    from pneubayes.discovery.openform.clock_reading import ticks_centred

    period = 0.01
    # ticks at 0.002 + k 0.01; changes 0.5 ms and 6.5 ms before their ticks
    changes = np.array([0.0015, 0.0155, 0.0255, 0.0335])
    phase, latency = ticks_centred(changes, period, 0.2, 0.004, (0.0, 0.05))
    # leads 0.5, 6.5, 6.5, 8.5 ms: ticks may move 0.5 ms earlier or 1.5 ms later
    assert phase == pytest.approx(0.25) and latency == pytest.approx(0.0035)
    lead = (phase * period - changes) % period
    assert np.min(lead) == pytest.approx(period - np.max(lead))
    switch = (0.2 * period + 0.004) % period
    assert (phase * period + latency) % period == pytest.approx(switch)
    # a latency of 0.2 ms can give only 0.2 ms
    phase, latency = ticks_centred(changes, period, 0.2, 0.0002, (0.0, 0.05))
    assert latency == 0.0 and phase == pytest.approx(0.22)
    assert ticks_centred([], period, 0.2, 0.004, (0.0, 0.05)) == (0.2, 0.004)
    assert ticks_centred(changes, 0.0, 0.2, 0.004, (0.0, 0.05)) == (0.2, 0.004)


def test_the_stage_s_joint_passes_are_checked_and_recorded():
    from pneubayes.discovery.stages import CommandClockForm

    assert CommandClockForm(joint_passes=0).options()["joint_passes"] == 0
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="joint_passes"):
            CommandClockForm(joint_passes=bad)
    with pytest.raises(ValueError, match="joint_min_gain"):
        CommandClockForm(joint_min_gain=1.0)
    assert CommandClockForm(polish_halvings=2).options()["polish_halvings"] == 2
    for bad in (-1, 2.0, False):
        with pytest.raises(ValueError, match="polish_halvings"):
            CommandClockForm(polish_halvings=bad)


def test_a_command_logged_on_a_coarse_grid_is_not_read_as_a_clock():
    """Changes logged every 10 ms and taken after a fixed delay are in phase at 10 ms
    (and its fractions) without any driver: those periods are not read. Takes of a
    12.3-ms driver behind the same changes still are."""
    from pneubayes.discovery.openform.clock_reading import clock_in_phase

    rng = np.random.default_rng(5)
    changes = np.sort(rng.choice(np.arange(2000), 300, replace=False)) * 0.01  # 20 s
    delayed = changes + 0.0031
    period, _, coherence, p = clock_in_phase(delayed, np.ones(300), 2e-3, 0.05, 20.0)
    assert coherence > 0.99 and p < 1e-100  # read as a clock where not masked
    period, _, coherence, p = clock_in_phase(delayed, np.ones(300), 2e-3, 0.05, 20.0,
                                             changes)
    assert not np.isfinite(period) or p > 1e-3
    ticks = (np.ceil(changes / 0.0123 - 0.37) + 0.37) * 0.0123 + 0.003
    period, offset, coherence, p = clock_in_phase(ticks, np.ones(300), 2e-3, 0.05, 20.0,
                                                  changes)
    assert period == pytest.approx(0.0123, rel=1e-5) and coherence > 0.99 and p < 1e-100
    assert offset == pytest.approx((0.37 * 0.0123 + 0.003) % 0.0123, abs=1e-5)


def test_a_driver_s_timing_a_fraction_of_a_millisecond_off_is_polished():
    """At the valve's true maps, a driver whose period is 6e-5 of itself off (its ticks
    drift by 0.3 ms from the windows' middle to their ends) and whose latency is 0.2 ms
    late (together 30 x the noise; the trajectory refinement's finite differences do
    not move either) is moved to the planted timing by the stage's compass search, and
    the training error falls to the noise."""
    from conftest import discovery_settings

    from pneubayes.bench.forms.valve import ZohDriver
    from pneubayes.discovery.loop import Discovery, noise_floor_Pa
    from pneubayes.discovery.stages import CommandClockForm
    from pneubayes.discovery.state import Ledger, LoopData
    from pneubayes.discovery.trials import TrialRunner

    recs = _plant_recordings(ZohDriver(0.0123, 0.003, 0.37), count=4)
    settings = discovery_settings(data={"holdout_recordings": 2})
    data = Discovery(settings, None, log=None)._data(recs)
    runner = TrialRunner(settings, LoopData(*data[1:5], data[5], noise_floor_Pa(data[0])),
                         Ledger(), None, log=lambda m: None)
    model = Model([CommandClock()])
    off = 0.0123 * (1.0 + 6e-5)
    # the same tick at 4 s (the windows' middle) on the longer period
    n = np.floor(4.0 / 0.0123 - 0.37)
    phase = ((0.37 + n) * 0.0123 / off - n) % 1.0
    start = {**BASE, "command_clock_period": off, "command_clock_phase": phase,
             "command_clock_latency": 0.0032}
    fit = runner.score(model, start)
    assert fit.train_rmse_Pa > 20.0 * runner.data.noise_Pa
    got = CommandClockForm()._polished(fit, runner, "hold")
    assert got.params["command_clock_period"] == pytest.approx(0.0123, rel=3e-6)
    assert got.params["command_clock_latency"] == pytest.approx(0.003, abs=3e-5)
    assert got.train_rmse_Pa < 1.2 * runner.data.noise_Pa
    assert CommandClockForm(polish_halvings=0)._polished(fit, runner, "hold") is fit


def test_a_centred_pwm_pulse_is_polished_from_one_read_at_the_tick():
    """A phase-correct (centred) 27.7-Hz PWM valve from the bench plant, the valve's true
    maps, and the driver read with its pulses from the tick (alignment 0, the search's
    start): the stage's compass moves the pulses to the centre of their periods and the
    training error to the noise."""
    from conftest import discovery_settings

    from pneubayes.bench.forms.valve import PwmValve
    from pneubayes.discovery.loop import Discovery, noise_floor_Pa
    from pneubayes.discovery.stages import CommandClockForm
    from pneubayes.discovery.state import Ledger, LoopData
    from pneubayes.discovery.trials import TrialRunner

    # (one recording to fit on, two held out)
    recs = _plant_recordings(PwmValve(27.7, 1.7e-3, 2.1e-3, 5.0, 0.5), count=3)
    settings = discovery_settings(data={"holdout_recordings": 2})
    data = Discovery(settings, None, log=None)._data(recs)
    runner = TrialRunner(settings, LoopData(*data[1:5], data[5], noise_floor_Pa(data[0])),
                         Ledger(), None, log=lambda m: None)
    model = Model([CommandClock("pwm")])
    start = {**_hold(1.0 / 27.7, 0.0, 1.7e-3), "command_clock_full_command": 5.0,
             "command_clock_pulse_trim": -4e-4, "command_clock_pulse_alignment": 0.0}
    fit = runner.score(model, start)
    assert fit.train_rmse_Pa > 5.0 * runner.data.noise_Pa
    got = CommandClockForm()._polished(fit, runner, "pwm")
    assert got.params["command_clock_pulse_alignment"] == pytest.approx(0.5, abs=0.02)
    assert got.train_rmse_Pa < 1.2 * runner.data.noise_Pa


def test_no_clock_faster_than_half_the_sampling_rate_is_read():
    """A 100-Hz recording (the ventilator's rate) of a valve without a driver: no period
    under 20 ms is read (faster clocks show only at their aliases on a 10-ms grid), and
    a search whose periods all lie under two sample intervals reads nothing."""
    from pneubayes.discovery.openform.command_clock import (
        CommandClockProblem,
        CommandClockSearch,
    )
    from pneubayes.inference.windows import WindowSet
    from pneubayes.io.recording import Recording

    recs = [Recording(r.metadata, r.time_s[::10], r.command_V[::10], r.pressure_Pa[::10],
                      source=r.source) for r in _plant_recordings(None)]
    problem = CommandClockProblem(WindowSet(recs, 2.0, 2.0), Model(), BASE,
                                  SolverConfig.standard())
    search = CommandClockSearch().fit(problem)
    assert search.best_ is None or search.best_.period_s >= 0.02
    fast = CommandClockSearch(longest_period_s=0.015).fit(problem)
    assert fast.best_ is None and fast.terms_ == []


def test_a_clock_fitted_to_no_period_is_neither_polished_nor_centred():
    """A trial that ends with the period at 0 (a pure delay) is left as it is."""
    from types import SimpleNamespace

    from pneubayes.discovery.stages import CommandClockForm

    fit = SimpleNamespace(params={"command_clock_period": 0.0, "command_clock_phase": 0.3,
                                  "command_clock_latency": 0.004})
    stage = CommandClockForm()
    assert stage._polished(fit, None, "hold") is fit
    assert stage._centred(fit, None) is fit


def test_phase_sums_agree_with_the_direct_sums_over_many_blocks():
    """The blocked recurrence against one complex exponential per frequency and time:
    random times over 120 s, a grid longer than several blocks."""
    from pneubayes.discovery.openform.clock_reading import PHASE_BLOCK, phase_sums

    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 120.0, 400))
    w = rng.uniform(0.1, 1.0, 400)
    n = 3 * PHASE_BLOCK + 17
    f = 20.0 + np.arange(n) * (0.02 / 120.0)
    direct = np.abs(np.exp(2j * np.pi * np.outer(f, t)) @ w)
    fast = phase_sums(20.0, 0.02 / 120.0, n, t, w)
    assert fast.shape == (n,)
    np.testing.assert_allclose(fast, direct, rtol=0.0, atol=1e-9 * direct.max())
