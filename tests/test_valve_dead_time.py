"""A valve's dead time that depends on the supply (:mod:`pneubayes.effects.valve_dead_time`),
the search that asks whether the recordings can show it, and its stage's settings."""

import numpy as np
import pytest
from conftest import BORE, P_ATM, STROKE, random_steps, valve1_params

from pneubayes.discovery.openform.dead_time import DeadTimeSearch
from pneubayes.discovery.settings import DiscoverySettings, StageSettings
from pneubayes.discovery.stages import ValveDeadTimeForm, default_stages
from pneubayes.effects import CATALOGUE, ValveDeadTime
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.io.recording import Recording, RecordingMetadata
from pneubayes.model import Model
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate

SOLVER = SolverConfig(rtol=1e-7, atol_Pa=0.1, atol_K=0.01, max_step_s=0.02,
                      min_step_s=1e-12, max_steps_per_s=2.5e6)
REF = 5e5  # the effect's reference gauge supply, Pa


def _law(d, n):
    return {"valve_dead_time_s": np.array([d]), "valve_dead_time_exponent": np.array([n])}


def test_the_law_per_rig_supply():
    e = ValveDeadTime()
    at_ref = Rig(BORE, P_ATM, P_ATM + REF)
    twice = Rig(BORE, P_ATM, P_ATM + 2 * REF)
    assert e.lower(_law(0.01, 0.7), at_ref)["command_delay_s"][0] == pytest.approx(0.01)
    assert e.dead_time_s(_law(0.01, 1.0), twice)[0] == pytest.approx(0.005)
    assert e.dead_time_s(_law(0.01, 0.5), twice)[0] == pytest.approx(0.01 / np.sqrt(2))
    assert e.dead_time_s(_law(0.01, -1.0), twice)[0] == pytest.approx(0.02)
    assert e.dead_time_s(_law(0.01, 0.0), twice)[0] == pytest.approx(0.01)
    assert ValveDeadTime(reference_gauge_Pa=2 * REF).dead_time_s(_law(0.01, 1.0), twice)[0] \
        == pytest.approx(0.01)
    assert ValveDeadTime().options() == {}
    assert ValveDeadTime(reference_gauge_Pa=4e5).options() == {"reference_gauge_Pa": 4e5}
    assert CATALOGUE["valve_dead_time"] is ValveDeadTime
    assert ValveDeadTime().neutral_values() == {"valve_dead_time_s": 0.0,
                                                "valve_dead_time_exponent": 0.0}


def test_a_bad_reference_is_named():
    for bad in (0.0, -1.0, True):
        with pytest.raises(ValueError, match="reference_gauge_Pa must be a number > 0"):
            ValveDeadTime(reference_gauge_Pa=bad)


def _recording(supply_gauge_Pa, seed, model, params, n=3001, noise=0.0):
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_ATM + supply_gauge_Pa,
                           293.15, position_m=0.015)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    u = random_steps(rng, n, 1e-3, hold_s=(0.05, 0.3))
    blank = Recording(md, t, u, np.full(n, P_ATM))
    p = simulate(model, params, Inputs.from_recording(blank), blank.rig(), P_ATM,
                 SOLVER).pressure_Pa[0]
    return Recording(md, t, u, p + rng.normal(0.0, noise, n) if noise else p,
                     source=f"supply{supply_gauge_Pa:g}_{seed}.csv")


@pytest.mark.parametrize("exponent, shift", [(0.0, 10), (1.0, 5)])
def test_the_dead_time_is_the_command_delayed(exponent, shift):
    """At twice the reference gauge supply, a 10-ms law of exponent n delays the command
    by 10 ms x 2^-n: the same trajectory as the plain model fed the command that many
    samples later (ground truth, the command held between samples)."""
    plain, model = Model(), Model([ValveDeadTime()])
    params = valve1_params()
    rec = _recording(2 * REF, 1, model, {**params, "valve_dead_time_s": 0.01,
                                         "valve_dead_time_exponent": exponent})
    u = np.concatenate([np.full(shift, rec.command_V[0]), rec.command_V[:-shift]])
    late = Recording(rec.metadata, rec.time_s, u, rec.pressure_Pa)
    ref = simulate(plain, params, Inputs.from_recording(late), late.rig(), P_ATM,
                   SOLVER).pressure_Pa[0]
    assert np.max(np.abs(rec.pressure_Pa - ref)) < 5.0  # Pa, of a 450-kPa range
    # and not the undelayed command's
    own = simulate(plain, params, Inputs.from_recording(rec), rec.rig(), P_ATM,
                   SOLVER).pressure_Pa[0]
    assert np.max(np.abs(rec.pressure_Pa - own)) > 1e4


def test_the_law_is_recovered_from_two_supplies():
    model = Model([ValveDeadTime()])
    truth = {**valve1_params(), "valve_dead_time_s": 0.008, "valve_dead_time_exponent": 0.5}
    recs = [_recording(3.5e5, 2, model, truth, noise=200.0),
            _recording(6e5, 3, model, truth, noise=200.0)]
    start = {**truth, "valve_dead_time_s": 0.002, "valve_dead_time_exponent": 0.0}
    fit = TrajectoryRefiner(model, SOLVER, 1.0, 1.0, max_nfev=60,
                            free=["valve_dead_time_s", "valve_dead_time_exponent"]).fit(
                                recs, start)
    assert fit.params_["valve_dead_time_s"] == pytest.approx(0.008, rel=0.02)
    assert fit.params_["valve_dead_time_exponent"] == pytest.approx(0.5, abs=0.05)
    assert fit.rmse_Pa_ < 230.0


def test_the_search_proposes_only_where_supplies_differ():
    model = Model()
    params = valve1_params()
    two = [_recording(4e5, 4, model, params, n=501), _recording(5e5, 5, model, params, n=501)]
    s = DeadTimeSearch().fit(WindowSet(two, 0.2, 0.2))
    assert s.supplies_gauge_Pa_ == pytest.approx([4e5, 5e5])
    assert s.supply_spread_ == pytest.approx(1e5 / 4.5e5)
    assert s.proposal_.dead_time_s == 0.002 and s.proposal_.exponent == 0.5
    assert s.terms_ == [] and s.best_ is None
    one = DeadTimeSearch().fit(WindowSet([two[0], _recording(4e5, 6, model, params, n=501)],
                                         0.2, 0.2))
    assert one.supply_spread_ == 0.0 and one.proposal_ is None
    with pytest.raises(ValueError, match="min_supply_spread must be > 0"):
        DeadTimeSearch(min_supply_spread=0.0).fit(WindowSet(two, 0.2, 0.2))


def test_the_stage_is_in_the_pipeline_and_can_be_switched_off():
    assert any(isinstance(s, ValveDeadTimeForm)
               for s in default_stages(DiscoverySettings()))
    off = DiscoverySettings(stages=StageSettings(valve_dead_time_min_noise_ratio=0))
    assert not any(isinstance(s, ValveDeadTimeForm) for s in default_stages(off))
    with pytest.raises(ValueError, match="valve_dead_time_min_noise_ratio"):
        StageSettings(valve_dead_time_min_noise_ratio=0.5)


def test_a_named_dead_time_a_stage_proposed_is_reported():
    """The stage's evidence has no inclusion probability (no library search proposed
    it): the report and the command line's summary say '-' there."""
    from types import SimpleNamespace

    from pneubayes.cli.discover import summary_lines
    from pneubayes.discovery.report_text import report_markdown as _report
    from pneubayes.discovery.result import DiscoveryResult

    model = Model([ValveDeadTime()])
    params = {**valve1_params(), "valve_dead_time_s": 0.01, "valve_dead_time_exponent": 0.4}
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=505.0)
    evidence = {"inclusion_probability": None, "t_max": 0.0,
                "best_term": "dead time 2 ms x (p_ref / p_s)^0.5 (gauge supplies)",
                "best_term_start": None}
    result = DiscoveryResult(
        settings=DiscoverySettings(), base=final, final=final,
        accepted=({"name": "valve_dead_time", "evidence": evidence, "score_gain": 50.0,
                   "score_p_value": 0.0002, "rmse_before_Pa": 5132.0,
                   "rmse_after_Pa": 505.0},),
        ledger=(), maps=(), searches=(), params=params, estimate="refined",
        noise_floor_Pa=517.0, range_Pa=4.5e5, span_Pa=4e5, posterior_summary=None)
    doc = result.to_dict()
    assert [e["name"] for e in doc["effects"]] == ["valve_dead_time"]
    text = _report({**doc, "recordings": ["a.csv"]}, result, {})
    assert "| valve_dead_time | valve_dead_time_s | 0.01 | - | - | 5132 -> 505 |" in text
    (line,) = summary_lines(doc)
    assert "inclusion -, RMSE 5132 -> 505 Pa" in line


def test_the_stage_says_why_it_stops_at_one_supply():
    from types import SimpleNamespace

    model = Model()
    params = valve1_params()
    one = [_recording(4e5, 7, model, params, n=501), _recording(4e5, 8, model, params, n=501)]
    said = []
    runner = SimpleNamespace(data=SimpleNamespace(train_ws=WindowSet(one, 0.2, 0.2)),
                             log=said.append,
                             fit=lambda *a: pytest.fail("no fit at one supply"))
    ValveDeadTimeForm()._run(None, runner, None)
    assert said == ["discover: valve dead time form: the training recordings' supplies "
                    "spread by 0.0% of their mean (under 5%): no law of the dead time in the "
                    "supply to tell from a fixed delay"]
