"""The discovery loop's catalogue sweep: near the noise floor, when nothing passed, the
catalogue's untried groups are tried before the open forms may add generic terms."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from pneubayes.discovery.settings import DiscoverySettings, StageSettings
from pneubayes.discovery.stages import CatalogueSweep, LastResort, OpenForm, default_stages
from pneubayes.discovery.state import RoundState
from pneubayes.model import Model


class _Runner:
    """Records the groups each ``trials`` call fits and the gap share it asks."""

    def __init__(self, passing=()):
        self.calls, self.passing = [], list(passing)
        self.ledger = SimpleNamespace(events=[], record=lambda action, **kw:
                                      self.ledger.events.append((action, kw)))

    def log(self, message):
        pass

    def trials(self, groups, state, min_gap_closed=0.0):
        self.calls.append((list(groups), min_gap_closed))
        return list(self.passing)


def _state(rmse_Pa, *, candidates=(), passing=(), started_far=False):
    search = SimpleNamespace(ranking_=["spool_lag", "cylinder_leak", "heat_transfer",
                                       "sensor_drift"])
    current = SimpleNamespace(heldout_rmse_Pa=rmse_Pa, model=Model(["spool_lag"]))
    return RoundState(number=2, current=current,
                      search=search, supported=[], tentative=[], started_far=started_far,
                      gap_ratio=2.0, noise_Pa=500.0, search_step=0, counts={},
                      candidates=list(candidates), passing=list(passing))


def test_near_the_noise_the_untried_groups_are_tried_in_the_searchs_order():
    stage = CatalogueSweep(min_noise_ratio=1.1, min_gap_closed=0.5)
    state = _state(780.0, candidates=["spool_lag"])  # 1.56 x: under the last resort's 2 x
    runner = _Runner(passing=[(560.0, "cylinder_leak", None, 1.0, 0.001)])
    assert stage.opens_empty_round(state)
    stage.run(state, runner)
    assert runner.calls == [(["cylinder_leak", "heat_transfer", "sensor_drift"], 0.5)]
    assert runner.ledger.events[0][0] == "catalogue sweep"
    assert runner.ledger.events[0][1]["groups"] == ["cylinder_leak", "heat_transfer",
                                                    "sensor_drift"]
    assert [t[1] for t in state.passing] == ["cylinder_leak"]
    assert "cylinder_leak" in state.candidates
    # what passed here is the round's catalogue trial the open form competes with: one
    # closing 79 % of the gap leaves the open form out
    assert OpenForm(min_noise_ratio=1.5)._applies(state, 500.0)[0] is False


@pytest.mark.parametrize("rmse_Pa, passing, started_far", [
    (540.0, (), False),    # 1.08 x the noise: at the floor, nothing to sweep for
    (1500.0, (), True),    # far above: the last resort's zone, not this stage's
    (780.0, [(700.0, "spool_lag", None, 1.0, 0.001)], False),  # one closing 29 % passed
])
def test_the_sweep_stays_out_at_the_floor_far_above_it_and_when_a_trial_closed_enough(
        rmse_Pa, passing, started_far):
    state = _state(rmse_Pa, candidates=["spool_lag"], passing=passing,
                   started_far=started_far)
    runner = _Runner()
    CatalogueSweep(1.1, 0.5).run(state, runner)
    assert runner.calls == [] and runner.ledger.events == []


def test_a_trial_that_passed_closing_little_of_the_gap_does_not_stop_the_sweep():
    small = (750.0, "sensor_lag", None, 1.0, 0.001)  # closes 11 % of the 280-Pa gap
    state = _state(780.0, candidates=["spool_lag", "sensor_lag"], passing=[small])
    runner = _Runner(passing=[(560.0, "cylinder_leak", None, 1.0, 0.001)])
    CatalogueSweep(1.1, 0.5, best_gap_closed=0.25).run(state, runner)
    assert runner.calls == [(["cylinder_leak", "heat_transfer", "sensor_drift"], 0.5)]
    assert [t[1] for t in state.passing] == ["sensor_lag", "cylinder_leak"]
    assert runner.ledger.events[0][1]["best_gap_closed_before"] == pytest.approx(30 / 280)
    # with the share at 0 the stage runs only when nothing passed
    state = _state(780.0, candidates=["spool_lag", "sensor_lag"], passing=[small])
    runner = _Runner()
    CatalogueSweep(1.1, 0.5, best_gap_closed=0.0).run(state, runner)
    assert runner.calls == []


def test_every_group_tried_already_leaves_nothing_to_sweep():
    state = _state(780.0, candidates=["spool_lag", "cylinder_leak", "heat_transfer",
                                      "sensor_drift"])
    runner = _Runner()
    CatalogueSweep().run(state, runner)
    assert runner.calls == []


def test_the_default_pipeline_sweeps_after_the_last_resort_and_the_setting_switches_it_off():
    kinds = [type(st) for st in default_stages(DiscoverySettings())]
    assert kinds.index(CatalogueSweep) == kinds.index(LastResort) + 1
    assert kinds.index(CatalogueSweep) < kinds.index(OpenForm)
    sweep = next(st for st in default_stages(DiscoverySettings())
                 if isinstance(st, CatalogueSweep))
    assert sweep.options() == {"min_noise_ratio": 1.1, "min_gap_closed": 0.5,
                               "best_gap_closed": 0.25}
    off = DiscoverySettings(stages=StageSettings(catalogue_sweep_min_noise_ratio=0.0))
    assert CatalogueSweep not in [type(st) for st in default_stages(off)]


@pytest.mark.parametrize("kw, message", [
    ({"catalogue_sweep_min_noise_ratio": 0.5}, "catalogue_sweep_min_noise_ratio must be 0"),
    ({"catalogue_sweep_min_gap_closed": 1.5}, "catalogue_sweep_min_gap_closed must be in"),
])
def test_bad_sweep_settings_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        StageSettings(**kw)
    with pytest.raises(ValueError, match="CatalogueSweep"):
        CatalogueSweep(min_noise_ratio=0.9)


def test_a_trial_is_not_fitted_once_the_runs_time_budget_is_spent(monkeypatch):
    """A stage that tries many groups (the sweep, the last resort) beside a slow model
    stops fitting them at the budget: each is a failed form, not a fit."""
    from pneubayes.discovery.rounds import TrialFitFailed
    from pneubayes.discovery.trials import TrialRunner

    spent = TrialRunner(DiscoverySettings(), None, None, log=lambda m: None, deadline_s=0.0)
    with pytest.raises(TrialFitFailed, match="time budget"):
        spent._fit_in_budget("cylinder_leak", None, {}, None, None)
    free = TrialRunner(DiscoverySettings(), None, None, log=lambda m: None)
    monkeypatch.setattr(free, "fit_trial", lambda *a: "fitted")
    assert free._fit_in_budget("cylinder_leak", None, {}, None, None) == "fitted"


def test_the_last_resort_names_a_share_outside_zero_to_one():
    """The share checks live on the last resort, so the sweep (its subclass) and it
    both name a bad one."""
    from pneubayes.discovery.stages.last_resort import LastResort

    with pytest.raises(ValueError, match=r"LastResort: best_gap_closed must be in \[0, 1\]"):
        LastResort(0.25, 1.5)
    with pytest.raises(ValueError, match=r"CatalogueSweep: min_gap_closed must be in"):
        CatalogueSweep(1.1, -0.1)
