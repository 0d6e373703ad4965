"""The public face (``import pneubayes as pb``) and identification in memory."""

from __future__ import annotations

import json

import numpy as np
import pytest

import pneubayes as pb
from pneubayes.bench.bench import BenchConfig, run_bench


def test_every_public_name_resolves_and_unknown_names_are_refused():
    for name in pb.__all__:
        assert getattr(pb, name) is not None, name
    assert {"Model", "Rig", "read_recording", "simulate", "identify", "Discovery",
            "PressurePredictor", "FitSettings", "SamplerSettings", "SolverConfig",
            "DiscoverySettings", "effects_from_names", "discover", "DiscoveryResult",
            "write_discovery"} <= set(pb.__all__)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        pb.nope  # noqa: B018


@pytest.fixture(scope="module")
def small_bench(tmp_path_factory):
    """Two 3-s fixed-volume recordings of the paper's model with its orifice leak."""
    out = tmp_path_factory.mktemp("bench")
    res = run_bench(BenchConfig("AIR37", "valve1", pb.effects_from_names(["cylinder_leak"]),
                                protocol="fixed", duration_s=3.0, seed=4,
                                positions=(0.3, 0.8), ranges_V=(5.0,)), out)
    return [pb.read_recording(p) for p in res.recordings], res


def test_identify_in_memory_equals_the_run_folder(small_bench, tmp_path):
    recs, res = small_bench
    model = pb.Model(pb.effects_from_names(["cylinder_leak"]))
    settings = pb.FitSettings(refine_max_nfev=15)
    fit = pb.identify(recs, model, settings, method="refine")
    assert isinstance(fit, pb.Fit) and fit.method == "refine" and fit.posterior is None
    assert set(fit.params) == set(model.parameter_names)
    assert fit.summary["refined"]["rmse_Pa"] < fit.summary["refined"]["start_rmse_Pa"]
    assert fit.noise_floor_Pa == fit.summary["noise_floor_Pa"] > 0
    assert len(fit.recordings) == 2
    with pytest.raises(ValueError, match="no posterior"):
        fit.draws(4, np.random.default_rng(0))
    # the run folder holds exactly what the object holds
    pb.write_fit(fit, tmp_path / "run")
    loaded_model, loaded = pb.Model.load_card(tmp_path / "run" / "model.json")
    assert loaded_model == model and loaded == pytest.approx(fit.params, rel=1e-12)
    card = json.loads((tmp_path / "run" / "model.json").read_text())
    assert card["fit"]["estimate"] == "refine"
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["refined"]["rmse_Pa"] == pytest.approx(fit.summary["refined"]["rmse_Pa"])
    # no checkpoint was asked for: nothing else was written anywhere near the recordings
    assert not (res.truth_path.parent / "chain.h5").exists()


def test_identify_rejects_an_unknown_method(small_bench):
    recs, _ = small_bench
    with pytest.raises(ValueError, match="method must be one of"):
        pb.identify(recs, pb.Model(), pb.FitSettings(), method="bayes")


def test_posterior_in_memory_gives_draws_and_a_predictor(small_bench, tmp_path):
    recs, _ = small_bench
    model = pb.Model(pb.effects_from_names(["cylinder_leak"]))
    settings = pb.FitSettings(refine_max_nfev=15,
                              sampler=pb.SamplerSettings(n_walkers=32, max_steps=40, seed=2))
    fit = pb.identify(recs, model, settings, checkpoint_dir=tmp_path / "ckpt")
    assert fit.posterior is not None and (tmp_path / "ckpt" / "chain.h5").exists()
    draws, noise = fit.draws(16, np.random.default_rng(0))
    assert draws.shape == (16, model.n_parameters) and noise.shape == (16, 2)
    api = fit.predictor(recs[0].rig(), pb.SolverConfig.standard(), 16,
                        np.random.default_rng(0))
    q = api.predict(3e5, np.array([np.full(40, 3.0), np.full(40, -3.0)]), 0.01, 0.005)
    assert q.shape == (2, 3, 41) and q[0, 1, -1] > q[1, 1, -1]
    # written and read back, the fit gives the same draws for the same seed
    pb.write_fit(fit, tmp_path / "run", figures=False)
    back = pb.read_fit(tmp_path / "run")
    assert back.method == "mcmc" and back.model == model and back.recordings == ()
    assert back.params == pytest.approx(fit.params, rel=1e-12)
    assert back.preparation == fit.preparation
    again, noise_again = back.draws(16, np.random.default_rng(0))
    assert np.array_equal(again, draws) and np.array_equal(noise_again, noise)
    # a posterior of another fit beside this card is refused
    other = dict(fit.params, dead_volume_m3=1.01 * fit.params["dead_volume_m3"])
    model.save_card(other, tmp_path / "run" / "model.json")
    with pytest.raises(ValueError, match="another model card"):
        pb.read_fit(tmp_path / "run")
