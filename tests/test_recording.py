"""Tests of the recording interchange format (pneubayes.io.recording)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pneubayes.errors import RecordingError
from pneubayes.io import (
    Recording,
    RecordingMetadata,
    check_recording,
    read_recording,
    recording_paths,
    write_recording,
)
from pneubayes.io.plausibility import RULES
from pneubayes.rig import Rig

#: The structural round trips below use values no rig has (1 Pa atmospheres): the
#: plausibility rules (tests/test_plausibility.py) are accepted there.
STRUCTURE_ONLY = tuple(RULES)

META = {
    "cylinder": "AIR37",
    "valve": "valve1",
    "bore_m": 0.009,
    "stroke_m": 0.0375,
    "atmospheric_pressure_Pa": 101325.0,
    "supply_pressure_Pa": 551325.0,
    "temperature_K": 293.15,
}
HEADER = "time_s,command_V,pressure_Pa,supply_pressure_Pa,position_m"
ROWS = [  # line 2 .. line 7 of the CSV
    "0.0,0.0,101325.0,551325.0,0.01",
    "0.001,2.5,150000.0,551000.0,0.011",
    "0.002,5.0,250000.0,550500.0,0.012",
    "0.003,-1.0,240000.0,550900.0,0.0125",
    "0.004,-5.0,180000.0,551200.0,0.012",
    "0.005,0.0,170000.0,551325.0,0.0119",
]
SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


def make_files(tmp_path, csv_text=None, meta=None, json_text=None, stem="run01"):
    """Write a recording's two files; return the stem path."""
    if csv_text is None:
        csv_text = "\n".join([HEADER, *ROWS]) + "\n"
    if json_text is None:
        json_text = json.dumps(META if meta is None else meta, indent=2)
    base = tmp_path / stem
    (tmp_path / f"{stem}.csv").write_bytes(csv_text.encode("utf-8", "surrogateescape"))
    (tmp_path / f"{stem}.json").write_bytes(json_text.encode("utf-8"))
    return base


def rows_with(line, row):
    """CSV text with data row at CSV line ``line`` replaced by ``row``."""
    rows = list(ROWS)
    rows[line - 2] = row
    return "\n".join([HEADER, *rows]) + "\n"


def meta_with(**changes):
    meta = dict(META)
    for key, value in changes.items():
        if value is ...:
            del meta[key]
        else:
            meta[key] = value
    return meta


def make_recording(n=5, supply=True, position=True, extra_columns=None, **meta_extra):
    t = np.linspace(0.0, 0.01, n)
    return Recording(
        metadata=RecordingMetadata(**META, extra=meta_extra),
        time_s=t,
        command_V=np.linspace(-5.0, 5.0, n),
        pressure_Pa=1.5e5 + 1e5 * np.sin(t * 300.0),
        supply_pressure_Pa=np.full(n, 551325.0) - t if supply else None,
        position_m=0.001 + t if position else None,
        extra_columns=extra_columns or {},
    )


def assert_same(a: Recording, b: Recording):
    assert a.metadata == b.metadata
    for name in ("time_s", "command_V", "pressure_Pa", "supply_pressure_Pa", "position_m"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert x.dtype == y.dtype == np.float64
            assert x.tobytes() == y.tobytes(), name  # bit-exact
    assert list(a.extra_columns) == list(b.extra_columns)
    for name, x in a.extra_columns.items():
        np.testing.assert_array_equal(x, b.extra_columns[name])
        assert x.dtype.kind == b.extra_columns[name].dtype.kind


def assert_valid(rec: Recording):
    """Invariants that every recording returned by read_recording satisfies."""
    n = rec.n_samples
    assert n >= 1
    for a in (rec.time_s, rec.command_V, rec.pressure_Pa, rec.supply_or_nominal(),
              rec.position_or_fixed()):
        assert a.shape == (n,) and a.dtype == np.float64 and np.all(np.isfinite(a))
    assert np.all(np.diff(rec.time_s) > 0)
    assert np.all(rec.pressure_Pa > 0) and np.all(rec.supply_or_nominal() > 0)
    assert np.all(np.abs(rec.command_V) <= 5.0)


# ---------------------------------------------------------------- round trips and API


@pytest.mark.parametrize("supply,position", [(True, True), (False, False), (True, False)])
def test_round_trip(tmp_path, supply, position):
    rec = make_recording(supply=supply, position=position)
    csv_path, json_path = write_recording(rec, tmp_path / "run01")
    assert (csv_path.name, json_path.name) == ("run01.csv", "run01.json")
    back = read_recording(tmp_path / "run01")
    assert_same(rec, back)
    assert back.source == str(csv_path)
    header = csv_path.read_text().splitlines()[0].split(",")
    assert header == ["time_s", "command_V", "pressure_Pa"] + \
        ["supply_pressure_Pa"] * supply + ["position_m"] * position


def test_round_trip_keeps_extra_columns_and_keys(tmp_path):
    extra = {"flow_slpm": np.array([1.0, np.nan, 0.1, -2e-300, 1e300]),
             "note, quoted \"x\"": np.array(["a", "b,c", "", " d ", "e\nf"])}
    rec = make_recording(extra_columns=extra, operator="ada", gains=[1, 2.5, None],
                         nested={"k": True})
    write_recording(rec, tmp_path / "run01.csv")
    back = read_recording(tmp_path / "run01.json")
    assert_same(rec, back)
    assert back.metadata.extra == {"operator": "ada", "gains": [1, 2.5, None],
                                   "nested": {"k": True}}


def test_reads_contract_example_by_any_name(tmp_path):
    stem = make_files(tmp_path, csv_text="pressure_Pa,time_s,command_V,spare\n"
                                         "101325,0,0,x\n2e5,0.5,+4.5,y\n")
    for name in (stem, f"{stem}.csv", f"{stem}.json"):
        rec = read_recording(name)
        np.testing.assert_array_equal(rec.time_s, [0.0, 0.5])
        np.testing.assert_array_equal(rec.pressure_Pa, [101325.0, 2e5])
        assert rec.supply_pressure_Pa is None and rec.position_m is None
        assert list(rec.extra_columns["spare"]) == ["x", "y"]
    assert recording_paths(tmp_path / "a.b.json") == (tmp_path / "a.b.csv", tmp_path / "a.b.json")
    assert recording_paths("run.01") == (recording_paths("run.01.csv"))


@pytest.mark.parametrize("newline", ["\r\n", "\r"])
def test_spreadsheet_exports_are_read(tmp_path, newline):
    """A BOM, CRLF or CR line ends, quoted cells, spaces and trailing blank lines."""
    text = newline.join(["\ufefftime_s, command_V ,pressure_Pa", '0,"1.5",1e5', " 1e-3 ,-2, 2E5",
                         "", ""])
    (tmp_path / "x.csv").write_bytes(text.encode())
    (tmp_path / "x.json").write_text(json.dumps(META))
    rec = read_recording(tmp_path / "x")
    assert rec.time_s.tolist() == [0.0, 0.001] and rec.command_V.tolist() == [1.5, -2.0]


def test_derived_quantities(tmp_path):
    rec = read_recording(make_files(tmp_path))
    assert rec.n_samples == 6
    np.testing.assert_array_equal(rec.supply_or_nominal(), rec.supply_pressure_Pa)
    np.testing.assert_array_equal(rec.position_or_fixed(), rec.position_m)
    assert rec.working_range_Pa == 551325.0 - 101325.0
    rig = rec.rig()
    assert isinstance(rig, Rig) and rig.gas.temperature_K == 293.15
    assert rig.bore_m == 0.009 and rig.working_range_Pa == rec.working_range_Pa
    part = rec.slice(1, 4)
    assert part.n_samples == 3 and part.time_s[0] == 0.001
    assert part.position_m.tolist() == rec.position_m[1:4].tolist()
    with pytest.raises(ValueError, match="no sample"):
        rec.slice(4, 4)
    with pytest.raises(ValueError):  # arrays are read-only
        rec.time_s[0] = 1.0


def test_nominal_supply_and_fixed_position(tmp_path):
    bare = make_recording(n=4, supply=False, position=False)
    np.testing.assert_array_equal(bare.supply_or_nominal(), np.full(4, 551325.0))
    np.testing.assert_array_equal(bare.position_or_fixed(), np.zeros(4))
    write_recording(bare, tmp_path / "fixed")
    meta = json.loads((tmp_path / "fixed.json").read_text())
    (tmp_path / "fixed.json").write_text(json.dumps({**meta, "position_m": 0.02}))
    rec = read_recording(tmp_path / "fixed")
    assert rec.metadata.position_m == 0.02
    np.testing.assert_array_equal(rec.position_or_fixed(), np.full(4, 0.02))


def test_command_within_rounding_is_clipped(tmp_path):
    stem = make_files(tmp_path, csv_text=rows_with(3, "0.001,5.0000005,150000.0,551000.0,0.011")
                      .replace("-5.0,", "-5.0000009,"))
    rec = read_recording(stem)
    assert rec.command_V[1] == 5.0 and rec.command_V[4] == -5.0


# ---------------------------------------------------------------- bad input

BAD = {
    # name: (csv text, json text or meta dict, location, reason)
    "missing_column": (
        "time_s,pressure_Pa\n0,101325\n1,101325", None,
        "run01.csv row 1", "missing required column 'command_V'"),
    "missing_column_case": (
        "Time_s,command_V,pressure_Pa\n0,0,101325", None,
        "run01.csv row 1", "missing required column 'time_s' (found 'Time_s'"),
    "no_header": ("\n".join(ROWS), None, "run01.csv row 1", "header row is needed"),
    "semicolons": ("time_s;command_V;pressure_Pa\n0;0;101325\n", None,
                   "run01.csv row 1", "separator must be ','"),
    "empty_file": ("", None, "run01.csv row 1", "empty file"),
    "duplicate_column": (
        "time_s,command_V,pressure_Pa,time_s\n0,0,101325,0\n", None,
        "run01.csv row 1", "duplicate column name 'time_s'"),
    "empty_column_name": (
        "time_s,command_V,pressure_Pa,\n0,0,101325,1\n", None,
        "run01.csv row 1", "column 4 has an empty name"),
    "too_many_fields": (rows_with(3, "0.001,2.5,150000.0,551000.0,0.011,7"), None,
                        "run01.csv row 3", "has 6 field(s), the header has 5"),
    "decimal_comma": (rows_with(4, "0.002,5.0,250000.0,550500.0,0,012"), None,
                      "run01.csv row 4", "has 6 field(s)"),
    "too_few_fields": (rows_with(5, "0.003,-1.0"), None, "run01.csv row 5", "has 2 field(s)"),
    "blank_line": (rows_with(6, ""), None, "run01.csv row 6", "blank line"),
    "no_data_rows": (HEADER + "\n", None, "run01.csv row 2", "no data rows"),
    "non_numeric": (rows_with(4, "0.002,5.0,2.5 bar,550500.0,0.012"), None,
                    "run01.csv row 4", "column 'pressure_Pa': '2.5 bar' is not a number"),
    "python_only_number": (rows_with(4, "0.002,5.0,250_000,550500.0,0.012"), None,
                           "run01.csv row 4", "'250_000' is not a number"),
    "empty_cell": (rows_with(7, "0.005,,170000.0,551325.0,0.0119"), None,
                   "run01.csv row 7", "column 'command_V': empty cell"),
    "decreasing_time": (rows_with(5, "0.0015,-1.0,240000.0,550900.0,0.0125"), None,
                        "run01.csv row 5", "decreasing time"),
    "duplicated_time": (rows_with(5, "0.002,-1.0,240000.0,550900.0,0.0125"), None,
                        "run01.csv row 5", "duplicated time"),
    "nan": (rows_with(3, "0.001,2.5,NaN,551000.0,0.011"), None,
            "run01.csv row 3", "column 'pressure_Pa': NaN value"),
    "infinite": (rows_with(6, "0.004,-5.0,180000.0,551200.0,-inf"), None,
                 "run01.csv row 6", "column 'position_m': infinite value"),
    "overflow": (rows_with(6, "1e999,-5.0,180000.0,551200.0,0.012"), None,
                 "run01.csv row 6", "column 'time_s': infinite value"),
    "negative_pressure": (rows_with(4, "0.002,5.0,-250000.0,550500.0,0.012"), None,
                          "run01.csv row 4", "absolute pressure must be > 0 Pa"),
    "zero_pressure": (rows_with(4, "0.002,5.0,0,550500.0,0.012"), None,
                      "run01.csv row 4", "absolute pressure must be > 0 Pa, got 0.0"),
    "negative_supply": (rows_with(2, "0.0,0.0,101325.0,-1,0.01"), None,
                        "run01.csv row 2", "column 'supply_pressure_Pa': absolute pressure"),
    "command_out_of_range": (rows_with(3, "0.001,10.0,150000.0,551000.0,0.011"), None,
                             "run01.csv row 3", "10.0 V is outside -5..+5 V"),
    "command_beyond_rounding": (rows_with(3, "0.001,-5.00001,150000.0,551000.0,0.011"),
                                None, "run01.csv row 3", "is outside -5..+5 V"),
    "not_utf8": ("time_s,command_V,pressure_Pa\n0,0,1\xe9\n".encode("latin-1").decode(
        "utf-8", "surrogateescape"), None, "run01.csv", "not UTF-8"),
    "missing_key": (None, meta_with(bore_m=...), "run01.json key 'bore_m'",
                    "missing required key"),
    "json_syntax": (None, '{"cylinder": "AIR37",,}', "run01.json line 1 column 22",
                    "JSON does not parse"),
    "json_empty": (None, "", "run01.json line 1", "JSON does not parse"),
    "json_not_object": (None, "[1, 2]", "run01.json top level", "must be a JSON object"),
    "json_duplicate_key": (None, json.dumps(META)[:-1] + ', "bore_m": 0.01}',
                           "run01.json key 'bore_m'", "duplicate key"),
    "json_string_number": (None, meta_with(bore_m="0.009"), "run01.json key 'bore_m'",
                           "must be a finite number, got '0.009'"),
    "json_bool_number": (None, meta_with(stroke_m=True), "run01.json key 'stroke_m'",
                         "must be a finite number, got True"),
    "json_nan": (None, json.dumps(meta_with(temperature_K=float("nan"))),
                 "run01.json key 'temperature_K'", "must be a finite number, got nan"),
    "json_huge_int": (None, meta_with(temperature_K=10**400),
                      "run01.json key 'temperature_K'", "must be a finite number"),
    "json_zero_bore": (None, meta_with(bore_m=0), "run01.json key 'bore_m'",
                       "value must be > 0, got 0.0"),
    "json_negative_pressure": (None, meta_with(atmospheric_pressure_Pa=-101325.0),
                               "run01.json key 'atmospheric_pressure_Pa'",
                               "absolute pressure must be > 0"),
    "json_supply_below_atmosphere": (None, meta_with(supply_pressure_Pa=101325.0),
                                     "run01.json key 'supply_pressure_Pa'",
                                     "must exceed atmospheric_pressure_Pa (101325.0)"),
    "json_cylinder_not_text": (None, meta_with(cylinder=37), "run01.json key 'cylinder'",
                               "must be a non-empty string, got 37"),
    "json_position_outside_stroke": (None, meta_with(position_m=0.5),
                                     "run01.json key 'position_m'", "within 0..stroke_m"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_reported_with_file_location_and_reason(tmp_path, case):
    csv_text, meta, location, reason = BAD[case]
    json_text = meta if isinstance(meta, str) else None
    meta = meta if isinstance(meta, dict) else None
    stem = make_files(tmp_path, csv_text=csv_text, meta=meta, json_text=json_text)
    with pytest.raises(RecordingError) as err:
        read_recording(stem)
    problems = err.value.problems
    assert any(loc.startswith(str(tmp_path / location)) and reason in why
               for loc, why in problems), problems
    assert str(tmp_path / location) in str(err.value) and reason in str(err.value)
    assert isinstance(err.value, ValueError)
    assert check_recording(stem) == problems


@pytest.mark.parametrize("missing", ["csv", "json"])
def test_missing_partner_file(tmp_path, missing):
    stem = make_files(tmp_path)
    (tmp_path / f"run01.{missing}").unlink()
    with pytest.raises(RecordingError) as err:
        read_recording(tmp_path / "run01.csv")
    assert err.value.problems == [(str(tmp_path / f"run01.{missing}"),
                                   ("file not found (a recording is a .csv and a .json file "
                                   "with the same stem)"))]
    assert check_recording(stem) == err.value.problems


def test_every_problem_is_reported(tmp_path):
    rows = list(ROWS)
    rows[1] = "0.001,9.0,NaN,551000.0,0.011"       # line 3: command and NaN
    rows[3] = "0.0005,-1.0,-4,550900.0,0.0125"     # line 5: time and pressure
    rows[4] = "0.004,-5.0,180000.0"                # line 6: field count
    stem = make_files(tmp_path, csv_text="\n".join([HEADER, *rows]),
                      meta=meta_with(valve=..., bore_m="x", supply_pressure_Pa=1.0))
    problems = check_recording(stem)
    where = sorted(loc.rsplit(os.sep, 1)[-1] for loc, _ in problems)
    assert where == ["run01.csv row 3", "run01.csv row 3", "run01.csv row 5",
                     "run01.csv row 5", "run01.csv row 6", "run01.json key 'bore_m'",
                     "run01.json key 'supply_pressure_Pa'", "run01.json key 'valve'"]
    with pytest.raises(RecordingError) as err:
        read_recording(stem)
    assert err.value.problems == problems
    assert str(err.value).count("\n") == len(problems)


def test_check_recording_of_valid_files_is_empty(tmp_path):
    assert check_recording(make_files(tmp_path)) == []
    assert check_recording(tmp_path / "absent") != []  # never raises


@pytest.mark.parametrize("valid", [True, False])
def test_reading_never_modifies_the_files(tmp_path, valid):
    csv_text = None if valid else rows_with(3, "0.001,9,NaN,-1,x")
    stem = make_files(tmp_path, csv_text=csv_text)
    paths = recording_paths(stem)
    for p in paths:
        os.utime(p, ns=(1_000_000_000, 1_000_000_000))
        p.chmod(0o444)
    before = [(p.read_bytes(), p.stat().st_mtime_ns, p.stat().st_mode) for p in paths]
    check_recording(stem)
    if valid:
        read_recording(stem)
    else:
        with pytest.raises(RecordingError):
            read_recording(stem)
    assert [(p.read_bytes(), p.stat().st_mtime_ns, p.stat().st_mode) for p in paths] == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run01.csv", "run01.json"]


# ---------------------------------------------------------------- writing


def test_write_refuses_to_overwrite(tmp_path):
    rec = make_recording()
    write_recording(rec, tmp_path / "run01")
    (tmp_path / "run01.csv").unlink()
    with pytest.raises(FileExistsError, match="run01.json"):
        write_recording(rec, tmp_path / "run01")
    assert not (tmp_path / "run01.csv").exists()
    write_recording(rec.slice(0, 2), tmp_path / "run01", overwrite=True)
    assert read_recording(tmp_path / "run01").n_samples == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run01.csv", "run01.json"]


def test_write_validates_first(tmp_path):
    good = make_recording(n=3)
    bad = Recording(metadata=RecordingMetadata(**meta_with(bore_m=-1.0)),
                    time_s=[0.0, 2.0, 1.0], command_V=[0.0, 7.0, 0.0],
                    pressure_Pa=[1e5, 1e5], position_m=good.position_m,
                    extra_columns={"time_s": [1, 2, 3]})
    with pytest.raises(RecordingError) as err:
        write_recording(bad, tmp_path / "out")
    where = sorted(loc.rsplit(os.sep, 1)[-1] for loc, _ in err.value.problems)
    assert where == ["out.csv column 'pressure_Pa'", "out.csv column 'time_s'",
                     "out.csv row 3", "out.csv row 4", "out.json key 'bore_m'"]
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------- property-based

finite = st.floats(allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=0.0, exclude_min=True, allow_infinity=False)
#: a sample's pressure: absolute, at most 10 MPa (a hard limit, not a plausibility rule)
pressure = st.floats(min_value=0.0, exclude_min=True, max_value=10e6)


@st.composite
def recordings(draw):
    n = draw(st.integers(2, 30))  # a recording holds one sampling interval at least
    t = sorted(draw(st.lists(finite, min_size=n, max_size=n, unique=True)))
    assume(all(b - a >= 1e-6 for a, b in zip(t, t[1:])))  # 1 us apart: a hard limit
    col = st.lists(finite, min_size=n, max_size=n)
    atm, sup = sorted(draw(st.lists(positive, min_size=2, max_size=2, unique=True)))
    stroke = draw(positive)
    name = st.text(min_size=1).filter(str.strip)
    meta = RecordingMetadata(
        cylinder=draw(name), valve=draw(name), bore_m=draw(positive), stroke_m=stroke,
        atmospheric_pressure_Pa=atm, supply_pressure_Pa=sup, temperature_K=draw(positive),
        position_m=draw(st.none() | st.floats(0.0, stroke)),
        extra=draw(st.dictionaries(
            st.text().filter(lambda k: k not in {**META, "position_m": 0}),
            st.none() | st.booleans() | finite | st.text(), max_size=3)))
    extra_name = st.text(min_size=1).filter(
        lambda s: s == s.strip() and s not in ("time_s", "command_V", "pressure_Pa",
                                               "supply_pressure_Pa", "position_m"))
    return Recording(
        metadata=meta, time_s=t,
        command_V=draw(st.lists(st.floats(-5.0, 5.0), min_size=n, max_size=n)),
        pressure_Pa=draw(st.lists(pressure, min_size=n, max_size=n)),
        supply_pressure_Pa=draw(st.none() | st.lists(pressure, min_size=n, max_size=n)),
        position_m=draw(st.none() | col),
        extra_columns=draw(st.dictionaries(extra_name, st.lists(
            st.floats(), min_size=n, max_size=n), max_size=2)))


@SETTINGS
@given(rec=recordings())
def test_random_recordings_round_trip_exactly(tmp_path, rec):
    write_recording(rec, tmp_path / "rt", overwrite=True)
    assert_same(rec, read_recording(tmp_path / "rt", accept=STRUCTURE_ONLY))


def test_times_near_the_largest_float_are_checked_without_overflow(tmp_path):
    """Found by the random round trip: the increasing-time check subtracted
    -1e292 from 1.8e308 and overflowed."""
    t = np.array([-9.97920155e291, 1.79769313e308])
    rec = Recording(RecordingMetadata("0", "0", 1.0, 1.0, 1.0, 2.0, 1.0), t,
                    np.zeros(2), np.ones(2))
    write_recording(rec, tmp_path / "big", overwrite=True)
    assert_same(rec, read_recording(tmp_path / "big", accept=STRUCTURE_ONLY))
    backwards = Recording(RecordingMetadata("0", "0", 1.0, 1.0, 1.0, 2.0, 1.0), t[::-1].copy(),
                          np.zeros(2), np.ones(2))
    with pytest.raises(RecordingError, match="decreasing time"):
        write_recording(backwards, tmp_path / "back", overwrite=True)


@st.composite
def corruptions(draw, text):
    """Apply a few random edits to ``text``: characters, whole lines, row order."""
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["delete", "replace", "insert", "drop", "shuffle", "dup"]))
        lines = text.split("\n")
        if op in ("delete", "replace", "insert") and text:
            i = draw(st.integers(0, len(text) - 1))
            char = draw(st.sampled_from(",.-+e0123456789\n\r\" ;nNaIf") | st.characters())
            keep = text[i + 1:] if op != "insert" else text[i:]
            text = text[:i] + ("" if op == "delete" else char) + keep
        elif op == "drop":
            del lines[draw(st.integers(0, len(lines) - 1))]
            text = "\n".join(lines)
        elif op == "dup":
            i = draw(st.integers(0, len(lines) - 1))
            text = "\n".join(lines[:i + 1] + lines[i:])
        elif op == "shuffle" and len(lines) > 2:
            text = "\n".join([lines[0], *draw(st.permutations(lines[1:]))])
    return text


def read_or_reject(stem):
    try:
        rec = read_recording(stem)
    except RecordingError as err:
        assert err.problems and all(isinstance(loc, str) and isinstance(why, str)
                                    for loc, why in err.problems)
        assert check_recording(stem) == err.problems
        return
    assert_valid(rec)
    assert check_recording(stem) == []


@SETTINGS
@given(data=st.data())
def test_corrupted_csv_is_read_or_rejected_never_crashes(tmp_path, data):
    text = data.draw(corruptions("\n".join([HEADER, *ROWS]) + "\n"))
    stem = make_files(tmp_path, csv_text=text.encode("utf-8", "surrogatepass").decode(
        "utf-8", "replace"))
    read_or_reject(stem)


@SETTINGS
@given(data=st.data())
def test_corrupted_json_is_read_or_rejected_never_crashes(tmp_path, data):
    text = data.draw(corruptions(json.dumps({**META, "position_m": 0.01}, indent=1)))
    stem = make_files(tmp_path, json_text=text.encode("utf-8", "surrogatepass").decode(
        "utf-8", "replace"))
    read_or_reject(stem)


# ---------------------------------------------------------------- preprocessing
def _moving_recording(noise_m, seed=0):
    from pneubayes.io import RecordingMetadata

    rng = np.random.default_rng(seed)
    t = np.arange(4000) * 1e-3
    x = 0.02 + 0.01 * np.sin(2 * np.pi * 3.0 * t)
    md = RecordingMetadata(cylinder="AIR37", valve="valve1", bore_m=0.009, stroke_m=0.0375,
                           atmospheric_pressure_Pa=101325.0, supply_pressure_Pa=551325.0,
                           temperature_K=293.15)
    rec = Recording(md, t, np.zeros_like(t), np.full_like(t, 2e5),
                    position_m=x + noise_m * rng.normal(size=t.size), source="mem.csv")
    return rec, x


def test_smooth_position_removes_sensor_noise_and_keeps_the_motion():
    from pneubayes.io import smooth_position

    rec, x = _moving_recording(1e-5)
    out = smooth_position(rec, 50.0)
    inner = slice(200, -200)
    assert np.std(rec.position_m[inner] - x[inner]) == pytest.approx(1e-5, rel=0.1)
    # 2nd-order zero-phase at 50 Hz: 3 Hz motion passes, white noise drops ~4x
    assert np.std(out.position_m[inner] - x[inner]) < 0.35e-5
    assert np.max(np.abs(out.position_m[inner] - x[inner])) < 2.5e-5
    # the input is untouched; other columns and the source are kept
    assert out is not rec and out.source == rec.source
    assert np.array_equal(out.pressure_Pa, rec.pressure_Pa)
    clean, _ = _moving_recording(0.0)
    # the ends too (odd extension): under 1 um, a tenth of the sensor noise
    assert np.max(np.abs(smooth_position(clean, 50.0).position_m - x)) < 1e-6


def test_smooth_position_off_and_bad_cutoffs():
    from pneubayes.io import smooth_position

    rec, _ = _moving_recording(1e-5)
    assert smooth_position(rec, None) is rec and smooth_position(rec, 0) is rec
    with pytest.raises(ValueError, match=r"mem.csv: position cutoff 600 Hz must be in .*"
                       r"fit's --position-cutoff \(0: raw\), discover's --set "
                       r"fit.position_cutoff_Hz=0"):
        smooth_position(rec, 600.0)


def test_a_default_cutoff_above_a_slow_recordings_nyquist_says_how_discover_sets_it():
    """A 200-Hz recording under discover's default supply low-pass (100 Hz, its Nyquist
    frequency) is refused naming the setting; the advised ``--set`` reaches the settings
    and the supply then drives the model raw."""
    from dataclasses import replace

    from pneubayes.cli import settings as cli_settings
    from pneubayes.cli.args import build_parser
    from pneubayes.discovery.settings import DiscoverySettings
    from pneubayes.io import smooth_inputs

    rec, _ = _moving_recording(0.0)
    slow = replace(rec, time_s=np.arange(rec.time_s.size) * 5e-3,
                   supply_pressure_Pa=np.full(rec.time_s.size, 551325.0))
    default = DiscoverySettings().fit
    with pytest.raises(ValueError, match=r"mem.csv: supply cutoff 100 Hz must be in \(0, 100\)"
                       r".*discover's --set fit.supply_cutoff_Hz=0"):
        smooth_inputs(slow, default.preparation())
    # a run's recorded preparation (predict, track) names the card to refit
    from pneubayes.inference.fit_folder import prepare_as_fitted

    with pytest.raises(ValueError, match=r"supply cutoff 100 Hz.*The run's model card "
                       r"run/model.json prepared its recordings so: refit"):
        prepare_as_fitted(slow, default.preparation(), "run/model.json")
    args = build_parser().parse_args(["discover", "r.csv", "--out", "o", "--set",
                                      "fit.supply_cutoff_Hz=0"])
    fit = cli_settings.discovery_settings(args).fit
    out = smooth_inputs(slow, fit.preparation())
    assert np.array_equal(out.supply_pressure_Pa, slow.supply_pressure_Pa)
    assert not np.array_equal(out.position_m, slow.position_m)  # the position's 50 Hz stays


def test_smooth_supply_removes_sensor_noise_keeps_the_wander_and_composes():
    """The supply column low-passed at 100 Hz: 500 Pa of white sensor noise drops to
    about 0.4 of it, a 2-Hz wander of 12 kPa passes; smooth_inputs applies both low-passes as
    a model card records them; a missing supply column or a None cutoff is a no-op."""
    from dataclasses import replace

    from pneubayes.io import smooth_inputs, smooth_position, smooth_supply

    rec, x = _moving_recording(1e-5)
    rng = np.random.default_rng(3)
    wander = 551325.0 + 12_000.0 * np.sin(2 * np.pi * 2.0 * rec.time_s)
    noisy = replace(rec, supply_pressure_Pa=wander + rng.normal(0, 500.0, wander.size))
    out = smooth_supply(noisy, 100.0)
    inner = slice(200, -200)
    assert np.std(out.supply_pressure_Pa[inner] - wander[inner]) < 0.45 * 500.0
    assert np.max(np.abs(smooth_supply(replace(
        rec, supply_pressure_Pa=wander), 100.0).supply_pressure_Pa - wander)) < 1.0
    assert np.array_equal(out.position_m, noisy.position_m) and out.source == rec.source
    both = smooth_inputs(noisy, {"position_cutoff_Hz": 50.0, "supply_cutoff_Hz": 100.0})
    assert np.array_equal(both.supply_pressure_Pa, out.supply_pressure_Pa)
    assert np.array_equal(both.position_m, smooth_position(noisy, 50.0).position_m)
    assert smooth_inputs(noisy, {}) is noisy  # a card without cutoffs: raw
    assert smooth_supply(rec, 100.0) is rec  # no supply column
    assert smooth_supply(noisy, None) is noisy
    with pytest.raises(ValueError, match=r"mem.csv: supply cutoff 600 Hz must be in"):
        smooth_supply(noisy, 600.0)


def test_despiking_replaces_each_glitch_by_its_neighbours_mean_when_asked():
    """Three one-sample glitches on a noisy chamber with valve reversals: despiking puts
    each back on its neighbours' mean and touches nothing else; a clean recording comes
    back as it was; the fit's preparation despikes only when its setting says so, and a
    model card records it (absent in an older card: not; not a bool: refused)."""
    from dataclasses import replace

    from conftest import chamber_recording

    from pneubayes.errors import ModelCardError
    from pneubayes.inference.fit import FitSettings
    from pneubayes.inference.fit_folder import card_preparation
    from pneubayes.io import despike_pressure, prepare_recording
    from pneubayes.settings_tree import FieldError

    rec = chamber_recording(duration_s=3.0, position=False)
    assert despike_pressure(rec) is rec
    p = rec.pressure_Pa.copy()
    glitches = np.array([700, 1500, 2300])
    p[glitches] += np.array([8e3, -12e3, 20e3])
    spiky = replace(rec, pressure_Pa=p)
    out = despike_pressure(spiky).pressure_Pa
    expected = p.copy()
    expected[glitches] = 0.5 * (p[glitches - 1] + p[glitches + 1])
    assert np.array_equal(out, expected)
    assert np.array_equal(spiky.pressure_Pa, p)  # (the input is not modified)
    raw = FitSettings(position_cutoff_Hz=None, supply_cutoff_Hz=None)
    asked = replace(raw, despike_pressure=True)
    assert np.array_equal(prepare_recording(spiky, raw.preparation()).pressure_Pa, p)
    assert np.array_equal(prepare_recording(spiky, asked.preparation()).pressure_Pa,
                          expected)
    assert card_preparation({"fit": asked.preparation()}, "m.json")["despike_pressure"]
    assert card_preparation({"fit": {}}, "m.json")["despike_pressure"] is False
    with pytest.raises(ModelCardError, match="m.json: key 'fit' -> 'despike_pressure'"):
        card_preparation({"fit": {"despike_pressure": "yes"}}, "m.json")
    with pytest.raises(FieldError, match="despike_pressure"):
        FitSettings(despike_pressure=1)


def test_a_0_to_10_volt_command_is_named_once_with_its_likely_convention(tmp_path):
    """Commands of a 0-10 V valve (neutral at 5 V) break the -5..+5 V rule in most rows:
    the first three are named, the rest counted, and the message says to subtract 5 V;
    a command merely out of range on the negative side gets no such hint."""
    volts = (5.0, 7.5, 10.0, 9.0, 6.0, 8.0)  # (5 V: the neutral, inside the range)
    shifted = [",".join([r.split(",")[0], repr(v), *r.split(",")[2:]])
               for r, v in zip(ROWS, volts)]
    stem = make_files(tmp_path, csv_text="\n".join([HEADER, *shifted]) + "\n")
    with pytest.raises(RecordingError) as err:
        read_recording(stem)
    text = str(err.value)
    assert text.count("is outside -5..+5 V") == 3, text
    assert "subtract 5 V" in text and "(and 2 more row(s) like it)" in text
    stem = make_files(tmp_path, csv_text=rows_with(3, "0.001,-7.0,150000.0,551000.0,0.011"),
                      stem="neg")
    with pytest.raises(RecordingError) as err:
        read_recording(stem)
    assert "-7.0 V is outside -5..+5 V" in str(err.value)
    assert "subtract" not in str(err.value)
