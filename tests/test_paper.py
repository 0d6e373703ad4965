"""The paper's study scripts and the report assembler (issue 5)."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))

import make_paper  # noqa: E402
import table3  # noqa: E402


def test_report_says_what_is_missing(tmp_path):
    path = make_paper.assemble(tmp_path / "none", tmp_path / "paper", smoke=False)
    text = path.read_text()
    assert "*Missing: run `python experiments/table3.py`.*" in text
    assert "## Where we differ from the paper, and why" in text


@pytest.mark.slow
def test_table3_smoke_then_report_carries_numbers_and_provenance(tmp_path):
    out = tmp_path / "results"
    assert table3.main(["--smoke", "--out", str(out), "--workers", "1", "-q"]) == 0
    doc = json.loads((out / "table3-smoke.json").read_text())
    (row,) = doc["numbers"]["rows"]
    assert row["cylinder"] == "SMC" and row["paper_percent"] == 3.2
    assert 0 < row["ours_paper_model_rmse_Pa"] < 0.2 * row["working_range_Pa"]
    assert doc["provenance"]["git_revision"] and doc["studies"]["table3"]["seeds"] == [0]
    report = make_paper.assemble(out, tmp_path / "paper", smoke=True).read_text()
    assert "Smoke build" in report
    assert f"| {row['ours_paper_model_rmse_Pa']:.0f} |" in report
    assert "seeds [0]" in report and "git revision" in report
    # a second run resumes from the cached cell
    assert table3.main(["--smoke", "--out", str(out), "--workers", "1", "-q"]) == 0
    again = json.loads((out / "studies" / "table3-smoke" / "results.json").read_text())
    assert again["counts"]["cached"] == 1 and again["counts"]["run_now"] == 0


def test_table3_discovery_summary_over_seeds():
    planted = ["tube_delay", "valve_deadzone", "supply_fluctuation", "cylinder_leak"]
    base = {"cylinder": "PRN", "paper_name": "PRN", "planted": planted,
            "noise_floor_Pa": 500.0}
    table = [dict(base, seed=0, discovered=["tube_delay", "spool_lag"],
                  ours_plain_rmse_Pa=4500.0, ours_discovery_rmse_Pa=1500.0),
             dict(base, seed=1, discovered=["tube_delay", "valve_deadzone",
                                            "cylinder_leak"],
                  ours_plain_rmse_Pa=2500.0, ours_discovery_rmse_Pa=900.0),
             # a seed whose plain model is already at the noise floor: no gap to shrink
             dict(base, seed=2, discovered=[], ours_plain_rmse_Pa=450.0,
                  ours_discovery_rmse_Pa=450.0)]
    (row,) = table3.discovery_summary(table)
    assert row["planted_named"] == [1, 3, 0] and row["planted_named_mean"] == 4 / 3
    assert row["not_planted_named"] == ["spool_lag"]
    assert row["gap_shrink"] == {"median": 0.775, "min": 0.75, "max": 0.8}
    assert row["final_over_noise"] == {"median": 1.8, "min": 0.9, "max": 3.0}
    md = table3.summary_markdown([row])
    assert "| PRN | 3 | 1.33 |" in md and "78 [75, 80] %" in md and "1.80 [0.90, 3.00]" in md
    # which revision computed each cell, and a cell carried over from an earlier id
    table[0].update(discovery_revision="1bd7fbd",
                    discovery_rekeyed={"from": "old-id", "why": "no round reached it"})
    table[1].update(discovery_revision="1a34be1")
    text = table3.revision_markdown(table)
    assert "`1bd7fbd`: PRN seed 0; `1a34be1`: PRN seed 1; `unknown`: PRN seed 2" in text
    assert "Carried over from an earlier cell id: PRN seed 0 (no round reached it)." in text
    assert table3.revision_markdown([dict(base, seed=0)]) == ""


def _real_results(out: Path, rw_final: float, setpoint: float):
    g = {"window": {"after_close_s": 0.03, "horizon_s": 0.044},
         "held_out_recordings": ["a"] * 8, "noise_floor_Pa": 1000.0, "span_Pa": 300000.0,
         "held_out_rmse_plain_Pa": 40000.0, "held_out_rmse_final_Pa": 8000.0,
         "ratio_final_over_plain": 0.2, "final_over_noise": 8.0,
         "effects": [{"name": "tube_delay"}], "seed": 0, "figures": [],
         "per_muscle": {"quantities": ["dead_volume_m3", "tube_delay_s"],
                        "held_out_rmse_shared_Pa": 7900.0, "held_out_rmse_Pa": 6100.0,
                        "over_noise": 6.1},
         "posterior": {"converged": False, "summary": {
             "tube_delay_s": {"median": 0.02, "q05": 0.018, "q95": 0.022}}}}
    (out / "real_gtdynamics").mkdir(parents=True)
    (out / "real_gtdynamics" / "real_gtdynamics.json").write_text(json.dumps(g))
    r = {"horizon_s": 2.0, "sets": {"OXY": {
        "held_out_rmse_plain_Pa": 400.0, "held_out_rmse_final_Pa": rw_final,
        "effects": [], "noise_floor_Pa": 10.0, "final_over_noise": rw_final / 10.0,
        "span_Pa": 3000.0, "setpoint_baseline_rmse_Pa": setpoint, "at_bounds": []}}}
    (out / "real_respiraworks").mkdir(parents=True)
    (out / "real_respiraworks" / "real_respiraworks.json").write_text(json.dumps(r))
    fit = {"held_out_rmse_Pa": 9000.0}
    tank = {"window_s": 0.044, "seed": 0, "noise_floor_Pa": 1000.0,
            "held_out_span_Pa": 300000.0,
            "fits": {k: fit for k in ("measured", "constant", "tank", "measured+tube_delay",
                                      "constant+tube_delay", "tank+tube_delay")},
            "tank_posterior": {
                "tank_volume_m3": {"median": 1.4e-3, "q05": 1.2e-3, "q95": 1.7e-3},
                "tube_delay_s": {"median": 0.02, "q05": 0.018, "q95": 0.022},
                "documented_tank_volume_m3": 1.475e-3, "documented_inside_90": True,
                "converged": True, "misfit": {"note": None}}}
    (out / "real_gtdynamics_tank").mkdir(parents=True)
    (out / "real_gtdynamics_tank" / "real_gtdynamics_tank.json").write_text(json.dumps(tank))
    form = {"train_rmse_Pa": 200.0, "held_out_after_cal_shared_Pa": 400.0,
            "held_out_after_cal_calibrated_Pa": 200.0, "noise_floor_Pa": 10.0,
            "span_after_cal_Pa": 2000.0, "setpoint_baseline_after_cal_Pa": setpoint,
            "held_out_second_half_own_fit_Pa": 40.0, "setpoint_baseline_second_half_Pa": 240.0}
    forms = {"horizon_s": 2.0, "calibration_s": 4.0, "max_nfev": 100,
             "forms": ["compliant/port", "two_compartment/separate"],
             "sets": {"OXY": {"compliant/port": form,
                              "two_compartment/separate": {
                                  **form, "held_out_after_cal_calibrated_Pa": 100.0}}}}
    (out / "real_respiraworks_forms").mkdir(parents=True)
    (out / "real_respiraworks_forms" / "real_respiraworks_forms.json").write_text(
        json.dumps(forms))


def test_real_section_states_the_numbers_and_never_claims_a_fit_it_misses(tmp_path):
    _real_results(tmp_path / "out", rw_final=390.0, setpoint=250.0)
    text = "\n".join(make_paper.real_section(tmp_path / "out", tmp_path / "paper", False))
    assert "| plain rig-card model | 40000 | 40.0 | 13.3 |" in text
    assert "20 [18, 22] ms" in text and "8.0 x the noise floor: misfit" in text
    assert ("| after discovery, each muscle's dead_volume_m3, tube_delay_s refitted on its "
            "own training recordings | 6100 | 6.1 | 2.0 |") in text
    assert "shared point estimate give 7900 Pa and with each muscle's own 6100 Pa" in text
    assert "loses to simply predicting the controller's set-point" in text
    assert "| OXY | 400 | 390 | none | 10 | 39.0 |" in text
    # the draining tank and the ventilator's forms, with their numbers
    assert "1.4 [1.2, 1.7] L" in text and "inside the interval" in text
    assert ("| OXY | two compartment / its own command | 200 | 400 | 100 | 10 | 5.0 | 250 |"
            " 40 | 4 | 240 |") in text
    assert "second half is predicted to 40 Pa (compliant/port), 4 x the noise floor" in text
    assert "cuts the held-out error by 62 %" in text
    assert "best form (two_compartment/separate) reaches 100 Pa, 10 x the noise floor, " \
        "below the set-point baseline's 250 Pa" in text
    # a model within 1.5 x the noise that beats the baseline gets no misfit sentence
    _real_results(tmp_path / "good", rw_final=12.0, setpoint=250.0)
    text = "\n".join(make_paper.real_section(tmp_path / "good", tmp_path / "p2", False))
    assert "On OXY" not in text and "What the model lacks" not in text


def test_open_form_paragraph_reads_the_ledger_and_states_the_floor(tmp_path):
    def trial(action, terms, train, after, better):
        return {"action": action, "terms": [{"term": t} for t in terms],
                "train_rmse_Pa": train, "heldout_rmse_before_Pa": 8000.0,
                "heldout_rmse_after_Pa": after, "windows_improved": better, "windows": 16}

    doc = {"noise_floor_Pa": 1000.0, "rmse_final_Pa": 8000.0, "found_terms": [],
           "ledger": [{"action": "open form search"},
                      trial("open form reject", ["pressure_relaxation", "one"], 5000, 9000, 3),
                      {"action": "open form search"},
                      trial("open form reject", ["pressure_hinge"], 6000, 8500, 6)]}
    path = tmp_path / "discovery.json"
    path.write_text(json.dumps(doc))
    text = make_paper._open_form_paragraph(path, "The stage", floor=3.0, revision="abc1234ff")[0]
    assert "at `abc1234`" in text and "searched the residual 2 time(s)" in text
    assert "`pressure_hinge`, `pressure_relaxation; one`" in text
    assert "training 5000-6000 Pa, held out 8000 -> 8500-9000 Pa (better in 3-6 of 16" in text
    assert "all rejected" in text and "8.0 x the 1000-Pa noise floor (issue 69's floor: 3 x)" \
        in text
    doc["ledger"][3]["action"] = "open form pass"
    doc["found_terms"] = [{"term": "pressure_hinge"}]
    path.write_text(json.dumps(doc))
    text = make_paper._open_form_paragraph(path, "The stage")[0]
    assert "1 kept" in text and "Found terms: `pressure_hinge`" in text
    # a run whose stage never searched: no paragraph
    doc["ledger"] = []
    path.write_text(json.dumps(doc))
    assert make_paper._open_form_paragraph(path, "The stage") == []
    assert make_paper._open_form_paragraph(tmp_path / "missing.json", "The stage") == []


def test_only_the_real_section_is_rewritten(tmp_path):
    paper = tmp_path / "paper"
    paper.mkdir()
    (paper / "report.md").write_text("# R\n\n## Table III\n\nkept\n\n"
                                     "## The paper's claims, checked on our data\n\nc\n")
    _real_results(tmp_path / "out", rw_final=390.0, setpoint=250.0)
    assert make_paper.main(["--out", str(tmp_path / "out"), "--paper", str(paper),
                            "--assemble-only", "--only", "real"]) == 0
    text = (paper / "report.md").read_text()
    assert text.index("kept") < text.index("## Real recordings") < text.index("claims")
    first = text
    assert make_paper.main(["--out", str(tmp_path / "out"), "--paper", str(paper),
                            "--assemble-only", "--only", "real"]) == 0
    assert (paper / "report.md").read_text() == first  # replaced, not added again


def test_only_table3_is_rewritten_with_its_discovery_summary(tmp_path):
    """``--only table3`` rewrites Table III's section, which carries the per-rig discovery
    summary, and removes the summary's old copy elsewhere (reports assembled before it
    moved there); the other sections are kept, and a second run changes nothing."""
    planted = ["tube_delay", "valve_deadzone", "supply_fluctuation", "cylinder_leak"]
    base = {"cylinder": "PRN", "paper_name": "PRN", "planted": planted,
            "noise_floor_Pa": 500.0, "ours_paper_model_rmse_Pa": 4000.0,
            "ours_paper_model_percent": 0.9}
    rows = [dict(base, seed=s, discovered=planted, ours_plain_rmse_Pa=4500.0,
                 ours_discovery_rmse_Pa=600.0 + 10 * s) for s in range(3)]
    summary = table3.discovery_summary(rows)
    out = tmp_path / "out"
    out.mkdir()
    (out / "table3.json").write_text(json.dumps({
        "numbers": {"rows": rows, "markdown": "| new Table III |",
                    "discovery_summary": summary,
                    "discovery_markdown": table3.summary_markdown(summary)},
        "studies": {"table3": {"seeds": [0, 1, 2]}},
        "provenance": {"git_revision": "abc1234def", "python": "3.11"}}))
    paper = tmp_path / "paper"
    paper.mkdir()
    (paper / "report.md").write_text(
        "# R\n\n## Table III: 2-s prediction error\n\n| old Table III |\n\n"
        "## Fig. 11: effect of volume and leakage\n\nkept 11\n\n"
        "## What is new: posteriors, band coverage and discovery\n\nkept new\n\n"
        "**Discovery on the Table III rigs**: old words.\n\n| cylinder | old |\n"
        "|---|---|\n| PRN | old row |\n\n## A blind set\n\nkept blind\n")
    args = ["--out", str(out), "--paper", str(paper), "--assemble-only", "--only", "table3"]
    assert make_paper.main(args) == 0
    text = (paper / "report.md").read_text()
    assert "old" not in text and "| new Table III |" in text
    for kept in ("kept 11", "kept new", "kept blind"):
        assert kept in text
    section = text[text.index("## Table III"):text.index("## Fig. 11")]
    assert "**Discovery on the Table III rigs**" in section and "| PRN | 3 | 4.00 |" in section
    assert "97 [97, 98] %" in section and "1.22 [1.20, 1.24]" in section
    assert "seeds [0, 1, 2]" in section
    assert text.count("**Discovery on the Table III rigs**") == 1
    first = text
    assert make_paper.main(args) == 0
    assert (paper / "report.md").read_text() == first


def _mpc_results(out: Path):
    """A summary as experiments/mpc_tracking.py writes it, from two made-up seeds whose
    pressure sits ``rmse`` above a reference capped at the limit (so both RMSEs are
    ``rmse``)."""
    import mpc_tracking

    reference = [5.0e5] * 201  # above the limit: capped at p_max (two holds)
    p_max = mpc_tracking.P_MAX_PA

    def seed(s, rmse, ticks):
        return {"seed": s, "fit": {"converged": True}, "posterior_noise_scale_Pa": 800.0,
                "fit_delay": {"converged": True, "tube_delay_s": {
                    "median": 0.015, "q05": 0.0149, "q95": 0.0151}},
                "reference_Pa": reference,
                "controllers": {k: {"tracking_rmse_Pa": r, "ticks_above_limit": t,
                                    "largest_excess_Pa": 1000.0 * t,
                                    "pressure_Pa": [p_max + r] * 201,
                                    "compute_ms_per_tick_median":
                                        8.0 if k == "delay_chance" else 2.0}
                                for k, r, t in zip(names, rmse, ticks)}}

    # per controller, in mpc_tracking.CONTROLLERS's order, then the back-offs (5-40 kPa:
    # fewer violations as the margin grows, at a growing RMSE)
    names = mpc_tracking.CONTROLLERS + tuple(mpc_tracking.BACKOFF_PA)
    assert tuple(mpc_tracking.BACKOFF_PA.values()) == (5e3, 10e3, 15e3, 20e3, 25e3, 30e3,
                                                      40e3)
    results = [seed(0, (40e3, 45e3, 38e3, 39e3, 39.5e3, 39e3, 40.1e3, 40.0e3, 39.9e3, 37e3,
                        37.5e3, 37.2e3, 40.2e3, 40.4e3, 40.6e3, 40.8e3, 41.0e3, 41.2e3,
                        41.6e3),
                    (30, 40, 12, 0, 0, 9, 2, 5, 4, 1, 0, 3, 20, 10, 6, 4, 2, 0, 0)),
               seed(1, (42e3, 44e3, 41e3, 43e3, 42e3, 41e3, 41.9e3, 41.8e3, 41.7e3, 40e3,
                        40e3, 39e3, 42.2e3, 42.4e3, 42.6e3, 42.8e3, 43.0e3, 43.2e3,
                        43.6e3),
                    (20, 30, 25, 2, 1, 14, 1, 3, 2, 0, 0, 0, 15, 8, 5, 3, 2, 1, 0))]
    assert all(len(r["controllers"]) == len(names) for r in results)
    folder = out / "mpc_tracking"
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({
        "seeds": [0, 1], "quick": False, "rate_Hz": 200.0, "horizon_s": 0.15,
        "candidates": 15, "draws": 64, "hidden_delay_s": 0.015, "p_max_Pa": 4.8e5,
        "run_s": 6.0, "controllers": mpc_tracking.summarise(results),
        "fits": [r["fit"] for r in results], "fits_delay": [r["fit_delay"] for r in results],
        "provenance": {"git_revision": "abc"}}))


def test_mpc_section_states_violations_and_tracking_per_seed(tmp_path):
    _mpc_results(tmp_path / "out")
    text = "\n".join(make_paper.mpc_section(tmp_path / "out", tmp_path / "paper", False))
    # the excess integrated over 201 ticks of 5 ms, 40 and 42 kPa over the limit: 82410 Pa s
    assert ("| nominal | 41.0 [40.0, 42.0] | 41.0 [40.0, 42.0] | 41.0 [40.0, 42.0] | 30, 20 "
            "| 30.0 | 2.00 | 82410 |") in text
    # the same-model comparison, the fitted delays and a controller slower than its tick
    assert ("`delay_chance` had 0 ticks above the limit against `delay_nominal`'s 1 (fewer "
            "on 1 of 2 seeds)") in text
    assert ("`delay_chance_window` had 3 ticks above the limit against `delay_nominal`'s 1 "
            "(fewer on 0 of 2 seeds)") in text
    assert "settled 38.1 against 38.5 kPa (not worse on 1 of 2 seeds)" in text
    # every made-up hold is above the limit: the other holds have no settled part
    assert "where the settled error is made" in text and "`nominal` 41.0 / -" in text
    assert "15.0 [14.9, 15.1] ms" in text
    assert ("`delay_chance` needed more than the 5-ms tick to choose (median over seeds; "
            "the threads not recorded for every loop)") in text
    assert ("`predictive` had 2 ticks above the limit against `nominal`'s 50 (fewer on 2 of "
            "2 seeds), at a median RMSE of 41.0 against 41.0 kPa (not worse on 1 of 2 "
            "seeds)") in text
    assert "`posterior` had 37 ticks" in text and "(fewer on 1 of 2 seeds)" in text
    assert "`chance_window` had 23 ticks above the limit against `nominal`'s 50" in text
    # against the fixed margins: chance's 1 tick lies between the 25-kPa back-off's 4 and
    # the 30-kPa one's 1, whose median capped RMSE (42.2 kPa) is above chance's (40.8)
    assert "20 kPa: 7 ticks, capped RMSE 41.8 kPa" in text
    assert "| `chance` | `nominal_backoff30k` | 1 / 1 (0 of 2 seeds) | 40.8 / 42.2 (2 of 2" \
        " seeds) | -1.4" in text
    assert ("`chance` (1 ticks, capped RMSE 40.8 kPa) has fewer violations than the 25-kPa "
            "back-off (4 ticks, capped RMSE 42.0 kPa) and no fewer than the 30-kPa "
            "back-off (1 ticks, capped RMSE 42.2 kPa), and tracks better") in text
    assert "Scenario `weak_data` not run" in text
    paper = tmp_path / "paper"
    paper.mkdir(exist_ok=True)
    (paper / "report.md").write_text("# R\n\n## The paper's claims, checked on our data\n")
    assert make_paper.main(["--out", str(tmp_path / "out"), "--paper", str(paper),
                            "--assemble-only", "--only", "mpc"]) == 0
    text = (paper / "report.md").read_text()
    assert text.index(make_paper.MPC_HEAD) < text.index("claims")


def test_settled_rmse_splits_the_holds_at_the_limit_from_the_others():
    import mpc_tracking as m

    hold = round(m.SETPOINT_HOLD_S * m.RATE_HZ)
    # three holds: above the limit, well below it, and 10 kPa under it (at the limit)
    ref = np.concatenate([np.full(hold, 5.0e5), np.full(hold, 3.0e5),
                          np.full(hold, m.P_MAX_PA - 10e3)])
    p = np.minimum(ref, m.P_MAX_PA)
    p[:hold] -= 40e3
    p[hold:2 * hold] += 5e3
    p[2 * hold:] -= 20e3
    assert m.settled_rmse(p, ref, True) == pytest.approx(np.sqrt((40e3**2 + 20e3**2) / 2))
    assert m.settled_rmse(p, ref, False) == pytest.approx(5e3)
    assert m.settled_rmse(p, ref) == pytest.approx(np.sqrt((40e3**2 + 5e3**2 + 20e3**2) / 3))
    assert np.isnan(m.settled_rmse(p[:hold], ref[:hold], False))


def test_paired_difference_has_the_student_t_interval():
    import mpc_tracking as m
    from scipy import stats

    d = m.paired_difference([10.0, 12.0, 9.0, 11.0], [10.5, 11.0, 9.5, 10.0])
    diffs = np.array([-0.5, 1.0, -0.5, 1.0])
    half = stats.t.ppf(0.975, 3) * diffs.std(ddof=1) / 2.0
    assert d["mean"] == pytest.approx(0.25) and d["seeds"] == 4
    assert d["sd"] == pytest.approx(diffs.std(ddof=1))
    assert d["ci95"] == pytest.approx([0.25 - half, 0.25 + half])
    assert m.paired_difference([1.0], [2.0]) == {"mean": -1.0, "sd": None, "ci95": None,
                                                 "seeds": 1}


def test_mpc_section_reports_the_wide_posterior_scenario(tmp_path):
    """The weak_data runs get their own table and the comparisons against the median,
    the mean and the least-squares point."""
    import mpc_tracking

    _mpc_results(tmp_path / "out")
    names = mpc_tracking.SCENARIOS["weak_data"]["controllers"]
    p_max = mpc_tracking.P_MAX_PA
    ticks = {"delay_nominal": (2, 0), "delay_nominal_mean": (40, 44),
             "delay_nominal_lsq": (0, 0), "delay_posterior": (0, 0), "delay_chance": (0, 0),
             "delay_chance_window": (0, 1), "delay_calibrated": (0, 0),
             "delay_calibrated_near": (1, 0), "delay_calibrated_online": (0, 0),
             **{f"delay_{b}": (0, 0) for b in mpc_tracking.BACKOFF_PA}}
    results = [{"seed": s, "reference_Pa": [5.0e5] * 201,
                "controllers": {k: {"tracking_rmse_Pa": 40e3 + 1e3 * i,
                                    "ticks_above_limit": ticks[k][s],
                                    "largest_excess_Pa": 500.0 * ticks[k][s],
                                    "pressure_Pa": [p_max + 40e3 + 1e3 * i] * 201,
                                    "compute_ms_per_tick_median": 2.0}
                                for i, k in enumerate(names)}} for s in (0, 1)]
    folder = tmp_path / "out" / "mpc_weak"
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({
        "seeds": [0, 1], "quick": False, "scenario": "weak_data",
        "controllers": mpc_tracking.summarise(results, "weak_data"),
        "fits_delay": [{"converged": False}, {"converged": True}],
        "provenance": {"git_revision": "abc"}}))
    text = "\n".join(make_paper.mpc_section(tmp_path / "out", tmp_path / "paper", False))
    assert "| delay_nominal_mean | 40, 44 | 41.0 [41.0, 41.0] |" in text
    assert ("`delay_chance` had 0 ticks above the limit against `delay_nominal`'s 2 (fewer "
            "on 1 of 2 seeds)") in text
    assert ("`delay_posterior` had 0 ticks above the limit against `delay_nominal_mean`'s "
            "84 (fewer on 2 of 2 seeds)") in text
    assert "against `delay_nominal_lsq`'s 0" in text and "[False, True]" in text
    # each margin in both scenarios: the back-offs' 0 ticks cost RMSE in this one (their
    # 46-52 kPa against chance's 44), and in the other only 30 and 40 kPa keep to its 1
    # tick, at 42.2 and 42.6 against 40.75 kPa: no margin is as good in both
    assert "| nominal, 30-kPa back-off | 1 | 42.20 | 0 | 51.00 |" in text
    assert "| chance (posterior-aware) | 1 | 40.75 | 0 | 44.00 |" in text
    assert "No fixed margin is at least as good as `chance`" in text


def _report_with_real_section(tmp_path):
    """A report folder whose report.md has Table III, the real recordings and the
    claims (a section inserted by ``--only`` goes before the real recordings)."""
    paper = tmp_path / "paper"
    paper.mkdir()
    (paper / "report.md").write_text("# R\n\n## Table III\n\nkept\n\n## Real recordings\n\n"
                                     "r\n\n## The paper's claims, checked on our data\n\nc\n")
    return paper


def test_blind_section_reports_the_set_once_and_checks_each_addition(tmp_path):
    paper = _report_with_real_section(tmp_path)
    out = tmp_path / "out"
    missing = make_paper.blind_section(out, paper, smoke=False)
    assert any("*Missing: `" in line for line in missing)

    def case(name, hidden, named, base, final, adds, wall_s, noise=500.0):
        ledger = [{"step": i, "action": "add", "effect": e, "heldout_rmse_before_Pa": b,
                   "heldout_rmse_after_Pa": a} for i, (e, b, a) in enumerate(adds)]
        return {"name": name, "cylinder": "SMC", "valve": "valve1", "hidden": hidden,
                "named": named, "correct": sorted(named) == sorted(hidden),
                "planted_named": len(set(named) & set(hidden)), "rmse_base_Pa": base,
                "rmse_final_Pa": final, "noise_floor_Pa": noise,
                "gap_shrink": None if base <= noise else 1 - (final - noise) / (base - noise),
                "final_over_noise": final / noise, "wall_time_s": wall_s, "ledger": ledger}

    cases = [case("b00_SMC_valve1_none", [], [], 505.0, 505.0, [], 60.0),
             case("b01_SMC_valve1_tube_delay", ["tube_delay"], ["tube_delay", "spool_lag"],
                  2500.0, 597.0, [("tube_delay", 2500.0, 600.0), ("spool_lag", 600.0, 597.0)],
                  600.0)]
    folder = out / "blind"
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({
        "seed": 4242, "duration_s": 20.0, "smoke": False, "tube_line_form": "wave",
        "min_tube_cells": 32, "floors": {}, "cases": cases,
        "provenance": {"git_revision": "abcdef0123", "python": "3.11"}}))
    assert make_paper.main(["--out", str(out), "--paper", str(paper), "--assemble-only",
                            "--only", "blind"]) == 0
    text = (paper / "report.md").read_text()
    assert text.index("kept") < text.index(make_paper.BLIND_HEAD) < text.index("## Real")
    assert "seed 4242" in text and "at least 32 cells" in text and "`abcdef0`" in text
    # the spool's 3-Pa gain is under the 5 Pa (1 % of the noise) the gain floor asks
    assert "1 of 2 additions meet it" in text
    assert "b01's `spool_lag`, 3 Pa against the 5 Pa asked" in text
    assert "median 6 min, longest 10 min" in text
    assert ("ran in 0 cases (pairs of effects fitted jointly); 0 cases (named effects "
            "refitted in other forms)") in text
    cases[1]["ledger"].append({"step": 9, "action": "pairs", "groups": ["a + b"]})
    (folder / "summary.json").write_text(json.dumps({
        "seed": 4242, "duration_s": 20.0, "smoke": False, "tube_line_form": "wave",
        "min_tube_cells": 32, "floors": {}, "cases": cases,
        "provenance": {"git_revision": "abcdef0123", "python": "3.11"}}))
    lines = make_paper.blind_section(out, paper, smoke=False)
    assert any("ran in 1 case (b01) (pairs of effects fitted jointly); 0 cases" in line
               for line in lines)
    assert "Earlier blind sets" not in text
    # a set the new one replaced, kept under blind_earlier/SEED: one row of what it measured
    early = out / "blind_earlier" / "4141"
    early.mkdir(parents=True)
    (early / "summary.json").write_text(json.dumps({
        "seed": 4141, "provenance": {"git_revision": "0123456789"}, "floors": {
            "control": {"nothing_named_fraction": 1.0},
            "single/pair": {"cases": 12, "all_planted_named_fraction": 10 / 12,
                            "gap_shrink_median": 0.99, "final_over_noise_median": 1.05},
            "four-effect": {"planted_named_mean": 4.0}}}))
    lines = make_paper.blind_section(out, paper, smoke=False)
    assert "| 4141 | `0123456` | 100 % | 83 % of 12 | 99 % | 1.05 | 4.00 |" in lines


def test_calibration_section_counts_named_and_stand_ins_and_reads_the_real_ledger(tmp_path):
    paper = _report_with_real_section(tmp_path)
    out = tmp_path / "out"
    assert any("*Missing: `" in line
               for line in make_paper.calibration_section(out, paper, smoke=False))

    def result(case, hidden, named, final, offset=None):
        est = {} if offset is None else {
            "sensor_calibration": {"reading_offset_Pa": {"estimate": offset}}}
        return {"case": f"{case}@AIR37-valve1-s0", "rig": "AIR37", "valve": "valve1",
                "seed": 0, "hidden": hidden, "named": named,
                "correct": sorted(named) == sorted(hidden), "rmse_base_Pa": 3000.0,
                "rmse_final_Pa": final, "noise_floor_Pa": 500.0, "gap_shrink": 0.9,
                "estimates": est, "wall_time_s": 100.0}

    results = [result("offset", ["sensor_calibration"], ["sensor_calibration"], 510.0, 4987.0),
               result("leak", ["cylinder_leak"], ["sensor_calibration"], 700.0, -2000.0),
               result("none", [], [], 505.0),
               {**result("offset", ["sensor_calibration"], ["cylinder_leak"], 1500.0),
                "case": "offset@AIR37-valve1-s0~off", "searched": False},
               {"case": "supply@AIR37-valve1-s0", "failed": "ValueError: boom"}]
    (out / "calibration").mkdir(parents=True)
    (out / "calibration" / "summary.json").write_text(json.dumps({
        "results": results, "provenance": {"git_revision": "abcdef0123"}}))
    real = out / "real_gtdynamics_calibration" / "discovery"
    real.mkdir(parents=True)
    (real / "discovery.json").write_text(json.dumps({"ledger": [
        {"action": "search"}, {"action": "add", "effect": "spool_lag"},
        {"action": "add", "effect": "tube_delay"}, {"action": "remove", "effect": "spool_lag"},
        {"action": "reject", "effect": "sensor_calibration",
         "fitted": {"reading_offset_Pa": -22269.0, "reading_gain_error": -0.107},
         "heldout_rmse_before_Pa": 7874.2, "heldout_rmse_after_Pa": 8160.4,
         "windows_improved": 4, "windows": 16}]}))
    assert make_paper.main(["--out", str(out), "--paper", str(paper), "--assemble-only",
                            "--only", "calibration"]) == 0
    text = (paper / "report.md").read_text()
    assert text.index("kept") < text.index(make_paper.CALIBRATION_HEAD) < text.index("## Real")
    assert ("| offset | AIR37/valve1 | 0 | yes | sensor_calibration | sensor_calibration | 510 "
            "| 1.02 |") in text
    assert make_paper._unsigned_zero("-0.000") == "0.000"
    assert make_paper._unsigned_zero("-0.001") == "-0.001"
    assert ("Not searched (the loop's defaults), where a calibration is planted: offset on "
            "AIR37 named cylinder_leak, ending at 3.00 x the noise floor.") in text
    assert "| 4987 |" in text
    # one planted case named; the leak control names the calibration (a stand-in)
    assert "named exactly in 1 of 1 cases" in text
    assert "in 1 of 2 controls the calibration is not named (1 of 2 named exactly)" in text
    assert "supply@AIR37-valve1-s0 (ValueError: boom)" in text
    assert ("beside tube_delay it was fitted at an offset of -22.3 kPa and a gain error of "
            "-0.107 and **was rejected** on the held-out trials (7874 -> 8160 Pa, better "
            "in 4 of 16 windows)") in text
    assert "`abcdef0`" in text


def test_the_sensor_section_reports_each_case_its_fit_and_the_stand_ins(tmp_path):
    """``--only sensor`` renders the drift and curvature study: each case with its
    revision and fitted values, the planted sets named, the controls where a sensor
    effect stood in; placed after the calibration and before the real recordings."""
    out, paper = tmp_path / "out", tmp_path / "paper"
    paper.mkdir()
    (paper / "report.md").write_text("# Report\n\n" + make_paper.CALIBRATION_HEAD
                                     + "\n\nkept\n\n## Real recordings\n\nreal\n")
    assert any("*Missing: `" in line
               for line in make_paper.sensor_section(out, paper, smoke=False))

    def result(case, hidden, named, final, est=None, rev="1234567abc"):
        return {"case": f"{case}@SMC-valve2-s0~off", "rig": "SMC", "valve": "valve2",
                "seed": 0, "hidden": hidden, "named": named,
                "correct": sorted(named) == sorted(hidden), "rmse_base_Pa": 3000.0,
                "rmse_final_Pa": final, "noise_floor_Pa": 500.0, "gap_shrink": 0.95,
                "estimates": est or {}, "git_revision": rev}

    drift = {"sensor_drift": {"reading_warm_up_Pa": {"median": 2987.4},
                              "reading_warm_up_time_constant_s": {"median": 4.93}}}
    curve = {"sensor_nonlinearity": {"reading_curvature_Pa": {"estimate": -311.0},
                                     "reading_curve_gain_error": {"estimate": 0.0182}}}
    results = [result("warm_up", ["sensor_drift"], ["sensor_drift"], 520.0, drift),
               result("bow", ["sensor_nonlinearity"], ["sensor_nonlinearity"], 530.0, curve,
                      "89abcdef00"),
               result("leak", ["cylinder_leak"], ["sensor_drift"], 700.0, drift),
               result("none", [], [], 505.0)]
    (out / "sensor").mkdir(parents=True)
    (out / "sensor" / "summary.json").write_text(json.dumps({"results": results}))
    assert make_paper.main(["--out", str(out), "--paper", str(paper), "--assemble-only",
                            "--only", "sensor"]) == 0
    text = (paper / "report.md").read_text()
    assert text.index("kept") < text.index(make_paper.SENSOR_HEAD) < text.index("## Real")
    assert ("| warm_up | SMC/valve2 | 0 | `1234567` | sensor_drift | sensor_drift | 520 | "
            "1.04 | 95 % | b = 2987 Pa, tau = 4.9 s |") in text
    assert "`89abcde`" in text and "k = -311 Pa, g - 1 = +0.0182" in text
    assert "named exactly in 2 of 2 cases" in text
    assert "in 1 of 2 controls neither sensor effect is named (1 of 2 named exactly)" in text


def test_calibration_study_collects_the_cases_of_several_calls_and_names_bad_cases(tmp_path):
    """``--collect`` writes one summary from every cached case (other rigs, seeds, the
    search off) and runs nothing; an unknown case is a usage error naming it."""
    import calibration_study

    cases = tmp_path / "cases"
    cases.mkdir()
    for name, correct in (("offset@AIR37-valve1-s0", True), ("none@PRN-valve1-s1", True),
                          ("offset@AIR37-valve1-s0~off", False)):
        (cases / f"{name}.json").write_text(json.dumps({"case": name, "correct": correct}))
    (cases / "leak@SMC-valve2-s0.json").write_text(json.dumps(
        {"case": "leak@SMC-valve2-s0", "failed": "ValueError: boom"}))
    assert calibration_study.main(["--out", str(tmp_path), "--collect"]) == 0
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert doc["cases"] == 4 and doc["correct"] == 2
    assert {r["case"] for r in doc["results"]} >= {"leak@SMC-valve2-s0", "none@PRN-valve1-s1"}
    with pytest.raises(SystemExit):
        calibration_study.main(["--out", str(tmp_path / "empty"), "--collect"])
    with pytest.raises(SystemExit):
        calibration_study.main(["--out", str(tmp_path / "x"), "--cases", "offset,nothing"])
    assert not (tmp_path / "x").exists()


def test_rigs_option_keeps_only_the_named_rigs_and_rejects_an_unknown_one():
    """``--rigs`` splits a long study (Table III) into parts: cylinders or CYLINDER:VALVE
    pairs select the same cells (same ids, so the cache is shared); an unknown name is an
    error naming the study's rigs."""
    from paper_common import STUDIES, select_rigs

    from pneubayes.ablation import load_study

    study = load_study(STUDIES / "table3.toml")
    part = select_rigs(study, "AIR37, PRN:valve2")
    assert part.grid.rigs == (("AIR37", "valve1"), ("PRN", "valve2"))
    ids = {c.id for c in study.cells()}
    assert len(part.cells()) == len(study.cells()) // 2
    assert all(c.id in ids for c in part.cells())
    with pytest.raises(SystemExit, match=r"'AIR99' is not a rig .*SMC:valve1"):
        select_rigs(study, "AIR37,AIR99")
    with pytest.raises(SystemExit, match="'PRN:valve1' is not a rig"):
        select_rigs(study, "PRN:valve1")


@pytest.fixture
def leak_controller(leak_model, base_params):
    """What the controller tests predict with: conftest's leak model and valve-1 vector
    (one draw), and a rig without a stroke (their piston sits at 0.05 m)."""
    from pneubayes.rig import Rig

    return leak_model, leak_model.vector(base_params)[None], Rig(0.009, 101325.0, 551325.0)


def test_mpc_controller_predicts_with_dense_output_and_chooses_as_without(leak_controller):
    """The closed-loop demo's controllers give their predictor a solver with dense output
    (``SolverConfig.sampling()``) or without (``standard()``); on a few ticks of the
    nominal controller both steppings pick the same commands (their predictions differ
    by tens of Pa, far below the candidates' spread)."""
    import mpc_tracking
    import numpy as np

    model, theta, rig = leak_controller
    chosen = {}
    for dense in (False, True):
        ctrl = mpc_tracking.Controller("nominal", model, theta, None, rig,
                                       np.random.default_rng(0), dense)
        assert ctrl.predictor.solver.dense_output is dense
        history, picks = np.zeros(4), []
        for k in range(6):
            picks.append(ctrl.step(2.0e5 + 2.0e4 * k, np.full(mpc_tracking.HORIZON_TICKS,
                                                              3.5e5), history, 0.05))
            history = np.r_[history[1:], picks[-1]]
        chosen[dense] = picks
    assert chosen[True] == chosen[False]
    assert len(set(chosen[True])) > 1  # the loop does move the command


def test_calibrated_mpc_adds_its_error_band_under_the_limit(leak_controller):
    """``calibrated`` tests the draws' quantile plus the fitted k-step error band against
    the limit: with a band of about 30 kPa, just under the limit with the reference above
    it, it does not fill as the nominal one does; without a band it refuses to start;
    ``calibrated_near`` drops the band after ``BAND_TICKS``."""
    import mpc_tracking
    import numpy as np

    from pneubayes.inference.error_band import PredictionErrorBand
    model, theta, rig = leak_controller
    h = mpc_tracking.HORIZON_TICKS
    rng = np.random.default_rng(0)
    pred = np.full((200, h + 1), 3e5)
    band = PredictionErrorBand(0.95).fit(pred, pred + np.abs(rng.normal(0, 15e3, pred.shape)),
                                         mpc_tracking.DT_S)
    assert band.margin_Pa_[1:].min() > 20e3
    with pytest.raises(ValueError, match="PredictionErrorBand"):
        mpc_tracking.Controller("calibrated", model, theta, None, rig, rng, True)
    picks = {}
    for kind in ("nominal", "calibrated", "calibrated_near"):
        ctrl = mpc_tracking.Controller(kind, model, theta, None, rig,
                                       np.random.default_rng(0), True, band)
        picks[kind] = ctrl.step(mpc_tracking.P_MAX_PA - 10e3, np.full(h, 5.0e5),
                                np.zeros(4), 0.05)
    assert picks["nominal"] > 0.0  # fills towards the limit
    assert picks["calibrated"] < picks["nominal"]
    assert picks["calibrated_near"] < picks["nominal"]


def test_calibrated_online_mpc_learns_the_loops_own_prediction_errors(leak_controller):
    """``calibrated_online`` predicts, each tick, the window that ended now from the
    reading HORIZON_TICKS ago under the commands applied since (with its point
    estimate), and refits its band every BAND_REFIT_TICKS on those errors and the
    calibration's: a plant whose reading climbs 1 kPa a tick whatever the commands (the
    model's pressure does not) raises the band."""
    import mpc_tracking
    import numpy as np

    from pneubayes.inference.error_band import PredictionErrorBand
    model, theta, rig = leak_controller
    h = mpc_tracking.HORIZON_TICKS
    rng = np.random.default_rng(0)
    pred = np.full((60, h + 1), 3e5)
    meas = pred + rng.normal(0, 500.0, pred.shape)
    meas[:, 0] = pred[:, 0]
    band = PredictionErrorBand(0.95).fit(pred, meas, mpc_tracking.DT_S)
    with pytest.raises(ValueError, match="point estimate"):
        mpc_tracking.Controller("calibrated_online", model, theta, None, rig, rng, True, band)
    ctrl = mpc_tracking.Controller("calibrated_online", model, theta, None, rig, rng, True,
                                   band, theta)
    applied, p_now = [], 3e5
    n = h + mpc_tracking.BAND_REFIT_TICKS
    for k in range(n):
        u = ctrl.step(p_now + 1e3 * k, np.full(h, 3e5), np.array(applied) if applied
                      else None, 0.05)
        applied.append(u)
    assert ctrl.pending == []  # its n - h windows went into the one refit:
    assert ctrl.band.predicted_Pa_.shape[0] == 60 + mpc_tracking.BAND_REFIT_TICKS
    assert band.predicted_Pa_.shape[0] == 60  # the loop's copy learnt, not the original
    assert ctrl.band.margin_Pa_[h].max() > band.margin_Pa_[h].max() + 10e3


def test_mpc_section_reads_the_floor_for_the_posterior_aware_controllers(tmp_path):
    """The floor's sentence lists the posterior-aware controllers with fewer violations
    than the nominal in total, each with the verdict of its paired interval; not the
    nominal on the other model or the back-offs."""
    _mpc_results(tmp_path / "out")
    text = "\n".join(make_paper.mpc_section(tmp_path / "out", tmp_path / "paper", False))
    floor = next(line for line in text.splitlines()
                 if line.startswith("**The floor, read from these runs**"))
    # made-up ticks: nominal 30 + 20; calibrated_online 4 + 2; chance 1 + 0
    assert "`calibrated_online` 6 against 50 ticks (fewer on 2 of 2 seeds), tracking" in floor
    assert "`chance` 1 against 50 ticks" in floor
    assert "delay_nominal" not in floor and "backoff" not in floor
    assert "`posterior` 37 against 50" in floor  # fewer in total, if not on every seed


def test_mpc_section_reports_the_changing_plant_and_its_floor(tmp_path):
    """The changing_plant runs: their table, the paired differences and the floor read
    from them (fewer violations online than frozen, tracking equal within the seeds)."""
    import mpc_tracking

    sc = mpc_tracking.SCENARIOS["changing_plant"]
    p_max = mpc_tracking.P_MAX_PA
    ticks = {"delay_nominal": (30, 20, 25, 10, 40), "delay_frozen": (20, 15, 20, 8, 30),
             "delay_chance": (10, 5, 8, 2, 9), "delay_online": (0, 1, 0, 0, 2)}
    rmse = {"delay_nominal": 40e3, "delay_frozen": 40.2e3, "delay_chance": 41e3,
            "delay_online": 40.1e3}
    change = {**sc["change"], "true_per_tick": [1e-5] * 400 + [4e-6] * 801}

    def seed(s):
        controllers = {}
        for k in sc["controllers"]:
            e = rmse[k] + 100.0 * s * (1 if k == "delay_online" else -1)
            controllers[k] = {"tracking_rmse_Pa": e, "ticks_above_limit": ticks[k][s],
                              "ticks_above_limit_after_change": ticks[k][s],
                              "largest_excess_Pa": 500.0 * ticks[k][s],
                              "pressure_Pa": [p_max - e] * 1201,
                              "compute_ms_per_tick_median": 9.0}
        controllers["delay_online"]["tracked"] = {
            "dead_volume_m3": [[0.9e-5, 1e-5, 1.1e-5]] * 500 + [[3.8e-6, 4.2e-6, 4.4e-6]] * 701}
        return {"seed": s, "reference_Pa": [p_max] * 1201, "change": change,
                "controllers": controllers}

    results = [seed(s) for s in range(5)]
    folder = tmp_path / "out" / "mpc_changing"
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({
        "seeds": list(range(5)), "quick": False, "scenario": "changing_plant",
        "change": sc["change"], "varying": sc["varying"], "online": mpc_tracking.ONLINE,
        "setpoint_range_Pa": list(sc["setpoint_range_Pa"]),
        "controllers": mpc_tracking.summarise(results, "changing_plant"),
        "provenance": {"git_revision": "abc"}}))
    text = "\n".join(make_paper._changing_plant_text(folder, tmp_path / "paper"))
    assert "| delay_online | 0, 1, 0, 0, 2 | 3 |" in text
    assert "| `delay_online` | `delay_frozen` | 3 / 93 (5 of 5) |" in text
    assert "3 against 93 ticks above the limit over 5 seeds (fewer on 5 of 5)" in text
    # online 40.1 + 0.1 s kPa against frozen 40.2 - 0.1 s: the difference runs from -0.1
    # to +0.7 kPa, its interval across 0: equal within the seeds' spread
    assert "capped tracking equal within the seeds' spread" in text and ": met." in text
    assert ("seed 0: 0.42 x against 0.40 x; within 20 % first 0.50 s after the change, for "
            "good from 0.50 s; from 1 s after it 1.05 x the plant's change (1.05-1.05); its "
            "volume before the change 1.00 x the plant's") in text


def test_openform_section_reports_each_set_with_its_floors_and_revision(tmp_path):
    """Built from a set's summary.json alone: every case's row, the floor check, the seed
    and revision; with no summary it says what to run."""
    import openform_blind

    out = tmp_path / "out"
    missing = "\n".join(make_paper.openform_section(out, tmp_path / "p", False))
    assert "*Missing:" in missing and "openform_blind.py --set N" in missing
    case = {"name": "t00_AIR37_valve1_SpoolUnderlap", "cylinder": "AIR37", "valve": "valve1",
            "hidden": ["SpoolUnderlap"], "named_catalogue": ["spool_lag"],
            "stand_ins": ["spool_lag"], "found_terms": ["inlet_drop*spool_hinge_up"],
            "no_stand_in": False, "clean_control": None, "rmse_base_Pa": 5000.0,
            "rmse_final_Pa": 1500.0, "noise_floor_Pa": 500.0, "gap_shrink": 0.7778,
            "final_over_noise": 3.0}
    control = dict(case, name="t01_SMC_valve2_none", cylinder="SMC", valve="valve2",
                   hidden=[], named_catalogue=[], stand_ins=[], found_terms=[],
                   no_stand_in=True, clean_control=True, rmse_base_Pa=510.0,
                   rmse_final_Pa=510.0, noise_floor_Pa=505.0, gap_shrink=None,
                   final_over_noise=1.01)
    cases = [case, control]
    floors, _ = openform_blind.summarise(cases)
    (out / "openform" / "set3").mkdir(parents=True)
    (out / "openform" / "set3" / "summary.json").write_text(json.dumps({
        "blind_set": 3, "seed": 1796214872, "floors": floors, "not_finished": ["t02"],
        "cases": cases, "provenance": {"git_revision": "abcdef123456", "numpy": "2.4"}}))
    text = "\n".join(make_paper.openform_section(out, tmp_path / "p", False))
    assert "**Set 3** (seed 1796214872; Iso6358Ports, SpoolSlewLimit" in text
    assert "`abcdef1`" in text and "numpy 2.4" in text
    assert "| t00_AIR37_valve1_SpoolUnderlap | AIR37/valve1 | SpoolUnderlap | spool_lag |" in text
    assert "5000 -> 1500 | 500 | 78 % | 3.00 |" in text
    assert "no catalogue stand-in in 0 of 1" in text and "in 1 of 1 (floor: all)" in text
    assert "Not finished when the set was reported: t02." in text


def test_the_refit_paragraph_gives_both_conformal_bands(tmp_path):
    """The ventilator's online refit: the draws' conformal band and the mode's, each
    with its coverage and width, in the table and the text (a set without the mode's
    band, from an older run, shows dashes)."""
    def one(mode=True):
        s = {"protocol_rmse_Pa": {"setpoint": 272.0, "frozen": 421.0, "online_refit": 37.0,
                                  "refit_without_anchor": 37.0},
             "chosen": {"relative_sd": 1.0, "error_Pa": 30.0}, "band_sd_Pa": 43.0,
             "online_over_setpoint": 0.136, "noise_floor_Pa": 7.0, "coverage_90": 1.0,
             "band_90_median_width_Pa": 1464.0, "conformal_coverage_90": 0.96,
             "conformal_band_90_median_width_Pa": 610.0, "refit_seconds": {"median": 0.86},
             "per_window_online_rmse_Pa": [20.0, 30.0, 80.0]}
        if mode:
            s.update(mode_conformal_coverage_90=0.88,
                     mode_conformal_band_90_median_width_Pa=111.0)
        return s
    path = tmp_path / "refit.json"
    path.write_text(json.dumps({"seed": 67, "grid": {"relative_sd": [0.1, 1.0],
                                                     "error_Pa": [30.0]}, "n_draws": 64,
                                "sets": {"OXY": one(), "AIR": one(mode=False)}}))
    text = "\n".join(make_paper._refit_paragraph(path))
    assert "| OXY | 1, 30 Pa | 43 |" in text
    assert "| 0.96 | 610 | 0.88 | 111 | 0.86 |" in text
    assert "| 0.96 | 610 | - | - | 0.86 |" in text
    assert ("The mode's conformal band covers OXY 0.88 at a median width of 111 Pa (3.0 x "
            "the online refit's error) (target 0.90).") in text
    # an anchor of each quantity's spread over the other runs' own fits
    doc = json.loads(path.read_text())
    doc["grid"]["spread_factor"] = [0.5, 1.0]
    doc["sets"]["AIR"]["chosen"] = {"spread_factor": 0.5, "error_Pa": 100.0}
    path.write_text(json.dumps(doc))
    text = "\n".join(make_paper._refit_paragraph(path))
    assert "| AIR | 0.5 x the runs' spread, 100 Pa | 43 |" in text
    assert "at least 0.01) times 0.5, 1; error scale 30 Pa" in text
