"""Import the RespiraWorks ventilator's 2020-07-01 control-variable tests.

Source: ``RespiraWorks/Ventilator`` at commit ``718bce04``,
``quality-assurance/testing/testing-data/v0.2/2020-07-01-Control-Tests-AIR-and-OXY/``
(Apache-2.0), as laid out in ``realdata/respiraworks-ventilator/{AIR,OXY}/``. One
format-2 recording per run file (the test lung is one chamber):

- ``time_s``: the file's time (s, 100 Hz);
- ``pressure_kPa_gauge``: the patient (test-lung side) pressure; the firmware labels it
  cmH2O but the numbers are kPa (they track the set-point at 1/10.2 of its cmH2O value;
  the data's README), made absolute by the reader with the stated atmosphere;
- ``command_V``: the inhale actuator's 0..1 command (OXY: ``cmd_psol``, the proportional
  solenoid, PWM duty 0.80 + 0.10 cmd in the firmware and closed below it; AIR:
  ``cmd_inh_valve``, the inhale pinch valve); the rig card declares it as unit ``duty``
  on [0, 1];
- the other columns kept as extra columns (``pc_setpoint_cmH2O``, ``dp_inhale``,
  ``dp_exhale``, ``cmd_exh_valve``, the unused inhale command).

The exhale pinch valve is commanded in closed loop from the inhale command
(``1 - 0.6 cmd - 0.4`` OXY, ``1 - 0.55 cmd - 0.4`` AIR, test READMEs; in the files it
follows ``0.63 - 0.62 cmd`` to within 0.03) and logged as ``cmd_exh_valve``: the rig
card's exhaust is a separate valve (kind ``gompertz``) on that column. The chamber is
two compartments (kind ``two_compartment``): the circuit, where the pressure is
measured, and the test lung behind its airway resistance (the QuickLung's selectable R
and C; the settings are not in the files, so all four are priors). Neither the
atmosphere, the temperature nor the supply pressure is recorded: 101325 Pa and 296 K
are assumed, and the supply is a constant of the card (OXY: a regulated line, 400 kPa
absolute assumed within the design's 120-440 kPa, so the inhale flow is choked and the
fitted area scales with the assumption; AIR: the blower's 5 kPa gauge).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.io.recording_format import FORMAT_2

SOURCE = {"repository": "https://github.com/RespiraWorks/Ventilator",
          "commit": "718bce04b057355dfa2d07d054d4cf412ec41643",
          "path": "quality-assurance/testing/testing-data/v0.2/"
                  "2020-07-01-Control-Tests-AIR-and-OXY/",
          "licence": "Apache-2.0"}
COLUMNS = ("time(sec)", "pc_setpoint", "pressure", "dp_inhale", "dp_exhale",
           "cmd_inh_valve", "cmd_exh_valve", "cmd_psol")
ATMOSPHERE_PA = 101325.0
TEMPERATURE_K = 296.0
SUPPLY_PA = {"OXY": 401325.0, "AIR": ATMOSPHERE_PA + 5000.0}
INHALE = {"OXY": "cmd_psol", "AIR": "cmd_inh_valve"}


def rig_card(kind: str) -> dict:
    """The test lung on the OXY (proportional solenoid) or AIR (blower + pinch valve)
    path: the circuit and the lung behind its resistance, a Gompertz inhale valve on the
    inhale command and a Gompertz exhale valve on its own logged command
    ``cmd_exh_valve``."""
    inlet = {"inlet_offset_m2": 0.0,
             "inlet_a_m2": {"prior": "log-uniform", "bounds": [1e-9, 1e-3]},
             "inlet_b": {"prior": "log-uniform", "bounds": [0.05, 50.0]},
             "inlet_c_per_V": {"prior": "uniform", "bounds": [0.5, 40.0]},
             "inlet_d_V": {"prior": "uniform", "bounds": [-1.5, 1.0]}}
    exhaust = {"kind": "gompertz", "column": "cmd_exh_valve",
               "command": {"unit": "duty", "range": [0.0, 1.0]},
               "offset_m2": {"prior": "uniform", "bounds": [0.0, 1e-4]},
               "a_m2": {"prior": "log-uniform", "bounds": [1e-7, 1e-3]},
               "b": {"prior": "log-uniform", "bounds": [0.05, 50.0]},
               "c_per_V": {"prior": "uniform", "bounds": [0.5, 40.0]},
               "d_V": {"prior": "uniform", "bounds": [-1.5, 1.0]}}
    supply = SUPPLY_PA[kind]
    return {
        "format": "pneubayes-rig/1",
        "name": f"RespiraWorks ventilator, {kind} path, QuickLung test lung",
        "atmospheric_pressure_Pa": ATMOSPHERE_PA, "temperature_K": TEMPERATURE_K,
        "command": {"unit": "duty", "range": [0.0, 1.0]},
        "chamber": {"kind": "two_compartment",
                    "volume_m3": {"prior": "log-uniform", "bounds": [1e-5, 5e-3]},
                    "lung_volume_m3": {"prior": "log-uniform", "bounds": [2e-4, 1e-2]},
                    "lung_compliance_m3_per_Pa": {"prior": "log-uniform",
                                                  "bounds": [3e-8, 2e-6]},
                    "resistance_Pa_s_per_m3": {"prior": "log-uniform",
                                               "bounds": [1e4, 1e8]}},
        "valve": {"kind": "gompertz", **inlet},
        "exhaust": exhaust,
        "supply": {"kind": "constant", "pressure_Pa": supply},
        "notes": (
            "Command: the inhale actuator's 0..1 command "
            + ("(PSOL; PWM duty 0.80 + 0.10 cmd, closed below about 0.80 duty). "
               if kind == "OXY" else "(inhale pinch valve, linearised in firmware). ")
            + "Exhaust: the exhale pinch valve on its own logged command cmd_exh_valve "
            "(0..1; closed loop, 0.63 - 0.62 cmd to within 0.03). Chamber: two "
            "compartments, the circuit at the pressure sensor (its volume) and the "
            "QuickLung behind its airway resistance R (5-50 cmH2O/(L/s)) with its "
            "compliance C (10-50 mL/cmH2O), both by the ISO test table, settings not in "
            "the files. Supply "
            + ("not recorded: a regulated line, 400 kPa absolute assumed (the inhale flow "
               "is choked, so the inhale area scales with this assumption). "
               if kind == "OXY" else "the blower at 100 % speed, about 5 kPa gauge. ")
            + "Atmosphere and temperature not recorded (101325 Pa, 296 K assumed)."),
    }


def _read(path: Path) -> np.ndarray:
    from pneubayes.limits import check_input_file

    if not path.exists():
        raise ValueError(f"{path}: file not found")
    check_input_file(path)
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a RespiraWorks .dat text file (not UTF-8 text: "
                         f"{exc.reason} at byte {exc.start})") from None
    content = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    if not content:
        raise ValueError(f"{path}: empty; a RespiraWorks .dat file starts with the header "
                         f"{' '.join(COLUMNS)}")
    header = content[0].split()
    if tuple(header) != COLUMNS:
        raise ValueError(f"{path}: expected the columns {' '.join(COLUMNS)}, got "
                         f"{' '.join(header)}")
    rows = []
    for i, ln in enumerate(lines, start=1):
        if not ln.strip() or ln.startswith("#") or ln.split() == list(COLUMNS):
            continue
        try:
            vals = [float(v) for v in ln.split()]
        except ValueError:
            raise ValueError(f"{path} line {i}: not numbers: {ln!r}") from None
        if len(vals) != len(COLUMNS):
            raise ValueError(f"{path} line {i}: expected {len(COLUMNS)} values, got "
                             f"{len(vals)}")
        if not all(np.isfinite(vals)):
            raise ValueError(f"{path} line {i}: not finite numbers: {ln!r}")
        rows.append(vals)
    if not rows:
        raise ValueError(f"{path}: no data rows after the header (a run needs samples)")
    return np.array(rows)


def import_run(path, out_dir) -> Path:
    """Write one run file as ``out_dir/<SET>/<file stem>``; returns the CSV path."""
    path = Path(path)
    kind = path.parent.name.upper()
    if not path.exists():
        raise ValueError(f"{path}: file not found")
    if kind not in SUPPLY_PA:
        raise ValueError(f"{path}: the run's folder must be AIR or OXY (it names the gas "
                         f"path), got {path.parent.name!r}")
    data = _read(path)
    col = {c: data[:, i] for i, c in enumerate(COLUMNS)}
    cmd = col[INHALE[kind]]
    other = "cmd_inh_valve" if kind == "OXY" else "cmd_psol"
    out = Path(out_dir) / kind
    out.mkdir(parents=True, exist_ok=True)
    stem = out / path.stem
    names = ["time_s", "command_V", "pressure_kPa_gauge", "pc_setpoint_cmH2O", "dp_inhale",
             "dp_exhale", "cmd_exh_valve", other]
    arrays = [col["time(sec)"], cmd, col["pressure"], col["pc_setpoint"], col["dp_inhale"],
              col["dp_exhale"], col["cmd_exh_valve"], col[other]]
    text = ",".join(names) + "\n" + "".join(
        ",".join(repr(float(a[i])) for a in arrays) + "\n" for i in range(data.shape[0]))
    tmp = stem.with_suffix(".csv.tmp")
    tmp.write_text(text)
    tmp.replace(stem.with_suffix(".csv"))
    sidecar = {
        "format": FORMAT_2, "rig": f"../respiraworks-{kind.lower()}.rig.json",
        "cylinder": "IngMar QuickLung test lung", "valve": (
            "PSOL proportional solenoid (SMC PVQ31 or Uflow IBV19M) + exhale pinch valve"
            if kind == "OXY" else "inhale pinch valve + exhale pinch valve"),
        "atmospheric_pressure_Pa": ATMOSPHERE_PA, "temperature_K": TEMPERATURE_K,
        "accept_unusual": ["working-range"] if kind == "AIR" else [],
        "import": {**SOURCE, "file": f"{kind}/{path.name}",
                   "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
                   "conversion": "pressure kept in kPa gauge (format 2; the reader adds "
                                 "the stated atmosphere); command = " + INHALE[kind]
                                 + "; other columns kept as extra columns"},
    }
    write_json_atomic(stem.with_suffix(".json"), sidecar)
    return stem.with_suffix(".csv")


def import_respiraworks(files, out_dir) -> list[Path]:
    """Import run files (``.../AIR/covent_pc_N.dat``, ``.../OXY/...``) into ``out_dir``
    with one rig card per gas path; returns the CSV paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [Path(f) for f in files]
    seen: dict = {}
    for f in files:
        key = (f.parent.name.upper(), f.stem)
        if key in seen:
            raise ValueError(f"{f}: given twice (as {seen[key]}); each run is imported once")
        seen[key] = f
    written = [import_run(f, out) for f in files]
    for kind in sorted({f.parent.name.upper() for f in files}):
        write_json_atomic(out / f"respiraworks-{kind.lower()}.rig.json", rig_card(kind))
    (out / "import.json").write_text(json.dumps(
        {"importer": "respiraworks", **SOURCE,
         "files": [f"{f.parent.name}/{f.name}" for f in files]}, indent=2) + "\n")
    return written
