"""The calibrated k-step prediction-error band (pneubayes.inference.error_band)."""

import numpy as np
import pytest
from scipy import stats

from pneubayes.inference.error_band import PredictionErrorBand, recording_errors
from pneubayes.simulation import SolverConfig

DT = 0.005
L = 11


def _planted(seed=0, n=4000):
    """Half the windows hold (error sd 1 kPa at every step), half ramp at 1 MPa/s
    (error sd 10 kPa): predictions and measurements (W, L)."""
    rng = np.random.default_rng(seed)
    fast = np.arange(n) % 2 == 1
    pred = np.full((n, L), 3e5)
    pred[fast] += 1e6 * DT * np.arange(L)
    sd = np.where(fast, 10e3, 1e3)[:, None]
    err = rng.normal(0.0, 1.0, (n, L)) * sd
    err[:, 0] = 0.0
    return pred, pred + err


def test_planted_quantiles_are_recovered_per_rate():
    pred, meas = _planted()
    band = PredictionErrorBand(0.95, rate_bins=2, min_count=30).fit(pred, meas, DT)
    z = stats.norm.ppf(0.95)
    slow = band.margin(pred[0])
    fast = band.margin(pred[1])
    assert slow[0] == 0.0 and fast[0] == 0.0  # the measured start
    # 2000 errors a cell: the 95 % quantile's sampling error is about 5 %
    assert np.allclose(slow[1:], z * 1e3, rtol=0.12)
    assert np.allclose(fast[1:], z * 10e3, rtol=0.12)
    # a flat prediction held under a fast one: each gets its own rate's margin
    both = band.margin(pred[:2])
    assert np.array_equal(both, np.stack([slow, fast]))


def test_margin_is_monotone_non_negative_and_zero_at_the_start():
    rng = np.random.default_rng(1)
    pred = 3e5 + np.cumsum(rng.normal(0, 2e3, (3000, L)), axis=1)
    meas = pred - 5e3 + rng.normal(0, 1e3, pred.shape)  # over-predicting everywhere
    band = PredictionErrorBand(0.95, rate_bins=4).fit(pred, meas, DT)
    m = band.margin_Pa_
    assert m.shape == (L, 4)
    assert np.all(m >= 0.0) and np.all(m[0] == 0.0)
    assert np.all(np.diff(m, axis=0) >= 0) and np.all(np.diff(m, axis=1) >= 0)
    assert np.all(m[1:] == 0.0)  # the model over-predicts: the limit is not loosened


def test_thin_cells_take_a_neighbouring_bins_margin():
    pred, meas = _planted(n=200)
    band = PredictionErrorBand(0.95, rate_bins=2, min_count=150).fit(pred, meas, DT)
    # 100 windows a cell < 150: every step pooled, no NaN
    assert np.all(np.isfinite(band.margin_Pa_))
    assert band.count_[1].sum() == 200


def test_faster_than_calibrated_gets_the_fastest_bins_margin():
    pred, meas = _planted()
    band = PredictionErrorBand(0.95, rate_bins=2).fit(pred, meas, DT)
    steep = 3e5 + 1e8 * DT * np.arange(L)
    assert np.array_equal(band.margin(steep), band.margin(pred[1]))


@pytest.mark.parametrize("kwargs, match", [
    ({"quantile": 0.4}, "quantile"),
    ({"quantile": 1.0}, "quantile"),
    ({"rate_bins": 0}, "rate_bins"),
    ({"min_count": 0}, "min_count"),
])
def test_bad_settings_are_named(kwargs, match):
    pred, meas = _planted(n=100)
    with pytest.raises(ValueError, match=match):
        PredictionErrorBand(**kwargs).fit(pred, meas, DT)


def test_bad_inputs_are_named():
    pred, meas = _planted(n=100)
    band = PredictionErrorBand()
    with pytest.raises(RuntimeError, match="not fitted"):
        band.margin(pred)
    with pytest.raises(ValueError, match=r"\(W, L\)"):
        band.fit(pred, meas[:, :-1], DT)
    bad = meas.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="finite"):
        band.fit(pred, bad, DT)
    with pytest.raises(ValueError, match="dt_s"):
        band.fit(pred, meas, 0.0)
    with pytest.raises(ValueError, match="min_count"):
        PredictionErrorBand(min_count=500).fit(pred, meas, DT)
    band.fit(pred, meas, DT)
    with pytest.raises(ValueError, match="longer than the calibrated"):
        band.margin(np.zeros(L + 1))


def test_recording_errors_band_is_noise_level_for_the_true_model(prn_leak_bench):
    recs, model, truth = prn_leak_bench
    solver = SolverConfig.standard()
    pred, meas = recording_errors(model, model.vector(truth), recs, 20, DT, DT, solver)
    assert pred.shape == meas.shape and pred.shape[1] == 21
    assert np.array_equal(pred[:, 0], meas[:, 0])  # started at the measured pressure
    true_band = PredictionErrorBand(0.95).fit(pred, meas, DT)
    # sensor noise 500 Pa: its 95 % quantile is 0.8 kPa; the bench's filter lags edges
    assert true_band.margin_Pa_[1:, 0].max() < 2.5e3
    # a leak four times the true one: the pressure is under-predicted, more so the longer
    # the prediction runs, so the upper band grows with the horizon
    leaky = {**truth, "leak_area_m2": 4 * truth["leak_area_m2"]}
    pred_w, meas_w = recording_errors(model, model.vector(leaky), recs, 20, DT, DT, solver)
    wrong_band = PredictionErrorBand(0.95).fit(pred_w, meas_w, DT)
    assert wrong_band.margin_Pa_[-1].max() > 2 * true_band.margin_Pa_[-1].max()
    with pytest.raises(ValueError, match="whole number"):
        recording_errors(model, model.vector(truth), recs, 20, 0.0055, DT, solver)


def test_partial_fit_refits_on_the_old_and_the_new_windows():
    pred, meas = _planted()
    whole = PredictionErrorBand(0.95, rate_bins=2).fit(pred, meas, DT)
    part = PredictionErrorBand(0.95, rate_bins=2).fit(pred[:3000], meas[:3000], DT)
    part.partial_fit(pred[3000:], meas[3000:])
    assert np.array_equal(part.margin_Pa_, whole.margin_Pa_)
    assert part.predicted_Pa_.shape == pred.shape
    fresh = PredictionErrorBand(0.95, rate_bins=2).partial_fit(pred, meas, DT)
    assert np.array_equal(fresh.margin_Pa_, whole.margin_Pa_)
    with pytest.raises(ValueError, match="needs dt_s"):
        PredictionErrorBand().partial_fit(pred, meas)
    with pytest.raises(ValueError, match="differs"):
        part.partial_fit(pred[:10], meas[:10], 2 * DT)
    with pytest.raises(ValueError, match=r"\(W, 11\)"):
        part.partial_fit(pred[:10, :5], meas[:10, :5])
