"""Issue 70's misuse trials: bad and careless inputs to every command of the real CLI.

Every trial runs ``python -m pneubayes.cli ...`` as a subprocess (nothing stubbed) in a
sandbox of its own and is judged by the universal checks

- the exit code is never 70 (an internal error) and never a signal;
- no ``Traceback`` in stdout or stderr;
- no file outside the trial's declared output changed, appeared or disappeared (the
  sandbox's inputs are hashed before and after), and the user's files a trial puts in
  (or at) its output beforehand survive byte-identical;
- wall time under ``--timeout`` (the process group is killed there) and the child's own
  peak RSS (``os.wait4``) under ``--max-rss-mb``;

and by its expectation: ``refuse`` (exit 1 or 2 and the output names what the user gave:
the option, key, file or row) or ``accept`` (exit 0 and the named output exists). A
nonsense input that exits 0 is "nonsense accepted silently": a failure.

    python benchmarks/misuse_trials.py --out results/misuse          # all, ~15 min
    python benchmarks/misuse_trials.py --out results/misuse --only table
    python benchmarks/misuse_trials.py --list

Resumable: each trial's result is cached in OUT/trials/NAME.json (delete it, or pass
``--rerun``, to run a trial again). Writes OUT/summary.md and OUT/summary.json.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ROOT / "experiments" / "studies" / "smoke.toml"
REALDATA = ROOT.parent / "shared" / "realdata" / "respiraworks-ventilator"
GOOD = "B/fixed_u3_x50"  # the recording every bad one is made from
OTHER = "B/fixed_u5_x10"

# The base argv of each command reading a recording; {rec} is the recording, {B} the
# sandbox's shared inputs, {T} the trial's folder. Every run is small (seconds).
READERS = {
    "check": ["check", "{rec}"],
    "simulate": ["simulate", "{rec}", "--model", "{B}/B/truth.json", "--out", "{T}/out.csv"],
    "fit": ["fit", "{rec}", "--method", "refine", "--horizon", "0.5", "--no-figures", "-q",
            "--out", "{T}/out"],
    "predict": ["predict", "{B}/M", "{rec}", "--horizon", "0.5", "--draws", "20",
                "--no-figure", "--out", "{T}/out.csv"],
    "discover": ["discover", "{rec}", "--held-out", "{B}/" + OTHER + ".csv", "--horizon",
                 "0.1", "--set", "rounds.max_effects=0", "--posterior", "none",
                 "--no-figures", "-q", "--out", "{T}/out"],
    "track": ["track", "{B}/R", "{rec}", "--vary", "dead_volume_m3", "--horizon", "0.5",
              "--particles", "16", "--draws", "8", "--out", "{T}/out.json"],
}
OUTPUT = {"check": None, "simulate": "out.csv", "fit": "out", "predict": "out.csv",
          "discover": "out", "track": "out.json"}
BENCH = ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1", "--duration",
         "1", "--protocol", "moving", "--count", "1", "-q", "--out", "{T}/out"]
IMPORT = ["import", "respiraworks", "{B}/OXY/covent_pc_1.dat", "--out", "{T}/out"]
ABLATE = ["ablate", str(SMOKE), "--dry-run", "-q", "--out", "{T}/out"]
ABLATE_RUN = ["ablate", str(SMOKE), "--smoke", "-q", "--out", "{T}/out"]  # ~20 s


# ------------------------------------------------------------------ bad recordings
def _rows(B: Path) -> tuple[list[str], list[list[str]], dict]:
    lines = (B / (GOOD + ".csv")).read_text().splitlines()
    return (lines[0].split(","), [r.split(",") for r in lines[1:]],
            json.loads((B / (GOOD + ".json")).read_text()))


def _write(T: Path, header, rows, meta, name="rec") -> None:
    (T / f"{name}.csv").write_text("\n".join([",".join(header), *(",".join(r) for r in rows)])
                                   + "\n")
    if meta is not None:
        (T / f"{name}.json").write_text(json.dumps(meta, indent=1))


def _edit(column, edit):
    """A maker: the good recording with ``edit(i, value) -> value`` on one column."""
    def make(B, T):
        header, rows, meta = _rows(B)
        j = header.index(column)
        for i, r in enumerate(rows):
            r[j] = edit(i, r[j])
        _write(T, header, rows, meta)
    return make


def _meta(**changes):
    """A maker: the good recording with its sidecar's keys changed (None removes)."""
    def make(B, T):
        header, rows, meta = _rows(B)
        for k, v in changes.items():
            if v is None:
                meta.pop(k, None)
            else:
                meta[k] = v
        _write(T, header, rows, meta)
    return make


def _raw_csv(data: bytes):
    def make(B, T):
        _, _, meta = _rows(B)
        (T / "rec.csv").write_bytes(data)
        (T / "rec.json").write_text(json.dumps(meta))
    return make


def _sidecar_text(text: str):
    def make(B, T):
        header, rows, _ = _rows(B)
        _write(T, header, rows, None)
        (T / "rec.json").write_text(text)
    return make


def _columns(drop=(), add=(), rename=None):
    def make(B, T):
        header, rows, meta = _rows(B)
        for c in drop:
            j = header.index(c)
            header = header[:j] + header[j + 1:]
            rows = [r[:j] + r[j + 1:] for r in rows]
        for name, value in add:
            header = [*header, name]
            rows = [[*r, value(i) if callable(value) else value] for i, r in enumerate(rows)]
        if rename:
            header = [rename.get(c, c) for c in header]
        _write(T, header, rows, meta)
    return make


def _special(kind):
    def make(B, T):
        _, _, meta = _rows(B)
        path = T / "rec.csv"
        if kind == "folder":
            path.mkdir()
        elif kind == "fifo":
            os.mkfifo(path)
        elif kind == "devzero":
            path.symlink_to("/dev/zero")
        elif kind == "sparse":
            with open(path, "wb") as fh:
                fh.truncate(2 * 1024 ** 3)
        elif kind == "dangling":
            path.symlink_to(T / "nowhere.csv")
        if kind != "missing":
            (T / "rec.json").write_text(json.dumps(meta))
    return make


def _no_sidecar(B, T):
    header, rows, _ = _rows(B)
    _write(T, header, rows, None)


def _header_only(B, T):
    header, _, meta = _rows(B)
    _write(T, header, [], meta)


def _one_row(B, T):
    header, rows, meta = _rows(B)
    _write(T, header, rows[:1], meta)


def _three_rows(B, T):
    header, rows, meta = _rows(B)
    _write(T, header, rows[:3], meta)


def _duplicate_column(B, T):
    header, rows, meta = _rows(B)
    _write(T, [*header, "pressure_Pa"], [[*r, r[2]] for r in rows], meta)


def _semicolons(B, T):
    header, rows, meta = _rows(B)
    (T / "rec.csv").write_text("\n".join(";".join(r) for r in [header, *rows]) + "\n")
    (T / "rec.json").write_text(json.dumps(meta))


def _decimal_comma(B, T):
    header, rows, meta = _rows(B)
    (T / "rec.csv").write_text("\n".join(";".join(v.replace(".", ",") for v in r)
                                         for r in [header, *rows]) + "\n")
    (T / "rec.json").write_text(json.dumps(meta))


def _kpa_in_pa(B, T):
    header, rows, meta = _rows(B)
    for r in rows:
        r[2] = repr(float(r[2]) / 1000)
        r[3] = repr(float(r[3]) / 1000)
    _write(T, header, rows, meta)


def _time_gap(B, T):
    header, rows, meta = _rows(B)
    for r in rows[500:]:
        r[0] = repr(float(r[0]) + 3600.0)
    _write(T, header, rows, meta)


def _good(B, T):
    header, rows, meta = _rows(B)
    _write(T, header, rows, meta)


def _crlf(B, T):
    header, rows, meta = _rows(B)
    (T / "rec.csv").write_bytes("\r\n".join(",".join(r) for r in [header, *rows])
                                .encode() + b"\r\n")
    (T / "rec.json").write_text(json.dumps(meta))


# kind -> (maker, words the refusal must contain; "accept" for a recording that is fine)
BAD_RECORDINGS = {
    "missing": (_special("missing"), ["rec.csv", "not found"]),
    "folder": (_special("folder"), ["rec.csv", "folder"]),
    "fifo": (_special("fifo"), ["rec.csv", "pipe"]),
    "devzero": (_special("devzero"), ["rec.csv", "device"]),
    "dangling-link": (_special("dangling"), ["rec.csv"]),
    "sparse-2GB": (_special("sparse"), ["rec.csv", "--max-file-mb"]),
    "empty": (_raw_csv(b""), ["rec.csv"]),
    "binary": (_raw_csv(bytes(range(256)) * 64), ["rec.csv"]),
    "non-utf8": (_raw_csv(b"time_s,command_V,pressure_Pa\n0.0,0.5,1.0e5\n"
                          + b"0.001,\xff\xfe,1.0e5\n"), ["rec.csv"]),
    "header-only": (_header_only, ["rec.csv"]),
    "one-row": (_one_row, ["rec.csv"]),
    "three-rows": (_three_rows, ["rec.csv"]),
    "no-sidecar": (_no_sidecar, ["rec.json"]),
    "sidecar-not-json": (_sidecar_text("{cylinder: AIR37"), ["rec.json"]),
    "sidecar-list": (_sidecar_text("[1, 2, 3]"), ["rec.json"]),
    "sidecar-binary": (_sidecar_text("\x00\x01\x02garbage"), ["rec.json"]),
    "sidecar-format-42": (_meta(format=42), ["rec.json", "format"]),
    "sidecar-format-9": (_meta(format="pneubayes-recording/9"), ["rec.json", "format"]),
    "sidecar-no-bore": (_meta(bore_m=None), ["rec.json", "bore_m"]),
    "sidecar-bore-mm-as-m": (_meta(bore_m=9.0), ["rec.json", "bore"]),
    "sidecar-temperature-C-as-K": (_meta(temperature_K=20.0), ["rec.json", "temperature"]),
    "sidecar-temperature_C-key": (_meta(temperature_K=None, temperature_C=293.15),
                                  ["rec.json", "temperature"]),
    "sidecar-supply-bar": (_meta(supply_pressure_Pa=5.5), ["rec.json", "supply"]),
    "sidecar-supply-text": (_meta(supply_pressure_Pa="5.5 bar"), ["rec.json", "supply"]),
    "sidecar-atm-nan": (_meta(atmospheric_pressure_Pa="NaN"), ["rec.json", "atmospheric"]),
    "sidecar-unknown-unit": (_meta(format="pneubayes-recording/2", temperature_K=None,
                                   temperature_R=527.0), ["rec.json", "temperature"]),
    "sidecar-accept-nonsense": (_meta(accept_unusual=["no-such-rule"]),
                                ["rec.json", "no-such-rule"]),
    "sidecar-rig-missing": (_meta(rig="nowhere.rig.json"), ["nowhere.rig.json"]),
    "pressure-nan": (_edit("pressure_Pa", lambda i, v: "nan" if i == 100 else v),
                     ["rec.csv", "row", "pressure_Pa"]),
    "pressure-inf": (_edit("pressure_Pa", lambda i, v: "inf" if i == 100 else v),
                     ["rec.csv", "row", "pressure_Pa"]),
    "pressure-1e300": (_edit("pressure_Pa", lambda i, v: "1e300" if i == 100 else v),
                       ["rec.csv", "row", "pressure_Pa"]),
    "pressure-negative": (_edit("pressure_Pa", lambda i, v: "-5000" if i == 100 else v),
                          ["rec.csv", "row", "pressure_Pa"]),
    "pressure-zero": (_edit("pressure_Pa", lambda i, v: "0" if i == 100 else v),
                      ["rec.csv", "row", "pressure_Pa"]),
    "pressure-text": (_edit("pressure_Pa", lambda i, v: "high" if i == 100 else v),
                      ["rec.csv", "pressure_Pa"]),
    "pressure-empty-cell": (_edit("pressure_Pa", lambda i, v: "" if i == 100 else v),
                            ["rec.csv", "pressure_Pa"]),
    "pressure-kPa-in-Pa": (_kpa_in_pa, ["rec.csv", "pressure"]),
    "supply-nan": (_edit("supply_pressure_Pa", lambda i, v: "nan" if i == 7 else v),
                   ["rec.csv", "row", "supply_pressure_Pa"]),
    "command-50V": (_edit("command_V", lambda i, v: "50" if i == 10 else v),
                    ["rec.csv", "row", "command_V"]),
    "command-nan": (_edit("command_V", lambda i, v: "nan" if i == 10 else v),
                    ["rec.csv", "row", "command_V"]),
    "time-non-monotonic": (_edit("time_s", lambda i, v: "0.5" if i == 20 else v),
                           ["rec.csv", "row", "time_s"]),
    "time-repeated": (_edit("time_s", lambda i, v: "0.019" if i == 20 else v),
                      ["rec.csv", "row", "time_s"]),
    "time-nanoseconds": (_edit("time_s", lambda i, v: repr(round(float(v) * 1e9))),
                         ["rec.csv", "time_s"]),
    "time-x1e-6": (_edit("time_s", lambda i, v: repr(float(v) * 1e-6)),
                   ["rec.csv", "time_s"]),
    "time-epoch": (_edit("time_s", lambda i, v: repr(1.7e9 + float(v))), "accept"),
    "time-gap-1h": (_time_gap, ["rec.csv", "time"]),
    "valid-all-0": (_columns(add=[("valid", "0")]), ["rec.csv", "valid"]),
    "valid-2": (_columns(add=[("valid", lambda i: "2" if i == 5 else "1")]),
                ["rec.csv", "row", "valid"]),
    "missing-column": (_columns(drop=["command_V"]), ["rec.csv", "command_V"]),
    "duplicate-column": (_duplicate_column, ["rec.csv", "pressure_Pa"]),
    "renamed-column": (_columns(rename={"pressure_Pa": "Pressure"}), ["rec.csv", "pressure_Pa"]),
    "semicolons": (_semicolons, ["rec.csv"]),
    "decimal-comma": (_decimal_comma, ["rec.csv"]),
    "position-beyond-stroke": (_columns(add=[("position_m", "2.0")]), ["rec.csv", "position"]),
    "extra-column": (_columns(add=[("note", "x")]), "accept"),
    "crlf": (_crlf, "accept"),
    "good": (_good, "accept"),
}
# a short but valid recording: fine to check and simulate, too short for windows
ACCEPTED_BY = {"three-rows": {"check", "simulate"}}
# a fine recording is accepted by check and simulate (fast); the other readers run too
# long on it for a refusal trial, and the out-folder trials cover their accepting runs
ACCEPTING = {"check", "simulate", "track", "predict"}


# ------------------------------------------------------------------ out-folder states
def _user_folder(T, out):
    (T / out / "figures").mkdir(parents=True)
    (T / out / "figures" / "my.png").write_bytes(b"\x89PNG mine")
    (T / out / "model.json").write_text('{"mine": 1}')
    (T / out / "summary.json").write_text('{"mine": 2}')
    (T / out / "notes.txt").write_text("precious")
    return [f"{out}/figures/my.png", f"{out}/model.json", f"{out}/summary.json",
            f"{out}/notes.txt"]


def _user_file(T, out):
    (T / out).write_text("a file of the user's\n")
    return [out]


def _run_folder(src):
    def make(T, out, B):
        shutil.copytree(B / src, T / out)
        (T / out / "mine.txt").write_text("the user's own note in a run folder")
        return [f"{out}/mine.txt"]
    return make


# ------------------------------------------------------------------ trials
def trial(name, cls, argv, expect, says=(), makes=None, setup=None, out=None, keep=(),
          env=None, timeout=None):
    """One trial as plain data. ``argv`` after ``pneubayes``, with {B} (the shared
    inputs), {T} (this trial's folder), {rec} ({T}/rec.csv); ``out``: the output the
    command may write (relative to {T}); ``keep``: files that must survive
    byte-identical; ``setup``: (kind, arg) of what to build in {T} first."""
    return {"name": name, "cls": cls, "argv": list(argv), "expect": expect,
            "says": list(says), "makes": makes, "setup": setup, "out": out,
            "keep": list(keep), "env": env or {}, "timeout": timeout}


def _sub(argv, **kw):
    return [a.format(**kw) if "{" in a else a for a in argv]


def table_trials() -> list[dict]:
    """(a) The rows of issue 70's table "The trials that failed", as literally as
    possible."""
    fit_r = ["fit", "{B}/" + GOOD + ".csv", "--method", "refine", "--horizon", "0.5",
             "--no-figures", "-q"]
    G = "{B}/" + GOOD + ".csv"
    t = [
        trial("t-fit-overwrite-user-folder", "table", [*fit_r, "--out", "{T}/U", "--overwrite"],
              "refuse", ["{T}/U", "run.json"], setup=("out", "user_folder"), out="U"),
        trial("t-ablate-overwrite-user-folder", "table",
              ["ablate", str(SMOKE), "--out", "{T}/P", "--overwrite", "-q"], "refuse",
              ["{T}/P"], setup=("out", "paper_folder"), out="P"),
        trial("t-fit-stamp-traversal", "table", [*fit_r, "--out", "{T}/T", "--overwrite"],
              "refuse", ["../victim"], setup=("traversal", "../victim"), out="T",
              keep=["victim/data.txt", "T/model.json"]),
        trial("t-fit-stamp-absolute", "table", [*fit_r, "--out", "{T}/T", "--overwrite"],
              "refuse", ["outside.txt"], setup=("traversal", "ABS"), out="T",
              keep=["outside.txt", "T/model.json"]),
        trial("t-simulate-out-is-input", "table",
              ["simulate", "{T}/X.csv", "--model", "{B}/B/truth.json", "--out", "{T}/X.csv",
               "--overwrite"], "refuse", ["X.csv", "input"], setup=("copy", "X"),
              out="X.csv", keep=["X.csv", "X.json"]),
        trial("t-predict-out-is-input", "table",
              ["predict", "{B}/M", "{T}/X.csv", "--out", "{T}/X.csv", "--overwrite"],
              "refuse", ["X.csv", "input"], setup=("copy", "X"), out="X.csv",
              keep=["X.csv", "X.json"]),
        trial("t-check-devzero", "table", ["check", "{rec}"], "refuse", ["rec.csv", "device"],
              setup=("rec", "devzero")),
        trial("t-check-sparse-2G", "table", ["check", "{rec}"], "refuse",
              ["rec.csv", "--max-file-mb"], setup=("rec", "sparse-2GB")),
        trial("t-check-fifo", "table", ["check", "{rec}"], "refuse", ["rec.csv", "pipe"],
              setup=("rec", "fifo")),
        trial("t-fit-stride-1e-6", "table",
              ["fit", G, "--method", "refine", "--horizon", "1", "--stride", "1e-6", "-q",
               "--out", "{T}/o"], "refuse", ["--stride"], out="o"),
        trial("t-predict-stride-one-sample", "table",
              ["predict", "{B}/M", G, "--horizon", "0.5", "--stride", "0.001", "--out",
               "{T}/p.csv"], "refuse", ["--force"], out="p.csv"),
        trial("t-predict-stride-1e-5", "table",
              ["predict", "{B}/M", G, "--horizon", "0.5", "--stride", "1e-5", "--out",
               "{T}/p.csv"], "refuse", ["--stride"], out="p.csv"),
        trial("t-bench-count-1e9", "table",
              ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1",
               "--protocol", "moving", "--count", "1000000000", "--out", "{T}/o"],
              "refuse", ["--count", "--force"], out="o"),
        trial("t-fit-walkers-1e9", "table",
              ["fit", G, "--walkers", "1000000000", "--horizon", "0.5", "-q", "--out",
               "{T}/o"], "refuse", ["--walkers", "chain.h5"], out="o"),
        trial("t-predict-horizon-1e-9", "table",
              ["predict", "{B}/M", G, "--horizon", "1e-9", "--out", "{T}/p.csv"], "refuse",
              ["--horizon"], out="p.csv"),
        trial("t-import-empty-dat", "table",
              ["import", "respiraworks", "{T}/OXY/empty.dat", "--out", "{T}/o"], "refuse",
              ["empty.dat"], setup=("dat", "empty"), out="o"),
        trial("t-check-1e300", "table", ["check", "{rec}"], "refuse",
              ["rec.csv", "row", "pressure_Pa"], setup=("rec", "pressure-1e300")),
        trial("t-fit-1e300", "table", [*fit_r[:1], "{rec}", *fit_r[2:], "--out", "{T}/o"],
              "refuse", ["rec.csv", "row"], setup=("rec", "pressure-1e300"), out="o"),
        trial("t-predict-valid-all-0", "table",
              ["predict", "{B}/M", "{rec}", "--horizon", "0.5", "--out", "{T}/p.csv"],
              "refuse", ["valid"], setup=("rec", "valid-all-0"), out="p.csv"),
        trial("t-check-format-42", "table", ["check", "{rec}"], "refuse",
              ["rec.json", "format"], setup=("rec", "sidecar-format-42")),
        trial("t-check-time-x1e-6", "table", ["check", "{rec}"], "refuse",
              ["rec.csv", "time_s"], setup=("rec", "time-x1e-6")),
        trial("t-check-rig-unknown-bound", "table",
              ["check", G, "--rig", "{T}/bad.rig.json"], "refuse",
              ["bad.rig.json", "no_such_param"], setup=("rig", "unknown_bound")),
        trial("t-fit-pressure-filter-2-1e9", "table",
              [*fit_r, "--pressure-filter", "2:1e9", "--out", "{T}/o"], "refuse",
              ["--pressure-filter"], out="o"),
        trial("t-fit-horizon-1e-9", "table",
              ["fit", G, "--method", "refine", "--horizon", "1e-9", "-q", "--out", "{T}/o"],
              "refuse", ["--horizon"], out="o"),
        trial("t-fit-model-and-effects", "table",
              [*fit_r, "--model", "{B}/B/truth.json", "--effects", "heat_transfer", "--out",
               "{T}/o"], "refuse", ["--effects"], out="o"),
        trial("t-fit-leak-form-without-leak", "table",
              [*fit_r, "--effects", "heat_transfer", "--leak-form", "laminar", "--out",
               "{T}/o"], "refuse", ["--leak-form"], out="o"),
        trial("t-fit-bounds-twice", "table",
              [*fit_r, "--bounds", "dead_volume_m3=1e-7:1e-5", "--bounds",
               "dead_volume_m3=1e-7:1e-4", "--out", "{T}/o"], "refuse", ["dead_volume_m3"],
              out="o"),
        trial("t-fit-effects-commas", "table", [*fit_r, "--effects", ",,", "--out", "{T}/o"],
              "refuse", ["--effects"], out="o"),
        trial("t-discover-holdout-recordings-against-held-out", "table",
              [*_sub(READERS["discover"], rec=G, B="{B}", T="{T}"), "--set",
               "data.holdout_recordings=2"], "refuse", ["--held-out", "holdout_recordings"],
              out="out"),
        trial("t-bench-positions-moving", "table",
              [*BENCH, "--positions", "0.5"], "refuse", ["--positions"], out="out"),
        trial("t-discover-library-negative", "table",
              [*_sub(READERS["discover"], rec=G, B="{B}", T="{T}"), "--set",
               "search.grid.strengths.tube_delay=[-1,-2]"], "refuse", ["--set", "tube_delay"],
              out="out"),
        trial("t-bench-into-fit-run", "table",
              [*BENCH[:-1], "{T}/R"], "refuse", ["{T}/R", "run"],
              setup=("out", "fit_run"), out="R"),
        trial("t-predict-draws-1", "table",
              ["predict", "{B}/M", G, "--horizon", "0.5", "--draws", "1", "--out",
               "{T}/p.csv"], "refuse", ["--draws"], out="p.csv"),
        trial("t-import-same-file-twice", "table",
              ["import", "respiraworks", "{B}/OXY/covent_pc_1.dat",
               "{B}/OXY/covent_pc_1.dat", "--out", "{T}/o"], "refuse", ["covent_pc_1.dat"],
              out="o"),
        trial("t-fit-resume-edited-refined", "table",
              ["fit", "{B}/" + OTHER + ".csv", "{B}/B/fixed_u3_x50.csv", "--horizon", "0.5",
               "--walkers", "24", "--max-steps", "60", "--no-figures", "-q", "--out",
               "{T}/M"], "refuse", ["refined.json"], setup=("edited_refined", ""),
              out="M", keep=["M/chain.h5", "M/refined.json"]),
        trial("t-check-dot", "table", ["check", "{T}"], "refuse", ["{T}", "folder"]),
        trial("t-fit-folder", "table", [*fit_r[:1], "{B}/B", *fit_r[2:], "--out", "{T}/o"],
              "refuse", ["{B}/B", "folder"], out="o"),
        trial("t-check-rig-binary", "table", ["check", G, "--rig", "{T}/binary.toml"],
              "refuse", ["binary.toml"], setup=("rig", "binary")),
        trial("t-import-respiraworks-on-gtdynamics", "table",
              ["import", "respiraworks", "{T}/OXY/covent_pc_1.dat", "--out", "{T}/o"],
              "refuse", ["covent_pc_1.dat"], setup=("dat", "gtdynamics"), out="o"),
        trial("t-fit-one-row", "table", [*fit_r[:1], "{rec}", *fit_r[2:], "--out", "{T}/o"],
              "refuse", ["rec.csv"], setup=("rec", "one-row"), out="o"),
        trial("t-bench-set-nan", "table",
              [*BENCH, "--effects", "tube_delay", "--set", "tube_delay_s=nan"], "refuse",
              ["tube_delay_s"], out="out"),
        trial("t-bench-rate-1e9", "table", [*BENCH, "--rate", "1e9"], "refuse", ["--rate"],
              out="out"),
        trial("t-simulate-max-step-1e-12", "table",
              [*_sub(READERS["simulate"], rec=G, B="{B}", T="{T}"), "--max-step", "1e-12"],
              "refuse", ["--max-step"], out="out.csv"),
        trial("t-discover-tube-line-segments-1e6", "table",
              [*_sub(READERS["discover"], rec=G, B="{B}", T="{T}"), "--set",
               "forms.tube_line_segments=1000000"], "refuse", ["--set", "tube_line_segments"],
              out="out"),
        trial("t-ablate-dead-scheduler", "table",
              ["ablate", str(SMOKE), "--out", "{T}/o", "-q", "--scheduler",
               "tcp://127.0.0.1:9"], "refuse", ["127.0.0.1:9"], out="o"),
        trial("t-bench-out-file-overwrite", "table", [*BENCH[:-1], "{T}/F", "--overwrite"],
              "refuse", ["{T}/F", "not a folder"], setup=("out", "user_file"), out="F"),
        trial("t-fit-resume-absolute-paths", "table",
              ["fit", "{B}/" + OTHER + ".csv", "{B}/B/fixed_u3_x50.csv", "--horizon", "0.5",
               "--walkers", "24", "--max-steps", "60", "--no-figures", "-q", "--out",
               "{T}/M"], "accept", makes="M/model.json", setup=("out", "mcmc_run"), out="M"),
        trial("t-fit-resume-other-settings", "table",
              ["fit", "{B}/" + OTHER + ".csv", "{B}/B/fixed_u3_x50.csv", "--horizon", "0.4",
               "--walkers", "24", "--max-steps", "60", "--no-figures", "-q", "--out",
               "{T}/M"], "refuse", ["horizon"], setup=("out", "mcmc_run"), out="M",
              keep=["M/chain.h5"]),
        trial("t-check-temperature_C-293", "table", ["check", "{rec}"], "refuse",
              ["rec.json", "temperature_C"], setup=("rec", "temperature_C-293")),
        trial("t-check-pressure_kPa-holding-Pa", "table", ["check", "{rec}"], "refuse",
              ["rec.csv", "pressure_kPa"], setup=("rec", "pressure_kPa-holding-Pa")),
        trial("t-import-nonexistent", "table",
              ["import", "respiraworks", "/nope/x.dat", "--out", "{T}/o"], "refuse",
              ["/nope/x.dat"], out="o"),
        trial("t-import-binary-dat", "table",
              ["import", "respiraworks", "{T}/OXY/b.dat", "--out", "{T}/o"], "refuse",
              ["b.dat"], setup=("dat", "binary"), out="o"),
        trial("t-check-epoch", "table", ["check", "{rec}"], "accept",  # times are relative
              setup=("rec", "time-epoch")),
        trial("t-simulate-epoch", "table",
              ["simulate", "{rec}", "--model", "{B}/B/truth.json", "--out", "{T}/s.csv"],
              "accept", makes="s.csv", setup=("rec", "time-epoch"), out="s.csv"),
        trial("t-check-nanoseconds", "table", ["check", "{rec}"], "refuse",
              ["rec.csv", "time_s"], setup=("rec", "time-nanoseconds")),
        trial("t-fit-bounds-unknown-name", "table",
              [*fit_r, "--bounds", "no_such_param=0:1", "--out", "{T}/o"], "refuse",
              ["no_such_param"], out="o"),
    ]
    return t


def recording_trials() -> list[dict]:
    """(b1) Every command reading recordings x every kind of bad recording."""
    out = []
    for kind, (_, says) in BAD_RECORDINGS.items():
        for cmd, argv in READERS.items():
            if says == "accept" and cmd not in ACCEPTING:
                continue
            o = OUTPUT[cmd]
            if says == "accept" or cmd in ACCEPTED_BY.get(kind, ()):
                out.append(trial(f"r-{cmd}-{kind}", "recording", argv, "accept",
                                 makes=o, setup=("rec", kind), out=o))
            else:
                out.append(trial(f"r-{cmd}-{kind}", "recording", argv, "refuse", says,
                                 setup=("rec", kind), out=o))
    return out


def out_state_trials() -> list[dict]:
    """(b2) Every command with --out x the states its --out may be in."""
    G = "{B}/" + GOOD + ".csv"
    commands = {  # argv with --out last; output kind
        "simulate": (_sub(READERS["simulate"], rec=G, B="{B}", T="{T}")[:-1], "file"),
        "predict": (_sub(READERS["predict"], rec=G, B="{B}", T="{T}")[:-1], "file"),
        "track": (_sub(READERS["track"], rec=G, B="{B}", T="{T}")[:-1], "file"),
        "fit": (_sub(READERS["fit"], rec=G, B="{B}", T="{T}")[:-1], "folder"),
        "discover": (_sub(READERS["discover"], rec=G, B="{B}", T="{T}")[:-1], "folder"),
        "bench": (BENCH[:-1], "folder"),
        "import": (IMPORT[:-1], "folder"),
        "ablate": (ABLATE_RUN[:-1], "folder"),
    }
    t = []
    for cmd, (argv, kind) in commands.items():
        o = "out.csv" if kind == "file" else "out"
        if cmd == "track":
            o = "out.json"
        makes = o if cmd != "ablate" else o + "/results.json"
        for overwrite in (False, True):
            ow = ["--overwrite"] if overwrite else []
            sfx = "-overwrite" if overwrite else ""
            # absent: the ordinary run
            if not overwrite:
                t.append(trial(f"o-{cmd}-absent", "out-state", [*argv, "{T}/" + o],
                               "accept", makes=makes, out=o))
            # a user's folder with files (bench writes its recordings beside them: nothing
            # is replaced, and a name of theirs it would write is refused)
            if cmd == "bench" and not overwrite:
                t.append(trial(f"o-{cmd}-user-folder", "out-state", [*argv, "{T}/" + o],
                               "accept", makes=o + "/truth.json",
                               setup=("out", "user_folder"), out=o))
            elif kind == "file" or not overwrite or cmd in ("fit", "discover", "ablate"):
                t.append(trial(f"o-{cmd}-user-folder{sfx}", "out-state",
                               [*argv, "{T}/" + o, *ow], "refuse", ["{T}/" + o],
                               setup=("out", "user_folder"), out=o))
            elif cmd in ("bench", "import"):  # writing beside the user's files is asked for
                t.append(trial(f"o-{cmd}-user-folder{sfx}", "out-state",
                               [*argv, "{T}/" + o, *ow], "accept",
                               makes=None, setup=("out", "user_folder"), out=o))
            # a file of the user's
            if kind == "file" and overwrite:  # replacing it is what --overwrite asks
                t.append(trial(f"o-{cmd}-user-file{sfx}", "out-state",
                               [*argv, "{T}/" + o, *ow], "accept", makes=o,
                               setup=("out", "user_file_replaced"), out=o))
            else:
                t.append(trial(f"o-{cmd}-user-file{sfx}", "out-state",
                               [*argv, "{T}/" + o, *ow], "refuse", ["{T}/" + o],
                               setup=("out", "user_file"), out=o))
            # another command's run folder (a fit's; for fit itself a bench folder)
            src = "bench_folder" if cmd == "fit" else "fit_run"
            if cmd in ("discover", "ablate") and overwrite:  # replacing a stamped run is
                t.append(trial(f"o-{cmd}-{src}{sfx}", "out-state",  # what --overwrite asks
                               [*argv, "{T}/" + o, *ow], "accept",
                               makes=o + ("/discovery.json" if cmd == "discover"
                                          else "/results.json"), setup=("out", src), out=o))
            else:
                t.append(trial(f"o-{cmd}-{src}{sfx}", "out-state", [*argv, "{T}/" + o, *ow],
                               "refuse", ["{T}/" + o], setup=("out", src), out=o))
        # an input as the output (never accepted, --overwrite or not)
        if cmd in ("simulate", "predict", "track", "fit", "discover"):
            argv_in = [("{T}/X.csv" if a == G else a) for a in argv]
            for ow in ([], ["--overwrite"]):
                for target in ("X.csv", "X.json"):
                    t.append(trial(f"o-{cmd}-input-{target}{'-overwrite' if ow else ''}",
                                   "out-state", [*argv_in, "{T}/" + target, *ow], "refuse",
                                   ["X."], setup=("copy", "X"), out=target,
                                   keep=["X.csv", "X.json"]))
    return t


NAN, INF, NEG, ZERO, HUGE, TEXT = "nan", "inf", "-1", "0", "1e30", "abc"
ALL = (NAN, INF, NEG, ZERO, HUGE, TEXT)


def option_trials() -> list[dict]:
    """(b3) Per command, every numeric option with the values that are nonsense for its
    meaning; each must be refused naming the option."""
    G = "{B}/" + GOOD + ".csv"
    mcmc = ["fit", G, "--horizon", "0.5", "--walkers", "24", "--max-steps", "60",
            "--no-figures", "-q", "--out", "{T}/out"]
    base = {
        "check": ["check", G],
        "bench": BENCH,
        "simulate": _sub(READERS["simulate"], rec=G, B="{B}", T="{T}"),
        "fit": _sub(READERS["fit"], rec=G, B="{B}", T="{T}"),
        "predict": _sub(READERS["predict"], rec=G, B="{B}", T="{T}"),
        "discover": _sub(READERS["discover"], rec=G, B="{B}", T="{T}"),
        "track": _sub(READERS["track"], rec=G, B="{B}", T="{T}"),
        "import": IMPORT,
        "ablate": ABLATE,
        "compile": ["compile"],
    }
    outs = {"check": None, "compile": None, "simulate": "out.csv", "predict": "out.csv",
            "track": "out.json"}
    # (command, option, nonsense values); an option's values replace its default
    table = [
        ("check", "--max-file-mb", (NAN, INF, NEG, ZERO, TEXT)),
        ("check", "--accept", ("no-such-rule", ",")),
        ("bench", "--duration", ALL),
        ("bench", "--seed", (NAN, INF, NEG, HUGE, TEXT)),
        ("bench", "--count", ALL),
        ("bench", "--rate", ALL + ("1e9",)),
        ("bench", "--fine-rate", ALL + ("1500",)),  # not a multiple of --rate
        ("bench", "--pressure-noise", (NAN, INF, NEG, HUGE, TEXT)),
        ("bench", "--effects", ("no_such_effect", ",,", "tube_delay,tube_delay")),
        ("bench", "--cylinder", ("AIR999",)),
        ("bench", "--valve", ("valve9",)),
        ("simulate", "--rtol", ALL),
        ("simulate", "--atol", ALL),
        ("simulate", "--max-step", (NAN, INF, NEG, ZERO, TEXT, "1e-12")),
        ("simulate", "--max-file-mb", (NAN, INF, NEG, ZERO, TEXT)),
        ("simulate", "--accept", ("no-such-rule",)),
        ("fit", "--max-steps", ALL),
        ("fit", "--walkers", (NAN, NEG, TEXT, HUGE, "1000000000")),
        ("fit", "--seed", (NAN, INF, NEG, HUGE, TEXT)),
        ("fit", "--position-cutoff", (NAN, INF, NEG, TEXT)),
        ("fit", "--supply-cutoff", (NAN, INF, NEG, TEXT)),
        ("fit", "--pressure-filter", (NAN, TEXT, "2:nan", "2:inf", "2:-1", "2:0", "2:1e30",
                                      "0:100", "-2:100", "2.5:100", "2")),
        ("fit", "--horizon", ALL + ("1e-9",)),
        ("fit", "--stride", (NAN, INF, NEG, ZERO, TEXT, "1e-6")),
        ("fit", "--jacobian-refresh", ALL),
        ("fit", "--bounds", ("dead_volume_m3=nan:1", "dead_volume_m3=1e-5:1e-7",
                             "dead_volume_m3=inf:1", "no_such_param=0:1", TEXT,
                             "dead_volume_m3=-1:1e-5", "dead_volume_m3=1e-5")),
        ("fit", "--effects", ("no_such_effect", ",,")),
        ("fit", "--model", ("{B}/nowhere.json", "{B}/B/fixed_u3_x50.csv")),
        ("fit", "--known-from", ("{B}/nowhere", "{B}/B")),
        ("fit", "--max-file-mb", (NAN, NEG, ZERO, TEXT)),
        ("predict", "--horizon", ALL + ("1e-9",)),
        ("predict", "--stride", (NAN, INF, NEG, ZERO, TEXT, "1e-5")),
        ("predict", "--draws", ALL + ("1",)),
        ("predict", "--seed", (NAN, NEG, TEXT)),
        ("discover", "--max-effects", ("0",)),  # gone: the message names its --set
        ("discover", "--horizon", (NAN, INF, NEG, ZERO, HUGE, TEXT, "1e-9")),
        ("discover", "--seed", (NAN, NEG, TEXT)),
        ("discover", "--posterior", ("gibbs",)),
        *((("discover", "--set", tuple(f"{key}={v}" for v in values))) for key, values in (
            ("rounds.max_effects", (NAN, NEG, HUGE, TEXT)),
            ("data.holdout_fraction", ALL + ("1",)),
            ("forms.tube_line_segments", (NAN, NEG, HUGE, TEXT, "1000000")),
            ("forms.settled_ratio", (NAN, INF, NEG, TEXT)),
            ("forms.later_min_share", (NAN, NEG, HUGE, TEXT)),
            ("forms.later_screen_share", (NAN, NEG, HUGE, TEXT)),
            ("stages.pair_members", (NAN, NEG, TEXT)),
            ("stages.max_form_swaps", (NAN, NEG, TEXT)),
            ("stages.open_form_min_noise_ratio", (NAN, INF, NEG, TEXT)),
            ("search.grid.strengths.tube_delay", ("[nan]", "[inf]", "[-1]", "[0]", TEXT)),
            ("search.grid.strengths.no_such_effect", ("[1]",)),
            ("fit.sampler.n_walkers", (NAN, NEG, TEXT)),
            ("rounds.max_effcts", ("2",)),
            ("nope", ("1",)))),
        ("track", "--tick", ALL),
        ("track", "--horizon", ALL + ("1e-9",)),
        ("track", "--particles", (NAN, NEG, ZERO, HUGE, TEXT)),
        ("track", "--draws", (NAN, NEG, ZERO, HUGE, TEXT)),
        ("track", "--predict-every", (NAN, NEG, ZERO, TEXT)),
        ("track", "--noise-std", (NAN, INF, NEG, ZERO, TEXT)),
        ("track", "--prior-log-sd", (NAN, INF, NEG, ZERO, TEXT)),
        ("track", "--lookback", (NAN, INF, NEG, TEXT)),
        ("track", "--temper", ALL),
        ("track", "--vary", ("no_such_param", ",", "leak_area_m2")),
        ("track", "--seed", (NEG, TEXT)),
        ("import", "--end", (NAN, INF, NEG, ZERO, TEXT)),
        ("import", "--max-file-mb", (NAN, NEG, ZERO)),
        ("ablate", "--workers", (NAN, NEG, ZERO, HUGE, TEXT)),
        ("compile", "--jobs", (NAN, NEG, ZERO, HUGE, TEXT)),
    ]
    t = []
    for cmd, opt, values in table:
        argv = list(base[cmd])
        if opt in argv:  # the base sets it: replace, not repeat
            i = argv.index(opt)
            argv = argv[:i] + argv[i + 2:]
        if cmd == "fit" and opt in ("--max-steps", "--walkers"):
            argv = [a for a in mcmc if a not in (opt,)]
            if opt == "--walkers":
                argv = [*mcmc[:4], *mcmc[6:]]
        for v in values:
            safe = v.replace("/", "_").replace("{B}", "B").replace(",", "comma")
            name = f"x-{cmd}{opt}={safe}"
            says = [opt]
            if opt == "--bounds" and v.startswith("no_such"):
                says = ["no_such_param"]
            if opt == "--set":  # the message names --set and the key's last part
                says = ["--set", v.split("=", 1)[0].split(".")[-1]]
            if opt in ("--model", "--known-from"):  # a path: the message names it
                says = [v.format(B="")]
            t.append(trial(name, "option", [*argv, f"{opt}={v}" if v.startswith("-")
                                            else opt, *([] if v.startswith("-") else [v])],
                           "refuse", says, out=outs.get(cmd, "out")))
    return t


def misc_trials() -> list[dict]:
    """import, ablate and bench trials beyond the option table."""
    t = [
        trial("m-import-respiraworks-ok", "misc", IMPORT, "accept", makes="out/import.json",
              out="out"),
        trial("m-import-gtdynamics-on-dat", "misc",
              ["import", "gtdynamics", "{B}/OXY/covent_pc_1.dat", "--out", "{T}/o"], "refuse",
              ["covent_pc_1.dat"], out="o"),
        trial("m-import-folder-not-air-oxy", "misc",
              ["import", "respiraworks", "{T}/XYZ/covent_pc_1.dat", "--out", "{T}/o"],
              "refuse", ["covent_pc_1.dat"], setup=("dat", "xyz"), out="o"),
        trial("m-import-truncated-dat", "misc",
              ["import", "respiraworks", "{T}/OXY/t.dat", "--out", "{T}/o"], "refuse",
              ["t.dat"], setup=("dat", "truncated"), out="o"),
        trial("m-import-nan-dat", "misc",
              ["import", "respiraworks", "{T}/OXY/n.dat", "--out", "{T}/o"], "refuse",
              ["n.dat"], setup=("dat", "nan"), out="o"),
        trial("m-import-fifo-dat", "misc",
              ["import", "respiraworks", "{T}/OXY/f.dat", "--out", "{T}/o"], "refuse",
              ["f.dat"], setup=("dat", "fifo"), out="o"),
        trial("m-import-devzero-dat", "misc",
              ["import", "respiraworks", "{T}/OXY/z.dat", "--out", "{T}/o"], "refuse",
              ["z.dat"], setup=("dat", "devzero"), out="o"),
        # writing beside the input (OXY/OXY/covent_pc_1.csv) replaces nothing: accepted
        trial("m-import-into-input-folder", "misc",
              ["import", "respiraworks", "{T}/OXY/covent_pc_1.dat", "--out", "{T}/OXY",
               "--overwrite"], "accept", makes="OXY/import.json", setup=("dat", "copy"),
              out="OXY", keep=["OXY/covent_pc_1.dat"]),
        trial("m-ablate-smoke-dry-run", "misc", ABLATE, "accept", out="out"),
        trial("m-ablate-missing-study", "misc",
              ["ablate", "{T}/nope.toml", "--dry-run", "--out", "{T}/o"], "refuse",
              ["nope.toml"], out="o"),
    ]
    bad_toml = {
        "syntax": ("[grid\nrigs = [", ["study.toml"]),
        "empty": ("", ["study.toml"]),
        "binary": ("\x00\x01\x02\x03", ["study.toml"]),
        "unknown-key": (SMOKE.read_text() + "\nno_such_key = 1\n", ["no_such_key"]),
        "unknown-effect": (SMOKE.read_text().replace('[["tube_delay"]]', '[["no_such"]]'),
                           ["no_such"]),
        "unknown-rig": (SMOKE.read_text().replace("AIR37:valve1", "AIR999:valve1"),
                        ["AIR999"]),
        "negative-duration": (SMOKE.read_text().replace("duration_s = 6.0",
                                                        "duration_s = -6.0"),
                              ["duration_s"]),
        "nan-duration": (SMOKE.read_text().replace("duration_s = 6.0", "duration_s = nan"),
                         ["duration_s"]),
        "zero-horizon": (SMOKE.read_text().replace("horizon_s = 2.0", "horizon_s = 0.0"),
                         ["horizon_s"]),
        "huge-duration": (SMOKE.read_text().replace("duration_s = 6.0",
                                                    "duration_s = 1e12"), ["duration_s"]),
        "unknown-method": (SMOKE.read_text().replace('method = "refine"',
                                                     'method = "magic"'), ["magic"]),
        "empty-axis": (SMOKE.read_text().replace("seeds = [0]", "seeds = []"), ["seeds"]),
        "range-text": (SMOKE.read_text().replace("[3.0, 0.1]", '["3V", 0.1]'),
                       ["command_ranges_V"]),
        "range-99V": (SMOKE.read_text().replace("[3.0, 0.1]", "[99.0, 0.1]"),
                      ["command_ranges_V"]),
    }
    for kind, (text, says) in bad_toml.items():
        for dry in (True, False):
            t.append(trial(f"m-ablate-bad-toml-{kind}{'-dry' if dry else ''}", "misc",
                           ["ablate", "{T}/study.toml", *(["--dry-run"] if dry else []),
                            "-q", "--out", "{T}/o"], "refuse", says,
                           setup=("text", ("study.toml", text)), out="o"))
    t += [
        trial("m-bench-ranges-6V", "misc",
              ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1",
               "--duration", "1", "--ranges", "6", "--out", "{T}/o"], "refuse", ["--ranges"],
              out="o"),
        trial("m-bench-set-unknown", "misc", [*BENCH, "--set", "no_such_param=1"], "refuse",
              ["no_such_param"], out="out"),
        trial("m-bench-set-inf", "misc", [*BENCH, "--effects", "tube_delay", "--set",
                                           "tube_delay_s=inf"], "refuse", ["tube_delay_s"],
              out="out"),
        trial("m-bench-set-negative", "misc", [*BENCH, "--effects", "tube_delay", "--set",
                                                "tube_delay_s=-1"], "refuse",
              ["tube_delay_s"], out="out"),
        trial("m-bench-set-effect-not-planted", "misc",
              [*BENCH, "--set", "tube_delay_s=0.005"], "refuse", ["tube_delay_s"],
              out="out"),
        trial("m-bench-leak-form-without-leak", "misc", [*BENCH, "--leak-form", "laminar"],
              "refuse", ["--leak-form"], out="out"),
        trial("m-bench-count-fixed", "misc",
              ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--seed", "1",
               "--duration", "1", "--count", "2", "--out", "{T}/o"], "refuse", ["--count"],
              out="o"),
        trial("m-simulate-model-missing", "misc",
              ["simulate", "{B}/" + GOOD + ".csv", "--model", "{T}/nope.json", "--out",
               "{T}/o.csv"], "refuse", ["nope.json"], out="o.csv"),
        trial("m-simulate-model-is-recording", "misc",
              ["simulate", "{B}/" + GOOD + ".csv", "--model", "{B}/" + GOOD + ".json",
               "--out", "{T}/o.csv"], "refuse", [GOOD.split("/")[1] + ".json"], out="o.csv"),
        trial("m-simulate-model-devzero", "misc",
              ["simulate", "{B}/" + GOOD + ".csv", "--model", "{T}/m.json", "--out",
               "{T}/o.csv"], "refuse", ["m.json"], setup=("link", ("m.json", "/dev/zero")),
              out="o.csv"),
        trial("m-predict-run-missing", "misc",
              ["predict", "{T}/nope", "{B}/" + GOOD + ".csv", "--out", "{T}/o.csv"],
              "refuse", ["nope"], out="o.csv"),
        trial("m-predict-run-is-bench-folder", "misc",
              ["predict", "{B}/B", "{B}/" + GOOD + ".csv", "--out", "{T}/o.csv"], "refuse",
              ["{B}/B"], out="o.csv"),
        trial("m-predict-refine-run", "misc",
              ["predict", "{B}/R", "{B}/" + GOOD + ".csv", "--horizon", "0.5", "--out",
               "{T}/o.csv"], "refuse", ["posterior"], out="o.csv"),
        trial("m-track-run-missing", "misc",
              ["track", "{T}/nope", "{B}/" + GOOD + ".csv", "--vary", "dead_volume_m3",
               "--out", "{T}/o.json"], "refuse", ["nope"], out="o.json"),
        trial("m-fit-two-into-one-locked", "misc",
              [*_sub(READERS["fit"], rec="{B}/" + GOOD + ".csv", B="{B}", T="{T}")[:-1],
               "{T}/L"], "refuse", ["pid"], setup=("out", "locked"), out="L"),
    ]
    return t


def all_trials() -> list[dict]:
    trials = [*table_trials(), *recording_trials(), *out_state_trials(), *option_trials(),
              *misc_trials()]
    names = [t["name"] for t in trials]
    dup = {n for n in names if names.count(n) > 1}
    assert not dup, dup
    return trials


# ------------------------------------------------------------------ setup
def _setup(trial_: dict, B: Path, T: Path) -> list[str]:
    """Build the trial's inputs in T; returns extra files to keep byte-identical."""
    if trial_["setup"] is None:
        return []
    kind, arg = trial_["setup"]
    out = trial_["out"]
    if kind == "rec":
        make = BAD_RECORDINGS[arg][0] if arg in BAD_RECORDINGS else EXTRA_RECORDINGS[arg]
        make(B, T)
        return []
    if kind == "copy":
        for sfx in (".csv", ".json"):
            shutil.copy(B / (GOOD + sfx), T / (arg + sfx))
        return []
    if kind == "text":
        name, text = arg
        (T / name).write_text(text)
        return []
    if kind == "link":
        (T / arg[0]).symlink_to(arg[1])
        return []
    if kind == "out":
        return {"user_folder": _user_folder, "user_file": _user_file,
                "user_file_replaced": lambda T, o: _user_file(T, o) and [],
                "fit_run": lambda T, o: _run_folder("R")(T, o, B),
                "mcmc_run": lambda T, o: _run_folder("M")(T, o, B),
                "bench_folder": lambda T, o: _run_folder("B")(T, o, B),
                "paper_folder": _paper_folder,
                "locked": _locked}[arg](T, out)
    if kind == "traversal":
        victim = T / "victim"
        victim.mkdir()
        (victim / "data.txt").write_text("precious")
        (T / "outside.txt").write_text("precious")
        shutil.copytree(B / "R", T / "T")
        stamp = json.loads((T / "T" / "run.json").read_text())
        bad = str(T / "outside.txt") if arg == "ABS" else arg
        stamp["identity_digest"] = "another run"  # a different run: --overwrite removes
        stamp["identity"] = {"another": "run"}
        stamp["files"] = {**stamp.get("files", {}), bad: "x"}
        stamp["created"] = [*stamp.get("created", []), bad]
        (T / "T" / "run.json").write_text(json.dumps(stamp))
        return []
    if kind == "edited_refined":
        shutil.copytree(B / "M", T / "M")
        doc = json.loads((T / "M" / "refined.json").read_text())
        _scale_first_number(doc)
        (T / "M" / "refined.json").write_text(json.dumps(doc))
        return []
    if kind == "rig":
        if arg == "binary":
            (T / "binary.toml").write_bytes(bytes(range(256)))
        else:
            card = json.loads((ROOT / "data" / "rigs" / "AIR37-valve2.rig.json").read_text())
            card["bounds"] = {"no_such_param": [0, 1]}
            (T / "bad.rig.json").write_text(json.dumps(card))
        return []
    if kind == "dat":
        (T / ("XYZ" if arg == "xyz" else "OXY")).mkdir()
        src = B / "OXY" / "covent_pc_1.dat"
        if arg == "empty":
            (T / "OXY" / "empty.dat").write_text("")
        elif arg == "binary":
            (T / "OXY" / "b.dat").write_bytes(bytes(range(256)) * 16)
        elif arg == "copy":
            shutil.copy(src, T / "OXY" / "covent_pc_1.dat")
        elif arg == "xyz":
            shutil.copy(src, T / "XYZ" / "covent_pc_1.dat")
        elif arg == "truncated":
            (T / "OXY" / "t.dat").write_text("\n".join(src.read_text().splitlines()[:3])
                                              + "\n1.0 2.0\n")
        elif arg == "nan":
            lines = src.read_text().splitlines()
            i = len(lines) // 2
            vals = lines[i].split()
            vals[2] = "nan"
            lines[i] = " ".join(vals)
            (T / "OXY" / "n.dat").write_text("\n".join(lines) + "\n")
        elif arg == "fifo":
            os.mkfifo(T / "OXY" / "f.dat")
        elif arg == "devzero":
            (T / "OXY" / "z.dat").symlink_to("/dev/zero")
        elif arg == "gtdynamics":  # a 4-column GTDynamics-like table named as a .dat
            (T / "OXY" / "covent_pc_1.dat").write_text(
                "t p_left p_right cmd\n" + "".join(f"{i * 0.01} 101325 101325 0\n"
                                                    for i in range(200)))
        return []
    raise ValueError(kind)


def _scale_first_number(doc) -> bool:
    if isinstance(doc, dict):
        for k, v in doc.items():
            if isinstance(v, float):
                doc[k] = v * 1.5
                return True
            if _scale_first_number(v):
                return True
    if isinstance(doc, list):
        for i, v in enumerate(doc):
            if isinstance(v, float):
                doc[i] = v * 1.5
                return True
            if _scale_first_number(v):
                return True
    return False


def _paper_folder(T, out):
    (T / out / "work").mkdir(parents=True)
    (T / out / "work" / "thesis.tex").write_text("chapter 1")
    (T / out / "cells").mkdir()
    (T / out / "cells" / "notes.txt").write_text("notes")
    (T / out / "results.csv").write_text("a,b\n")
    return [f"{out}/work/thesis.tex", f"{out}/cells/notes.txt", f"{out}/results.csv"]


def _locked(T, out):
    """A run folder held by a live process (this script's own pid stands in for it)."""
    import socket

    (T / out).mkdir()
    (T / out / ".pneubayes.lock").write_text(json.dumps({
        "pid": os.getpid(), "host": socket.gethostname(), "command": "fit",
        "argv": ["fit", "x.csv", "--out", str(T / out)], "started": "2026-01-01T00:00:00Z"}))
    return []


def _temperature_c_293(B, T):
    _meta(format="pneubayes-recording/2", temperature_K=None, temperature_C=293.15)(B, T)


def _pressure_kpa_holding_pa(B, T):
    _columns(rename={"pressure_Pa": "pressure_kPa"})(B, T)
    meta = json.loads((T / "rec.json").read_text())
    meta["format"] = "pneubayes-recording/2"
    (T / "rec.json").write_text(json.dumps(meta))


EXTRA_RECORDINGS = {"temperature_C-293": _temperature_c_293,
                    "pressure_kPa-holding-Pa": _pressure_kpa_holding_pa}


# ------------------------------------------------------------------ the checks
def _snapshot(root: Path, skip: Path | None) -> dict:
    """path -> a fingerprint (content hash for files under 64 MB; size and mtime above;
    the target of a link; the kind of anything else), skipping ``skip`` (the output)."""
    snap = {}
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        for name in [*dirnames, *filenames]:
            p = d / name
            if skip is not None and (p == skip or skip in p.parents
                                     or _companion(p, skip)):
                continue
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                snap[str(p)] = "link:" + os.readlink(p)
            elif stat.S_ISREG(st.st_mode):
                if st.st_size > 64e6:
                    snap[str(p)] = f"big:{st.st_size}:{st.st_mtime_ns}"
                else:
                    snap[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
            elif stat.S_ISDIR(st.st_mode):
                snap[str(p)] = "dir"
            else:
                snap[str(p)] = f"special:{stat.S_IFMT(st.st_mode)}"
        dirnames[:] = [n for n in dirnames if not (d / n).is_symlink()]
    return snap


def _companion(p: Path, out: Path) -> bool:
    """A file a command writes beside its output file (PRED.metrics.json, PRED.png, the
    temporary file of an atomic write)."""
    if p.parent != out.parent or out.suffix == "":
        return False
    stem = out.name[: -len(out.suffix)]
    return (p.name.startswith(stem + ".") or p.name.startswith("." + out.name + ".")
            or p.name.startswith("." + stem + "."))


def _run(argv, cwd: Path, env: dict, timeout: float) -> dict:
    """Run the CLI in its own process group; wall time, the child's peak RSS (wait4),
    exit code or signal, stdout and stderr."""
    cmd = [sys.executable, "-m", "pneubayes.cli", *argv]
    with tempfile.TemporaryFile() as fo, tempfile.TemporaryFile() as fe:
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=fo, stderr=fe,
                                stdin=subprocess.DEVNULL, start_new_session=True)
        timed_out = False
        while True:
            pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() - t0 > timeout:
                timed_out = True
                os.killpg(proc.pid, signal.SIGKILL)
                pid, status, ru = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
        wall = time.monotonic() - t0
        proc.returncode = 0  # reaped by wait4; keep Popen from waiting again
        try:  # any of its own children left behind
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        fo.seek(0)
        fe.seek(0)
        out = fo.read().decode(errors="replace")
        err = fe.read().decode(errors="replace")
    code = os.waitstatus_to_exitcode(status)
    return {"exit": code, "signal": -code if code < 0 else None, "timed_out": timed_out,
            "wall_s": round(wall, 2), "rss_mb": round(ru.ru_maxrss / 1024, 1),
            "stdout": out[-4000:], "stderr": err[-4000:]}


def run_trial(tr: dict, base: Path, work: Path, timeout: float, max_rss_mb: float) -> dict:
    T = work / tr["name"]
    if T.exists():
        _rmtree(T)
    T.mkdir(parents=True)
    keep = [*tr["keep"], *_setup(tr, base, T)]
    kept = {k: (T / k).read_bytes() for k in keep}
    out = T / tr["out"] if tr["out"] else None
    before_T = _snapshot(T, out)
    before_B = _snapshot(base, None)
    before_repo = _snapshot(ROOT / "experiments" / "studies", None)
    fmt = {"B": str(base), "T": str(T), "rec": str(T / "rec.csv")}
    argv = [a.format(**fmt) if "{" in a else a for a in tr["argv"]]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_NUM_THREADS": "1",
           "OMP_NUM_THREADS": "1", **tr["env"]}
    env.pop("PNEUBAYES_TRACEBACK", None)
    r = _run(argv, T, env, tr["timeout"] or timeout)
    problems = []
    if r["timed_out"]:
        problems.append(f"hang: killed after {r['wall_s']} s")
    elif r["signal"]:
        problems.append(f"killed by signal {r['signal']}")
    if r["exit"] == 70:
        problems.append("crash: exit 70 (internal error)")
    if "Traceback" in r["stdout"] + r["stderr"]:
        problems.append("traceback in the output")
    if r["rss_mb"] > max_rss_mb:
        problems.append(f"memory: peak RSS {r['rss_mb']} MB")
    changed = _diff(before_T, _snapshot(T, out)) + _diff(before_B, _snapshot(base, None)) \
        + _diff(before_repo, _snapshot(ROOT / "experiments" / "studies", None))
    if changed:
        problems.append("files outside --out changed: " + "; ".join(changed[:5]))
    for k, data in kept.items():
        p = T / k
        if not (p.is_file() and not p.is_symlink() and p.read_bytes() == data):
            problems.append(f"file lost: {k} ({'changed' if p.exists() else 'removed'})")
    text = r["stdout"] + r["stderr"]
    fmt_says = [s.format(**fmt) if "{" in s else s for s in tr["says"]]
    if tr["expect"] == "refuse" and not r["timed_out"]:
        if r["exit"] == 0:
            problems.append("nonsense accepted silently (exit 0)")
        elif r["exit"] not in (1, 2):
            problems.append(f"refused with exit {r['exit']}, not 1 or 2")
        else:
            missing = [s for s in fmt_says if s not in text]
            if missing:
                problems.append(f"refusal does not name {missing}")
        if tr["keep"] == [] and tr["setup"] is None and _wrote(out):
            problems.append(f"refused but wrote {tr['out']}")
    elif tr["expect"] == "accept" and not r["timed_out"]:
        if r["exit"] != 0:
            problems.append(f"a fine input refused (exit {r['exit']})")
        elif tr["makes"] and not (T / tr["makes"]).exists():
            problems.append(f"exit 0 but {tr['makes']} not written")
    first = next((ln for ln in r["stderr"].splitlines() if ln.strip()), "")
    if not first:
        first = next((ln for ln in r["stdout"].splitlines() if ln.strip()), "")
    result = {**{k: tr[k] for k in ("name", "cls", "expect", "says")},
              "argv": argv, "exit": r["exit"], "signal": r["signal"],
              "timed_out": r["timed_out"], "wall_s": r["wall_s"], "rss_mb": r["rss_mb"],
              "first_line": first[:400], "stderr": r["stderr"][-2000:],
              "stdout": r["stdout"][-1000:], "problems": problems,
              "ok": not problems, "revision": REVISION}
    _rmtree(T)
    return result


def _wrote(out: Path | None) -> bool:
    """A refused command left a result at ``out`` (a file, or a folder holding more than
    an empty run stamp and lock)."""
    if out is None or not (out.exists() or out.is_symlink()):
        return False
    if not out.is_dir():
        return True
    return any(p.is_file() and p.name not in ("run.json", ".pneubayes.lock")
               for p in out.rglob("*"))


def _rmtree(T: Path) -> None:
    for dirpath, dirnames, _filenames in os.walk(T):  # make everything removable
        for n in dirnames:
            p = Path(dirpath) / n
            if not p.is_symlink():
                os.chmod(p, 0o755)
    shutil.rmtree(T, ignore_errors=True)


def _diff(a: dict, b: dict) -> list[str]:
    out = [f"removed {k}" for k in a if k not in b]
    out += [f"added {k}" for k in b if k not in a]
    out += [f"changed {k}" for k in a if k in b and a[k] != b[k]]
    return out


# ------------------------------------------------------------------ sandbox, report
def build_sandbox(base: Path, timeout: float) -> None:
    """The shared inputs: bench recordings, a refine run, a small mcmc run, a RespiraWorks
    file. Built once; every trial reads them and none may change them."""
    if (base / "done").exists():
        return
    if base.exists():
        _rmtree(base)
    base.mkdir(parents=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    steps = [  # relative paths, so a trial can resume the mcmc run with absolute ones
        ["bench", "--cylinder", "AIR37", "--valve", "valve1", "--duration", "1", "--seed",
         "1", "-q", "--out", "B"],
        ["fit", GOOD + ".csv", "--method", "refine", "--horizon", "0.5", "--no-figures",
         "-q", "--out", "R"],
        ["fit", OTHER + ".csv", GOOD + ".csv", "--horizon", "0.5", "--walkers", "24",
         "--max-steps", "60", "--no-figures", "-q", "--out", "M"],
    ]
    for argv in steps:
        print("sandbox: pneubayes", " ".join(argv), flush=True)
        r = _run(argv, base, env, max(timeout, 600))
        if r["exit"] != 0:
            sys.exit(f"sandbox step failed: {r['stderr']}")
    (base / "OXY").mkdir()
    src = REALDATA / "OXY" / "covent_pc_1.dat"
    if not src.exists():
        src = REALDATA / "AIR" / "covent_pc_1.dat"
    shutil.copy(src, base / "OXY" / "covent_pc_1.dat")
    os.chmod(base / "OXY" / "covent_pc_1.dat", 0o644)
    (base / "done").write_text("")


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)


REVISION = "unknown"  # the git revision the trials run at (set by main)


def _revision() -> str:
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                             text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "pneubayes"], cwd=ROOT,
                               capture_output=True, text=True).stdout.strip()
        return rev + (" (pneubayes/ modified)" if dirty else "")
    except OSError:
        return "unknown"


def summarize(results: list[dict], out: Path, elapsed: float) -> dict:
    classes = sorted({r["cls"] for r in results})
    counts = {c: {"trials": sum(r["cls"] == c for r in results),
                  "ok": sum(r["cls"] == c and r["ok"] for r in results),
                  "failed": sum(r["cls"] == c and not r["ok"] for r in results),
                  "refuse": sum(r["cls"] == c and r["expect"] == "refuse" for r in results),
                  "accept": sum(r["cls"] == c and r["expect"] == "accept" for r in results)}
              for c in classes}
    kinds = {}
    for r in results:
        for p in r["problems"]:
            key = p.split(":")[0].split(" (")[0]
            if key.startswith("refusal does not name"):
                key = "refusal does not name the input"
            kinds[key] = kinds.get(key, 0) + 1
    failures = [r for r in results if not r["ok"]]
    revisions = sorted({r.get("revision", "unrecorded") for r in results})
    doc = {"revision": _revision(), "trial_revisions": revisions, "total": len(results),
           "ok": len(results) - len(failures), "failed": len(failures),
           "per_class": counts, "per_problem": kinds,
           "max_wall_s": max((r["wall_s"] for r in results), default=0),
           "max_rss_mb": max((r["rss_mb"] for r in results), default=0),
           "run_wall_s": round(elapsed, 1),
           "failures": [{k: r[k] for k in ("name", "cls", "argv", "exit", "wall_s",
                                            "rss_mb", "first_line", "problems")}
                        for r in failures]}
    _write_atomic(out / "summary.json", json.dumps(doc, indent=2) + "\n")
    lines = ["# Misuse trials (issue 70)\n", f"revision {doc['revision']} (trials run at "
             f"{', '.join(revisions)}); "
             f"{doc['total']} trials, {doc['ok']} ok, {doc['failed']} failed; slowest "
             f"{doc['max_wall_s']} s, largest peak RSS {doc['max_rss_mb']} MB; this run "
             f"{doc['run_wall_s']} s (cached trials not re-run)\n",
             "| class | trials | refuse | accept | ok | failed |", "|---|---|---|---|---|---|"]
    for c, n in counts.items():
        lines.append(f"| {c} | {n['trials']} | {n['refuse']} | {n['accept']} | {n['ok']} | "
                     f"{n['failed']} |")
    if kinds:
        lines += ["", "| problem | trials |", "|---|---|"]
        lines += [f"| {k} | {v} |" for k, v in sorted(kinds.items())]
    if failures:
        lines += ["", "## Failures", ""]
        for r in failures:
            lines.append(f"- **{r['name']}** exit {r['exit']}, {r['wall_s']} s, "
                         f"{r['rss_mb']} MB: {'; '.join(r['problems'])}  \n"
                         f"  `pneubayes {' '.join(r['argv'])}`  \n"
                         f"  first line: `{r['first_line']}`")
    _write_atomic(out / "summary.md", "\n".join(lines) + "\n")
    return doc


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="results/misuse", help="sandbox and report folder")
    p.add_argument("--only", default=None, metavar="CLASS[,CLASS]",
                   help="only these classes (table, recording, out-state, option, misc) "
                        "or trials whose name starts with this")
    p.add_argument("--list", action="store_true", help="list the trials and exit")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds per trial (60)")
    p.add_argument("--max-rss-mb", type=float, default=2048.0,
                   help="peak RSS per trial, MB (2048)")
    p.add_argument("--rerun", action="store_true", help="ignore cached results")
    p.add_argument("--rerun-failed", action="store_true",
                   help="run again the trials whose cached result failed")
    args = p.parse_args(argv)
    global REVISION
    REVISION = _revision()
    trials = all_trials()
    if args.only:
        wanted = args.only.split(",")
        trials = [t for t in trials if t["cls"] in wanted
                  or any(t["name"].startswith(w) for w in wanted)]
    if args.list:
        for t in trials:
            print(f"{t['cls']:10s} {t['name']:55s} {t['expect']:6s} pneubayes "
                  f"{' '.join(t['argv'])}")
        print(f"{len(trials)} trials")
        return 0
    out = Path(args.out).resolve()
    (out / "trials").mkdir(parents=True, exist_ok=True)
    base = out / "sandbox" / "base"
    work = out / "sandbox" / "t"
    t0 = time.monotonic()
    build_sandbox(base, args.timeout)
    results = []
    for i, tr in enumerate(trials, 1):
        cache = out / "trials" / (tr["name"] + ".json")
        r = None
        if cache.exists() and not args.rerun:
            r = json.loads(cache.read_text())
            if args.rerun_failed and not r["ok"]:
                r = None
            elif r is not None:
                r["cls"] = tr["cls"]
        if r is None:
            r = run_trial(tr, base, work, args.timeout, args.max_rss_mb)
            _write_atomic(cache, json.dumps(r, indent=1) + "\n")
            tag = "ok  " if r["ok"] else "FAIL"
            print(f"[{i:3d}/{len(trials)}] {tag} {tr['name']:55s} exit {r['exit']:>3} "
                  f"{r['wall_s']:6.2f} s {r['rss_mb']:7.1f} MB"
                  + ("" if r["ok"] else f"  {'; '.join(r['problems'])}"), flush=True)
        results.append(r)
    doc = summarize(results, out, time.monotonic() - t0)
    print(f"{doc['total']} trials: {doc['ok']} ok, {doc['failed']} failed; "
          f"report in {out / 'summary.md'}")
    return 0 if doc["failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
