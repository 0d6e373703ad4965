"""Read, check and write recordings: the CSV + JSON interchange format.

``<stem>.csv`` holds the samples, ``<stem>.json`` what is known about the rig (the
contract is ``recording-format.md``). Reading collects *every* problem and raises one
:class:`~pneubayes.errors.RecordingError` with ``(location, reason)`` pairs; a location
names the file and the row (1-based CSV line number, header = row 1) or the JSON key.

Rules: both files exist and are UTF-8 (a BOM is allowed). CSV: a header of unique,
non-empty names including ``time_s``, ``command_V``, ``pressure_Pa``; at least one data
row; every row as many fields as the header (blank lines only at the end); cells of
known columns are decimal numbers ('.' point), finite; time strictly increasing;
``pressure_Pa`` and ``supply_pressure_Pa`` > 0 Pa (absolute); ``|command_V|`` <= 5 V
+ ``COMMAND_TOLERANCE_V``. JSON: parses, an object without duplicate keys, every
required key; ``cylinder``, ``valve`` non-empty strings; bore, stroke, pressures and
temperature finite numbers > 0; supply > atmosphere; ``position_m``, if given, within
0..stroke. Unknown columns and keys are kept unvalidated (a column is float64 when every
cell is a number, else text). The ``position_m`` column is not bounded: a length sensor
reads slightly outside the stroke. The only normalisation: commands within the tolerance
are clipped to exactly +-5 V. Input files are only ever opened read-only.
"""

from __future__ import annotations

import csv
import difflib
import errno
import io
import json
import math
import numbers
import os
import re
import secrets
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from pneubayes.errors import RecordingError
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.rig import Rig

COMMAND_LIMIT_V = 5.0
COMMAND_TOLERANCE_V = 1e-6
REQUIRED_COLUMNS = ("time_s", "command_V", "pressure_Pa")
OPTIONAL_COLUMNS = ("supply_pressure_Pa", "position_m")
REQUIRED_KEYS = ("cylinder", "valve", "bore_m", "stroke_m", "atmospheric_pressure_Pa",
                 "supply_pressure_Pa", "temperature_K")
OPTIONAL_KEYS = ("position_m",)
_KNOWN_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
_KNOWN_KEYS = REQUIRED_KEYS + OPTIONAL_KEYS
_TEXT_KEYS = ("cylinder", "valve")
_PRESSURE_COLUMNS = ("pressure_Pa", "supply_pressure_Pa")
# A decimal number ('.' point) or nan/inf (rejected later with a clear reason); stricter
# than float(), which also takes '1_000', non-ASCII digits and other Python spellings.
_NUMBER = re.compile(r"[ \t]*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:e[+-]?[0-9]+)?"
                     r"|nan|inf(?:inity)?)[ \t]*", re.IGNORECASE)
# A column made of these characters only is all numbers iff float() takes every cell.
_PLAIN = re.compile(r"[0-9.eE+\- \t\n]*")


@dataclass(frozen=True)
class RecordingMetadata:
    """What is known about the rig (the JSON file).

    Parameters
    ----------
    cylinder, valve : str
        Free-text names of the cylinder and the valve.
    bore_m, stroke_m : float
        Piston bore diameter and stroke length, m.
    atmospheric_pressure_Pa, supply_pressure_Pa : float
        Absolute exhaust (ambient) and nominal supply pressures, Pa.
    temperature_K : float
        Supply air temperature, K.
    position_m : float or None
        Fixed piston position, m (0 = fully retracted), for recordings without a
        ``position_m`` column; None when not given.
    extra : dict
        Unknown JSON keys, kept unchanged and written back.
    """

    cylinder: str
    valve: str
    bore_m: float
    stroke_m: float
    atmospheric_pressure_Pa: float
    supply_pressure_Pa: float
    temperature_K: float
    position_m: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _frozen(values, numeric: bool = True) -> np.ndarray:
    a = np.array(values)
    a = a.astype(np.float64 if numeric or a.dtype.kind in "biuf" else str)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Recording:
    """One chamber, one valve, one continuous stretch of time.

    Arrays are stored as read-only copies (float64; an extra column that is not
    numeric throughout is kept as a string array). Construction does not validate:
    :func:`write_recording` does, and :func:`read_recording` only returns valid ones.

    Parameters
    ----------
    metadata : RecordingMetadata
        The rig description.
    time_s, command_V, pressure_Pa : ndarray
        Sample times (s, strictly increasing), valve command (V, -5..+5; + opens the
        inlet, - the exhaust) and absolute chamber pressure (Pa).
    supply_pressure_Pa, position_m : ndarray or None
        Measured absolute supply pressure (Pa) and piston position (m); None when the
        column is absent.
    extra_columns : dict of str to ndarray
        Unknown CSV columns, kept (and written back) but not used.
    source : str or None
        The CSV path the recording was read from.
    pressure_filter : PressureFilter or None
        The pressure channel's zero-phase anti-alias filter, when the user declares it
        (:func:`pneubayes.io.prepare_recording`); the recording format does not carry
        it, so a recording read from files has None. Passed on to :meth:`rig`.
    """

    metadata: RecordingMetadata
    time_s: np.ndarray
    command_V: np.ndarray
    pressure_Pa: np.ndarray
    supply_pressure_Pa: np.ndarray | None = None
    position_m: np.ndarray | None = None
    extra_columns: dict[str, np.ndarray] = field(default_factory=dict)
    source: str | None = None
    pressure_filter: PressureFilter | None = None

    def __post_init__(self):
        for name in _KNOWN_COLUMNS:
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "extra_columns", {
            k: _frozen(v, numeric=False) for k, v in self.extra_columns.items()})

    @property
    def n_samples(self) -> int:
        """Number of samples (CSV data rows)."""
        return len(self.time_s)

    @property
    def working_range_Pa(self) -> float:
        """Nominal supply minus atmospheric pressure, Pa."""
        return self.metadata.supply_pressure_Pa - self.metadata.atmospheric_pressure_Pa

    def supply_or_nominal(self) -> np.ndarray:
        """Absolute supply pressure per sample, Pa: the column, else the nominal value."""
        if self.supply_pressure_Pa is not None:
            return self.supply_pressure_Pa
        return np.full(self.n_samples, self.metadata.supply_pressure_Pa)

    def position_or_fixed(self) -> np.ndarray:
        """Piston position per sample, m.

        The measured ``position_m`` column if present; otherwise the metadata's fixed
        ``position_m`` repeated; otherwise zeros. Zero (fully retracted) is not a guess
        about the rig: without any position the volume is fixed, and the identified
        dead volume then stands for the whole chamber volume.
        """
        if self.position_m is not None:
            return self.position_m
        fixed = self.metadata.position_m
        return np.full(self.n_samples, 0.0 if fixed is None else fixed)

    def rig(self) -> Rig:
        """The :class:`~pneubayes.rig.Rig` described by the metadata (gas at ``temperature_K``)."""
        md = self.metadata
        return Rig(md.bore_m, md.atmospheric_pressure_Pa, md.supply_pressure_Pa,
                   gas=GasConstants(temperature_K=md.temperature_K), stroke_m=md.stroke_m,
                   pressure_filter=self.pressure_filter)

    def slice(self, start: int | None, stop: int | None) -> Recording:
        """Samples ``start:stop`` (Python slice rules) as a new recording, times kept.

        Raises ValueError if the slice holds no sample.
        """
        s = slice(start, stop)
        if len(range(*s.indices(self.n_samples))) == 0:
            raise ValueError(f"Recording.slice({start}, {stop}) of a recording with "
                             f"{self.n_samples} samples holds no sample")
        cut = {c: getattr(self, c)[s] for c in _KNOWN_COLUMNS if getattr(self, c) is not None}
        return replace(self, **cut, extra_columns={k: v[s] for k, v in self.extra_columns.items()})


def recording_paths(path: str | os.PathLike) -> tuple[Path, Path]:
    """``(csv_path, json_path)`` of a recording given its .csv, its .json or its stem."""
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".csv", ".json") else p
    return Path(f"{stem}.csv"), Path(f"{stem}.json")


def _show(value, limit: int = 40) -> str:
    text = repr(float(value)) if isinstance(value, (float, np.floating)) else repr(value)
    return text if len(text) <= limit else text[:limit] + "...'"


def _finite_number(value) -> float | None:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return None
    try:
        x = float(value)
    except OverflowError:
        return None
    return x if math.isfinite(x) else None


def _hint(name: str, candidates) -> str:
    close = difflib.get_close_matches(name, [c for c in candidates if c != name], n=1)
    return f" (found {close[0]!r}; names are case-sensitive)" if close else ""


def _check_metadata(data: dict, name: str, problems: list) -> RecordingMetadata | None:
    """Validate a JSON object against the contract; append problems, return metadata or None."""
    def at(key):
        return f"{name} key {key!r}"
    n_before, values = len(problems), {}
    for key in _KNOWN_KEYS:
        if key not in data:
            if key in REQUIRED_KEYS:
                problems.append((at(key), "missing required key" + _hint(key, data)))
            continue
        v = data[key]
        if key in _TEXT_KEYS:
            if isinstance(v, str) and v.strip():
                values[key] = v
            else:
                problems.append((at(key), f"must be a non-empty string, got {_show(v)}"))
            continue
        x = _finite_number(v)
        if x is None:
            problems.append((at(key), f"must be a finite number, got {_show(v)}"))
        elif key != "position_m" and x <= 0:
            what = "absolute pressure" if "pressure" in key else "value"
            problems.append((at(key), f"{what} must be > 0, got {x!r}"))
        else:
            values[key] = x
    atm, sup = values.get("atmospheric_pressure_Pa"), values.get("supply_pressure_Pa")
    if atm is not None and sup is not None and sup <= atm:
        problems.append((at("supply_pressure_Pa"),
                         f"must exceed atmospheric_pressure_Pa ({atm!r}), got {sup!r}"))
    pos, stroke = values.get("position_m"), values.get("stroke_m")
    if pos is not None and stroke is not None and not 0.0 <= pos <= stroke:
        problems.append((at("position_m"), f"must be within 0..stroke_m ({stroke!r}), got {pos!r}"))
    extra = {k: v for k, v in data.items() if k not in _KNOWN_KEYS}
    for key, v in extra.items():
        try:
            json.dumps(v, allow_nan=False)
        except (TypeError, ValueError) as e:
            problems.append((at(key), f"value cannot be stored as JSON: {e}"))
    if len(problems) > n_before:
        return None
    return RecordingMetadata(**values, extra=extra)


def _check_columns(cols: dict, bad: dict, lines, name: str) -> list:
    """Value rules of the known columns. ``bad`` masks cells already reported as unparsable."""
    problems = []

    def at(i):
        return f"{name} row {lines[i]}"
    for col, x in cols.items():
        finite = np.isfinite(x)
        for i in np.flatnonzero(~finite & ~bad.get(col, np.zeros(len(x), bool))):
            kind = "NaN" if np.isnan(x[i]) else "infinite"
            problems.append((at(i), f"column {col!r}: {kind} value ({_show(x[i])})"))
        if col in _PRESSURE_COLUMNS:
            for i in np.flatnonzero(finite & (x <= 0)):
                problems.append((at(i), (f"column {col!r}: absolute pressure must be > 0 Pa, "
                                        f"got {_show(x[i])}")))
        if col == "command_V":
            for i in np.flatnonzero(finite & (np.abs(x) > COMMAND_LIMIT_V + COMMAND_TOLERANCE_V)):
                problems.append((at(i), (f"column 'command_V': {_show(x[i])} V is outside "
                                        f"-5..+5 V")))
        if col == "time_s":
            idx = np.flatnonzero(finite)
            t = x[idx]
            # compared, not subtracted: a difference of huge times overflows
            for k in np.flatnonzero(t[1:] <= t[:-1]):
                i, j = idx[k + 1], idx[k]
                kind = "duplicated" if t[k + 1] == t[k] else "decreasing"
                problems.append((at(i), (f"column 'time_s': {kind} time {_show(x[i])} s (row "
                                        f"{lines[j]} has {_show(x[j])} s); time must be "
                                        f"strictly increasing")))
    return problems


def _read_text(path: Path, problems: list) -> str | None:
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:  # read-only, always
            return f.read()
    except FileNotFoundError:
        problems.append((str(path), ("file not found (a recording is a .csv and a .json file "
                                    "with the same stem)")))
    except UnicodeDecodeError as e:
        problems.append((str(path), f"not UTF-8 text ({e.reason} at byte {e.start})"))
    except OSError as e:
        problems.append((str(path), f"cannot be read: {e.strerror or e}"))
    return None


def _parse_json(text: str, name: str, problems: list) -> RecordingMetadata | None:
    duplicates = []

    def pairs(items):
        seen = set()
        for key, _ in items:
            if key in seen:
                duplicates.append((f"{name} key {key!r}", "duplicate key"))
            seen.add(key)
        return dict(items)
    try:
        data = json.loads(text, object_pairs_hook=pairs, parse_constant=float)
    except json.JSONDecodeError as e:
        problems.append((f"{name} line {e.lineno} column {e.colno}",
                         f"JSON does not parse: {e.msg}"))
        return None
    except RecursionError:
        problems.append((name, "JSON does not parse: nested too deeply"))
        return None
    problems.extend(duplicates)
    if not isinstance(data, dict):
        problems.append((f"{name} top level", f"must be a JSON object, got {type(data).__name__}"))
        return None
    metadata = _check_metadata(data, name, problems)
    return None if duplicates else metadata


def _floats(cells) -> np.ndarray:
    return np.fromiter(map(float, cells), dtype=np.float64)


def _numbers(cells: list) -> tuple[np.ndarray, list]:
    """Values of a column (NaN where a cell is not a number) and which cells are numbers."""
    text = "\n".join(cells)
    if text.count("\n") == len(cells) - 1 and _PLAIN.fullmatch(text):  # fast path
        try:
            return _floats(cells), [True] * len(cells)
        except ValueError:
            pass
    ok = [bool(_NUMBER.fullmatch(c)) for c in cells]
    return _floats(c if g else "nan" for c, g in zip(cells, ok)), ok


def _parse_csv(text: str, name: str, problems: list):
    """Return ``(columns, extra_columns)`` or None; append problems."""
    header, rows, lines, last = None, [], [], 0
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        for row in reader:
            start, last = last + 1, reader.line_num
            if header is None:
                header = [c.strip() for c in row]
            else:
                rows.append(row)
                lines.append(start)
    except csv.Error as e:
        problems.append((f"{name} row {last + 1}", f"CSV does not parse: {e}"))
    head = f"{name} row 1 (header)"
    if not header:
        problems.append((head, "empty file: no header row" if header is None else "empty header"))
        return None
    while rows and not rows[-1]:  # blank lines at the very end are harmless
        rows.pop()
        lines.pop()
    columns = {}
    for j, col in enumerate(header):
        if not col:
            problems.append((head, f"column {j + 1} has an empty name"))
        elif col in columns:
            problems.append((head, (f"duplicate column name {col!r} (columns {columns[col] + 1} "
                                   f"and {j + 1})")))
        else:
            columns[col] = j
    if all(_NUMBER.fullmatch(c) for c in header):
        general = "; the first line looks like data: a header row is needed"
    elif any(";" in c or "\t" in c for c in header):
        general = "; the separator must be ',' (found ';' or a tab in the header)"
    else:
        general = ""
    for col in REQUIRED_COLUMNS:
        if col not in columns:
            hint = general or _hint(col, columns)
            problems.append((head, f"missing required column {col!r}" + hint))
    good_rows, good_lines = [], []
    for row, line in zip(rows, lines):
        if len(row) == len(header):
            good_rows.append(row)
            good_lines.append(line)
        else:
            reason = "blank line" if not row else \
                f"has {len(row)} field(s), the header has {len(header)}"
            problems.append((f"{name} row {line}", reason))
    if not rows:
        problems.append((f"{name} row 2", "no data rows: a recording needs at least one sample"))
    known, extra, bad = {}, {}, {}
    for col, j in columns.items():
        cells = [row[j] for row in good_rows]
        values, ok = _numbers(cells)
        if col not in _KNOWN_COLUMNS:  # kept as numbers if all numeric, else as text
            extra[col] = values if all(ok) else np.array(cells, dtype=str)
            continue
        for c, good, line in zip(cells, ok, good_lines):
            if not good:
                what = "empty cell" if not c.strip() else f"{_show(c)} is not a number"
                problems.append((f"{name} row {line}", f"column {col!r}: {what}"))
        known[col], bad[col] = values, ~np.array(ok, dtype=bool)
    problems.extend(_check_columns(known, bad, good_lines, name))
    return known, extra


def _problems_and_recording(path) -> tuple[list, Recording | None]:
    csv_path, json_path = recording_paths(path)
    problems: list = []
    csv_text = _read_text(csv_path, problems)
    json_text = _read_text(json_path, problems)
    metadata = None if json_text is None else _parse_json(json_text, str(json_path), problems)
    parsed = None if csv_text is None else _parse_csv(csv_text, str(csv_path), problems)
    if problems or parsed is None or metadata is None:
        return problems, None
    known, extra = parsed
    known["command_V"] = np.clip(known["command_V"], -COMMAND_LIMIT_V, COMMAND_LIMIT_V)
    return [], Recording(metadata=metadata, extra_columns=extra, source=str(csv_path), **known)


def check_recording(path: str | os.PathLike) -> list[tuple[str, str]]:
    """Every problem of the recording at ``path`` (.csv, .json or stem); [] when valid.

    Never raises for bad content (unreadable or missing files are problems too).
    """
    return _problems_and_recording(path)[0]


def read_recording(path: str | os.PathLike) -> Recording:
    """Read and validate a recording given its .csv, its .json or its stem.

    The rules are listed in the module docstring.

    Raises
    ------
    RecordingError
        Listing every problem found, each with file and row or key.
    """
    problems, recording = _problems_and_recording(path)
    if recording is None:
        raise RecordingError(problems)
    return recording


def _recording_problems(rec: Recording, csv_name: str, json_name: str) -> list:
    """The read rules applied to an in-memory recording about to be written."""
    md = rec.metadata
    data = {k: getattr(md, k) for k in _KNOWN_KEYS if getattr(md, k) is not None}
    problems: list = []
    for key in md.extra:
        if key in _KNOWN_KEYS or not isinstance(key, str):
            problems.append((f"{json_name} key {key!r}", ("extra key must be a string that is "
                                                         "not a standard key")))
    extra = {k: v for k, v in md.extra.items() if k not in _KNOWN_KEYS}
    _check_metadata({**extra, **data}, json_name, problems)
    n = rec.time_s.shape[0] if rec.time_s.ndim else 0
    cols = {c: getattr(rec, c) for c in _KNOWN_COLUMNS if getattr(rec, c) is not None}
    for col, a in list(cols.items()) + list(rec.extra_columns.items()):
        if a.shape != (n,):
            problems.append((f"{csv_name} column {col!r}",
                             f"has shape {a.shape}, time_s has {n} samples"))
            cols.pop(col, None)
    for col in rec.extra_columns:
        if not isinstance(col, str) or not col or col != col.strip() or col in _KNOWN_COLUMNS:
            problems.append((f"{csv_name} column {col!r}", ("extra column name must be a "
                             "non-empty string without surrounding spaces, not a standard name")))
    if n == 0:
        problems.append((f"{csv_name} row 2",
                         "no data rows: a recording needs at least one sample"))
    return problems + _check_columns(cols, {}, range(2, n + 2), csv_name)


def _quote(text: str) -> str:
    """A CSV field (RFC 4180 quoting; csv.writer leaves a lone '\\r' unquoted)."""
    if any(c in text for c in ',"\r\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def _write_temp(target: Path, text: str, temps: list) -> Path:
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(6)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # umask applies
    temps.append(tmp)
    with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    return tmp


def write_recording(recording: Recording, stem_path: str | os.PathLike,
                    overwrite: bool = False) -> tuple[Path, Path]:
    """Write ``<stem>.csv`` and ``<stem>.json`` so that :func:`read_recording` gives it back.

    Columns are ``time_s, command_V, pressure_Pa``, then ``supply_pressure_Pa`` and
    ``position_m`` when present, then the extra columns; numbers are written with
    ``repr`` (shortest exact form), so a round trip is exact. Commands within the
    tolerance outside +-5 V are clipped, as reading would. Each file is written to a
    temporary file in the same directory and moved into place with ``os.replace``
    (each file is replaced atomically; the pair is not one atomic step).

    Parameters
    ----------
    recording : Recording
        What to write; validated first with the rules of reading.
    stem_path : str or path-like
        The stem, or either file's path.
    overwrite : bool
        Replace existing files (refused by default).

    Returns
    -------
    (csv_path, json_path) : tuple of Path

    Raises
    ------
    RecordingError
        If the recording breaks the contract (nothing is written).
    FileExistsError
        If a target file exists and ``overwrite`` is False.
    """
    csv_path, json_path = recording_paths(stem_path)
    problems = _recording_problems(recording, str(csv_path), str(json_path))
    if problems:
        raise RecordingError(problems)
    if not overwrite:
        for p in (csv_path, json_path):
            if p.exists():
                raise FileExistsError(errno.EEXIST, "refusing to overwrite an existing "
                                      "recording file (pass overwrite=True)", str(p))
    columns = {c: getattr(recording, c) for c in _KNOWN_COLUMNS
               if getattr(recording, c) is not None}
    columns["command_V"] = np.clip(columns["command_V"], -COMMAND_LIMIT_V, COMMAND_LIMIT_V)
    columns.update(recording.extra_columns)
    cells = [map(repr, a.tolist()) if a.dtype.kind == "f" else map(_quote, a.tolist())
             for a in columns.values()]
    csv_text = "".join(",".join(row) + "\n" for row in [map(_quote, columns), *zip(*cells)])
    md = recording.metadata
    meta = {k: float(getattr(md, k)) if k not in _TEXT_KEYS else getattr(md, k)
            for k in _KNOWN_KEYS if getattr(md, k) is not None}
    json_text = json.dumps({**meta, **md.extra}, indent=2, allow_nan=False) + "\n"
    temps: list[Path] = []
    try:
        staged = [(_write_temp(p, text, temps), p)
                  for p, text in ((csv_path, csv_text), (json_path, json_text))]
        for tmp, target in staged:
            os.replace(tmp, target)
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
    return csv_path, json_path
