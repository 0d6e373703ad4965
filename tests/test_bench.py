"""Virtual bench: protocols, sensor chain, truth, determinism."""

import json

import numpy as np
import pytest

from pneubayes.bench import SensorChain, piston_motion, step_commands
from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.effects import effects_from_names
from pneubayes.evaluation import predict_windows
from pneubayes.io import check_recording, read_recording
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


def _holds(t, u):
    switch = np.nonzero(np.diff(u) != 0)[0] + 1
    edges = np.concatenate([[0], switch])
    return np.diff(t[edges])


def test_step_commands_follow_the_paper_protocol():
    rng = np.random.default_rng(0)
    t = np.arange(20001) / 1000.0
    u = step_commands(t, rng, 3.0, clock_s=1e-3)
    holds = _holds(t, u)
    assert holds.min() >= 0.030 - 1e-9 and holds.max() <= 0.300 + 1e-3
    assert np.all(np.abs(u) <= 3.0)
    assert u.min() < -2.0 and u.max() > 2.0  # the range is used
    assert 20 / 0.3 < holds.size + 1 < 20 / 0.03


def test_step_commands_reject_bad_range():
    with pytest.raises(ValueError, match="range_V"):
        step_commands(np.arange(10.0), np.random.default_rng(0), 6.0)


def test_piston_motion_stays_in_stroke_and_is_aggressive():
    t = np.arange(100001) / 10000.0
    x = piston_motion(t, np.random.default_rng(1), 0.0375)
    assert x.min() >= 0.0 and x.max() <= 0.0375
    speed = np.abs(np.gradient(x, t))
    assert speed.max() > 0.05  # m/s: full-stroke moves in a fraction of a second
    assert np.ptp(x) > 0.5 * 0.0375


def test_sensor_chain_noise_and_small_lag():
    rng = np.random.default_rng(2)
    fine = np.arange(200001) / 10000.0
    out_t = np.arange(20001) / 1000.0
    s = SensorChain(pressure_noise_Pa=500.0)
    flat = s.measure(fine, np.full(fine.size, 3e5), out_t, 500.0, rng)
    assert abs(np.std(flat) - 500.0) < 15.0 and abs(np.mean(flat) - 3e5) < 15.0
    step = np.where(fine >= 1.0, 2e5, 1e5)
    y = s.measure(fine, step, out_t, 0.0, rng)
    t_half = out_t[np.argmax(y >= 1.5e5)]
    assert 0.999 <= t_half <= 1.001  # linear phase, delay compensated: no lag
    causal = SensorChain(phase="causal").measure(fine, step, out_t, 0.0, rng)
    t_half_c = out_t[np.argmax(causal >= 1.5e5)]
    assert 1.0 < t_half_c < 1.0015  # an analogue filter's sub-ms group delay


@pytest.fixture(scope="module")
def fixed_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench_fixed")
    cfg = BenchConfig("AIR37", "valve1", effects_from_names(["cylinder_leak", "tube_delay"]),
                      protocol="fixed", duration_s=4.0, seed=7, positions=(0.2,),
                      overrides={"tube_delay_s": 0.004})
    return run_bench(cfg, out)


def test_bench_writes_valid_recordings_and_truth(fixed_set):
    assert len(fixed_set.recordings) == 3  # ranges 5, 3, 0.5
    for p in fixed_set.recordings:
        assert check_recording(p) == []
        rec = read_recording(p)
        assert rec.n_samples == 4001 and np.allclose(np.diff(rec.time_s), 1e-3)
        rng_V = rec.metadata.extra["command_range_V"]
        assert np.abs(rec.command_V).max() <= rng_V
    model, truth = Model.load_card(fixed_set.truth_path)
    assert model.effect_names == ("cylinder_leak", "tube_delay")
    assert truth["tube_delay_s"] == 0.004
    assert truth["leak_area_m2"] == pytest.approx(np.pi / 4 * 1.9665e-4**2)
    # the tube's volume is part of the dead volume (recording-format.md)
    tube = model.effect("tube_delay").tube_volume_m3({"tube_delay_s": 0.004}, read_recording(
        fixed_set.recordings[0]).rig())
    assert truth["dead_volume_m3"] == pytest.approx(1.5e-7 + tube)
    bench = json.loads(fixed_set.truth_path.read_text())["bench"]
    assert bench["seed"] == 7 and bench["planted_effects"] == ["cylinder_leak", "tube_delay"]


def test_true_model_predicts_its_bench_data_near_the_noise(fixed_set):
    model, truth = Model.load_card(fixed_set.truth_path)
    plain = Model()
    for p in fixed_set.recordings:
        rec = read_recording(p)
        wp = predict_windows(model, truth, rec, 2.0, 0.5, SolverConfig.standard())
        # noise 500 Pa plus the anti-alias lag on steep edges
        assert wp.rmse_Pa()[0] < 3 * 500.0
        wrong = predict_windows(plain, {n: truth[n] for n in plain.parameter_names}, rec,
                                2.0, 0.5, SolverConfig.standard())
        assert wrong.rmse_Pa()[0] > 3 * wp.rmse_Pa()[0]


def test_bench_is_deterministic_per_seed(tmp_path):
    def make(seed, sub):
        cfg = BenchConfig("PRN", "valve2", effects_from_names(["supply_fluctuation"]),
                          protocol="moving", duration_s=1.0, seed=seed, count=1)
        return run_bench(cfg, tmp_path / sub).recordings[0].read_bytes()

    first = make(3, "a")
    assert first == make(3, "b")
    assert first != make(4, "c")


def test_supply_fluctuation_shows_in_the_supply_column(tmp_path):
    def supply_std(effects, sub):
        cfg = BenchConfig("SMC", "valve1", effects_from_names(effects), protocol="moving",
                          duration_s=5.0, seed=1, count=1)
        rec = read_recording(run_bench(cfg, tmp_path / sub).recordings[0])
        return np.std(rec.supply_pressure_Pa)

    assert supply_std([], "none") < 600.0
    assert supply_std(["supply_fluctuation"], "fluct") > 4000.0


def test_a_bench_at_another_supply_records_it(tmp_path):
    supply = 101_325.0 + 3e5
    cfg = BenchConfig("AIR37", "valve1", (), protocol="moving", duration_s=1.0, seed=1,
                      count=1, supply_Pa=supply)
    res = run_bench(cfg, tmp_path)
    rec = read_recording(res.recordings[0])
    assert rec.metadata.supply_pressure_Pa == supply
    assert abs(np.median(rec.supply_pressure_Pa) - supply) < 1e3
    assert res.truth["bench"]["rig"]["supply_pressure_Pa"] == supply
    assert np.max(rec.pressure_Pa) < supply + 3e3  # the chamber never passes its supply
    with pytest.raises(ValueError, match="supply_Pa must be above the atmosphere"):
        BenchConfig("AIR37", "valve1", supply_Pa=101_325.0)


def test_bench_refuses_to_overwrite_and_rejects_unknown_override(tmp_path, fixed_set):
    cfg = BenchConfig("AIR37", "valve1", (), protocol="moving", duration_s=0.5, seed=1,
                      count=1)
    run_bench(cfg, tmp_path)
    with pytest.raises(FileExistsError):
        run_bench(cfg, tmp_path)
    bad = BenchConfig("AIR37", "valve1", (), protocol="moving", duration_s=0.5, seed=1,
                      count=1, overrides={"tube_delay_s": 0.01})
    with pytest.raises(ValueError, match="tube_delay_s"):
        run_bench(bad, tmp_path / "x")


def test_a_bench_recording_drawn_to_a_vacuum_accepts_it_and_reads(tmp_path):
    """The bench's pressures are absolute by construction: a recording whose chamber the
    piston draws below half an atmosphere (a sealed, expanding chamber) accepts the
    reader's ``pressure-low`` rule, which otherwise refuses it as a gauge reading; a
    recording above it accepts nothing."""
    from pneubayes.bench.bench import accepted_rules
    from pneubayes.io import Recording, RecordingMetadata, read_recording, write_recording

    t = np.arange(200) * 1e-3
    p = 101325.0 - 70e3 * np.sin(np.pi * t / t[-1])  # down to 31 kPa and back
    assert accepted_rules(p) == ("pressure-low",)
    assert accepted_rules(np.full(200, 101325.0)) == ()
    meta = dict(cylinder="SMC", valve="valve2", bore_m=0.016, stroke_m=0.1,
                atmospheric_pressure_Pa=101325.0, supply_pressure_Pa=551325.0,
                temperature_K=293.15, position_m=0.05)
    for accept, name in (((), "refused"), (accepted_rules(p), "accepted")):
        rec = Recording(metadata=RecordingMetadata(**meta, accept_unusual=accept),
                        time_s=t, command_V=np.zeros(200), pressure_Pa=p)
        write_recording(rec, tmp_path / name)
    with pytest.raises(ValueError, match="far below the atmosphere"):
        read_recording(tmp_path / "refused.csv")
    assert read_recording(tmp_path / "accepted.csv").pressure_Pa.min() < 0.5 * 101325.0
