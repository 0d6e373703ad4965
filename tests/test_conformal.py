"""The online conformal band: the model's band until predictions complete, then the run's
own errors; it never scores a prediction before its outcome is measured."""

import numpy as np
import pytest

from pneubayes.inference.conformal import OnlineConformalBand


def _stream(band, errors_scale, n_pred, h=20, every=5, rng=None, start=0):
    """Predictions every ``every`` samples of ``h`` steps, of a signal whose errors
    against the predictive mean have standard deviation ``errors_scale`` x the model's
    scale (1 Pa); returns the coverage of each prediction."""
    rng = rng or np.random.default_rng(0)
    n = start + every * n_pred + h + 1
    y = np.zeros(n)
    scale = np.ones(h)
    cover = []
    for i in range(n_pred):
        k = start + every * i
        band.observe(k, y[:k + 1])  # only what is measured by now
        # the outcome, drawn now but written to y only as it is measured
        e = rng.normal(0.0, errors_scale(k), size=h)
        lo, hi = band.predict(k, np.zeros(h), scale)
        y[k + 1:k + h + 1] = np.where(y[k + 1:k + h + 1] == 0.0, e, y[k + 1:k + h + 1])
        cover.append(np.mean((y[k + 1:k + h + 1] >= lo) & (y[k + 1:k + h + 1] <= hi)))
    return np.array(cover)


def test_before_any_prediction_completes_the_band_is_the_models():
    band = OnlineConformalBand(coverage=0.9, min_predictions=3)
    lo, hi = band.interval(np.array([1e5, 2e5]), np.array([10.0, 20.0]))
    assert np.allclose(hi - lo, 2 * 1.6448536269514722 * np.array([10.0, 20.0]))
    band.predict(0, np.zeros(4), np.ones(4))
    assert band.observe(3, np.zeros(10)) == 0  # its last sample (4) is not measured yet
    assert band.observe(4, np.zeros(10)) == 1 and band.n_completed_ == 1


def test_errors_larger_than_the_model_expects_are_covered_at_the_target():
    # the model's band alone covers ~40 % of errors three times its scale
    model_only = _stream(OnlineConformalBand(min_predictions=10**6), lambda k: 3.0, 200)
    assert 0.3 < model_only[20:].mean() < 0.5
    cover = _stream(OnlineConformalBand(coverage=0.9), lambda k: 3.0, 200)
    assert 0.85 <= cover[20:].mean() <= 0.95


def test_the_level_follows_errors_that_grow_mid_run():
    band = OnlineConformalBand(coverage=0.9, step=0.05, memory=40)
    cover = _stream(band, lambda k: 1.0 if k < 500 else 4.0, 200)
    # right after the change the band under-covers; adaptive conformal inference and
    # the memory bring it back
    assert cover[100:104].mean() < 0.8
    assert 0.8 <= cover[150:].mean() <= 0.97


@pytest.mark.parametrize("kw, why", [({"coverage": 1.0}, "coverage"),
                                     ({"min_predictions": 0}, "min_predictions"),
                                     ({"step": -1.0}, "step"), ({"memory": 0}, "memory")])
def test_bad_settings_are_refused(kw, why):
    with pytest.raises(ValueError, match=why):
        OnlineConformalBand(**kw)
