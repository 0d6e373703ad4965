"""Per-unit refits (:mod:`pneubayes.inference.units`): two actuators of one kind, each
its own dead volume, recovered per unit where a shared fit averages them."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import valve1_params, valve1_recordings

from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.units import UnitRefit, unit_name
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

SOLVER = SolverConfig(rtol=1e-6, atol_Pa=1.0, atol_K=0.01, max_step_s=0.02, min_step_s=1e-12,
                      max_steps_per_s=2.5e6)
VOLUMES = {"a": 2.4e-6, "b": 4.0e-6}


def _unit(model, name, seed0, count):
    recs = valve1_recordings(model, valve1_params(VOLUMES[name]), name, seed0,
                             count=count, n=2001)
    return [replace(r, metadata=replace(r.metadata, cylinder=f"AIR37-{name}"))
            for r in recs]


@pytest.fixture(scope="module")
def units():
    model = Model()
    train = _unit(model, "a", 10, 2) + _unit(model, "b", 20, 2)
    held = _unit(model, "a", 30, 1) + _unit(model, "b", 40, 1)
    start = valve1_params(3.0e-6)
    shared = TrajectoryRefiner(model, SOLVER, 1.0, 1.0, free=["dead_volume_m3"],
                               max_nfev=40).fit(train, start).params_
    refit = UnitRefit(model, SOLVER, ["dead_volume_m3"], 1.0, 1.0).fit(train, shared)
    return model, train, held, shared, refit


def test_each_unit_recovers_its_own_volume(units):
    model, train, held, shared, refit = units
    assert sorted(refit.units_) == ["AIR37-a / valve1", "AIR37-b / valve1"]
    assert refit.recordings_ == {"AIR37-a / valve1": 2, "AIR37-b / valve1": 2}
    for name, volume in VOLUMES.items():
        got = refit.units_[f"AIR37-{name} / valve1"]
        assert got["dead_volume_m3"] == pytest.approx(volume, rel=0.03)
        sd = refit.sd_[f"AIR37-{name} / valve1"]["dead_volume_m3"]
        assert 0.0 < sd < 0.1 * volume
        # the rest of the shared fit is kept
        assert {k: v for k, v in got.items() if k != "dead_volume_m3"} == \
            {k: v for k, v in shared.items() if k != "dead_volume_m3"}
    # the shared fit lies between the two units
    assert VOLUMES["a"] < shared["dead_volume_m3"] < VOLUMES["b"]


def test_unit_values_predict_new_recordings_of_each_unit(units):
    model, train, held, shared, refit = units
    own = float(np.sqrt(np.mean(refit.residuals(held) ** 2)))
    pooled = float(np.sqrt(np.mean(
        WindowSet(held, 1.0, 1.0).residuals(model, shared, SOLVER) ** 2)))
    assert own < 260.0 < pooled  # 200 Pa of noise in the recordings
    assert refit.params_for(held[0]) is refit.units_[unit_name(held[0])]


def test_unit_named_by_a_callable(units):
    model, train, held, shared, _ = units
    refit = UnitRefit(model, SOLVER, ["dead_volume_m3"], 1.0, 1.0,
                      unit=lambda r: str(r.source)[0], max_nfev=20).fit(train[:2], shared)
    assert list(refit.units_) == ["a"]


def test_unknown_unit_and_bad_names_are_named(units):
    model, train, held, shared, refit = units
    stranger = replace(held[0], metadata=replace(held[0].metadata, cylinder="SMC"))
    with pytest.raises(ValueError, match="unit 'SMC / valve1' was not fitted"):
        refit.params_for(stranger)
    with pytest.raises(ValueError, match="not parameters"):
        UnitRefit(model, SOLVER, ["bore_volume"], 1.0, 1.0).fit(train, shared)
    with pytest.raises(ValueError, match="none given"):
        UnitRefit(model, SOLVER, [], 1.0, 1.0).fit(train, shared)
    with pytest.raises(ValueError, match="no value for"):
        UnitRefit(model, SOLVER, ["dead_volume_m3"], 1.0, 1.0).fit(
            train, {"dead_volume_m3": 3e-6})


def test_each_unit_is_written_as_a_run_folder_a_fit_reads(units, tmp_path):
    from pneubayes.inference.fit_folder import read_fit

    model, train, held, shared, refit = units
    folders = refit.write_units(tmp_path / "units", extra={"fit": {"estimate": "refine"}})
    assert {k: v.name for k, v in folders.items()} == {
        "AIR37-a / valve1": "AIR37-a_valve1", "AIR37-b / valve1": "AIR37-b_valve1"}
    for name, folder in folders.items():
        fit = read_fit(folder)
        assert fit.params["dead_volume_m3"] == pytest.approx(
            refit.units_[name]["dead_volume_m3"], rel=1e-12)
        card = model.read_card(folder / "model.json")
        assert card["unit"]["name"] == name and card["unit"]["train_recordings"] == 2
        assert card["fit"] == {"estimate": "refine"}
    clash = UnitRefit(model, SOLVER, ["dead_volume_m3"], 1.0, 1.0,
                      unit=lambda r: "a/b" if str(r.source).startswith("a") else "a b",
                      max_nfev=5).fit(train, shared)
    with pytest.raises(ValueError, match="write the same folder"):
        clash.write_units(tmp_path / "clash")
