"""Trust at the command line: run folders that protect files, clean stops, no traceback."""

import json
import os
import signal
import threading
from pathlib import Path

import pytest
from conftest import chamber_recording

from pneubayes import interrupt
from pneubayes.cli import main
from pneubayes.io import write_recording
from pneubayes.run_folder import RunFolderError, check_file, open_run_folder, read_stamp

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ run folders
def test_a_new_or_empty_folder_starts_a_run_and_the_same_run_resumes(tmp_path):
    f = open_run_folder(tmp_path / "run", "fit", {"x": 1})
    assert not f.resumed and read_stamp(tmp_path / "run")["command"] == "fit"
    (tmp_path / "run" / "model.json").write_text("{}")
    f.record("model.json")
    again = open_run_folder(tmp_path / "run", "fit", {"x": 1})
    assert again.resumed
    check_file(tmp_path / "run", "model.json")
    (tmp_path / "run" / "model.json").write_text('{"other": 1}')
    with pytest.raises(RunFolderError, match="not the file its run produced"):
        check_file(tmp_path / "run", "model.json")
    (tmp_path / "empty").mkdir()
    assert not open_run_folder(tmp_path / "empty", "fit", {"x": 1}).resumed
    # a stamp alone: that run wrote nothing; another run may start there
    assert not open_run_folder(tmp_path / "empty", "discover", {"y": 2}).resumed
    assert read_stamp(tmp_path / "empty")["command"] == "discover"


def test_another_run_is_refused_and_overwrite_removes_only_its_files(tmp_path):
    out = tmp_path / "run"
    f = open_run_folder(out, "fit", {"x": 1})
    (out / "model.json").write_text("{}")
    (out / "mine.txt").write_text("keep me")
    f.record("model.json")
    for command, identity in (("fit", {"x": 2}), ("discover", {"x": 1})):
        with pytest.raises(RunFolderError, match="refusing to mix runs.*--overwrite"):
            open_run_folder(out, command, identity)
    with pytest.raises(RunFolderError, match="nothing to resume"):
        open_run_folder(out, "fit", {"x": 2}, resume=True)
    g = open_run_folder(out, "fit", {"x": 2}, overwrite=True)
    assert not g.resumed and not (out / "model.json").exists()
    assert (out / "mine.txt").read_text() == "keep me"
    # a folder of files no run stamped: refused, even with overwrite (issue 70)
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "summary.json").write_text("{}")
    (plain / "notes.md").write_text("mine")
    for overwrite in (False, True):
        with pytest.raises(RunFolderError, match="no pneubayes run stamped.*notes.md"):
            open_run_folder(plain, "fit", {}, overwrite=overwrite, outputs=("summary.json",))
    assert (plain / "summary.json").exists() and (plain / "notes.md").exists()
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(RunFolderError, match="is a file"):
        open_run_folder(tmp_path / "a_file", "fit", {})


def test_a_file_the_run_did_not_produce_is_refused(tmp_path):
    f = open_run_folder(tmp_path, "fit", {})
    (tmp_path / "model.json").write_text("{}")
    f.record("model.json")
    (tmp_path / "posterior.nc").write_bytes(b"from elsewhere")
    with pytest.raises(RunFolderError, match="not produced by the 'fit' run"):
        check_file(tmp_path, "posterior.nc")


# ------------------------------------------------------------------ clean stops
def test_signals_are_recorded_and_raised_at_the_next_check():
    before = signal.getsignal(signal.SIGTERM)
    with interrupt.stop_on_signals():
        interrupt.check()  # nothing requested
        os.kill(os.getpid(), signal.SIGTERM)
        assert interrupt.stop_requested() == signal.SIGTERM
        with pytest.raises(interrupt.Interrupted) as exc:
            interrupt.check()
        assert exc.value.exit_code == 143
        assert isinstance(exc.value, KeyboardInterrupt)  # not swallowed as an error
    assert signal.getsignal(signal.SIGTERM) is before
    assert interrupt.stop_requested() is None


@pytest.mark.slow
def test_sigterm_stops_a_study_cleanly_and_it_resumes(tmp_path, capsys):
    study, out = str(ROOT / "experiments" / "studies" / "smoke.toml"), tmp_path / "abl"
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM))
    timer.start()
    try:
        rc = main(["ablate", study, "--out", str(out), "--smoke", "-q"])
    finally:
        timer.cancel()
    err = capsys.readouterr().err
    assert rc == 143, err
    assert "interrupted by SIGTERM" in err and "run the same command again" in err
    assert "Traceback" not in err and not (out / "results.json").exists()
    assert not list((out / "cells").glob("*.json"))  # no cell recorded as a failure
    assert main(["ablate", study, "--out", str(out), "--smoke", "-q"]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["counts"]["ok"] == 1
    # another study into the same folder is refused
    other = tmp_path / "other.toml"
    other.write_text((ROOT / "experiments" / "studies" / "smoke.toml").read_text()
                     .replace('name = "smoke"', 'name = "other"'))
    capsys.readouterr()
    assert main(["ablate", str(other), "--out", str(out), "--smoke", "-q"]) == 2
    assert "refusing to mix runs" in capsys.readouterr().err


# ------------------------------------------------------------------ no traceback
@pytest.fixture
def rec(tmp_path):
    write_recording(chamber_recording(duration_s=0.5), tmp_path / "rec")
    return tmp_path / "rec.csv"


@pytest.mark.parametrize("argv", [
    ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--rate", "0"],
    ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--duration", "-2"],
    ["discover", "REC", "--max-effects", "-4"],
    ["discover", "REC", "--set", "=1.5"],
    ["fit", "REC", "--max-steps", "0"],
    ["simulate", "REC", "--model", "CARD", "--rtol", "nan"],
    ["ablate", "STUDY", "--workers", "0"],
])
def test_bad_options_are_refused_before_any_work(argv, tmp_path, capsys):
    argv = [a.replace("REC", "r.csv").replace("CARD", "c.json").replace("STUDY", "s.toml")
            for a in argv]
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    assert "Traceback" not in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_ablate_into_a_file_is_a_message(tmp_path, capsys):
    (tmp_path / "a_file").write_text("mine")
    study = str(ROOT / "experiments" / "studies" / "smoke.toml")
    assert main(["ablate", study, "--out", str(tmp_path / "a_file"), "-q"]) == 2
    assert "is a file" in capsys.readouterr().err
    assert (tmp_path / "a_file").read_text() == "mine"


def test_simulate_into_a_folder_or_under_a_file_is_a_message(rec, tmp_path, capsys):
    card = str(ROOT / "data" / "air37_leak_tube" / "moving" / "truth.json")
    (tmp_path / "dir.csv").mkdir()
    capsys.readouterr()
    assert main(["simulate", str(rec), "--model", card, "--out", str(tmp_path / "dir.csv"),
                 "--overwrite"]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert not list(tmp_path.glob(".*tmp"))
    (tmp_path / "f").write_text("x")
    assert main(["simulate", str(rec), "--model", card, "--out",
                 str(tmp_path / "f" / "p.csv")]) == 2
    err = capsys.readouterr().err
    assert "is a file, not a folder" in err and "Traceback" not in err


def test_bench_into_existing_recordings_names_the_flag(tmp_path, capsys):
    argv = ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--duration",
            "0.3", "--positions", "0.5", "--ranges", "5", "--out", str(tmp_path), "-q"]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "use --overwrite" in err and "overwrite=True" not in err


def test_an_unexpected_failure_is_one_message_with_exit_70(rec, monkeypatch, capsys):
    import pneubayes.cli as cli

    def broken(args):
        raise RuntimeError("boom")
    monkeypatch.setattr(cli, "cmd_check", broken)
    monkeypatch.delenv("PNEUBAYES_TRACEBACK", raising=False)
    assert main(["check", str(rec)]) == 70
    err = capsys.readouterr().err
    assert "internal error (RuntimeError: boom)" in err and "Traceback" not in err


def test_short_triggered_trials_fit_on_shorter_windows(tmp_path, capsys):
    data = tmp_path / "short"
    assert main(["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "2",
                 "--duration", "0.8", "--positions", "0.25,0.75", "--ranges", "5",
                 "--out", str(data), "-q"]) == 0
    recs = [str(p) for p in sorted(data.glob("fixed_*.csv"))]
    capsys.readouterr()
    assert main(["fit", *recs, "--out", str(tmp_path / "a"), "--method", "refine", "-q"]) == 2
    assert "--horizon 2: longer than" in capsys.readouterr().err  # names the option
    out = tmp_path / "b"
    assert main(["fit", *recs, "--out", str(out), "--method", "refine", "--horizon", "0.2",
                 "--no-figures"]) == 0
    err = capsys.readouterr().err
    assert "refined 0.2-s RMSE" in err and " 2-s" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["horizon_s"] == 0.2 and summary["settings"]["stride_s"] == 0.2
    from pneubayes.cli.common import run_horizon

    assert run_horizon(out) == 0.2 and run_horizon(tmp_path) == 2.0
    # bounds sized for another rig are set per run and recorded in the card
    wide = tmp_path / "wide"
    assert main(["fit", *recs, "--out", str(wide), "--method", "refine", "--horizon", "0.2",
                 "--bounds", "dead_volume_m3=1e-7:5e-3", "--no-figures", "-q"]) == 0
    card = json.loads((wide / "model.json").read_text())
    assert card["bounds"] == {"dead_volume_m3": [1e-7, 5e-3]}
    capsys.readouterr()
    assert main(["fit", *recs, "--out", str(tmp_path / "c"), "--horizon", "0.2", "--bounds",
                 "volume=1:2"]) == 2
    assert "bounds for ['volume']" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
