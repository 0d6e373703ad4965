"""Do the plausibility rules catch unit slips, and leave correct recordings alone?

    python experiments/unit_slips.py --out results/unit_slips [--realdata ../shared/realdata]
    python experiments/unit_slips.py --smoke --out /tmp/slips

Sources: the shipped bench recordings (``data/``), and the real third-party recordings
in ``--realdata`` (RespiraWorks ventilator runs, kPa gauge at 100 Hz; GTDynamics muscles,
psi gauge at 500 Hz), converted here as a user would, with their units declared in
format 2. Every source is checked as it is ("correct": no error may fire; warnings are
counted) and with each slip a user makes ("bar": every pressure written in bar into the
``_Pa`` fields; "kPa": in kPa; "psi": in psi; "gauge": the chamber pressure as gauge Pa;
"ms": time stamps in milliseconds in ``time_s``; "celsius": ``temperature_K`` in degrees
C; "mm": bore and stroke in millimetres). A slip counts as caught when reading the file
fails, and as named when the message names the unit that was meant.

The real recordings split into a tuning half (ventilator runs 1-2, GTDynamics trials 1-2:
looked at while the rules were written) and a blind half (the others), reported apart.
Writes OUT/unit_slips.json (per source and slip) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.errors import RecordingError
from pneubayes.io import read_recording, write_recording
from pneubayes.io.recording import Recording, inspect_recording
from pneubayes.provenance import provenance

ROOT = Path(__file__).resolve().parents[1]
ATM = 101325.0
PSI = 6894.757293168361
#: slip -> (what the message must name, how the recording is changed)
SLIPS = ("bar", "kPa", "psi", "gauge", "ms", "celsius", "mm")
NAMED = {"bar": "probably bar", "kPa": "probably kPa", "psi": "probably psi",
         "gauge": "gauge", "ms": "milliseconds", "celsius": "degrees C", "mm": "mm ("}


def _pressures(rec: Recording, scale: float) -> Recording:
    md = rec.metadata
    md = replace(md, atmospheric_pressure_Pa=md.atmospheric_pressure_Pa / scale,
                 supply_pressure_Pa=md.supply_pressure_Pa / scale)
    sup = None if rec.supply_pressure_Pa is None else rec.supply_pressure_Pa / scale
    return replace(rec, metadata=md, pressure_Pa=rec.pressure_Pa / scale,
                   supply_pressure_Pa=sup)


def slipped(rec: Recording, slip: str) -> Recording:
    """``rec`` (SI, absolute) with the slip ``slip`` made in its numbers."""
    md = rec.metadata
    if slip in ("bar", "kPa", "psi"):
        return _pressures(rec, {"bar": 1e5, "kPa": 1e3, "psi": PSI}[slip])
    if slip == "gauge":
        return replace(rec, pressure_Pa=rec.pressure_Pa - md.atmospheric_pressure_Pa)
    if slip == "ms":
        return replace(rec, time_s=rec.time_s * 1e3)
    if slip == "celsius":
        return replace(rec, metadata=replace(md, temperature_K=md.temperature_K - 273.15))
    if slip == "mm":
        pos = None if rec.position_m is None else rec.position_m * 1e3
        return replace(rec, metadata=replace(md, bore_m=md.bore_m * 1e3,
                                             stroke_m=md.stroke_m * 1e3), position_m=pos)
    raise ValueError(f"unknown slip {slip!r}")


def _write_format2(stem: Path, header: str, rows, meta: dict) -> Path:
    stem.with_suffix(".csv").write_text(header + "\n" + "".join(
        ",".join(repr(float(v)) for v in row) + "\n" for row in rows))
    stem.with_suffix(".json").write_text(json.dumps({"format": "pneubayes-recording/2",
                                                     **meta}))
    return stem.with_suffix(".csv")


def respiraworks(folder: Path, work: Path) -> list[tuple[str, Path]]:
    """Ventilator runs as format-2 recordings: kPa gauge, the inflow valve's command
    (0..1) shown as 0..5 V, the test lung as a fixed volume (no piston)."""
    out = []
    for gas in ("AIR", "OXY"):
        for f in sorted((folder / gas).glob("covent_pc_*.dat")):
            a = np.loadtxt(f, comments="#", skiprows=4)
            cmd = a[:, 7] if gas == "OXY" else a[:, 5]
            stem = work / f"rw_{gas}_{f.stem}"
            blower_kPa = 5.0 if gas == "AIR" else 200.0  # AIR: the blower; OXY: a guess
            out.append((f"respiraworks {gas} {f.stem}", _write_format2(
                stem, "time_s,command_V,pressure_kPa_gauge",
                zip(a[:, 0], 5.0 * cmd, a[:, 2]),
                {"cylinder": "QuickLung", "valve": gas, "bore_m": 0.1, "stroke_m": 0.1,
                 "atmospheric_pressure_Pa": ATM, "supply_pressure_kPa_gauge": blower_kPa,
                 "temperature_K": 296.15,
                 "accept_unusual": ["sample-interval", "pressure-span", "working-range"]})))
    return out


def gtdynamics(folder: Path, work: Path) -> list[tuple[str, Path]]:
    """Each muscle of each trial as a format-2 recording: psi gauge, the source tank as
    the measured supply, the valve open between the recorded times shown as +5 V."""
    out = []
    for trial in sorted((folder / "trials").iterdir()):
        a = np.loadtxt(trial / "pressure_raw_psi.csv", delimiter=",")
        times = np.loadtxt(trial / "t_valve.csv", delimiter=",", comments="#")
        for j, muscle in enumerate(("knee_r", "hip_r", "hip_l", "knee_l")):
            opened = (a[:, 0] >= times[0, j]) & (a[:, 0] < times[1, j])
            stem = work / f"gt_{trial.name[:20]}_{muscle}"
            out.append((f"gtdynamics {trial.name[:27]} {muscle}", _write_format2(
                stem, "time_s,command_V,pressure_psi_gauge,supply_pressure_psi_gauge",
                zip(a[:, 0], 5.0 * opened, a[:, 2 + j], a[:, 1]),
                {"cylinder": muscle, "valve": "on-off", "bore_m": 0.02, "stroke_m": 0.05,
                 "atmospheric_pressure_Pa": ATM, "supply_pressure_psi_gauge": 80.0,
                 "temperature_K": 296.15})))
    return out


def judge(path: Path, slip: str | None, work: Path) -> dict:
    """Read ``path`` as it is (slip None) or with ``slip`` made; what the rules said."""
    rec = read_recording(path, accept=())
    if slip is not None:
        rec = slipped(rec, slip)
    md = rec.metadata
    accept = md.accept_unusual if slip is None else ()
    rec = replace(rec, metadata=replace(md, accept_unusual=accept))
    stem = work / f"{path.stem}_{slip or 'correct'}"
    try:
        write_recording(rec, stem, overwrite=True)
    except RecordingError as exc:  # the format itself refuses it (e.g. p <= 0)
        return {"caught": True, "named": slip is not None and NAMED[slip] in str(exc),
                "by": "format", "messages": [why for _, why in exc.problems[:3]]}
    found = inspect_recording(stem, accept)
    return {"caught": bool(found.problems),
            "named": slip is not None and any(NAMED[slip] in why for _, why in found.problems),
            "by": "plausibility" if found.problems else None,
            "messages": [why for _, why in found.problems[:3]],
            "warnings": [f.rule for f in found.warnings if not f.accepted]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--realdata", default=str(ROOT.parent / "shared" / "realdata"))
    ap.add_argument("--smoke", action="store_true", help="two bench recordings, no real data")
    args = ap.parse_args(argv)
    out = Path(args.out)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        sources = [(f"bench {p.parent.name}/{p.stem}", p)
                   for p in sorted((ROOT / "data").glob("*/*/*.csv"))]
        if args.smoke:
            sources = sources[:2]
        else:
            real = Path(args.realdata)
            sources += respiraworks(real / "respiraworks-ventilator", work)
            sources += gtdynamics(real / "gtdynamics-jumping-robot", work)
        for name, path in sources:
            tuning = any(k in name for k in ("covent_pc_1", "covent_pc_2", "0p00_0p06"))
            half = "bench" if name.startswith("bench") else ("tuning" if tuning else "blind")
            for slip in (None, *SLIPS):
                r = judge(path, slip, work)
                rows.append({"source": name, "half": half, "slip": slip or "correct", **r})
    table = {}
    for r in rows:
        t = table.setdefault(r["half"], {}).setdefault(r["slip"], {"n": 0, "caught": 0,
                                                                   "named": 0})
        t["n"] += 1
        t["caught"] += r["caught"]
        t["named"] += r["named"]
    write_json_atomic(out / "unit_slips.json", {"table": table, "rows": rows,
                                                "smoke": args.smoke,
                                                "provenance": provenance()})
    print(f"{'half':8s} {'slip':8s} {'n':>4s} {'caught':>7s} {'named':>6s}")
    for half, slips in table.items():
        for slip, t in slips.items():
            print(f"{half:8s} {slip:8s} {t['n']:4d} {t['caught']:7d} {t['named']:6d}")
    print(out / "unit_slips.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
