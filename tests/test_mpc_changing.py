"""The changing-plant MPC scenario (issue 67 item 4): ``experiments/mpc_tracking.py
--scenario changing_plant``. The fast test runs one seed's loops for a few ticks on a
stand-in posterior (the bench's truth, jittered: no emcee); the slow one the real
quick scenario."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))

import mpc_tracking as m  # noqa: E402


class _StandInFit:
    """What ``run_seed`` reads of a fit: the model, a summary with medians, and draws
    (the truth with a 1 % log jitter) with AR(1) noise factors."""

    def __init__(self, model, truth):
        self.model = model
        self.theta = model.vector(truth)
        self.summary = {"converged": True, "steps": 0, "tau_max": None,
                        "parameters": {k: {"median": float(v), "q05": 0.99 * v,
                                           "q95": 1.01 * v}
                                       for k, v in zip(model.parameter_names, self.theta)}}

    def draws(self, n, rng):
        jitter = np.exp(rng.normal(0.0, 0.01, (n, self.theta.size)))
        return self.theta[None, :] * jitter, np.tile([600.0, 0.5], (n, 1))


def test_changing_plant_runs_and_the_online_tracker_follows_the_volume(tmp_path,
                                                                       monkeypatch):
    from pneubayes.model import Model

    def stand_in(recs, names, fit_dir, seed, quick, log):
        bench = fit_dir.parent / "bench" / "truth.json"
        return _StandInFit(*Model.load_card(bench))

    monkeypatch.setattr(m, "fit_model", stand_in)
    monkeypatch.setattr(m, "RUN_S", 0.4)  # 80 ticks
    monkeypatch.setattr(m, "N_DRAWS", 16)
    monkeypatch.setattr(m, "ONLINE", {**m.ONLINE, "n_particles": 16})
    sc = dict(m.SCENARIOS["changing_plant"])
    sc["change"] = {**sc["change"], "at_s": 0.1}
    monkeypatch.setitem(m.SCENARIOS, "changing_plant", sc)
    result = m.run_seed(0, tmp_path, True, lambda s: None, "changing_plant")
    change = result["change"]
    assert change["true_at_end"] < 0.4 * change["true_before"]
    assert set(result["controllers"]) == set(sc["controllers"])
    q = np.asarray(result["controllers"]["delay_online"]["tracked"]["dead_volume_m3"])
    assert q.shape == (80, 3)
    true = np.asarray(change["true_per_tick"])
    before = abs(np.log(q[19, 1] / true[-1]))  # the tick before the change
    after = abs(np.log(q[-1, 1] / true[-1]))
    assert after < 0.5 * before, (q[19], q[-1], true[-1])
    # the frozen controllers never learn: their draws are the stand-in's throughout
    assert "tracked" not in result["controllers"]["delay_frozen"]
    summary = m.summarise([result], "changing_plant")
    vs = summary["delay_online"]["versus_delay_frozen"]
    assert "paired_excess_integral_difference_Pa_s" in vs
    t = summary["delay_online"]["tracked"][0]
    assert t["change_seen"] == pytest.approx(q[-1, 1] / np.median(q[:20, 1]))
    assert t["change_planted"] == pytest.approx(true[-1] / true[0])
    assert json.loads((tmp_path / "seed0.json").read_text())["scenario"] == "changing_plant"


def test_plant_schedule_steps_then_drifts():
    from pneubayes.effects import effects_from_names
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset

    model = Model(effects_from_names(["cylinder_leak"]))
    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2e-6,
             "leak_area_m2": 1e-8}
    change = {"parameter": "dead_volume_m3", "at_s": 0.01, "factor": 0.5,
              "drift_log_per_s": -1.0}
    theta = m.plant_schedule(model, truth, change, 5)
    j = model.parameter_names.index("dead_volume_m3")
    v = truth["dead_volume_m3"]
    assert theta[:2, j] == pytest.approx([v, v])  # ticks at 0 and 5 ms
    assert theta[2:, j] == pytest.approx(0.5 * v * np.exp(-np.array([0.0, 0.005, 0.01])))
    others = [i for i in range(theta.shape[1]) if i != j]
    assert np.all(theta[:, others] == model.vector(truth)[others])


@pytest.mark.slow
def test_changing_plant_quick_scenario_end_to_end(tmp_path):
    """The real quick scenario, one seed: bench, emcee, the four loops, the figure."""
    assert m.main(["--scenario", "changing_plant", "--quick", "--seeds", "0", "--out",
                   str(tmp_path)]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert set(s["controllers"]) == set(m.SCENARIOS["changing_plant"]["controllers"])
    assert (tmp_path / "mpc_changing.png").exists()
