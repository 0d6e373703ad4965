"""Issue 70: the command line never loses a user's file, never exhausts the machine and
never accepts nonsense silently. One test per class, on tiny data, each reproducing the
trial's commands (everything here is refused before any simulation)."""

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import chamber_recording

from pneubayes.cli import main
from pneubayes.io import write_recording
from pneubayes.run_folder import LOCK, open_run_folder

ROOT = Path(__file__).resolve().parents[1]
SMOKE = str(ROOT / "experiments" / "studies" / "smoke.toml")
TRUTH = str(ROOT / "data" / "air37_leak_tube" / "moving" / "truth.json")


@pytest.fixture
def rec(tmp_path):
    write_recording(chamber_recording(duration_s=0.5), tmp_path / "rec")
    return tmp_path / "rec.csv"


def _tree(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


# ------------------------------------------------------------------ 1. files lost
def test_no_file_of_the_user_is_ever_lost(rec, tmp_path, capsys):
    # a folder of the user's (no run stamp): never emptied, not even with --overwrite
    user = tmp_path / "U"
    (user / "figures").mkdir(parents=True)
    (user / "figures" / "my.png").write_bytes(b"png")
    (user / "model.json").write_text('{"mine": 1}')
    (user / "summary.json").write_text('{"mine": 2}')
    before = _tree(user)
    assert main(["fit", str(rec), "--method", "refine", "--horizon", "0.2", "--out",
                 str(user), "--overwrite", "-q"]) == 2
    err = capsys.readouterr().err
    assert str(user) in err and "figures/" in err and "model.json" in err
    assert _tree(user) == before and not (user / LOCK).exists()
    paper = tmp_path / "P"
    (paper / "work").mkdir(parents=True)
    (paper / "work" / "thesis.tex").write_text("chapter 1")
    (paper / "cells").mkdir()
    (paper / "cells" / "notes.txt").write_text("notes")
    (paper / "results.csv").write_text("a,b\n")
    before = _tree(paper)
    assert main(["ablate", SMOKE, "--out", str(paper), "--overwrite", "-q"]) == 2
    assert _tree(paper) == before
    # a stamp listing a path outside its folder is not trusted: nothing removed
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "data.txt").write_text("precious")
    (tmp_path / "outside.txt").write_text("precious")
    run = tmp_path / "T"
    open_run_folder(run, "fit", {"other": 1}).release()
    (run / "model.json").write_text("{}")
    stamp = json.loads((run / "run.json").read_text())
    for bad in ("../victim", str(tmp_path / "outside.txt"), "link/data.txt", ".", "./"):
        (run / "link").unlink(missing_ok=True)
        (run / "link").symlink_to(victim)
        stamp["files"] = {"model.json": "x", bad: "x"}
        stamp["created"] = [bad]
        (run / "run.json").write_text(json.dumps(stamp))
        capsys.readouterr()
        assert main(["fit", str(rec), "--method", "refine", "--horizon", "0.2", "--out",
                     str(run), "--overwrite", "-q"]) == 2
        assert "not a path inside" in capsys.readouterr().err
        assert (victim / "data.txt").read_text() == "precious"
        assert (tmp_path / "outside.txt").read_text() == "precious"
        assert (run / "model.json").exists()  # nothing removed at all
    # a stamped run's own files go on --overwrite, a file of the user's beside them stays
    run2 = tmp_path / "R2"
    f = open_run_folder(run2, "fit", {"other": 1}, outputs=("model.json", "figures"))
    (run2 / "model.json").write_text("{}")
    (run2 / "figures").mkdir()
    (run2 / "figures" / "a.png").write_bytes(b"x")
    (run2 / "mine.txt").write_text("keep")
    f.record("model.json")
    f.release()
    open_run_folder(run2, "fit", {"other": 2}, overwrite=True,
                    outputs=("model.json", "figures")).release()
    assert not (run2 / "model.json").exists() and not (run2 / "figures").exists()
    assert (run2 / "mine.txt").read_text() == "keep"


def test_no_command_writes_over_its_own_inputs(rec, tmp_path, capsys):
    before = rec.read_bytes()
    assert main(["simulate", str(rec), "--model", TRUTH, "--out", str(rec),
                 "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "is the input" in err and str(rec) in err
    # through another spelling of the same path, and a sidecar
    other = tmp_path / "sub" / ".." / "rec.csv"
    (tmp_path / "sub").mkdir()
    assert main(["simulate", str(rec), "--model", TRUTH, "--out", str(other),
                 "--overwrite"]) == 2
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text("{}")
    (run / "posterior.nc").write_bytes(b"")
    assert main(["predict", str(run), str(rec), "--out", str(rec), "--overwrite"]) == 2
    # a companion of the output (p.metrics.json) that is the input's sidecar
    write_recording(chamber_recording(duration_s=0.5), tmp_path / "p.metrics")
    assert main(["predict", str(run), str(tmp_path / "p.metrics.csv"), "--out",
                 str(tmp_path / "p.csv"), "--overwrite", "--no-figure"]) == 2
    assert "is the input" in capsys.readouterr().err
    assert rec.read_bytes() == before


def test_a_busy_run_folder_names_its_holder_and_a_stale_lock_is_taken_over(
        rec, tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (out / LOCK).write_text(json.dumps({
            "pid": sleeper.pid, "host": socket.gethostname(), "command": "fit",
            "argv": ["fit", "x.csv", "--out", str(out)], "started": "2026-01-01T00:00:00Z"}))
        assert main(["fit", str(rec), "--method", "lsq", "--out", str(out), "-q",
                     "--horizon", "0.2"]) == 2
        err = capsys.readouterr().err
        assert f"pid {sleeper.pid}" in err and "pneubayes fit x.csv" in err
    finally:
        sleeper.kill()
        sleeper.wait()
    # the holder is gone: its lock is taken over, with a note
    folder = open_run_folder(out, "fit", {"x": 1}, log=print)
    assert "taking over the lock" in capsys.readouterr().out
    holder = json.loads((out / LOCK).read_text())
    assert holder["pid"] == os.getpid()
    folder.release()
    assert not (out / LOCK).exists()


# ------------------------------------------------------------------ 2. the machine
def _sidecar_beside(rec: Path, stem: Path) -> None:
    stem.with_suffix(".json").write_text(rec.with_suffix(".json").read_text())


def test_only_regular_files_of_bounded_size_are_read(rec, tmp_path, capsys, monkeypatch):
    import time

    zero = tmp_path / "z.csv"
    zero.symlink_to("/dev/zero")
    _sidecar_beside(rec, zero)
    fifo = tmp_path / "f.csv"
    os.mkfifo(fifo)
    _sidecar_beside(rec, fifo)
    sparse = tmp_path / "s.csv"
    with open(sparse, "wb") as fh:
        fh.truncate(3_000_000)
    _sidecar_beside(rec, sparse)
    t0 = time.monotonic()
    monkeypatch.setenv("PNEUBAYES_MAX_FILE_MB", "2")
    assert main(["check", str(zero), str(fifo), str(sparse), str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert time.monotonic() - t0 < 10
    assert f"{zero}: is a device" in out and f"{fifo}: is a named pipe" in out
    assert f"{sparse}: is 3 MB, over the input limit of 2 MB" in out and "--max-file-mb" in out
    assert f"{tmp_path}: is a folder" in out
    # the option overrides the environment
    assert main(["check", str(rec), "--max-file-mb", "0.001"]) == 1
    assert "over the input limit of 0.001 MB" in capsys.readouterr().out
    monkeypatch.delenv("PNEUBAYES_MAX_FILE_MB")
    assert main(["check", str(rec)]) == 0
    # a command's option lasts the command: the process's next reader has the default
    from pneubayes.io import read_recording
    from pneubayes.limits import MAX_FILE_MB, max_file_bytes

    assert main(["check", str(rec), "--max-file-mb", "0.001"]) == 1
    assert max_file_bytes() == MAX_FILE_MB * 1e6
    read_recording(rec)


@pytest.mark.parametrize("argv, says", [
    (["fit", "REC", "--method", "refine", "--horizon", "0.01", "--stride", "0.001"],
     "prediction windows"),
    (["predict", "RUN", "REC", "--horizon", "0.4", "--stride", "0.001", "--out", "P"],
     "simulated samples"),
    (["fit", "REC", "--walkers", "1000000000", "--horizon", "0.2"], "MB on disk in chain.h5"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--protocol",
      "moving", "--count", "1000000000"], "simulated samples"),
])
def test_work_is_sized_before_it_starts(argv, says, rec, tmp_path, capsys, monkeypatch):
    import pneubayes.limits as limits

    monkeypatch.setattr(limits, "MAX_WINDOWS", 200)  # the tiny recording's scale
    monkeypatch.setattr(limits, "MAX_WINDOW_SAMPLES", 20_000)
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text("{}")
    (run / "posterior.nc").write_bytes(b"")
    argv = [{"REC": str(rec), "RUN": str(run), "P": str(tmp_path / "p.csv")}.get(a, a)
            for a in argv]
    out = tmp_path / "out"
    if "--out" not in argv:
        argv += ["--out", str(out)]
    assert main([*argv, "-q"] if argv[0] != "predict" else argv) == 2
    err = capsys.readouterr().err
    assert says in err and "--force" in err
    assert not out.exists() and not (tmp_path / "p.csv").exists()


# ------------------------------------------------------------------ misuse trials
# What benchmarks/misuse_trials.py (the floor, re-run on the real CLI) found.
@pytest.mark.parametrize("argv, says", [
    # a stride under half a sample was rounded up to one sample, silently
    (["fit", "REC", "--method", "refine", "--horizon", "0.4", "--stride", "1e-6", "-q",
      "--out", "O"], "--stride 1e-06: under half a sample interval of"),
    (["predict", "RUN", "REC", "--horizon", "0.4", "--stride", "1e-5", "--out", "P"],
     "--stride 1e-05: under half a sample interval of"),
    # a prediction of 4e7 samples (2 GB) was under the old 4e8 limit
    (["predict", "RUN", "REC", "--horizon", "0.4", "--stride", "0.001", "--draws", "1000",
      "--out", "P"], "simulated samples"),
    # a setting out of range names the key the user gave
    (["discover", "REC", "--set", "forms.tube_line_segments=1000000", "-q", "--out", "O"],
     "tube_line_segments must be in 0..8"),
    (["track", "RUN", "REC", "--vary", "x", "--tick", "1e30", "--horizon", "0.1", "--out",
      "J"], "--tick 1e+30: over half of"),
    (["track", "RUN", "REC", "--vary", "x", "--horizon", "1e-9", "--out", "J"],
     "--horizon 1e-09: shorter than 4 sample intervals"),
    (["discover", "REC", "--set", "stages.open_form_min_noise_ratio=inf", "-q", "--out",
      "O"], "--set stages.open_form_min_noise_ratio: expected a finite number"),
    (["discover", "REC", "--set", "stages.open_form_min_noise_ratio=-1", "-q", "--out", "O"],
     "open_form_min_noise_ratio must be 0 (off) or >= 1"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--ranges", "6",
      "--out", "O"], "--ranges 6: must be in (0, 5] V"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--positions",
      "0.5,1e30", "--out", "O"], "--positions 1e+30: must be fractions"),
    (["ablate", "HUGE", "--dry-run", "--out", "O"], "settings.duration_s: 1e+12 s"),
    (["bench", "--cylinder", "AIR999", "--valve", "valve1", "--seed", "1", "--out", "O"],
     "--cylinder AIR999: unknown"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve9", "--seed", "1", "--out", "O"],
     "--valve valve9: unknown"),
    # a horizon longer than the recording: the fit's message named no option
    (["fit", "REC", "--method", "refine", "--horizon", "1e30", "-q", "--out", "O"],
     "--horizon 1e+30: longer than"),
    # tolerances that ask for no accuracy were accepted
    (["simulate", "REC", "--model", "TRUTH", "--rtol", "1e30", "--out", "P"], "--rtol 1e+30"),
    (["simulate", "REC", "--model", "TRUTH", "--atol", "1e30", "--out", "P"], "--atol 1e+30"),
    (["check", "REC", "--accept", ","], "--accept: names no rule"),
    (["fit", "REC", "--method", "refine", "--horizon", "0.2", "--bounds",
      "dead_volume_m3=-1:1e-5", "-q", "--out", "O"], "--bounds: Parameter dead_volume_m3"),
    (["fit", "REC", "--method", "refine", "--effects", "no_such_effect", "-q", "--out", "O"],
     "--effects: unknown effect(s) no_such_effect"),
])
def test_misuse_trial_findings_are_refused_naming_the_option(argv, says, rec, tmp_path,
                                                             capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text("{}")
    (run / "posterior.nc").write_bytes(b"")
    huge = tmp_path / "huge.toml"
    huge.write_text(Path(SMOKE).read_text().replace("duration_s = 6.0", "duration_s = 1e12"))
    argv = [{"REC": str(rec), "RUN": str(run), "P": str(tmp_path / "p.csv"), "HUGE": str(huge),
             "O": str(tmp_path / "o"), "TRUTH": TRUTH, "J": str(tmp_path / "o.json")}.get(a, a)
            for a in argv]
    assert main(argv) == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "o").exists() and not (tmp_path / "p.csv").exists()
    assert not (tmp_path / "o.json").exists()


def test_a_recording_with_no_valid_sample_is_refused_and_track_never_scores_one(
        rec, tmp_path, capsys):
    lines = rec.read_text().splitlines()
    for name, mark in (("none", lambda i: "0"), ("some", lambda i: "0" if i == 7 else "1")):
        p = tmp_path / f"{name}.csv"
        p.write_text("\n".join([lines[0] + ",valid",
                                *(r + "," + mark(i) for i, r in enumerate(lines[1:]))]) + "\n")
        _sidecar_beside(rec, p)
    assert main(["check", str(tmp_path / "none.csv")]) == 1
    assert "column 'valid': every sample is marked invalid" in capsys.readouterr().out
    assert main(["check", str(tmp_path / "some.csv")]) == 0
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text("{}")
    assert main(["track", str(run), str(tmp_path / "some.csv"), "--vary", "x",
                 "--out", str(tmp_path / "t.json")]) == 2
    assert f"{tmp_path / 'some.csv'} row 9: its 'valid' column" in capsys.readouterr().err
    assert not (tmp_path / "t.json").exists()


def test_import_never_writes_into_a_run_folder(tmp_path, capsys):
    run = tmp_path / "run"
    open_run_folder(run, "fit", {"x": 1}).release()
    (tmp_path / "OXY").mkdir()
    (tmp_path / "OXY" / "covent_pc_1.dat").write_text("")
    assert main(["import", "respiraworks", str(tmp_path / "OXY" / "covent_pc_1.dat"),
                 "--out", str(run), "--overwrite"]) == 2
    assert "is the run folder of a 'pneubayes fit'" in capsys.readouterr().err
    assert sorted(p.name for p in run.iterdir()) == ["run.json"]


def test_a_refused_import_leaves_nothing_and_a_non_finite_sample_is_refused(tmp_path,
                                                                            capsys):
    from pneubayes.io.importers.respiraworks import COLUMNS

    (tmp_path / "OXY").mkdir()
    dat = tmp_path / "OXY" / "n.dat"
    dat.write_text(" ".join(COLUMNS) + "\n" + "".join(
        f"{i * 0.01} 10 {'nan' if i == 5 else 1.0} 0 0 0.5 0.5 0.5\n" for i in range(50)))
    assert main(["import", "respiraworks", str(dat), "--out", str(tmp_path / "o")]) == 2
    assert f"{dat} line 7: not finite numbers" in capsys.readouterr().err
    assert main(["import", "gtdynamics", str(dat), "--out", str(tmp_path / "o")]) == 2
    assert "not a GTDynamics trial folder" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # not even the rig card it wrote first


def test_track_names_its_vary_option(rec, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text(Path(TRUTH).read_text())
    assert main(["track", str(run), str(rec), "--vary", "leak_area_m2", "--horizon", "0.1",
                 "--out", str(tmp_path / "t.json")]) == 2
    assert "--vary leak_area_m2: its lower bound is 0" in capsys.readouterr().err


def test_a_recording_of_one_sample_is_refused_naming_it(rec, tmp_path, capsys):
    one = tmp_path / "one.csv"
    one.write_text("\n".join(rec.read_text().splitlines()[:2]) + "\n")
    _sidecar_beside(rec, one)
    assert main(["check", str(one)]) == 1
    assert f"{one} row 2: one data row" in capsys.readouterr().out
    assert main(["simulate", str(one), "--model", TRUTH, "--out", str(tmp_path / "s.csv")]) == 2
    assert f"{one} row 2: one data row" in capsys.readouterr().err


# ------------------------------------------------------------------ 3. nonsense
def _edited(rec: Path, name: str, column: str, edit) -> Path:
    lines = rec.read_text().splitlines()
    j = lines[0].split(",").index(column)
    rows = [r.split(",") for r in lines[1:]]
    for i, r in enumerate(rows):
        r[j] = edit(i, r[j])
    out = rec.with_name(name + ".csv")
    out.write_text("\n".join([lines[0], *(",".join(r) for r in rows)]) + "\n")
    _sidecar_beside(rec, out)
    return out


def test_impossible_samples_and_settings_are_errors_naming_where(rec, tmp_path, capsys):
    big = _edited(rec, "big", "pressure_Pa", lambda i, v: "1e300" if i == 100 else v)
    ns = _edited(rec, "ns", "time_s", lambda i, v: repr(float(v) * 1e-6))
    odd = _edited(rec, "odd", "time_s", lambda i, v: v)
    odd.with_suffix(".json").write_text(json.dumps(
        {**json.loads(rec.with_suffix(".json").read_text()), "format": 42}))
    assert main(["check", str(big), str(ns), str(odd)]) == 1
    out = capsys.readouterr().out
    assert "odd.json key 'format': unknown format 42" in out
    assert f"{big} row 102: column 'pressure_Pa': 1e+300 Pa" in out
    assert f"{ns} row 3: column 'time_s'" in out and "under 1 us" in out
    assert main(["fit", str(big), "--method", "refine", "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text("{}")
    (run / "posterior.nc").write_bytes(b"")
    capsys.readouterr()
    for argv, says in (
            (["predict", str(run), str(rec), "--horizon", "1e-9", "--out",
              str(tmp_path / "p.csv")], "--horizon 1e-09: shorter than 4 sample"),
            (["predict", str(run),
              str(_edited(rec, "inval", "command_V", lambda i, v: v)), "--out",
              str(tmp_path / "p.csv")], None),
            (["fit", str(rec), "--method", "refine", "--horizon", "1e-9"], "--horizon 1e-09"),
            (["predict", str(run), str(rec), "--draws", "1", "--out",
              str(tmp_path / "p.csv")], "--draws 1: the 5-95 % bands"),
            (["fit", str(rec), "--method", "refine", "--pressure-filter", "2:1e9"],
             "x the sample rate of"),
    ):
        if says is None:  # predict honours the valid column, as fit does
            stem = Path(argv[2]).with_suffix("")
            lines = Path(argv[2]).read_text().splitlines()
            Path(argv[2]).write_text("\n".join([lines[0] + ",valid", *(
                r + (",1" if i < 100 else ",0") for i, r in enumerate(lines[1:]))]) + "\n")
            argv[2] = str(stem) + ".csv"
            says = "no 0.4-s window (--horizon) lies within the samples its 'valid'"
            argv += ["--horizon", "0.4"]
        if argv[0] == "fit":
            argv += ["--out", str(tmp_path / "o")]
        assert main(argv) == 2, argv
        assert says in capsys.readouterr().err
    assert not (tmp_path / "p.csv").exists() and not (tmp_path / "o").exists()
    assert main(["discover", str(rec), "--set", "search.grid.strengths.tube_delay=[-1,-2]",
                 "--out", str(tmp_path)]) == 2
    assert "finite numbers > 0" in capsys.readouterr().err
    # a rig card's [bounds] naming no parameter
    card = json.loads((ROOT / "data" / "rigs" / "AIR37-valve2.rig.json").read_text())
    card["bounds"] = {"no_such_param": [0, 1]}
    (tmp_path / "bad.rig.json").write_text(json.dumps(card))
    with pytest.raises(SystemExit):
        main(["check", str(rec), "--rig", str(tmp_path / "bad.rig.json")])
    assert "key 'bounds': ['no_such_param']" in capsys.readouterr().err
    # an empty RespiraWorks file: a message, not a crash
    (tmp_path / "OXY").mkdir()
    (tmp_path / "OXY" / "empty.dat").write_text("")
    assert main(["import", "respiraworks", str(tmp_path / "OXY" / "empty.dat"), "--out",
                 str(tmp_path / "imp")]) == 2
    assert "empty.dat: empty" in capsys.readouterr().err
    assert not (tmp_path / "imp").exists()  # a refused import leaves no empty folder


def test_a_non_finite_rmse_is_never_a_result(tmp_path):
    from pneubayes.inference.fit_folder import _non_finite_rmse

    assert _non_finite_rmse({"refined": {"rmse_Pa": float("nan"), "x": 1.0},
                             "start": {"rmse_Pa": 3.0}}) == [("refined.rmse_Pa",
                                                              pytest.approx(float("nan"),
                                                                            nan_ok=True))]
    assert _non_finite_rmse({"a": [{"rmse_Pa": 1.0}], "rmse_final_Pa": 2.0}) == []


# ------------------------------------------------------------------ 4. contradictions
@pytest.mark.parametrize("argv, says", [
    (["fit", "REC", "--model", "CARD", "--effects", "heat_transfer"], "contradict"),
    (["fit", "REC", "--effects", "heat_transfer", "--leak-form", "laminar"],
     "--leak-form laminar: only with cylinder_leak"),
    (["fit", "REC", "--effects", ",,"], "an empty name between commas"),
    (["fit", "REC", "--bounds", "dead_volume_m3=1e-5:1e-3", "--bounds",
      "dead_volume_m3=1e-5:1e-2"], "given more than once"),
    (["discover", "REC", "--set", "data.holdout_recordings=2"], "named with --held-out"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--protocol",
      "moving", "--positions", "0.5"], "--positions: only with --protocol fixed"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--count", "3"],
     "--count: only with --protocol moving"),
    (["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--leak-form",
      "laminar"], "no leak is planted"),
])
def test_contradictory_options_are_errors(argv, says, rec, tmp_path, capsys):
    argv = [{"REC": str(rec), "CARD": TRUTH}.get(a, a) for a in argv]
    assert main([*argv, "--out", str(tmp_path / "out"), "-q"]) == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ 5. property-based
# Generated recordings, option sets and --out folders, every command: exit 0, 1 or 2
# (never 70), no traceback, no input changed, no file of the user's in --out removed, and
# each example in bounded time and memory. The work itself (a fit, a simulation, a bench
# session) is stubbed: what is tested is everything a command does before it starts.
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from pneubayes.errors import PneubayesError  # noqa: E402


class _Reached(PneubayesError):
    """Every check passed: the command would start its work now."""


@pytest.fixture
def stubbed(monkeypatch):
    import pneubayes.ablation.runner as runner
    import pneubayes.bench.bench as bench
    import pneubayes.discovery.report as report
    import pneubayes.inference.pipeline as pipeline
    import pneubayes.simulation as simulation

    def reached(*args, **kwargs):
        raise _Reached("reached the work")
    for module, name in ((pipeline, "run_fit"), (pipeline, "run_predict"),
                         (report, "run_discover"), (bench, "run_bench"),
                         (simulation, "simulate"), (runner, "run_study")):
        monkeypatch.setattr(module, name, reached)


_PRESSURES = ["1e300", "-1", "0", "nan", "inf", "2e7", "1e7", "5e4", "abc", ""]
_HORIZONS = ["1e-9", "0.001", "0.004", "0.05", "0.3", "100"]
_OPTIONS = {
    "fit": [("--method", ["lsq", "refine", "mcmc", "laplace"]), ("--horizon", _HORIZONS),
            ("--stride", ["1e-9", "1e-6", "0.001", "0.1"]),
            ("--walkers", ["0", "1", "64", "1000000000"]), ("--max-steps", ["10", "1000000"]),
            ("--pressure-filter", ["2:1e9", "2:100", "1:499"]),
            ("--effects", ["", ",,", "tube_delay", "cylinder_leak,cylinder_leak",
                           "heat_transfer", "no_such"]),
            ("--leak-form", ["orifice", "laminar"]), ("--model", ["CARD"]),
            ("--bounds", ["dead_volume_m3=1e-5:1e-3", "no_such=1:2"]),
            ("--overwrite", None), ("--force", None),
            ("--max-file-mb", ["0.0001", "100"])],
    "predict": [("--horizon", _HORIZONS), ("--stride", ["1e-9", "1e-5", "0.01"]),
                ("--draws", ["1", "200"]), ("--force", None), ("--overwrite", None)],
    "discover": [("--posterior", ["laplace", "emcee", "none"]),
                 ("--set", ["search.grid.strengths.tube_delay=[-1,-2]",
                            "search.grid.strengths.tube_delay=[0.001]",
                            "search.grid.strengths.no_such=[1]", "rounds.max_effects=abc",
                            "fit.stride_s=1e-6", "fit.stride_s=0.1", "nope=1"]),
                 ("--horizon", _HORIZONS),
                 ("--overwrite", None)],
    "simulate": [("--overwrite", None), ("--max-step", ["1e-12", "0.02"])],
    "check": [("--max-file-mb", ["0.0001", "100"]), ("--accept", ["pressure-span"])],
    "bench": [("--protocol", ["fixed", "moving"]), ("--count", ["1", "1000000000"]),
              ("--positions", ["0.5", "0.1,0.9"]), ("--ranges", ["5", "0.5"]),
              ("--duration", ["0.1", "1e6"]), ("--leak-form", ["laminar"]),
              ("--effects", ["cylinder_leak", ",,", "tube_delay"]), ("--overwrite", None),
              ("--force", None)],
}


def _recording_text(data, base: Path) -> str:
    n = data.draw(st.integers(0, 60))
    dt = data.draw(st.sampled_from([1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 1.0]))
    t0 = data.draw(st.sampled_from([0.0, 1.7e9, -5.0]))
    rng = data.draw(st.randoms(use_true_random=False))
    head = base.read_text().splitlines()[0].split(",")
    valid = data.draw(st.sampled_from([None, "0", "1", "mixed"]))
    rows = []
    for i in range(n):
        row = {"time_s": repr(t0 + i * dt), "command_V": repr(rng.choice([-5.0, 0.0, 5.0])),
               "pressure_Pa": repr(rng.uniform(1.0e5, 6.0e5)),
               "supply_pressure_Pa": repr(6.0e5), "position_m": repr(0.01)}
        rows.append([row.get(c, "0") for c in head]
                    + ([] if valid is None else
                       [str(rng.randint(0, 1)) if valid == "mixed" else valid]))
    if rows and data.draw(st.booleans()):
        i = data.draw(st.integers(0, len(rows) - 1))
        rows[i][head.index("pressure_Pa")] = data.draw(st.sampled_from(_PRESSURES))
    header = head + ([] if valid is None else ["valid"])
    return "\n".join([",".join(header), *(",".join(r) for r in rows)]) + "\n"


def _property(data, seeds_dir: Path):
    import resource
    import tempfile
    import time

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        inputs = tmp / "inputs"
        inputs.mkdir()
        rec = inputs / "rec.csv"
        # hypothesis favours the first of a list; a drawn Random picks every one alike
        rnd = data.draw(st.randoms(use_true_random=False))
        kind = rnd.choice(["text", "text", "text", "text", "fifo", "zero", "dir"])
        sidecar = json.loads((seeds_dir / "rec.json").read_text())
        if data.draw(st.integers(0, 5)) == 0:
            sidecar["format"] = 42
        (inputs / "rec.json").write_text(json.dumps(sidecar))
        if kind == "text":
            rec.write_text(_recording_text(data, seeds_dir / "rec.csv"))
        elif kind == "fifo":
            os.mkfifo(rec)
        elif kind == "zero":
            rec.symlink_to("/dev/zero")
        else:
            rec.mkdir()
        (inputs / "card.json").write_text((seeds_dir / "card.json").read_text())
        run = inputs / "run"
        run.mkdir()
        (run / "model.json").write_text("{}")
        (run / "posterior.nc").write_bytes(b"")
        # --out: absent, a folder of the user's, or a stamped run with a file of the user's
        out = tmp / "out"
        state = rnd.choice(["absent", "user", "stamped"])
        if state == "stamped":
            open_run_folder(out, "fit", {"earlier": 1}, outputs=("model.json",)).release()
            (out / "model.json").write_text("{}")
        if state != "absent":
            out.mkdir(exist_ok=True)
            (out / "mine.txt").write_text("the user's")
        command = rnd.choice(sorted(_OPTIONS))
        target = rnd.choice(["fresh", "fresh", "input", "sidecar"])
        out_file = {"fresh": str(out / "p.csv"), "input": str(rec),
                    "sidecar": str(inputs / "rec.metrics.csv")}[target]
        argv = {"check": ["check", str(rec)],
                "simulate": ["simulate", str(rec), "--model", "CARD", "--out", out_file],
                "fit": ["fit", str(rec), "--out", str(out)],
                "predict": ["predict", str(run), str(rec), "--out", out_file],
                "discover": ["discover", str(rec), "--out", str(out)],
                "bench": ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1",
                          "--out", str(out)]}[command]
        pool = _OPTIONS[command]
        for option, values in rnd.sample(pool, rnd.randint(0, min(4, len(pool)))):
            argv += [option] if values is None else [option, rnd.choice(values)]
        argv = [str(inputs / "card.json") if a == "CARD" else a for a in argv]
        before = _tree(inputs) if kind != "zero" else None
        mine = _tree(out) if out.is_dir() else {}
        t0 = time.monotonic()
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse's usage errors
            rc = exc.code
        assert time.monotonic() - t0 < 30, argv
        assert rc in (0, 1, 2), argv
        if kind != "zero":
            assert _tree(inputs) == before, argv
        for name, content in mine.items():
            if name == "mine.txt":
                assert (out / name).read_bytes() == content, argv
        assert not (out / LOCK).exists(), argv
        # the peak resident memory of this process stays far from the 2-GB floor
        assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss < 2_000_000, argv


_PROPERTY = dict(derandomize=True, deadline=None, database=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture,
                                        HealthCheck.too_slow])


@settings(max_examples=40, **_PROPERTY)
@given(data=st.data())
def test_any_command_on_any_input_is_safe(stubbed, rec, data, capsys):
    _property(data, _seeds(rec))
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.slow
@settings(max_examples=10_000, **_PROPERTY)
@given(data=st.data())
def test_any_command_on_any_input_is_safe_at_length(stubbed, rec, data, capsys):
    _property(data, _seeds(rec))
    assert "Traceback" not in capsys.readouterr().err


def _seeds(rec: Path) -> Path:
    card = rec.parent / "card.json"
    if not card.exists():
        doc = json.loads(Path(TRUTH).read_text())
        doc.pop("bench", None)
        card.write_text(json.dumps(doc))
    return rec.parent


@pytest.mark.parametrize("command", ["check", "bench", "simulate", "fit", "predict",
                                     "discover", "import", "ablate", "track", "compile"])
def test_help_shows_no_literal_double_percent(command, capsys):
    # argparse %-formats an option's help, but a description only when it holds %(prog)
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "%%" not in capsys.readouterr().out
