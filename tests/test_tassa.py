"""The Tassa et al. (2013) baseline: its formulas, the exact step, recovery, bench, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pneubayes.baselines import (
    PUBLISHED_PARAMETERS,
    TassaModel,
    simulate_windows,
    tassa_coefficients,
    tassa_rhs,
    zoh_step,
)
from pneubayes.baselines.tassa import SOFTABS_EPS, NotFittedError
from pneubayes.errors import ParameterError
from pneubayes.evaluation import WindowPrediction
from pneubayes.io.recording import Recording, RecordingMetadata

STROKE = 0.0375
#: A planted set for a small chamber sampled at 1 kHz: targets from atmosphere to supply
#: (MPa absolute), rates of tens per second, c5 = 1.4 c6 (adiabatic compression).
PLANTED = np.array([0.101, 0.55, 0.02, 3.0, 5.0, 5.6, 4.0, 60.0, 0.2, 5.0])


def _steps(rng, n, dt):
    u = np.empty(n)
    i = 0
    while i < n:
        hold = max(1, int(round(rng.uniform(0.03, 0.3) / dt)))
        u[i:i + hold] = rng.uniform(-5.0, 5.0)
        i += hold
    return np.round(u, 4)


def _moving(rng, t):
    ph = rng.uniform(0.0, 2.0 * np.pi, 2)
    return STROKE * (0.5 + 0.25 * np.sin(2 * np.pi * 1.3 * t + ph[0])
                     + 0.1 * np.sin(2 * np.pi * 3.7 * t + ph[1]))


def _synthetic(seed, duration_s=8.0, noise_Pa=500.0, params=PLANTED):
    """A moving-piston recording simulated from the Tassa model itself, plus white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration_s * 1000)) + 1) / 1000.0
    u, x = _steps(rng, t.size, 1e-3), _moving(rng, t)
    clean = simulate_windows(params, t, u, x, [0], t.size, [300e3], stroke_m=STROKE)[0]
    md = RecordingMetadata("SYN", "planted", 0.009, STROKE, 101325.0, 551325.0, 293.15)
    noise = rng.normal(0.0, noise_Pa, t.size)
    return Recording(md, t, u, clean + noise, position_m=x), noise


# ---------------------------------------------------------------- the formulas
def test_rhs_is_the_notes_model_written_out_by_hand():
    c = PUBLISHED_PARAMETERS
    for u, x, v, p in [(0.3, 0.2, 0.0, 0.25), (-0.7, 0.9, 1.5, 0.4), (0.0359, 0.0, -0.4, 0.1)]:
        up = u - c[2]
        w = c[3] * up + c[4] * up**3
        sigma = w / math.sqrt(w * w + 1.0)
        b = (c[1] + c[0]) / 2 + (c[1] - c[0]) / 2 * sigma
        softabs = math.sqrt(up * up + SOFTABS_EPS**2)
        r0 = (c[7] * (softabs + c[8] * up) + c[9]) / (1 + c[6] * x)
        r = r0 + c[5] * v / (1 + c[6] * x)
        a = b * r0 / r
        assert tassa_rhs(p, u, x, v, c) == pytest.approx(r * (a - p), rel=1e-12)
        got = tassa_coefficients(u, x, v, c)
        assert np.allclose(got, (b, r0, r), rtol=1e-12)


def test_published_target_spans_atmosphere_to_supply_in_absolute_MPa():
    b, r0, _ = tassa_coefficients(np.array([-1.0, 1.0]), 0.0, 0.0, PUBLISHED_PARAMETERS)
    assert b[0] == pytest.approx(0.094, abs=0.002) and b[1] == pytest.approx(0.513, abs=0.002)
    assert np.all(r0 > 0)


def test_batch_of_parameter_sets_adds_a_leading_axis():
    c = np.stack([PUBLISHED_PARAMETERS, PLANTED])
    u = np.linspace(-1, 1, 7)
    out = tassa_rhs(0.3, u, 0.5, 0.1, c)
    assert out.shape == (2, 7)
    assert np.allclose(out[1], tassa_rhs(0.3, u, 0.5, 0.1, PLANTED))


# ---------------------------------------------------------------- the exact step
def test_zoh_step_limits_and_sign_of_rate():
    p, g, dt = 0.3, 2.0, 1e-3
    assert zoh_step(p, 0.0, g, dt) == pytest.approx(p + g * dt, rel=1e-15)
    assert zoh_step(p, 1e-12, g, dt) == pytest.approx(p + g * dt, rel=1e-12)
    for r in (-40.0, 25.0, 3000.0):  # growth, relaxation, a stiff relaxation
        ref = solve_ivp(lambda t, y, r=r: [g - r * y[0]], (0, dt), [p], method="DOP853",
                        rtol=1e-12, atol=1e-15).y[0, -1]
        assert zoh_step(p, r, g, dt) == pytest.approx(ref, rel=1e-10)
    assert zoh_step(p, 25.0, 25.0 * 0.4, 10.0) == pytest.approx(0.4, rel=1e-12)  # a = g / r


def test_window_simulator_matches_a_fine_ode_solution_with_held_inputs():
    rng = np.random.default_rng(3)
    t = np.arange(401) / 1000.0
    u = _steps(rng, t.size, 1e-3)
    u[200:] = 0.0  # valve nearly closed while the piston moves fast
    x = STROKE * (0.5 + 0.4 * np.sin(2 * np.pi * 3.0 * t))
    _, _, r = tassa_coefficients(u[:-1] / 5.0, 0.5 * (x[1:] + x[:-1]) / STROKE,
                                 np.diff(x) / STROKE / 1e-3, PLANTED)
    assert np.any(r < 0)  # compression outruns the valve somewhere: the growth branch
    pred = simulate_windows(PLANTED, t, u, x, [0], t.size, [2.0e5], stroke_m=STROKE)[0]
    p, ref = 0.2, [0.2]
    for k in range(t.size - 1):
        held = (u[k] / 5.0, 0.5 * (x[k] + x[k + 1]) / STROKE, (x[k + 1] - x[k]) / STROKE / 1e-3)
        sol = solve_ivp(lambda _, y, h=held: [tassa_rhs(y[0], *h, PLANTED)], (t[k], t[k + 1]),
                        [p], method="DOP853", rtol=1e-12, atol=1e-15)
        p = float(sol.y[0, -1])
        ref.append(p)
    assert np.allclose(pred, np.array(ref) * 1e6, rtol=1e-9, atol=0)


def test_windows_start_at_the_given_pressure_and_continue_one_long_run():
    rng = np.random.default_rng(4)
    t = np.arange(1001) / 1000.0
    u, x = _steps(rng, t.size, 1e-3), _moving(rng, t)
    long = simulate_windows(PLANTED, t, u, x, [0], t.size, [3e5], stroke_m=STROKE)[0]
    starts = np.array([0, 250, 500, 700])
    win = simulate_windows(PLANTED, t, u, x, starts, 301, long[starts], stroke_m=STROKE)
    assert win.shape == (4, 301)
    idx = starts[:, None] + np.arange(301)[None, :]
    assert np.allclose(win, long[idx], rtol=1e-12)
    batch = simulate_windows(np.stack([PLANTED, PLANTED]), t, u, x, starts, 301, long[starts],
                             stroke_m=STROKE)
    assert batch.shape == (2, 4, 301) and np.array_equal(batch[1], win)


# ---------------------------------------------------------------- identification
def test_planted_parameters_are_recovered_from_the_published_start():
    data = [_synthetic(seed) for seed in (1, 2)]
    model = TassaModel(n_restarts=1, seed=0)
    assert model.fit([rec for rec, _ in data]) is model
    assert model.frozen_ == ()
    noise = np.concatenate([n[1:].reshape(-1, 2000) for _, n in data]).ravel()
    noise_rms = float(np.sqrt(np.mean(noise**2)))
    assert model.rmse_Pa_ < 1.02 * noise_rms
    assert model.start_rmse_Pa_ > 100 * noise_rms  # the published set is far off
    assert np.allclose(model.params_, PLANTED, rtol=0.02, atol=2e-3)
    held_out, _ = _synthetic(9)
    pred = model.predict_windows(held_out, np.stack([model.params_, PLANTED]))
    rmse = pred.rmse_Pa()
    assert rmse[0] < 1.01 * rmse[1]


@pytest.fixture(scope="module")
def bench_recording(tmp_path_factory):
    from pneubayes.bench.bench import BenchConfig, run_bench
    from pneubayes.io import read_recording

    cfg = BenchConfig("AIR37", "valve1", protocol="fixed", duration_s=6, positions=(0.5,),
                      ranges_V=(5.0,), seed=0)
    result = run_bench(cfg, tmp_path_factory.mktemp("air37"))
    return read_recording(result.recordings[0])


def test_fitted_baseline_beats_the_published_set_on_a_bench_recording(bench_recording):
    from pneubayes.inference.predictive import estimate_noise_std

    rec = bench_recording
    model = TassaModel(n_restarts=1).fit(rec)
    fitted = model.predict_windows(rec)
    published = model.predict_windows(rec, PUBLISHED_PARAMETERS)
    assert isinstance(fitted, WindowPrediction)
    assert fitted.predicted_Pa.shape == (1, 3, 2001)
    assert np.array_equal(fitted.measured_Pa[:, 0], rec.pressure_Pa[[0, 2000, 4000]])
    rmse = float(fitted.rmse_Pa()[0])
    assert np.isfinite(rmse) and rmse == pytest.approx(model.rmse_Pa_, rel=1e-12)
    assert rmse < 0.1 * float(published.rmse_Pa()[0])
    # a first-order model cannot follow choked filling: well above the sensor noise
    assert rmse > 3 * estimate_noise_std(rec.pressure_Pa)
    assert model.frozen_ == ("c5", "c6")  # fixed piston: no velocity, one position
    target, _, _ = tassa_coefficients(np.linspace(-1, 1, 41), 0.5, 0.0, model.params_)
    assert np.all(np.diff(target) >= 0)  # bounds c3, c4 >= 0: no fold-back beyond the data
    assert np.array_equal(model.params_[[5, 6]], np.array(PUBLISHED_PARAMETERS)[[5, 6]])


# ---------------------------------------------------------------- contract and errors
def test_init_only_stores():
    model = TassaModel(horizon_s=1.0, max_nfev=5)
    assert (model.horizon_s, model.max_nfev) == (1.0, 5)
    assert not [k for k in vars(model) if k.endswith("_")]
    with pytest.raises(NotFittedError, match="not fitted"):
        model.predict_windows(_synthetic(0, duration_s=3.0)[0])


T = np.arange(11) / 1000.0
U = np.zeros(11)
X = np.full(11, 0.01)


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(params=np.ones(9)), ParameterError, r"shape \(10,\) or \(B, 10\)"),
    (dict(params=np.r_[PUBLISHED_PARAMETERS[:3], np.nan, PUBLISHED_PARAMETERS[4:]]),
     ParameterError, "c3 .* must be finite"),
    (dict(params={"c0": 1.0}), ParameterError, "missing"),
    (dict(time_s=T[::-1]), ValueError, "time_s must be strictly increasing"),
    (dict(command_V=U[:5]), ValueError, "command_V must be 1-D with 11 samples"),
    (dict(position_m=np.r_[X[:-1], np.inf]), ValueError, r"position_m\[10\]"),
    (dict(starts=[8]), ValueError, r"starts\[0\] = 8 is outside 0..6"),
    (dict(starts=[0.0]), ValueError, "starts must be a 1-D array of sample indices"),
    (dict(length=1), ValueError, "length must be an integer >= 2"),
    (dict(p0_Pa=[1e5, 2e5]), ValueError, "p0_Pa must be 1-D with 1 samples"),
    (dict(p0_Pa=[-3.0]), ValueError, "absolute and must be > 0 Pa"),
    (dict(stroke_m=0.0), ValueError, "stroke_m must be a finite number > 0"),
])
def test_simulator_rejects_bad_input_naming_the_argument(kwargs, error, match):
    args = dict(params=PUBLISHED_PARAMETERS, time_s=T, command_V=U, position_m=X, starts=[0],
                length=5, p0_Pa=[2e5], stroke_m=STROKE)
    args.update(kwargs)
    stroke = args.pop("stroke_m")
    with pytest.raises(error, match=match):
        simulate_windows(**args, stroke_m=stroke)


@pytest.mark.parametrize("make, recordings, error, match", [
    (lambda: TassaModel(), [], ValueError, "recordings is empty"),
    (lambda: TassaModel(), ["run.csv"], TypeError, r"recordings\[0\] is a str"),
    (lambda: TassaModel(), "run.csv", TypeError, "must be a Recording or a sequence"),
    (lambda: TassaModel(horizon_s=-1.0), None, ValueError, r"horizon_s=...\) must be"),
    (lambda: TassaModel(max_nfev=0), None, ValueError, r"max_nfev=...\) must be an integer"),
    (lambda: TassaModel(tr_solver="svd"), None, ValueError, "tr_solver"),
    (lambda: TassaModel(initial_params=np.r_[PUBLISHED_PARAMETERS[:8], 2.0, 0.1]), None,
     ParameterError, r"c8 = 2.0 is outside its fitting bounds"),
    (lambda: TassaModel(horizon_s=5.0), None, ValueError,
     "recording planted.csv: horizon 5.0 s is longer than the recording"),
])
def test_fit_rejects_bad_input_with_a_clear_message(make, recordings, error, match):
    if recordings is None:
        rec, _ = _synthetic(0, duration_s=3.0)
        object.__setattr__(rec, "source", "planted.csv")
        recordings = [rec]
    with pytest.raises(error, match=match):
        make().fit(recordings)
