"""The blind discovery study's draw and report (issue 22, item 5); the study itself
runs in experiments/, not here."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))

import blind_study  # noqa: E402


def _public(cases):
    return [{k: v for k, v in c.items() if not k.startswith("_")} for c in cases]


def test_the_draw_is_fixed_by_its_seed_and_covers_every_kind():
    a, b = blind_study.draw_cases(123), blind_study.draw_cases(123)
    assert _public(a) == _public(b)
    assert _public(a) != _public(blind_study.draw_cases(124))
    sizes = [len(c["hidden"]) for c in a]
    assert sizes.count(0) == blind_study.N_CONTROLS
    assert sizes.count(1) == len(blind_study.SINGLES)
    assert sizes.count(2) == blind_study.N_PAIRS and sizes.count(4) == blind_study.N_FOUR
    for c in a:
        assert set(c["forms"]) == set(c["hidden"])
        assert f"{c['cylinder']}:{c['valve']}" in blind_study.RIGS


def test_a_finer_plant_tube_changes_only_the_tubes_cell_count_and_shear():
    bench = blind_study.draw_cases(123)
    fine = blind_study.draw_cases(123, min_tube_cells=32, tube_unsteady_friction=1.0)
    assert [c["name"] for c in bench] == [c["name"] for c in fine]
    tubes = 0
    for a, b in zip(bench, fine):
        assert a["bench_seed"] == b["bench_seed"]
        for h in a["hidden"]:
            fa, fb = dict(a["forms"][h]), dict(b["forms"][h])
            if h == "tube_delay":
                tubes += 1
                assert 8 <= fa.pop("segments") <= 24 and fb.pop("segments") == 32
                assert fa.pop("unsteady_friction") == 0.0 and fb.pop("unsteady_friction") == 1.0
                assert b["_objects"][h].unsteady_friction == 1.0
            assert fa == fb
    assert tubes >= 1


def test_drawn_forms_stay_in_their_physical_ranges():
    import numpy as np

    rng = np.random.default_rng(0)
    for _ in range(50):
        tube = blind_study.draw_form("tube_delay", "SMC", rng)
        assert 0.4 <= tube.length_m <= 3.0 and 8 <= tube.segments <= 24
        dz = blind_study.draw_form("valve_deadzone", "SMC", rng)
        assert dz.rounding_V <= dz.halfwidth_V <= 0.5
        lag = blind_study.draw_form("sensor_lag", "SMC", rng)
        assert lag.phase == "causal" and 120 <= lag.cutoff_Hz <= 600
    with pytest.raises(ValueError, match="unknown effect 'nope'"):
        blind_study.draw_form("nope", "SMC", rng)


def test_the_report_checks_the_floors_per_kind():
    def res(hidden, named, base, final, noise=500.0):
        gap0 = base - noise
        return {"name": "x", "cylinder": "SMC", "valve": "valve1", "hidden": hidden,
                "named": named, "correct": sorted(named) == sorted(hidden),
                "planted_named": len(set(named) & set(hidden)), "rmse_base_Pa": base,
                "rmse_final_Pa": final, "noise_floor_Pa": noise,
                "gap_shrink": None if gap0 <= 0 else 1 - (final - noise) / gap0,
                "final_over_noise": final / noise}

    results = [res([], [], 520.0, 520.0), res([], ["spool_lag"], 530.0, 510.0),
               res(["tube_delay"], ["tube_delay"], 2500.0, 700.0),
               res(["valve_deadzone", "cylinder_leak"], ["valve_deadzone"], 1500.0, 900.0),
               res(list(blind_study.FOUR), ["tube_delay", "valve_deadzone",
                                            "supply_fluctuation"], 4500.0, 1300.0)]
    table, md = blind_study.summarise(results)
    assert table["control"]["nothing_named_fraction"] == 0.5
    sp = table["single/pair"]
    assert sp["all_planted_named_fraction"] == 0.5 and sp["planted_named_mean"] == 1.0
    assert sp["gap_shrink_median"] == pytest.approx((0.9 + 0.6) / 2)
    assert table["four-effect"]["planted_named_mean"] == 3.0
    assert "nothing named in 50 % (floor 90 %)" in md


def test_case_option_runs_only_the_named_cases_and_writes_no_summary(tmp_path, monkeypatch):
    ran = []

    def fake_run(case, args, root):
        ran.append(case["name"])
        return {"name": case["name"], "named": []}

    monkeypatch.setattr(blind_study, "run_case", fake_run)
    names = [c["name"] for c in blind_study.draw_cases(123)]
    prefix = names[-1].split("_")[0]
    assert blind_study.main(["--out", str(tmp_path), "--seed", "123", "--case", prefix,
                             "--case", names[0]]) == 0
    assert ran == [names[0], names[-1]]  # in the draw's order
    assert sorted(p.stem for p in (tmp_path / "cases").glob("*.json")) == sorted(ran)
    assert not (tmp_path / "summary.json").exists()
    # a second call reads them from the cache
    blind_study.main(["--out", str(tmp_path), "--seed", "123", "--case", prefix])
    assert ran == [names[0], names[-1]]


def test_case_option_names_an_unknown_case(tmp_path, capsys):
    with pytest.raises(SystemExit):
        blind_study.main(["--out", str(tmp_path), "--seed", "123", "--case", "b99"])
    assert "b99" in capsys.readouterr().err


def test_addition_gains_check_each_added_effect_against_the_gain_floor():
    ledger = [{"step": 0, "action": "fit base", "heldout_rmse_Pa": 1500.0},
              {"step": 1, "action": "pass", "effect": "tube_delay", "gap_closed": 0.9},
              {"step": 2, "action": "add", "effect": "tube_delay",
               "heldout_rmse_before_Pa": 1500.0, "heldout_rmse_after_Pa": 600.0},
              {"step": 3, "action": "add", "effect": "spool_lag",
               "heldout_rmse_before_Pa": 600.0, "heldout_rmse_after_Pa": 597.0}]
    gains = blind_study.addition_gains({"name": "c", "noise_floor_Pa": 500.0,
                                        "ledger": ledger}, 0.01, 0.01)
    assert [g["effect"] for g in gains] == ["tube_delay", "spool_lag"]
    # the tube: gap 1000 Pa, so 1 % of it (10 Pa) is the larger floor; gain 900 Pa
    assert gains[0]["least_gain_Pa"] == pytest.approx(10.0) and gains[0]["meets"]
    # the spool: gap 100 Pa; 1 % of the noise (5 Pa) is the larger floor; gain 3 Pa
    assert gains[1]["gain_Pa"] == pytest.approx(3.0)
    assert gains[1]["least_gain_Pa"] == pytest.approx(5.0) and not gains[1]["meets"]
