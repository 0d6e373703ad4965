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
    assert main(["fit", str(rec), "--method", "refine", "--out", str(user),
                 "--overwrite", "-q"]) == 2
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
    for bad in ("../victim", str(tmp_path / "outside.txt"), "link/data.txt"):
        (run / "link").unlink(missing_ok=True)
        (run / "link").symlink_to(victim)
        stamp["files"] = {"model.json": "x", bad: "x"}
        (run / "run.json").write_text(json.dumps(stamp))
        capsys.readouterr()
        assert main(["fit", str(rec), "--method", "refine", "--out", str(run),
                     "--overwrite", "-q"]) == 2
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
        assert main(["fit", str(rec), "--method", "refine", "--out", str(out), "-q",
                     "--horizon", "1e-9"]) == 2
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
