"""Writing recordings: a :class:`Recording` -> CSV and JSON files, atomically per file."""

from __future__ import annotations

import errno
import json
import os
import secrets
from pathlib import Path

import numpy as np

from pneubayes.errors import RecordingError
from pneubayes.io.recording_format import (
    ACCEPT_KEY,
    COMMAND_LIMIT_V,
    KNOWN_COLUMNS,
    KNOWN_KEYS,
    TEXT_KEYS,
    Recording,
    check_columns,
    check_metadata,
    recording_paths,
)


def _recording_problems(rec: Recording, csv_name: str, json_name: str) -> list:
    """The read rules applied to an in-memory recording about to be written."""
    md = rec.metadata
    data = {k: getattr(md, k) for k in KNOWN_KEYS if getattr(md, k) is not None}
    if md.accept_unusual:
        data[ACCEPT_KEY] = list(md.accept_unusual)
    problems: list = []
    for key in md.extra:
        if key in KNOWN_KEYS or key == ACCEPT_KEY or not isinstance(key, str):
            problems.append((f"{json_name} key {key!r}", ("extra key must be a string that is "
                                                         "not a standard key")))
    extra = {k: v for k, v in md.extra.items() if k not in KNOWN_KEYS}
    check_metadata({**extra, **data}, json_name, problems)
    n = rec.time_s.shape[0] if rec.time_s.ndim else 0
    cols = {c: getattr(rec, c) for c in KNOWN_COLUMNS if getattr(rec, c) is not None}
    for col, a in list(cols.items()) + list(rec.extra_columns.items()):
        if a.shape != (n,):
            problems.append((f"{csv_name} column {col!r}",
                             f"has shape {a.shape}, time_s has {n} samples"))
            cols.pop(col, None)
    for col in rec.extra_columns:
        if not isinstance(col, str) or not col or col != col.strip() or col in KNOWN_COLUMNS:
            problems.append((f"{csv_name} column {col!r}", ("extra column name must be a "
                             "non-empty string without surrounding spaces, not a standard name")))
    if n < 2:
        problems.append((f"{csv_name} row 2", ("no data rows" if n == 0 else "one data row")
                         + ": a recording needs at least two samples (one sampling "
                         "interval)"))
    return problems + check_columns(cols, {}, range(2, n + 2), csv_name)


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
    if recording.rig_card is not None:
        raise ValueError(f"write_recording: {recording.source} is bound to the rig card "
                         f"{recording.rig_card.source} (its columns are as the model reads "
                         "them); write the recording as read, before binding")
    problems = _recording_problems(recording, str(csv_path), str(json_path))
    if problems:
        raise RecordingError(problems)
    if not overwrite:
        for p in (csv_path, json_path):
            if p.exists():
                raise FileExistsError(errno.EEXIST, "refusing to overwrite an existing "
                                      "recording file (pass overwrite=True)", str(p))
    columns = {c: getattr(recording, c) for c in KNOWN_COLUMNS
               if getattr(recording, c) is not None}
    columns["command_V"] = np.clip(columns["command_V"], -COMMAND_LIMIT_V, COMMAND_LIMIT_V)
    columns.update(recording.extra_columns)
    cells = [map(repr, a.tolist()) if a.dtype.kind == "f" else map(_quote, a.tolist())
             for a in columns.values()]
    csv_text = "".join(",".join(row) + "\n" for row in [map(_quote, columns), *zip(*cells)])
    md = recording.metadata
    meta = {k: float(getattr(md, k)) if k not in TEXT_KEYS else getattr(md, k)
            for k in KNOWN_KEYS if getattr(md, k) is not None}
    if md.accept_unusual:
        meta[ACCEPT_KEY] = list(md.accept_unusual)
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
