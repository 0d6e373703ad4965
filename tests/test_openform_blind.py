"""The open-form blind set's draw and report (experiments/openform_blind.py); the set
itself runs in experiments/, not here."""

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))

import openform_blind  # noqa: E402

from pneubayes.bench.forms import OUT_OF_CATALOGUE, form_from_dict  # noqa: E402
from pneubayes.bench.sensors import SensorChain  # noqa: E402


@pytest.mark.parametrize("blind_set", [pytest.param(n, marks=pytest.mark.slow)
                                       for n in (1, 2, 3, 4, 5, 6)]
                         + [7])  # (the spent sets' lists in the slow tier)
def test_list_gives_every_form_on_two_rigs_and_two_controls_with_the_seed(blind_set):
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / "openform_blind.py"),
                          "--list", "--set", str(blind_set)], capture_output=True, text=True,
                         check=True, cwd=ROOT / "experiments").stdout
    cases = [json.loads(line) for line in out.splitlines()]
    assert {c["seed"] for c in cases} == {openform_blind.SET_SEEDS[blind_set]}
    assert {c["blind_set"] for c in cases} == {blind_set}
    forms = {}
    for c in cases:
        for name, rec in c["forms"].items():
            f = form_from_dict(rec)
            # (set 3's ISO 6358 ports became a realistic form of `critical_ratio` afterwards)
            assert (f.catalogue_name is None or name == "Iso6358Ports") \
                and type(f).__name__ == name
            forms.setdefault(name, set()).add(f"{c['cylinder']}:{c['valve']}")
    assert len(forms) >= 4 and set(forms) == set(openform_blind.SET_FORMS[blind_set])
    assert all(len(rigs) >= 2 for rigs in forms.values())
    assert sum(not c["hidden"] for c in cases) >= 2
    assert len({c["name"] for c in cases}) == len(cases)
    assert {c["name"][0] for c in cases} == {openform_blind.SET_PREFIX[blind_set]}


def test_the_sets_are_disjoint_and_cover_the_out_of_catalogue_forms():
    sets = [set(forms) for forms in openform_blind.SET_FORMS.values()]
    assert sum(len(s) for s in sets) == len(set().union(*sets))  # disjoint
    # (set 3's ISO 6358 ports became a realistic form of `critical_ratio` afterwards)
    assert set().union(*sets) == set(OUT_OF_CATALOGUE) | {"Iso6358Ports"}
    assert openform_blind.OPENFORM_SEED == 69069  # set 1's record stays as it ran


def test_the_draw_is_fixed_by_its_seed_and_stays_in_physical_ranges():
    pub = openform_blind._public
    a, b = openform_blind.draw_cases(5), openform_blind.draw_cases(5)
    assert [pub(c) for c in a] == [pub(c) for c in b]
    assert [pub(c) for c in a] != [pub(c) for c in openform_blind.draw_cases(6)]
    import numpy as np
    rng = np.random.default_rng(0)
    for _ in range(30):
        r = openform_blind.draw_openform("ReliefValve", "AIR37", rng)
        assert 101_325 + 2.5e5 <= r.crack_pressure_Pa <= 101_325 + 3.8e5
        h = openform_blind.draw_openform("SpoolHysteresis", "SMC", rng)
        assert 0.08 <= h.half_band_V <= 0.3
        s = openform_blind.draw_openform("ExhaustSilencer", "AIR37", rng)
        assert 30e3 <= s.back_pressure_Pa <= 300e3 and 0.5e-6 <= s.volume_m3 <= 5e-6
        b = openform_blind.draw_openform("ScoredBarrelLeak", "SMC", rng)
        assert 0.0 < b.start_m < b.end_m <= 0.025 and 2e-8 <= b.area_m2 <= 2e-7
        w = openform_blind.draw_openform("CreepingWall", "AIR37", rng)
        assert 0.05 <= w.time_constant_s <= 1.0
        p = openform_blind.draw_openform("PilotInletValve", "SMC", rng)
        assert 20e3 <= p.min_pressure_difference_Pa <= 100e3
        c = openform_blind.draw_openform("ExhaustCheckValve", "SMC", rng)
        assert 10e3 <= c.crack_pressure_Pa <= 80e3
        k = openform_blind.draw_openform("SeatLeak", "AIR37", rng)
        assert 5e-9 <= k.area_m2 <= 5e-8
        f = openform_blind.draw_openform("InletFlowLimiter", "SMC", rng, "valve2")
        full = openform_blind._full_inlet_flow("valve2")
        assert 0.3 * full <= f.max_flow_kg_per_s <= full and 5e-4 < full < 2e-3
        d = openform_blind.draw_openform("ReleaseDelay", "AIR37", rng)
        assert 1e-3 <= d.delay_s <= 8e-3
        b = openform_blind.draw_openform("PistonSealBypass", "SMC", rng)
        assert 5e-17 <= b.conductance_kg_per_s_Pa2 <= 4e-16 and 1e-8 <= b.vent_area_m2 <= 1e-7
        e = openform_blind.draw_openform("EnergisedSealLeak", "AIR37", rng)
        assert 0.8e5 <= e.energising_pressure_Pa <= 3e5
        z = openform_blind.draw_openform("SensorZeroDrift", "SMC", rng)
        assert 2e3 <= abs(z.drift_Pa) <= 15e3 and 3.0 <= z.time_constant_s <= 30.0
        c = openform_blind.draw_openform("EndCushion", "AIR37", rng)
        assert 0.05 * 0.0375 <= c.length_m <= 0.2 * 0.0375 and 2e-8 <= c.needle_area_m2 <= 2e-7
    with pytest.raises(ValueError, match="unknown out-of-catalogue form 'Nope'"):
        openform_blind.draw_openform("Nope", "SMC", rng)


def test_classify_and_floors():
    c = openform_blind.classify(["closure"], [{"term": "max(0, p/Patm - 3.9)"}],
                                ["ReliefValve"])
    assert c["no_stand_in"] and c["found_terms"] == ["max(0, p/Patm - 3.9)"]
    c = openform_blind.classify(["cylinder_leak"], [], ["LipSealLeak"])
    assert not c["no_stand_in"] and c["stand_ins"] == ["cylinder_leak"]
    assert openform_blind.classify([], [], [])["clean_control"] is True
    assert openform_blind.classify([], [{"term": "x"}], [])["clean_control"] is False

    def res(hidden, named, terms, shrink, fon):
        return {"name": "x", "cylinder": "AIR37", "valve": "valve1", "hidden": hidden,
                **openform_blind.classify(named, terms, hidden), "rmse_base_Pa": 3000.0,
                "rmse_final_Pa": 500.0 * fon, "noise_floor_Pa": 500.0,
                "gap_shrink": shrink, "final_over_noise": fon}
    results = ([res(["ReliefValve"], [], [{"term": "t"}], 0.9, 1.2)] * 8
               + [res(["LipSealLeak"], ["cylinder_leak"], [], 0.5, 3.0)] * 2
               + [res([], [], [], None, 1.0), res([], ["sensor_lag"], [], None, 1.0)])
    floors, md = openform_blind.summarise(results)
    o = floors["out_of_catalogue"]
    assert o["no_stand_in_cases"] == 8 and o["meets"] == {
        "no_stand_in": True, "gap_shrink": True, "final_over_noise": True}
    assert floors["control"] == {"cases": 2, "errors": 0, "clean": 1, "meets": False}
    assert "no catalogue stand-in in 8 of 10 (floor 8; 0 with a stand-in kept at a bound" in md
    # a stand-in kept at a bound is not named, but it is listed, and it spoils a control
    kept = {**res(["LipSealLeak"], [], [], 0.5, 3.0), "kept_at_bound": ["cylinder_leak"]}
    floors, md = openform_blind.summarise([kept])
    assert floors["out_of_catalogue"]["kept_at_bound_cases"] == 1
    assert "(kept at a bound, not named: cylinder_leak)" in md
    assert openform_blind.classify([], [], [], ["heat_transfer"])["clean_control"] is False
    assert openform_blind.parse_settings(["rounds.max_effects=2"]) == {
        "rounds": {"max_effects": 2}}
    with pytest.raises(ValueError, match="--setting.nope: unknown key"):
        openform_blind.settings_for({"bench_seed": 1}, SimpleNamespace(
            settings=openform_blind.parse_settings(["nope=1"])), SensorChain())


def test_main_runs_caches_and_reports_with_the_loop_stubbed(tmp_path, monkeypatch):
    """The plumbing around the (hours-long) loop: bench, discovery and reading stubbed;
    a document without ``found_terms`` (no open-form stage yet) reports none."""
    calls = []

    def fake_six(cylinder, valve, seed, work, **bench):
        assert bench["duration_s"] == 13.0 and bench["forms"]
        return [Path(f"r{i}.csv") for i in range(6)], {}

    def fake_discover(recs, settings, out, log, figures):
        calls.append((recs, settings))
        return {"effects": [{"name": "cylinder_leak"}], "rmse_base_Pa": 5000.0,
                "rmse_final_Pa": 800.0, "noise_floor_Pa": 500.0, "ledger": []}

    monkeypatch.setattr(openform_blind, "six_recordings", fake_six)
    monkeypatch.setattr(openform_blind, "read_recording", lambda p: p.name)
    monkeypatch.setattr(openform_blind, "run_discover", fake_discover)
    argv = ["--out", str(tmp_path), "--smoke", "--setting", "rounds.max_effects=2"]
    assert openform_blind.main(argv) == 0
    (recs, settings), = calls
    assert recs == ["r0.csv", "r3.csv", "r4.csv", "r5.csv"] and settings.rounds.max_effects == 2
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["seed"] == openform_blind.SMOKE_SEED and summary["smoke"]
    assert "git" in json.dumps(summary["provenance"]).lower()
    (case,) = summary["cases"]
    assert case["hidden"] == ["ReliefValve"] and case["stand_ins"] == ["cylinder_leak"]
    assert case["found_terms"] == [] and case["gap_shrink"] == pytest.approx(1 - 300 / 4500)
    assert "tuning draw" in (tmp_path / "summary.md").read_text()
    assert openform_blind.main(argv) == 0 and len(calls) == 1  # read from the cache


def test_report_reads_the_cache_runs_nothing_and_names_the_unfinished(tmp_path, monkeypatch):
    cases = openform_blind.draw_cases(openform_blind.OPENFORM_SEED_2, 2)
    (tmp_path / "cases").mkdir()
    done = cases[0]
    res = openform_blind._public(done) | {
        **openform_blind.classify([], [], done["hidden"]), "named": [],
        "rmse_base_Pa": 900.0, "rmse_final_Pa": 600.0, "noise_floor_Pa": 500.0,
        "gap_shrink": 0.75, "final_over_noise": 1.2}
    (tmp_path / "cases" / f"{done['name']}.json").write_text(json.dumps(res))
    monkeypatch.setattr(openform_blind, "run_case", lambda *a: pytest.fail("ran a case"))
    assert openform_blind.main(["--set", "2", "--out", str(tmp_path), "--report"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["blind_set"] == 2 and summary["seed"] == openform_blind.OPENFORM_SEED_2
    assert [c["name"] for c in summary["cases"]] == [done["name"]]
    assert summary["not_finished"] == [c["name"] for c in cases[1:]]
    md = (tmp_path / "summary.md").read_text()
    assert md.startswith("Open-form blind set 2, seed 1796182831") and "Not finished" in md
