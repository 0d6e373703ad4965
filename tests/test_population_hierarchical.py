"""The hierarchical population (pneubayes.inference.hierarchical): planted recovery on
synthetic per-run Gaussians, the runs' integral against its closed form, bad input."""

import numpy as np
import pytest
from scipy import stats

from pneubayes.inference.hierarchical import (
    HierarchicalPopulation,
    PredictivePrior,
    marginal_log_likelihood,
)
from pneubayes.model import Model

MU = np.array([np.log(2.4e-7), np.log(1.0e6)])
TAU = np.array([0.3, 0.8])


def planted(n_runs=10, run_sd=0.1, seed=3):
    """Per-run log values drawn from the planted population, each measured with a
    Gaussian of SD ``run_sd`` (the stage-1 result a fit would give)."""
    rng = np.random.default_rng(seed)
    z = MU + TAU * rng.normal(size=(n_runs, 2))
    sd = np.full((n_runs, 2), run_sd)
    return z + sd * rng.normal(size=z.shape), sd, z


@pytest.fixture(scope="module")
def fitted():
    m, sd, z = planted()
    hp = HierarchicalPopulation(["c", "r"], n_walkers=16, n_steps=2000, n_chains=4,
                                seed=1).fit(m, log_sd=sd)
    return hp, z


def test_planted_population_recovered_with_rhat(fitted):
    hp, _ = fitted
    lo_mu, hi_mu = np.quantile(hp.mu_, [0.025, 0.975], axis=0)
    lo_tau, hi_tau = np.quantile(hp.tau_, [0.025, 0.975], axis=0)
    assert np.all((lo_mu < MU) & (MU < hi_mu)), (lo_mu, hi_mu, MU)
    assert np.all((lo_tau < TAU) & (TAU < hi_tau)), (lo_tau, hi_tau, TAU)
    assert max(hp.rhat_.values()) <= 1.01, hp.rhat_
    assert min(hp.ess_.values()) > 200, hp.ess_
    s = hp.summary()
    assert s["c"]["median"]["q05"] < np.exp(MU[0]) < s["c"]["median"]["q95"]
    assert s["r"]["rhat"]["tau"] == hp.rhat_["tau[r]"]


def test_runs_shrunk_towards_population(fitted):
    hp, z = fitted
    # each run's posterior sits near its own value (run SD 0.1 << tau)
    med = np.median(hp.run_draws_, axis=0)
    assert np.max(np.abs(med - z)) < 0.35
    assert np.allclose(hp.run_log_sd_, 0.1)


def test_marginal_likelihood_matches_closed_form():
    rng = np.random.default_rng(0)
    m = rng.normal(size=(3, 2))
    a = rng.normal(size=(3, 2, 2))
    cov = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(2)
    mu = rng.normal(size=(5, 2))
    tau = rng.uniform(0.2, 2.0, size=(5, 2))
    got = marginal_log_likelihood(mu, tau, m, np.linalg.inv(cov))
    want = np.array([sum(stats.multivariate_normal(mu[w], cov[j] + np.diag(tau[w] ** 2))
                         .logpdf(m[j]) for j in range(3)) for w in range(5)])
    # equal up to a constant that depends on the runs' precisions alone
    assert np.allclose(got - want, (got - want)[0])


def test_uninformative_run_direction_is_allowed():
    m, sd, _ = planted(n_runs=4)
    prec = np.einsum("ji,ik->jik", sd ** -2.0, np.eye(2))
    prec[0, 0, 0] = 0.0  # run 0 says nothing of the first quantity
    hp = HierarchicalPopulation(["c", "r"], n_walkers=8, n_steps=300, n_chains=2,
                                seed=0).fit(m, log_precision=prec)
    assert np.all(np.isfinite(hp.mu_)) and np.isinf(hp.run_log_sd_[0, 0])


def test_predictive_prior_for_the_tracker():
    model = Model()
    mu = np.log(2e-6) + 0.05 * np.random.default_rng(0).normal(size=(400, 1))
    tau = np.full((400, 1), 0.3)
    pr = PredictivePrior(model, ["dead_volume_m3"], mu, tau, n_mix=100)
    z = pr.sample(4000, np.random.default_rng(1))
    assert np.all(z >= pr.log_lower) and np.all(z <= pr.log_upper)
    assert np.std(z) == pytest.approx(pr.log_sd[0], rel=0.1)
    assert np.mean(z) == pytest.approx(np.log(2e-6), abs=0.03)
    lp = pr.logpdf(np.array([[np.log(2e-6)], [np.log(2e-6) + 0.9], [np.log(1e-3)]]))
    assert lp[0] > lp[1] > -np.inf and lp[2] == -np.inf
    assert pr.describe()["kind"].startswith("hierarchical")


@pytest.mark.parametrize("kwargs, match", [
    ({"log_mean": [[0.0, 1.0]], "log_sd": [[0.1, 0.1]]}, "log_mean.*at least 2 runs"),
    ({"log_mean": [[0.0, 1.0], [0.5, 1.0]], "log_sd": [[0.1, 0.0], [0.1, 0.1]]},
     "log_sd must be finite and > 0"),
    ({"log_mean": [[0.0, 1.0], [0.5, 1.0]], "log_sd": [[0.1, 0.1, 0.1]] * 2},
     "log_sd has shape"),
    ({"log_mean": [[0.0, 1.0], [0.5, 1.0]], "log_cov": np.zeros((2, 2, 2))},
     "log_cov must be positive definite"),
    ({"log_mean": [[0.0, 1.0], [0.5, 1.0]], "log_precision": np.ones((3, 2, 2))},
     "log_precision has shape"),
    ({"log_mean": [[0.0, 1.0], [0.5, 1.0]]}, "exactly one of log_sd"),
    ({"log_mean": [0.0, 1.0], "log_sd": [0.1, 0.1]}, "log_mean must be"),
])
def test_bad_input_names_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        HierarchicalPopulation(["c", "r"]).fit(**kwargs)


def test_bad_settings_name_the_argument():
    m, sd, _ = planted(n_runs=3)
    with pytest.raises(ValueError, match="names has 1"):
        HierarchicalPopulation(["c"]).fit(m, log_sd=sd)
    with pytest.raises(ValueError, match="tau_prior_scale must be finite and > 0"):
        HierarchicalPopulation(["c", "r"], tau_prior_scale=0.0).fit(m, log_sd=sd)
    with pytest.raises(ValueError, match="mu_prior_sd has shape"):
        HierarchicalPopulation(["c", "r"], mu_prior_sd=[1.0, 1.0, 1.0]).fit(m, log_sd=sd)
    with pytest.raises(ValueError, match="n_walkers must be >= 8"):
        HierarchicalPopulation(["c", "r"], n_walkers=4).fit(m, log_sd=sd)
