"""ArrayFROLS against pysindy's FROLS: the same selections, coefficients and error
reductions (up to summation order), with one target or several, with and without the
L0 penalty; and pysindy's error on an empty column."""

import numpy as np
import pysindy as ps
import pytest

from pneubayes.discovery.openform.frols import ArrayFROLS


def _library(seed, n=600, m=60, targets=1):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, m))
    x[:, 1] = 0.99 * x[:, 0] + 0.01 * x[:, 2]  # a near-copy: the greedy order matters
    y = np.stack([0.7 * x[:, 5] - 0.3 * x[:, 17] + 0.1 * x[:, 1]
                  + 0.05 * rng.normal(size=n) for _ in range(targets)], axis=1)
    y[:, -1] += 0.4 * x[:, 9]
    return x / np.sqrt(n), (y[:, 0] if targets == 1 else y) / np.sqrt(n)


@pytest.mark.parametrize("targets, kappa, max_iter", [(1, None, 6), (2, None, 4),
                                                      (1, 1e-3, 8)])
def test_array_frols_is_pysindys_frols(targets, kappa, max_iter):
    for seed in range(3):
        x, y = _library(seed, targets=targets)
        kw = dict(max_iter=max_iter, alpha=1e-6, kappa=kappa, unbias=False)
        ref = ps.FROLS(**kw).fit(x, y)
        new = ArrayFROLS(**kw).fit(x, y)
        assert len(new.history_) == len(ref.history_)
        for h_new, h_ref in zip(new.history_, ref.history_):
            np.testing.assert_array_equal(h_new != 0, h_ref != 0)
            np.testing.assert_allclose(h_new, h_ref, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(new.ERR_global, ref.ERR_global, rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose(new.coef_, ref.coef_, rtol=1e-9, atol=1e-12)
        assert new.initial_guess is None  # the fit leaves its parameters as it found them


def test_an_empty_column_raises_as_pysindy_does():
    x, y = _library(0)
    x[:, 3] = 0.0
    for opt in (ps.FROLS, ArrayFROLS):
        with pytest.raises(ValueError, match="linearly dependent"):
            opt(max_iter=4, alpha=1e-6, unbias=False).fit(x, y)
