"""The recording contract: its names, the in-memory recording, and the value rules.

:mod:`pneubayes.io.recording` documents the rules; reading is
:mod:`pneubayes.io.recording_read`, writing :mod:`pneubayes.io.recording_write`.
"""

from __future__ import annotations

import difflib
import json
import math
import numbers
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from pneubayes.io.plausibility import Finding, check_accept
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.rig import Rig

COMMAND_LIMIT_V = 5.0
COMMAND_TOLERANCE_V = 1e-6
REQUIRED_COLUMNS = ("time_s", "command_V", "pressure_Pa")
OPTIONAL_COLUMNS = ("supply_pressure_Pa", "position_m")
REQUIRED_KEYS = ("cylinder", "valve", "bore_m", "stroke_m", "atmospheric_pressure_Pa",
                 "supply_pressure_Pa", "temperature_K")
OPTIONAL_KEYS = ("position_m", "command_before_start")
#: The JSON key naming the recording's rig card (a path relative to the sidecar).
RIG_KEY = "rig"
#: The optional column marking invalid stretches (1 valid, 0 invalid: a sensor glitch,
#: an event the command does not contain); windows and discovery rows touching an
#: invalid sample are left out.
VALID_COLUMN = "valid"
#: A separately commanded exhaust valve's command (its unit declared by the rig card's
#: ``exhaust`` table), held between samples like ``command_V``.
EXHAUST_COMMAND_COLUMN = "exhaust_command"
#: Keys that may be any finite number (others must be > 0).
SIGNED_KEYS = ("position_m", "command_before_start")
#: The JSON key naming the format; absent or FORMAT_1 is format 1, FORMAT_2 allows
#: columns and keys in declared units (:mod:`pneubayes.io.units`).
FORMAT_KEY = "format"
FORMAT_1 = "pneubayes-recording/1"
FORMAT_2 = "pneubayes-recording/2"
#: The JSON key listing plausibility rules accepted for this recording.
ACCEPT_KEY = "accept_unusual"
KNOWN_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
KNOWN_KEYS = REQUIRED_KEYS + OPTIONAL_KEYS
TEXT_KEYS = ("cylinder", "valve")
PRESSURE_COLUMNS = ("pressure_Pa", "supply_pressure_Pa")
# A decimal number ('.' point) or nan/inf (rejected later with a clear reason); stricter
# than float(), which also takes '1_000', non-ASCII digits and other Python spellings.
NUMBER_PATTERN = re.compile(r"[ \t]*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:e[+-]?[0-9]+)?"
                     r"|nan|inf(?:inity)?)[ \t]*", re.IGNORECASE)
# A column made of these characters only is all numbers iff float() takes every cell.
PLAIN_PATTERN = re.compile(r"[0-9.eE+\- \t\n]*")


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
    command_before_start : float or None
        The command held before the first sample (a triggered recording's pre-trigger
        command), in the command's unit; None: the first sample's command.
    accept_unusual : tuple of str
        Plausibility rules accepted for this recording (:mod:`pneubayes.io.plausibility`).
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
    command_before_start: float | None = None
    accept_unusual: tuple[str, ...] = ()
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
    rig_card : RigCard or None
        The rig card the recording is bound to (:meth:`pneubayes.rigcard.RigCard.bind`):
        its columns are then as the card's model reads them (a chamber coordinate
        mapped to the equivalent piston position).
    findings : tuple of Finding
        Plausibility warnings and accepted findings found when it was read (errors stop
        the reading); runs record them.
    conversions : tuple of str
        How declared units were converted to SI when it was read (format 2).
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
    rig_card: Any = None
    findings: tuple[Finding, ...] = ()
    conversions: tuple[str, ...] = ()

    def __post_init__(self):
        for name in KNOWN_COLUMNS:
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

    def valid_mask(self) -> np.ndarray:
        """Per sample, whether it may be used (the ``valid`` column; all True without)."""
        v = self.extra_columns.get(VALID_COLUMN)
        if v is None:
            return np.ones(self.n_samples, dtype=bool)
        return np.asarray(v).astype(float) > 0.5

    def exhaust_command(self) -> np.ndarray | None:
        """A separate exhaust valve's command per sample (the ``exhaust_command`` column,
        in the unit its rig card declares), or None without one."""
        v = self.extra_columns.get(EXHAUST_COMMAND_COLUMN)
        return None if v is None else np.asarray(v, dtype=np.float64)

    @property
    def command_before_start(self) -> float | None:
        """The pre-trigger command (metadata), or None."""
        return self.metadata.command_before_start

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
        cut = {c: getattr(self, c)[s] for c in KNOWN_COLUMNS if getattr(self, c) is not None}
        return replace(self, **cut, extra_columns={k: v[s] for k, v in self.extra_columns.items()})


def recording_paths(path: str | os.PathLike) -> tuple[Path, Path]:
    """``(csv_path, json_path)`` of a recording given its .csv, its .json or its stem."""
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".csv", ".json") else p
    return Path(f"{stem}.csv"), Path(f"{stem}.json")


def show_value(value, limit: int = 40) -> str:
    text = repr(float(value)) if isinstance(value, (float, np.floating)) else repr(value)
    return text if len(text) <= limit else text[:limit] + "...'"


def finite_number(value) -> float | None:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return None
    try:
        x = float(value)
    except OverflowError:
        return None
    return x if math.isfinite(x) else None


def name_hint(name: str, candidates) -> str:
    close = difflib.get_close_matches(name, [c for c in candidates if c != name], n=1)
    return f" (found {close[0]!r}; names are case-sensitive)" if close else ""


def check_metadata(data: dict, name: str, problems: list) -> RecordingMetadata | None:
    """Validate a JSON object against the contract; append problems, return metadata or None."""
    def at(key):
        return f"{name} key {key!r}"
    n_before, values = len(problems), {}
    for key in KNOWN_KEYS:
        if key not in data:
            if key in REQUIRED_KEYS:
                problems.append((at(key), "missing required key" + name_hint(key, data)))
            continue
        v = data[key]
        if key in TEXT_KEYS:
            if isinstance(v, str) and v.strip():
                values[key] = v
            else:
                problems.append((at(key), f"must be a non-empty string, got {show_value(v)}"))
            continue
        x = finite_number(v)
        if x is None:
            problems.append((at(key), f"must be a finite number, got {show_value(v)}"))
        elif key not in SIGNED_KEYS and x <= 0:
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
    if ACCEPT_KEY in data:
        try:
            values[ACCEPT_KEY] = check_accept(data[ACCEPT_KEY], at(ACCEPT_KEY))
        except ValueError as exc:
            problems.append((at(ACCEPT_KEY), str(exc).partition(": ")[2]))
    extra = {k: v for k, v in data.items() if k not in KNOWN_KEYS and k != ACCEPT_KEY}
    for key, v in extra.items():
        try:
            json.dumps(v, allow_nan=False)
        except (TypeError, ValueError) as e:
            problems.append((at(key), f"value cannot be stored as JSON: {e}"))
    if len(problems) > n_before:
        return None
    return RecordingMetadata(**values, extra=extra)


#: Hard limits on every sample (not plausibility rules: never accepted): no absolute
#: pressure above this, Pa, and no two time stamps closer than this, s (time stamps in
#: nanoseconds or microseconds written as seconds).
SAMPLE_PRESSURE_MAX_Pa = 10e6
MIN_TIME_STEP_s = 1e-6
#: Rows named per hard-limit problem; the rest are counted.
_ROWS_NAMED = 3


def _first_rows(found: list, total: int) -> list:
    """The problems of the first offending rows (``found``) and a count of the rest."""
    out = list(found[:_ROWS_NAMED])
    if total > len(out):
        loc, text = out[-1]
        out[-1] = (loc, f"{text} (and {total - len(out)} more row(s) like it)")
    return out


def check_columns(cols: dict, bad: dict, lines, name: str, labels=None) -> list:
    """Value rules of the known columns. ``bad`` masks cells already reported as unparsable;
    ``labels`` names a column converted from a declared unit as the file has it.
    Every sample is checked: finite, pressures absolute and at most 10 MPa, time strictly
    increasing in steps of at least 1 us."""
    problems = []

    def at(i):
        return f"{name} row {lines[i]}"
    for si_col, x in cols.items():
        col = (labels or {}).get(si_col, si_col)
        finite = np.isfinite(x)
        for i in np.flatnonzero(~finite & ~bad.get(col, np.zeros(len(x), bool))):
            kind = "NaN" if np.isnan(x[i]) else "infinite"
            problems.append((at(i), f"column {col!r}: {kind} value ({show_value(x[i])})"))
        if si_col in PRESSURE_COLUMNS:
            for i in np.flatnonzero(finite & (x <= 0)):
                problems.append((at(i), (f"column {col!r}: absolute pressure must be > 0 Pa, "
                                        f"got {show_value(x[i])} (a gauge pressure? format 2 "
                                        "declares one with a _gauge column)")))
            high = np.flatnonzero(finite & (x > SAMPLE_PRESSURE_MAX_Pa))
            problems += _first_rows([(at(i), (
                f"column {col!r}: {show_value(x[i])} Pa is above any pneumatic pressure "
                "(10 MPa absolute); another unit, or a corrupt value?"))
                for i in high[:_ROWS_NAMED]], high.size)
        if si_col == "command_V":
            out = np.flatnonzero(finite & (np.abs(x) > COMMAND_LIMIT_V + COMMAND_TOLERANCE_V))
            # a 0-10 V valve's convention (neutral at 5 V) is the likeliest slip
            hint = ("; a 0-10 V command (neutral at 5 V)? command_V is the valve's "
                    "command about its neutral, -5..+5 V: subtract 5 V"
                    if out.size and np.all(x[finite] >= -COMMAND_TOLERANCE_V)
                    and np.all(x[finite] <= 2 * COMMAND_LIMIT_V + COMMAND_TOLERANCE_V)
                    else "")
            problems += _first_rows([(at(i), (
                f"column 'command_V': {show_value(x[i])} V is outside -5..+5 V{hint}"))
                for i in out[:_ROWS_NAMED]], out.size)
        if si_col == "time_s":
            idx = np.flatnonzero(finite)
            t = x[idx]
            # compared, not subtracted: a difference of huge times overflows
            for k in np.flatnonzero(t[1:] <= t[:-1]):
                i, j = idx[k + 1], idx[k]
                kind = "duplicated" if t[k + 1] == t[k] else "decreasing"
                problems.append((at(i), (f"column {col!r}: {kind} time {show_value(x[i])} s (row "
                                        f"{lines[j]} has {show_value(x[j])} s); time must be "
                                        f"strictly increasing")))
            with np.errstate(over="ignore", invalid="ignore"):
                step = t[1:] - t[:-1]
            # (a relative 1e-3 below: 1 us steps summed in binary fall a little short)
            close = np.flatnonzero((t[1:] > t[:-1]) & (step < MIN_TIME_STEP_s * (1 - 1e-3)))
            problems += _first_rows([(at(idx[k + 1]), (
                f"column {col!r}: {show_value(t[k + 1])} s is only {step[k]:.3g} s after "
                f"row {lines[idx[k]]}; samples under 1 us apart are time stamps in another "
                "unit (nanoseconds or microseconds as seconds?)"))
                for k in close[:_ROWS_NAMED]], close.size)
    return problems


