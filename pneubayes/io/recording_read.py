"""Reading recordings: CSV and JSON text -> a validated :class:`Recording`.

The rules are in :mod:`pneubayes.io.recording`'s docstring; format 2's declared units
(:mod:`pneubayes.io.units`) are converted to SI names here, before any check, and the
plausibility rules (:mod:`pneubayes.io.plausibility`) run on the result.
"""

from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pneubayes.errors import RecordingError
from pneubayes.io.plausibility import Finding, check_accept, recording_findings
from pneubayes.io.recording_format import (
    COMMAND_LIMIT_V,
    EXHAUST_COMMAND_COLUMN,
    FORMAT_1,
    FORMAT_2,
    FORMAT_KEY,
    KNOWN_COLUMNS,
    KNOWN_KEYS,
    NUMBER_PATTERN,
    PLAIN_PATTERN,
    REQUIRED_COLUMNS,
    RIG_KEY,
    VALID_COLUMN,
    Recording,
    check_columns,
    check_metadata,
    finite_number,
    name_hint,
    recording_paths,
    show_value,
)
from pneubayes.io.units import parse_declared


def _read_text(path: Path, problems: list) -> str | None:
    from pneubayes.errors import PneubayesError
    from pneubayes.limits import input_file_problem

    try:
        why = input_file_problem(path)  # never opened: a named pipe cannot block
    except PneubayesError as exc:
        why = str(exc)
    if why is not None:
        problems.append((str(path), why))
        return None
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


def _parse_json(text: str, name: str, problems: list, rig_card=None):
    """``(metadata or None, format version, conversions, rig card or None)``; append
    problems. The card is ``rig_card`` if given, else the one the ``rig`` key names
    (a path relative to the sidecar); it supplies the keys the sidecar leaves out."""
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
        return None, 1, [], None
    except RecursionError:
        problems.append((name, "JSON does not parse: nested too deeply"))
        return None, 1, [], None
    problems.extend(duplicates)
    if not isinstance(data, dict):
        problems.append((f"{name} top level", f"must be a JSON object, got {type(data).__name__}"))
        return None, 1, [], None
    version = _format_version(data, name, problems)
    conversions = _declared_keys(data, name, problems) if version == 2 else []
    card = rig_card if rig_card is not None else _named_rig_card(data, name, problems)
    if card is not None:
        for key, value in card.metadata_defaults().items():
            data.setdefault(key, value)
    metadata = check_metadata(data, name, problems)
    return (None if duplicates else metadata), version, conversions, card


def _named_rig_card(data: dict, name: str, problems: list):
    """The rig card the sidecar's ``rig`` key names, or None (absent or broken: a
    problem naming the key)."""
    from pneubayes.errors import RigCardError
    from pneubayes.rigcard import load_rig_card

    ref = data.get(RIG_KEY)
    if ref is None:
        return None
    if not (isinstance(ref, str) and ref.strip()):
        problems.append((f"{name} key {RIG_KEY!r}", f"must be the path of a rig card "
                         f"(relative to this file), got {show_value(ref)}"))
        return None
    try:
        return load_rig_card(Path(name).parent / ref)
    except RigCardError as exc:
        problems.append((f"{name} key {RIG_KEY!r}", str(exc)))
        return None


def _format_version(data: dict, name: str, problems: list) -> int:
    """1 or 2 from the ``format`` key (absent, or another kind of value: format 1)."""
    fmt = data.get(FORMAT_KEY)
    if fmt == FORMAT_2:
        return 2
    if fmt is not None and fmt != FORMAT_1:
        problems.append((f"{name} key {FORMAT_KEY!r}", (f"unknown format {show_value(fmt)}; "
                         f"this version reads {FORMAT_1!r} and {FORMAT_2!r} (or no "
                         "'format' key: format 1)")))
    return 1


def _declared_keys(data: dict, name: str, problems: list) -> list[str]:
    """Format 2: replace keys in declared units (``bore_mm``, ``supply_pressure_psi_gauge``)
    by their SI, absolute keys in place; return what was converted."""
    declared = _declared(list(data), KNOWN_KEYS, problems,
                         lambda k: (f"{name} key {k!r}", ""))
    atm = None
    order = sorted(declared.items(), key=lambda kd: kd[1].gauge)  # the atmosphere first
    conversions = []
    for k, d in order:
        x = finite_number(data[k])
        if x is None:
            problems.append((f"{name} key {k!r}",
                             f"must be a finite number, got {show_value(data[k])}"))
            continue
        if d.gauge:
            atm = data.get("atmospheric_pressure_Pa")
            if finite_number(atm) is None:
                problems.append((f"{name} key {k!r}", ("a gauge pressure needs a valid "
                                 "atmospheric pressure")))
                continue
        data[d.si_name] = d.to_si(x, atm)
        del data[k]
        conversions.append(f"{name} key {d.describe()}")
    return conversions


def _floats(cells) -> np.ndarray:
    return np.fromiter(map(float, cells), dtype=np.float64)


def _numbers(cells: list) -> tuple[np.ndarray, list]:
    """Values of a column (NaN where a cell is not a number) and which cells are numbers."""
    text = "\n".join(cells)
    if text.count("\n") == len(cells) - 1 and PLAIN_PATTERN.fullmatch(text):  # fast path
        try:
            return _floats(cells), [True] * len(cells)
        except ValueError:
            pass
    ok = [bool(NUMBER_PATTERN.fullmatch(c)) for c in cells]
    return _floats(c if g else "nan" for c, g in zip(cells, ok)), ok


def _declared_columns(header_names, name: str, version: int, problems: list) -> dict:
    """Format 2: the header's columns in declared units, name -> :class:`DeclaredUnit`."""
    if version != 2:
        return {}
    return _declared(list(header_names), KNOWN_COLUMNS, problems,
                     lambda c: (f"{name} row 1 (header)", f"column {c!r} "))


def _declared(names: list, known, problems: list, where) -> dict:
    """The ``names`` in declared units of a quantity in ``known``, name ->
    :class:`DeclaredUnit`; a quantity given twice (two units, or a unit and its SI name)
    is a problem at ``where(name)``, a (location, message prefix) pair."""
    declared = {n: d for n in names if (d := parse_declared(n)) is not None
                and d.si_name in known and not d.is_si}
    seen = {}
    for n, d in declared.items():
        other = seen.get(d.si_name, d.si_name if d.si_name in names else None)
        if other is not None:
            location, prefix = where(n)
            problems.append((location, f"{prefix}gives {d.si_name} again (also {other!r})"))
        seen[d.si_name] = n
    return declared


def _parse_csv(text: str, name: str, problems: list, version: int = 1,
               atmospheric_pressure_Pa: float | None = None):
    """Return ``(columns, extra_columns, conversions)`` or None; append problems.

    In format 2 a column in a declared unit is converted to its SI name (a gauge
    pressure needs ``atmospheric_pressure_Pa``; without it the values stay unconverted
    and the missing atmosphere has already been reported)."""
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
    if all(NUMBER_PATTERN.fullmatch(c) for c in header):
        general = "; the first line looks like data: a header row is needed"
    elif any(";" in c or "\t" in c for c in header):
        general = "; the separator must be ',' (found ';' or a tab in the header)"
    else:
        general = ""
    declared = _declared_columns(columns, name, version, problems)
    present = {declared[c].si_name if c in declared else c for c in columns}
    for col in REQUIRED_COLUMNS:
        if col not in present:
            hint = general or name_hint(col, columns)
            if version == 1 and any((d := parse_declared(c)) is not None and d.si_name == col
                                    for c in columns):
                hint += (f"; columns in other units need \"{FORMAT_KEY}\": \"{FORMAT_2}\" "
                         "in the JSON file")
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
        problems.append((f"{name} row 2", "no data rows: a recording needs at least two "
                         "samples (one sampling interval)"))
    elif len(rows) == 1:
        problems.append((f"{name} row 2", "one data row: a recording needs at least two "
                         "samples (one sampling interval)"))
    known, extra, bad, labels, conversions = {}, {}, {}, {}, []
    for col, j in columns.items():
        cells = [row[j] for row in good_rows]
        values, ok = _numbers(cells)
        d = declared.get(col)
        si = d.si_name if d is not None else col
        if si not in KNOWN_COLUMNS or si in known:  # kept as numbers if all numeric, else text
            extra[col] = values if all(ok) else np.array(cells, dtype=str)
            continue
        for c, good, line in zip(cells, ok, good_lines):
            if not good:
                what = "empty cell" if not c.strip() else f"{show_value(c)} is not a number"
                problems.append((f"{name} row {line}", f"column {col!r}: {what}"))
        if d is not None:
            labels[si] = f"{col} (as {si})"
            if not d.gauge or atmospheric_pressure_Pa is not None:
                values = d.to_si(values, atmospheric_pressure_Pa)
                conversions.append(f"{name} column {d.describe()}")
        known[si], bad[si] = values, ~np.array(ok, dtype=bool)
    problems.extend(check_columns(known, bad, good_lines, name, labels))
    return known, extra, conversions


def _problems_and_recording(path, accept=(), rig_card=None) -> tuple[list, Recording | None]:
    from pneubayes.errors import RigCardError

    if Path(path).is_dir():
        return [(str(path), "is a folder, not a recording (a .csv and a .json file with "
                 "the same stem)")], None
    csv_path, json_path = recording_paths(path)
    accept = check_accept(accept, "accept")
    problems: list = []
    csv_text = _read_text(csv_path, problems)
    json_text = _read_text(json_path, problems)
    metadata, version, conversions, card = (None, 1, [], None) if json_text is None else \
        _parse_json(json_text, str(json_path), problems, rig_card)
    atm = None if metadata is None else metadata.atmospheric_pressure_Pa
    parsed = None if csv_text is None else _parse_csv(csv_text, str(csv_path), problems,
                                                      version, atm)
    if problems or parsed is None or metadata is None:
        return problems, None
    known, extra, column_conversions = parsed
    if VALID_COLUMN in extra:  # the mask of invalid stretches: 1 valid, 0 invalid
        v = extra[VALID_COLUMN]
        bad = np.nonzero(~np.isin(np.asarray(v).astype(str), ("0", "1", "0.0", "1.0")))[0]
        if bad.size:
            return [(f"{csv_path} row {int(bad[0]) + 2} column {VALID_COLUMN!r}",
                     f"must be 1 (valid) or 0 (invalid), got {show_value(v[bad[0]])}")], None
        if not np.any(np.asarray(v).astype(float) == 1.0):
            return [(f"{csv_path} column {VALID_COLUMN!r}",
                     "every sample is marked invalid (0): nothing in the recording can be "
                     "fitted, simulated from or scored")], None
    if EXHAUST_COMMAND_COLUMN in extra:  # a separate exhaust valve's command
        v = np.asarray(extra[EXHAUST_COMMAND_COLUMN])
        ok = np.isfinite(v) if v.dtype.kind == "f" else np.zeros(v.shape, bool)
        if not ok.all():
            i = int(np.nonzero(~ok)[0][0])
            return [(f"{csv_path} row {i + 2} column {EXHAUST_COMMAND_COLUMN!r}",
                     f"must be a finite number, got {show_value(v[i])}")], None
    known["command_V"] = np.clip(known["command_V"], -COMMAND_LIMIT_V, COMMAND_LIMIT_V)
    rec = Recording(metadata=metadata, extra_columns=extra, source=str(csv_path),
                    conversions=tuple(conversions + column_conversions), **known)
    findings = recording_findings(rec, str(csv_path), str(json_path),
                                  set(accept) | set(metadata.accept_unusual),
                                  position_is_coordinate=card is not None
                                  and card.chamber.maps_position)
    errors = [(f.location, f.text()) for f in findings
              if f.severity == "error" and not f.accepted]
    if errors:
        return errors, None
    rec = replace(rec, findings=tuple(findings))
    if card is not None:
        try:
            rec = card.bind(rec)
        except RigCardError as exc:
            return [(str(json_path), str(exc))], None
    return [], rec


@dataclass(frozen=True)
class RecordingCheck:
    """What :func:`inspect_recording` found: ``problems`` (``(location, reason)`` pairs;
    the recording is unusable when any), ``recording`` (None then) and its plausibility
    ``warnings`` (:class:`~pneubayes.io.plausibility.Finding`, accepted ones included)
    and unit ``conversions``."""

    problems: list
    recording: Recording | None

    @property
    def warnings(self) -> tuple[Finding, ...]:
        return () if self.recording is None else self.recording.findings

    @property
    def conversions(self) -> tuple[str, ...]:
        return () if self.recording is None else self.recording.conversions


def inspect_recording(path: str | os.PathLike, accept=(), rig_card=None) -> RecordingCheck:
    """Read the recording at ``path`` and report everything: the contract's problems,
    plausibility errors (as problems) and warnings, and unit conversions.

    ``accept`` lists plausibility rules to accept beyond the recording's own
    ``accept_unusual`` (:mod:`pneubayes.io.plausibility`). Never raises for bad content.
    """
    return RecordingCheck(*_problems_and_recording(path, accept, rig_card))


def check_recording(path: str | os.PathLike, accept=()) -> list[tuple[str, str]]:
    """Every problem of the recording at ``path`` (.csv, .json or stem); [] when valid.

    Plausibility errors (:mod:`pneubayes.io.plausibility`) are problems; warnings are
    not (see :func:`inspect_recording`). Never raises for bad content (unreadable or
    missing files are problems too).
    """
    return _problems_and_recording(path, accept)[0]


def read_recording(path: str | os.PathLike, accept=(), rig_card=None) -> Recording:
    """Read and validate a recording.

    The rules are listed in the module docstring; then the plausibility rules of
    :mod:`pneubayes.io.plausibility` run: an error is a problem, warnings are kept in
    ``Recording.findings``.

    Parameters
    ----------
    path : str or path-like
        The recording's .csv, its .json or its stem.
    accept : iterable of str
        Plausibility rules accepted beyond the recording's own ``accept_unusual``.
    rig_card : RigCard or None
        A :class:`~pneubayes.rigcard.RigCard` (None: the one the sidecar's ``rig`` key
        names, if any) that supplies the keys the sidecar leaves out and binds the
        recording (:meth:`~pneubayes.rigcard.RigCard.bind`).

    Returns
    -------
    Recording

    Raises
    ------
    RecordingError
        Listing every problem found, each with file and row or key.
    """
    problems, recording = _problems_and_recording(path, accept, rig_card)
    if recording is None:
        raise RecordingError(problems)
    return recording


