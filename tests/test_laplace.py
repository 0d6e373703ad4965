"""The Laplace approximation of the window posterior (pneubayes.inference.laplace)."""

import numpy as np
import pytest
from gaussian_target import IDENT, GaussianTarget, information_of, random_covariance

from pneubayes.bench.bench import BenchConfig, run_bench
from pneubayes.inference.importance import importance_check
from pneubayes.inference.laplace import (
    LaplaceIdentification,
    laplace_approximation,
    truncated_draws,
)
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


def test_laplace_of_a_gaussian_is_the_gaussian_and_its_draws_follow_it():
    """On an exactly Gaussian target 1.5x wider than the information given, and rotated
    from it, the centre is the mean and the covariance the target's (second differences
    are exact on a quadratic); 20,000 draws have its mean and covariance to sampling
    error, the nuisance coordinate is uniform over its range, and a bound that cuts the
    Gaussian truncates the draws instead of clipping them."""
    rng = np.random.default_rng(5)
    laplace = random_covariance(rng, 4.0)
    ident, info = IDENT, information_of(laplace)
    q = np.linalg.qr(np.eye(4) + 0.2 * rng.normal(size=(4, 4)))[0]
    true_cov = 1.5 * q @ laplace @ q.T
    mean = np.array([1.0, -2.0, 0.0, 0.5, 3.0])
    target = GaussianTarget(mean, np.linalg.inv(true_cov))
    start = mean.copy()
    start[ident] += np.array([2.0, -1.0, 1.5, -2.0]) * np.sqrt(np.diag(true_cov))
    fit = laplace_approximation(target, start, info, 3)
    assert fit.step_sd == 2.0 and fit.rounds == 0  # the information within 4x of it
    assert fit.shift_sd == 0.0 and fit.bounded == ()
    idc, cov = fit.ident, fit.cov_z
    assert list(idc) == ident
    np.testing.assert_allclose(fit.x_centre[ident], mean[ident], atol=1e-6)
    np.testing.assert_array_equal(fit.mean_z, fit.z_centre)
    np.testing.assert_allclose(cov, true_cov, rtol=1e-6, atol=1e-9)
    assert np.all(fit.eigenvalues > 0)
    assert fit.log_posterior[0] == pytest.approx(0.0, abs=1e-9)
    zc = fit.z_centre
    z = truncated_draws(target, zc, idc, cov, np.random.default_rng(0), 20_000)
    assert z.shape == (20_000, 5)
    np.testing.assert_allclose(np.mean(z[:, ident], axis=0), mean[ident],
                               atol=4 * np.sqrt(np.diag(true_cov) / 20_000).max())
    d = np.diag(true_cov)
    se = np.sqrt((np.outer(d, d) + true_cov**2) / 20_000)  # a sample covariance's SE
    assert np.all(np.abs(np.cov(z[:, ident].T) - true_cov) < 4 * se)
    assert abs(np.mean(z[:, 2])) < 2.0 and np.ptp(z[:, 2]) > 190.0  # U(-100, 100)
    # an information 10^4 x too large (least squares on correlated misfit): the steps of 2
    # of its SDs see a curvature 10^-4 of theirs, and the Hessian is taken again in
    # coordinates whitened by the first: exact again (one round more)
    far = laplace_approximation(target, mean, 1e4 * info, 0)
    assert far.rounds == 1 and np.all(np.abs(far.eigenvalues - 1.0) < 1e-6)
    np.testing.assert_allclose(far.cov_z, true_cov, rtol=1e-6, atol=1e-9)
    # a bound 0.6 SDs of the information's from the mean of coordinate 4 leaves points 2
    # and 1 SDs out there: the differences take 0.5-SD steps, exact on the quadratic
    near = GaussianTarget(mean, np.linalg.inv(true_cov))
    near.bounds = (np.full(5, -100.0),
                   np.r_[np.full(4, 100.0), mean[4] + 0.6 * np.sqrt(laplace[3, 3])])
    near_fit = laplace_approximation(near, start, info, 3)
    assert near_fit.step_sd == 0.5 and np.all(near_fit.eigenvalues > 0)
    assert near_fit.bounded == ()
    np.testing.assert_allclose(near_fit.cov_z, true_cov, rtol=1e-6, atol=1e-9)
    # the importance check: the draws' density is the target's (constant ratios), one
    # with a tenth of the variance misses mass (Pareto k past the threshold), one 1.5 x
    # too wide passes with a smaller effective sample
    exact = importance_check(target, z[:200], fit.mean_z, fit.ident, fit.cov_z)
    assert exact["pareto_k"] is None and exact["ess_fraction"] == 1.0
    for scale, reliable in ((0.1, False), (1.5, True)):
        zs = truncated_draws(target, zc, idc, scale * cov, np.random.default_rng(2), 400)
        check = importance_check(target, zs, zc, idc, scale * cov)
        assert (check["pareto_k"] <= check["khat_threshold"]) == reliable
        assert check["ess_fraction"] < 0.9
    # a bound at the mean of coordinate 0: half the Gaussian, none of it piled on the bound
    target.bounds = (np.array([mean[0], -100, -100, -100, -100.0]), np.full(5, 100.0))
    z = truncated_draws(target, zc, idc, cov, np.random.default_rng(1), 4000)
    assert np.all(z[:, 0] >= mean[0]) and np.mean(z[:, 0] - mean[0] < 1e-3) < 0.01



def test_the_centring_stops_when_a_step_would_gain_little_and_its_hessian_is_reused():
    """On a Gaussian target the first Newton step lands on the mode (the Hessian is
    exact); later iterations take the slope alone with that Hessian (2 k points, not
    2 k + k (k - 1) / 2) and predict a rise of ~0 nats. With a tolerance the centring
    stops at the first such slope; started at the mode it stops at once, and the
    approximation takes the Hessian the centring just took there: one stencil in all.
    The mean and covariance are the same either way."""
    rng = np.random.default_rng(5)
    laplace = random_covariance(rng, 4.0)
    info = information_of(laplace)
    q = np.linalg.qr(np.eye(4) + 0.2 * rng.normal(size=(4, 4)))[0]
    true_cov = 1.5 * q @ laplace @ q.T
    mean = np.array([1.0, -2.0, 0.0, 0.5, 3.0])
    off = mean.copy()
    off[IDENT] += np.array([1.0, -0.5, 0.5, -1.0]) * np.sqrt(np.diag(true_cov))
    fits, counts = {}, {}
    for start, tol in ((off, 0.0), (off, 0.01), (mean, 0.01)):
        target = GaussianTarget(mean, np.linalg.inv(true_cov))
        calls = []
        evaluate = target.log_prob_sampling
        target.log_prob_sampling = lambda z, evaluate=evaluate, calls=calls: (
            calls.append(len(z)) or evaluate(z))
        key = ("off" if start is off else "mode", tol)
        fits[key] = laplace_approximation(target, start, info, 3, tol)
        # batches: a Hessian's stencil (14 points), a slope's (8)
        counts[key] = (calls.count(2 * 4 + 4 * 3 // 2), calls.count(2 * 4))
    assert counts == {("off", 0.0): (2, 2), ("off", 0.01): (2, 1), ("mode", 0.01): (1, 0)}
    rises = fits["off", 0.01].centre_rises
    assert len(rises) == 2 and rises[0] > 0.1 and rises[1] < 1e-9
    for key in (("off", 0.01), ("mode", 0.01)):
        np.testing.assert_allclose(fits[key].x_centre, fits["off", 0.0].x_centre, atol=1e-9)
        np.testing.assert_allclose(fits[key].cov_z, fits["off", 0.0].cov_z, rtol=1e-9,
                                   atol=1e-12)
    with pytest.raises(ValueError, match="tolerance_nats"):
        laplace_approximation(target, off, info, 3, -1.0)


def test_laplace_with_its_mode_on_a_prior_bound_is_the_cut_gaussian():
    """A Gaussian whose mean is 1 SD beyond the upper bound of coordinate 4 and 0.5 SD
    beyond the lower bound of coordinate 0: the posterior's mode is on both bounds, no
    step of the differences fits inside at it, so the Hessian and slope are taken at a
    point moved inside; on a quadratic that is exact: the covariance is the target's and
    the Gaussian's mean its mean, beyond the bounds. The draws are the Gaussian cut at
    the bounds: coordinate 0's marginal is the truncated normal (mean to 4 SEs, no draw
    outside), and a mean 5 SDs beyond a bound (1 in 3.5 million inside) is an error that
    names emcee. Before the bound-aware design the Hessian could not be taken here."""
    from scipy.stats import truncnorm

    cov4 = random_covariance(np.random.default_rng(7), 2.0)
    ident, info = IDENT, information_of(cov4)
    mean = np.array([1.0, -2.0, 0.0, 0.5, 3.0])
    sd = np.sqrt(np.diag(cov4))
    target = GaussianTarget(mean, np.linalg.inv(cov4))
    lo0, hi4 = mean[0] + 0.5 * sd[0], mean[4] - 1.0 * sd[3]
    target.bounds = (np.r_[lo0, np.full(4, -100.0)], np.r_[np.full(4, 100.0), hi4])
    start = np.r_[lo0, mean[1:4], hi4]  # on both bounds (clipped just inside)
    fit = laplace_approximation(target, start, info, 3)
    assert fit.bounded == ("p0", "p4") and fit.shift_sd > 0 and fit.step_sd == 2.0
    assert np.all(fit.eigenvalues > 0)
    np.testing.assert_allclose(fit.cov_z, cov4, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fit.mean_z[ident], mean[ident], atol=1e-6)
    assert fit.x_centre[0] >= lo0 and fit.x_centre[4] <= hi4
    n = 20_000
    z = truncated_draws(target, fit.mean_z, fit.ident, fit.cov_z,
                        np.random.default_rng(3), n)
    assert np.all(z[:, 0] >= lo0) and np.all(z[:, 4] <= hi4)
    # the marginal of coordinate 0 given the other cut (a 2-D cut): check the
    # 1-D cut alone, by a target cut only there
    one = GaussianTarget(mean, np.linalg.inv(cov4))
    one.bounds = (np.r_[lo0, np.full(4, -100.0)], np.full(5, 100.0))
    z1 = truncated_draws(one, fit.mean_z, fit.ident, fit.cov_z, np.random.default_rng(4), n)
    cut = truncnorm(0.5, np.inf, loc=mean[0], scale=sd[0])
    assert abs(np.mean(z1[:, 0]) - cut.mean()) < 4 * cut.std() / np.sqrt(n)
    assert abs(np.std(z1[:, 0]) - cut.std()) < 4 * cut.std() / np.sqrt(2 * n)
    beyond = fit.mean_z.copy()
    beyond[0] = lo0 - 5.0 * sd[0]
    with pytest.raises(FloatingPointError, match="use emcee"):
        truncated_draws(one, beyond, fit.ident, fit.cov_z, np.random.default_rng(5), 1000)


def test_laplace_posterior_on_the_bench_covers_the_planted_leak(prn_leak_bench):
    """From the refined point of two bench recordings with a planted orifice leak: every
    draw inside the priors, the summary's keys and the 4 chains of the InferenceData;
    the 90 % intervals cover the planted leak area and dead volume and at least 10 of
    the 12 parameters; and the window likelihood's curvature at its centre, whitened by
    the least squares' Fisher information, has eigenvalues within a factor of 2 of 1
    (two independent computations of one curvature: white noise here)."""
    recs, model, truth = prn_leak_bench
    solver = SolverConfig.standard()
    data = WindowSet(recs[:2], 2.0, 2.0)
    ref = TrajectoryRefiner(model, solver).fit(data, truth)
    lap = LaplaceIdentification(model, solver, n_draws=2000, check_draws=200,
                                centre_iterations=2, seed=4,
                                max_solver_jitter_nats=0.3, max_solver_tightenings=2
                                ).fit(data, ref.params_, ref.information_)
    lo, hi = model.bounds
    ms = lap.model_samples()
    assert ms.shape == (2000, model.n_parameters)
    assert np.all((ms >= lo) & (ms <= hi))
    s = lap.summary()
    assert set(s) == set(model.parameter_names) | {"noise_scale_Pa", "noise_ar1"}
    covered = {n for n in model.parameter_names
               if s[n]["q05"] <= truth[n] <= s[n]["q95"]}
    assert {"leak_area_m2", "dead_volume_m3"} <= covered and len(covered) >= 10
    lam = np.array(lap.diagnostics_["hessian_eigenvalues"])
    assert np.all((lam > 0.5) & (lam < 2.0)) and lap.converged_
    idata = lap.inference_data({"seed": 4})
    assert idata.posterior["leak_area_m2"].shape == (4, 500)
    assert lap.diagnostics_["method"] == "laplace" and lap.diagnostics_["draws"] == 2000
    check = lap.diagnostics_["importance_check"]
    assert check["draws"] == 200 and check["pareto_k"] <= check["khat_threshold"]


def test_discover_with_a_laplace_posterior_writes_one_predict_reads(tmp_path, capsys):
    """``pneubayes discover --posterior laplace --set rounds.max_effects=0`` (the base
    model and its posterior; no search round, so no disagreement map to draw or tabulate):
    discovery.json records the method, posterior.nc holds 4 chains of its draws, the
    report names the approximation, and ``pneubayes predict`` reads the run folder's
    posterior as it reads emcee's; an unknown method is a usage error."""
    import json

    from pneubayes.cli import main as cli_main

    cfg = BenchConfig("AIR37", "valve1", (), protocol="fixed", duration_s=14.0, seed=2,
                      positions=(0.5, 0.9), ranges_V=(5.0, 0.5))
    paths = [str(p) for p in run_bench(cfg, tmp_path / "bench").recordings]
    run = tmp_path / "run"
    assert cli_main(["discover", *paths, "--out", str(run), "--posterior", "laplace",
                     "--set", "rounds.max_effects=0", "--no-figures", "-q"]) == 0
    doc = json.loads((run / "discovery.json").read_text())
    assert doc["posterior"]["method"] == "laplace" and doc["posterior"]["steps"] == 0
    assert doc["settings"]["posterior"]["method"] == "laplace"
    assert "Laplace approximation" in (run / "report.md").read_text()
    from pneubayes.inference.sampler import arviz

    idata = arviz().from_netcdf(run / "posterior.nc")
    assert idata.posterior["dead_volume_m3"].shape == (4, 1000)
    out = tmp_path / "pred.csv"
    assert cli_main(["predict", str(run), paths[0], "--out", str(out), "--draws", "20",
                     "--no-figure"]) == 0
    assert out.is_file()
    capsys.readouterr()
    with pytest.raises(SystemExit):
        cli_main(["discover", *paths, "--out", str(tmp_path / "bad"), "--posterior",
                  "gibbs"])
    assert "invalid choice: 'gibbs'" in capsys.readouterr().err


def test_fit_method_laplace_writes_a_run_folder_predict_reads(prn_leak_bench, tmp_path, capsys):
    """``pneubayes fit --method laplace``: model.json is the draws' median and says so,
    summary.json records the method's own diagnostics (no chain: 0 steps; the negative
    Hessian's eigenvalues; concave at the mode), posterior.nc holds the draws, and
    ``pneubayes predict`` reads the run folder."""
    import json

    from pneubayes.cli import main as cli_main

    recs, model, truth = prn_leak_bench
    paths = [str(r.source) for r in recs]
    run = tmp_path / "run"
    assert cli_main(["fit", *paths[:2], "--method", "laplace",
                     "--out", str(run), "--seed", "3", "-q", "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert ("Laplace, 4000 draws, concave at the mode and its draws reliable True" in out
            and "R-hat" not in out)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["method"] == "laplace" and summary["steps"] == 0
    assert summary["converged"] and summary["non_concave_directions"] == 0
    assert summary["importance_check"]["draws"] == 200
    assert all(v > 0 for v in summary["hessian_eigenvalues"])
    fitted, median = Model.load_card(run / "model.json")
    card = json.loads((run / "model.json").read_text())
    assert card["fit"]["estimate"] == "posterior median"
    assert card["fit"]["posterior_method"] == "laplace"
    assert median["dead_volume_m3"] == pytest.approx(
        summary["parameters"]["dead_volume_m3"]["median"])
    s = summary["parameters"]["leak_area_m2"]
    assert s["q05"] <= truth["leak_area_m2"] <= s["q95"]
    out = tmp_path / "pred.csv"
    assert cli_main(["predict", str(run), paths[1], "--out", str(out), "--draws", "20",
                     "--no-figure"]) == 0
    assert out.is_file()
