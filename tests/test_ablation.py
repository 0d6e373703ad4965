"""The ablation runner: study files, cells, caching and resume, failures, executors, and
one real study end to end through the command line."""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import pytest

from pneubayes.ablation.executor import DaskExecutor, LocalExecutor
from pneubayes.ablation.runner import run_study
from pneubayes.ablation.study import StudyError, load_study, parse_study
from pneubayes.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _table(name: str, values: dict) -> list[str]:
    """A TOML table (JSON scalars and arrays are valid TOML values), sub-tables after."""
    lines = ["", f"[{name}]"]
    lines += [f"{k} = {json.dumps(v)}" for k, v in values.items() if not isinstance(v, dict)]
    for k, v in values.items():
        if isinstance(v, dict):
            lines += _table(f"{name}.{k}", v)
    return lines


def toml(grid: dict, settings: dict | None = None, name: str = "t") -> str:
    """A study file from dicts; a dict value in ``settings`` is a nested table."""
    lines = [f"name = {json.dumps(name)}"] + _table("grid", grid)
    lines += _table("settings", settings or {})
    return "\n".join(lines) + "\n"


GRID = {"rigs": ["AIR37:valve1"], "data_effects": [[]], "model_effects": [[]],
        "seeds": [0, 1, 2]}


def write_study(tmp_path, grid=None, settings=None, name="t") -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(toml(GRID if grid is None else grid, settings, name))
    return path


# ---------------------------------------------------------------- cell functions
# Module level, so that process pools and Dask can pickle them by reference.
def fake_cell(cell, workdir):
    """Records the call in OUT/calls.txt; fails for seed 1 while OUT/fail exists."""
    out = Path(workdir).parents[1]
    with open(out / "calls.txt", "a") as fh:
        fh.write(cell.id + "\n")
    if cell.seed == 1 and (out / "fail").exists():
        raise RuntimeError("planted failure")
    if cell.seed == 2 and (out / "interrupt").exists():
        raise KeyboardInterrupt
    Path(workdir).mkdir(parents=True, exist_ok=True)
    (Path(workdir) / "scratch.txt").write_text("x")
    return {"metrics": {"rmse_Pa": 100.0 + cell.seed, "noise_floor_Pa": float("nan")}}


def unserialisable_cell(cell, workdir):
    return {"metrics": {"rmse_Pa": object()}}


def calls(out: Path) -> list[str]:
    f = out / "calls.txt"
    return f.read_text().split() if f.exists() else []


# ---------------------------------------------------------------- study files
def test_example_studies_parse():
    study = load_study(ROOT / "experiments" / "studies" / "smoke.toml")
    assert study.name == "smoke" and study.n_cells == len(study.cells()) == 4
    for path in sorted((ROOT / "experiments" / "studies").glob("*.toml")):
        assert load_study(path).n_cells >= 1
    table3 = load_study(ROOT / "experiments" / "studies" / "table3.toml")
    assert table3.settings.discovery.search.n_bags == 40


def test_nested_tables_are_the_librarys_own_settings_over_the_studys_defaults():
    """``[settings.fit.sampler]`` changes the sampler's keys it names and keeps the
    study's other defaults (4000 emcee steps); ``[settings.discovery]`` is the loop's
    own DiscoverySettings; both are validated by those dataclasses."""
    from pneubayes.discovery.settings import DiscoverySettings, RoundSettings, SearchSettings

    study = parse_study(toml(GRID, {"fit": {"sampler": {"n_walkers": 48},
                                            "refine_max_nfev": 30},
                                    "discovery": {"search": {"n_bags": 12},
                                                  "rounds": {"max_effects": 2}}}), "n.toml")
    s = study.settings
    assert s.fit.sampler.n_walkers == 48 and s.fit.sampler.max_steps == 4000
    assert s.fit.refine_max_nfev == 30
    assert s.discovery == DiscoverySettings(search=SearchSettings(n_bags=12),
                                            rounds=RoundSettings(max_effects=2))
    default = parse_study(toml(GRID), "d.toml").settings
    assert default.fit.sampler.max_steps == 4000 and default.discovery == DiscoverySettings()


@pytest.mark.parametrize("grid, settings, key, why", [
    ({**GRID, "data_effects": [["tube_dela"]]}, {}, "grid.data_effects[0][0]",
     "unknown effect 'tube_dela'"),
    ({**GRID, "model_effects": [[], ["spool_lag", 3]]}, {}, "grid.model_effects[1][1]",
     "expected an effect name"),
    ({**GRID, "model_effects": ["discovr"]}, {}, "grid.model_effects[0]", "discover"),
    ({**GRID, "rigs": ["AIR38:valve1"]}, {}, "grid.rigs[0]", "unknown cylinder 'AIR38'"),
    ({**GRID, "rigs": ["AIR37:valve3"]}, {}, "grid.rigs[0]", "unknown valve 'valve3'"),
    ({**GRID, "rigs": ["AIR37"]}, {}, "grid.rigs[0]", "CYLINDER:VALVE"),
    ({**GRID, "seeds": []}, {}, "grid.seeds", "empty"),
    ({**GRID, "seeds": [0, 0]}, {}, "grid.seeds[1]", "duplicate"),
    ({**GRID, "seeds": [True]}, {}, "grid.seeds[0]", "expected an integer"),
    ({**GRID, "seeds": 3}, {}, "grid.seeds", "expected a list"),
    ({**GRID, "protocols": ["moving", "still"]}, {}, "grid.protocols[1]", "unknown value"),
    ({**GRID, "command_ranges_V": [7.0]}, {}, "grid.command_ranges_V[0]", "<= 5"),
    ({**GRID, "data_forms": ["real"]}, {}, "grid.data_forms[0]", "catalogue, realistic"),
    ({k: v for k, v in GRID.items() if k != "rigs"}, {}, "grid.rigs", "missing"),
    ({**GRID, "rig": ["AIR37:valve1"]}, {}, "grid.rig", "unknown key"),
    (GRID, {"duration_s": "20"}, "settings.duration_s", "expected a number"),
    (GRID, {"duration_s": -1}, "settings.duration_s", "must be > 0"),
    (GRID, {"durations": 20}, "settings.durations", "unknown key"),
    (GRID, {"method": "nuts"}, "settings.method", "lsq, refine, mcmc"),
    (GRID, {"supply": "regulated"}, "settings.supply", "measured, nominal"),
    (GRID, {"fit_positions": [0.5, 1.5]}, "settings.fit_positions[1]", "<= 1"),
    (GRID, {"fit_command_ranges_V": []}, "settings.fit_command_ranges_V", "empty"),
    (GRID, {"duration_s": 1.5}, "settings.horizon_s", "do not fit"),
    (GRID, {"fit": {"sampler": {"max_steps": 2.5}}}, "settings.fit.sampler.max_steps",
     "expected an integer"),
    (GRID, {"fit": {"sampler": {"max_step": 10}}}, "settings.fit.sampler.max_step",
     "unknown key; SamplerSettings has"),
    (GRID, {"fit": {"sampler": {"max_steps": 0}}}, "settings.fit.sampler",
     "SamplerSettings.max_steps must be >= 1"),
    (GRID, {"discovery": {"search": {"min_inclusion": 2.0}}}, "settings.discovery.search",
     "min_inclusion must be in (0, 1]"),
    (GRID, {"discovery": {"search": {"grid": {"strengths": {"tube": [0.001]}}}}},
     "settings.discovery.search.grid", "unknown effect 'tube'"),
    (GRID, {"discovery": {"seed": 3}}, "settings.discovery.seed", "set by each cell"),
    (GRID, {"fit": {"horizon_s": 1.0}}, "settings.fit.horizon_s", "settings.horizon_s"),
    (GRID, {"fit": "fast"}, "settings.fit", "expected a table of FitSettings"),
    ({**GRID, "model_effects": ["discover"]}, {"duration_s": 7.0}, "settings.duration_s",
     "needs at least 7"),
])
def test_invalid_studies_name_file_and_key(tmp_path, grid, settings, key, why):
    path = write_study(tmp_path, grid, settings, name="bad")
    with pytest.raises(StudyError) as err:
        load_study(path)
    msg = str(err.value)
    assert str(path) in msg and f"{key}:" in msg and why in msg, msg


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(StudyError, match="not found"):
        load_study(tmp_path / "missing.toml")
    bad = tmp_path / "broken.toml"
    bad.write_text("[grid\nrigs = 1\n")
    with pytest.raises(StudyError, match="broken.toml: not valid TOML"):
        load_study(bad)
    nogrid = tmp_path / "nogrid.toml"
    nogrid.write_text('name = "x"\n')
    with pytest.raises(StudyError, match=r"nogrid.toml: missing the \[grid\] table"):
        load_study(nogrid)


def test_grid_expansion_counts_defaults_and_stable_ids():
    grid = {"rigs": ["AIR37:valve1", "SMC:valve2"],
            "data_effects": [[], ["tube_delay", "cylinder_leak"]],
            "data_forms": ["catalogue", "realistic"],
            "model_effects": [[], ["cylinder_leak"], "discover", "tassa"],
            "command_ranges_V": [3, 0.1], "protocols": ["fixed", "moving"], "seeds": [0, 7]}
    study = parse_study(toml(grid), "g.toml")
    cells = study.cells()
    assert len(cells) == study.n_cells == 2 * 2 * 2 * 4 * 2 * 2 * 2
    assert {c.kind for c in cells} == {"effects", "discover", "tassa"}
    assert all(c.model_effects == () for c in cells if c.kind == "tassa")
    ids = [c.id for c in cells]
    assert len(set(ids)) == len(ids)
    assert ids == [c.id for c in parse_study(toml(grid), "other.toml").cells()]
    first = cells[0]
    assert first.id.startswith("AIR37-valve1.data-none.catalogue.model-plain.u3.fixed.s0.")
    assert len(first.digest) == 8 and first.id.endswith(first.digest)
    # effects are canonical (catalogue order) whatever order the file gives
    c = next(c for c in cells if c.data_effects)
    assert c.data_effects == ("cylinder_leak", "tube_delay")
    assert "data-cylinder_leak+tube_delay" in c.id
    assert any(c.discover and c.model_effects == () and ".model-discover." in c.id
               for c in cells)
    assert any(".u0p1." in i for i in ids)
    # omitted axes take their documented defaults
    small = parse_study(toml(GRID), "s.toml")
    assert small.grid.data_forms == ("catalogue",) and small.grid.protocols == ("moving",)
    assert small.grid.command_ranges_V == (5.0,) and small.n_cells == 3


def test_hash_follows_the_settings_that_matter():
    base = parse_study(toml(GRID), "a.toml").cells()[0]
    longer = parse_study(toml(GRID, {"duration_s": 30.0}), "a.toml").cells()[0]
    assert longer.id != base.id and longer.id.rsplit(".", 1)[0] == base.id.rsplit(".", 1)[0]
    # emcee and discovery settings cannot change a refine fit of a fixed model
    same = parse_study(toml(GRID, {"fit": {"sampler": {"max_steps": 10}},
                                   "discovery": {"search": {"n_bags": 5}},
                                   "smoke_duration_s": 9.0, "eval_positions": [0.2],
                                   "leak_form": "laminar"}), "a.toml").cells()[0]
    assert same.id == base.id
    # nor can the sampler's solver: nothing is sampled
    stepping = {"fit": {"sample_solver": {"dense_output": False}}}
    assert parse_study(toml(GRID, stepping), "a.toml").cells()[0].id == base.id
    mcmc = parse_study(toml(GRID, {"method": "mcmc"}), "a.toml").cells()[0]
    mcmc2 = parse_study(toml(GRID, {"method": "mcmc", "fit": {"sampler": {"max_steps": 10}}}),
                        "a.toml").cells()[0]
    mcmc3 = parse_study(toml(GRID, {"method": "mcmc", **stepping}), "a.toml").cells()[0]
    cutoff = parse_study(toml(GRID, {"fit": {"position_cutoff_Hz": 30.0}}),
                         "a.toml").cells()[0]
    assert len({base.id, mcmc.id, mcmc2.id, mcmc3.id, cutoff.id}) == 5


def test_smoke_keeps_one_cell_with_short_recordings():
    grid = {**GRID, "model_effects": ["discover", []], "protocols": ["fixed", "moving"]}
    study = parse_study(toml(grid, {"duration_s": 20.0, "smoke_duration_s": 15.0}), "s.toml")
    smoke = study.smoke()
    assert smoke.n_cells == 1 and smoke.settings.duration_s == 15.0
    assert smoke.cells()[0].seed == 0 and smoke.cells()[0].protocol == "fixed"
    too_short = parse_study(toml(grid, {"duration_s": 20.0, "smoke_duration_s": 7.0}),
                            "s.toml")
    with pytest.raises(StudyError, match="smoke_duration_s = 7 s"):
        too_short.smoke()


# ---------------------------------------------------------------- runner
def test_cache_resume_and_outputs(tmp_path):
    study = parse_study(toml(GRID), "t.toml")
    out = tmp_path / "run"
    doc = run_study(study, out, progress=False, log=lambda m: None, cell_fn=fake_cell)
    assert len(calls(out)) == 3 and doc["counts"]["run_now"] == 3
    assert doc["counts"]["ok"] == 3 and doc["seeds"] == [0, 1, 2]
    for c in study.cells():
        res = json.loads((out / "cells" / f"{c.id}.json").read_text())
        assert res["status"] == "ok" and res["id"] == c.id and res["cell"]["seed"] == c.seed
        assert res["metrics"]["noise_floor_Pa"] is None  # NaN stored as null
        assert res["provenance"]["pneubayes"]
    assert not (out / "work").exists()  # scratch removed after success
    results = json.loads((out / "results.json").read_text())
    assert results["format"] == "pneubayes-ablation/1"
    assert results["study"]["toml"] == study.text and results["provenance"]["numpy"]
    assert [r["id"] for r in results["cells"]] == [c.id for c in study.cells()]
    rows = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    assert [float(r["rmse_Pa"]) for r in rows] == [100.0, 101.0, 102.0]
    assert {"id", "status", "cylinder", "model", "seed", "error"} <= set(rows[0])
    # a second run runs nothing new
    again = run_study(study, out, progress=False, log=lambda m: None, cell_fn=fake_cell)
    assert len(calls(out)) == 3
    assert again["counts"] == {"cells": 3, "ok": 3, "error": 0, "run_now": 0, "cached": 3}


def test_failed_cell_is_recorded_others_complete_and_rerun_retries(tmp_path):
    study = parse_study(toml(GRID), "t.toml")
    out = tmp_path / "run"
    out.mkdir()
    (out / "fail").touch()
    logs = []
    doc = run_study(study, out, progress=False, log=logs.append, cell_fn=fake_cell)
    assert doc["counts"]["ok"] == 2 and doc["counts"]["error"] == 1
    bad = next(r for r in doc["cells"] if r["status"] == "error")
    assert bad["cell"]["seed"] == 1 and bad["error"] == "RuntimeError: planted failure"
    assert "planted failure" in bad["traceback"] and "fake_cell" in bad["traceback"]
    assert any("ERROR RuntimeError" in m for m in logs)
    rows = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    assert [r["status"] for r in rows] == ["ok", "error", "ok"]
    assert rows[1]["error"] == "RuntimeError: planted failure" and rows[1]["rmse_Pa"] == ""
    (out / "fail").unlink()
    doc = run_study(study, out, progress=False, log=lambda m: None, cell_fn=fake_cell)
    assert doc["counts"]["ok"] == 3 and doc["counts"]["run_now"] == 1
    assert calls(out).count(bad["id"]) == 2 and len(calls(out)) == 4


def test_interrupt_keeps_finished_cells(tmp_path):
    study = parse_study(toml(GRID), "t.toml")
    out = tmp_path / "run"
    out.mkdir()
    (out / "interrupt").touch()
    logs = []
    with pytest.raises(KeyboardInterrupt):
        run_study(study, out, progress=False, log=logs.append, cell_fn=fake_cell)
    cells = study.cells()
    assert sorted(p.stem for p in (out / "cells").glob("*.json")) == sorted(
        c.id for c in cells[:2])
    assert not (out / "results.json").exists()
    assert any("run the study again to resume" in m for m in logs)
    (out / "interrupt").unlink()
    doc = run_study(study, out, progress=False, log=lambda m: None, cell_fn=fake_cell)
    assert doc["counts"]["run_now"] == 1 and doc["counts"]["ok"] == 3


def test_unserialisable_result_is_a_failed_cell(tmp_path):
    study = parse_study(toml({**GRID, "seeds": [0]}), "t.toml")
    doc = run_study(study, tmp_path / "run", progress=False, log=lambda m: None,
                    cell_fn=unserialisable_cell)
    assert doc["cells"][0]["status"] == "error" and "TypeError" in doc["cells"][0]["error"]


def test_local_process_pool(tmp_path):
    study = parse_study(toml({**GRID, "seeds": [0, 1]}), "t.toml")
    out = tmp_path / "run"
    out.mkdir()
    (out / "fail").touch()
    with LocalExecutor(2) as ex:
        doc = run_study(study, out, ex, progress=False, log=lambda m: None, cell_fn=fake_cell)
    assert [r["status"] for r in doc["cells"]] == ["ok", "error"]
    assert "planted failure" in doc["cells"][1]["traceback"]
    with pytest.raises(ValueError, match="workers"):
        LocalExecutor(0)


def worker_threads(_):
    """The thread pools a worker process runs (numba, then each BLAS library's)."""
    import numba
    from threadpoolctl import threadpool_info

    return numba.get_num_threads(), [pool["num_threads"] for pool in threadpool_info()]


def test_local_workers_share_the_cores_instead_of_each_taking_them_all():
    with LocalExecutor(2, threads_per_worker=1) as ex:
        numba_threads, blas_threads = ex.submit(worker_threads, 0).result()
    assert numba_threads == 1 and blas_threads and set(blas_threads) == {1}
    assert LocalExecutor(2).threads_per_worker == max(1, (os.cpu_count() or 1) // 2)
    with pytest.raises(ValueError, match="threads_per_worker"):
        LocalExecutor(2, threads_per_worker=0)


def test_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    study = parse_study(toml(GRID), "t.toml")
    out = tmp_path / "run"
    out.mkdir()
    (out / "fail").touch()
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        with DaskExecutor(cluster.scheduler_address) as ex:
            doc = run_study(study, out, ex, progress=False, log=lambda m: None,
                            cell_fn=fake_cell)
    assert [r["status"] for r in doc["cells"]] == ["ok", "error", "ok"]
    assert doc["cells"][1]["error"] == "RuntimeError: planted failure"
    assert len(calls(out)) == 3


# ---------------------------------------------------------------- end to end
def test_cli_errors(tmp_path, capsys):
    path = write_study(tmp_path, {**GRID, "rigs": ["AIR38:valve1"]}, name="bad")
    assert main(["ablate", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "pneubayes ablate: error:" in err and "bad.toml: grid.rigs[0]" in err
    ok = write_study(tmp_path, name="ok")
    assert main(["ablate", str(ok), "--out", str(tmp_path / "o"), "--workers", "2",
                 "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--workers" in capsys.readouterr().err


@pytest.mark.slow
def test_real_cells_through_the_cli(tmp_path, capsys):
    """Bench data with a tube: the model with tube_delay beats the plain model and the
    Tassa peer baseline on the held-out moving-piston recording, and reaches the noise
    floor."""
    grid = {"rigs": ["AIR37:valve1"], "data_effects": [["tube_delay"]],
            "model_effects": [[], ["tube_delay"], "tassa"], "command_ranges_V": [3.0],
            "protocols": ["moving"], "seeds": [0]}
    settings = {"duration_s": 4.0, "fit_moving_count": 0, "eval_moving_count": 1,
                "eval_command_bands_V": [0.5, 3.0]}
    path = write_study(tmp_path, grid, settings, name="tube")
    out = tmp_path / "run"
    assert main(["ablate", str(path), "--out", str(out), "-q"]) == 0
    assert "3 ok, 0 failed" in capsys.readouterr().out
    doc = json.loads((out / "results.json").read_text())
    plain, tube, tassa = doc["cells"]
    assert tassa["cell"]["model"] == "tassa" and tassa["model"]["effects"] == ["tassa"]
    assert set(tassa["model"]["parameters"]) == {f"c{i}" for i in range(10)}
    assert tube["metrics"]["rmse_Pa"] < tassa["metrics"]["rmse_Pa"] < 0.1 * 450e3
    assert plain["cell"]["model"] == "plain" and tube["model"]["effects"] == ["tube_delay"]
    for r in (plain, tube, tassa):
        m = r["metrics"]
        assert r["status"] == "ok" and math.isfinite(m["rmse_Pa"])
        assert m["windows"] == 2 and 300 < m["noise_floor_Pa"] < 800
        assert m["samples_within_3V"] == m["samples"]
        assert 0 < m["samples_within_0.5V"] < m["samples"]
        assert m["rmse_percent_of_range"] == pytest.approx(100 * m["rmse_Pa"] / 450e3)
        assert m["rmse_truth_Pa"] < 1.3 * m["noise_floor_Pa"]
    assert tube["metrics"]["rmse_Pa"] < 0.5 * plain["metrics"]["rmse_Pa"]
    assert tube["metrics"]["rmse_Pa"] < 1.5 * tube["metrics"]["noise_floor_Pa"]
    assert tube["model"]["parameters"]["tube_delay_s"] == pytest.approx(
        tube["truth"]["parameters"]["tube_delay_s"], rel=0.3)
    # resumes: nothing runs again
    assert main(["ablate", str(path), "--out", str(out), "-q"]) == 0
    assert "0 run now, 3 cached" in capsys.readouterr().out


@pytest.mark.slow
def test_example_study_smoke_mode(tmp_path, capsys):
    out = tmp_path / "smoke"
    assert main(["ablate", str(ROOT / "experiments" / "studies" / "smoke.toml"), "--smoke",
                 "--out", str(out), "-q"]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["counts"]["ok"] == 1 and doc["study"]["n_cells"] == 1
    assert math.isfinite(doc["cells"][0]["metrics"]["rmse_Pa"])


def test_a_discovery_cell_keeps_the_loops_ledger(tmp_path, monkeypatch):
    """A discovery cell's result carries the loop's ledger (every trial, its verdict and
    held-out numbers), so why an effect was or was not named can be read after the
    cell's work folder is gone."""
    import types

    import pneubayes.discovery.loop as loop
    import pneubayes.discovery.report as report
    from pneubayes.ablation.cell import fit_model

    cell = next(c for c in parse_study(toml({**GRID, "model_effects": ["discover"]}),
                                       "d.toml").cells() if c.discover)
    ledger = [{"step": 0, "action": "reject", "effect": "tube_delay",
               "heldout_rmse_before_Pa": 8716.0, "heldout_rmse_after_Pa": 8700.0}]
    result = types.SimpleNamespace(model="m", params={"dead_volume_m3": 1e-6})

    class FakeDiscovery:
        def __init__(self, settings, out, log):
            pass

        def fit(self, recordings):
            return types.SimpleNamespace(result_=result)

    monkeypatch.setattr(loop, "Discovery", FakeDiscovery)
    monkeypatch.setattr(report, "write_discovery", lambda *a, **k: {
        "effects": [], "rmse_base_Pa": 8716.0, "rmse_final_Pa": 8716.0, "ledger": ledger})
    model, params, info = fit_model(cell, [], tmp_path)
    assert info["discovered"] == [] and info["discovery_ledger"] == ledger
    assert model == "m" and params == result.params
