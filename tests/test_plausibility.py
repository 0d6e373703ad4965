"""Plausibility rules (unit slips), declared units (format 2) and card validation."""

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import ATM, SUPPLY, chamber_recording, ventilator_like

from pneubayes.cli import main
from pneubayes.errors import ModelCardError, RecordingError
from pneubayes.io import read_recording, write_recording
from pneubayes.io.plausibility import RULES, recorded_findings, rig_findings
from pneubayes.io.recording import Recording, inspect_recording
from pneubayes.io.units import PRESSURE_UNITS, parse_declared, pressure_readings
from pneubayes.model import Model


@pytest.fixture
def good(tmp_path):
    write_recording(chamber_recording(), tmp_path / "good")
    return tmp_path / "good.csv"


def _slip(tmp_path, name, rec):
    write_recording(rec, tmp_path / name)
    return tmp_path / f"{name}.csv"


def _check_output(capsys, *paths, extra=()):
    capsys.readouterr()
    rc = main(["check", *map(str, paths), *extra])
    return rc, capsys.readouterr().out


def test_plausible_recording_has_no_findings(good):
    found = inspect_recording(good)
    assert found.problems == [] and found.warnings == ()
    assert read_recording(good).findings == ()


def test_every_pressure_in_bar_is_an_error_naming_bar(tmp_path, capsys):
    rec = chamber_recording()
    md = replace(rec.metadata, atmospheric_pressure_Pa=ATM / 1e5, supply_pressure_Pa=SUPPLY / 1e5)
    path = _slip(tmp_path, "bar", replace(rec, metadata=md, pressure_Pa=rec.pressure_Pa / 1e5))
    rc, out = _check_output(capsys, path)
    assert rc == 1
    lines = out.splitlines()
    for key in ("'atmospheric_pressure_Pa'", "'supply_pressure_Pa'", "column 'pressure_Pa'"):
        line = next(x for x in lines if key in x)
        assert "probably bar (" in line, line
    with pytest.raises(RecordingError):
        read_recording(path)


def test_milliseconds_written_as_seconds_is_an_error(tmp_path, capsys):
    rec = chamber_recording()
    rc, out = _check_output(capsys, _slip(tmp_path, "ms", replace(rec, time_s=rec.time_s * 1e3)))
    assert rc == 1 and "[time-unit]" in out and "milliseconds" in out


def test_slow_but_genuine_sampling_is_only_a_warning(tmp_path, capsys):
    # 10 Hz of a slow chamber (0.5 s): the pressure is resolved, the interval is long
    rec = chamber_recording(rate_Hz=10.0, duration_s=60.0, tau_s=0.5, position=False)
    rc, out = _check_output(capsys, _slip(tmp_path, "slow", rec))
    assert rc == 0 and "[sample-interval]" in out and "[time-unit]" not in out


def test_celsius_is_an_error_naming_celsius(tmp_path, capsys):
    rec = chamber_recording()
    path = _slip(tmp_path, "c", replace(rec, metadata=replace(rec.metadata, temperature_K=20.0)))
    rc, out = _check_output(capsys, path)
    assert rc == 1 and "probably degrees C (20 C = 293.15 K)" in out


def test_millimetres_are_errors_naming_mm(tmp_path, capsys):
    rec = chamber_recording()
    md = replace(rec.metadata, bore_m=9.0, stroke_m=37.5)
    rc, out = _check_output(capsys, _slip(tmp_path, "mm", replace(rec, metadata=md)))
    assert rc == 1
    assert "probably" in out and "mm (9 mm = 0.009 m)" in out and "mm (37.5 mm = 0.0375 m)" in out
    rc, out = _check_output(capsys, _slip(tmp_path, "pos", replace(
        rec, position_m=rec.position_m * 1e3)))
    assert rc == 1 and "[position]" in out and "probably mm" in out


def test_gauge_pressure_column_is_an_error_naming_kpa_gauge(tmp_path, capsys):
    rec = chamber_recording(noise_Pa=0.0)
    gauge_kPa = (rec.pressure_Pa - ATM) / 1e3 + 2.0  # an offset keeps it > 0
    rc, out = _check_output(capsys, _slip(tmp_path, "g", replace(rec, pressure_Pa=gauge_kPa)))
    assert rc == 1 and "probably kPa gauge" in out


def test_gauge_supply_is_a_warning(tmp_path, capsys):
    rec = chamber_recording()
    md = replace(rec.metadata, supply_pressure_Pa=SUPPLY - ATM + 1e3)
    rc, out = _check_output(capsys, _slip(tmp_path, "gs", replace(rec, metadata=md)))
    assert rc == 0 and "warning" in out and "[pressure-above-supply]" in out


def test_unusual_real_rig_warns_and_is_accepted(tmp_path, capsys):
    path = _slip(tmp_path, "vent", ventilator_like())
    rc, out = _check_output(capsys, path)
    assert rc == 0
    for rule in ("sample-interval", "pressure-span", "working-range"):
        assert "warning: " in out and f"[{rule}]" in out
    assert len(read_recording(path).findings) == 3
    accept = "sample-interval,pressure-span,working-range"
    rc, out = _check_output(capsys, path, extra=["--accept", accept])
    assert rc == 0 and "warning" not in out and out.count("(accepted)") == 3
    # the same, declared by the recording itself
    meta = json.loads(path.with_suffix(".json").read_text())
    meta["accept_unusual"] = accept.split(",")
    path.with_suffix(".json").write_text(json.dumps(meta))
    rec = read_recording(path)
    assert all(f.accepted for f in rec.findings) and len(rec.findings) == 3
    assert rec.metadata.accept_unusual == tuple(accept.split(","))
    # and it survives a round trip
    write_recording(rec, tmp_path / "again")
    assert read_recording(tmp_path / "again").metadata.accept_unusual == rec.metadata.accept_unusual


def test_accepted_error_rule_lets_the_recording_through(tmp_path):
    rec = chamber_recording()
    path = _slip(tmp_path, "ms", replace(rec, time_s=rec.time_s * 1e3))
    out = read_recording(path, accept=["time-unit"])
    assert [f.rule for f in out.findings] == ["time-unit"] and out.findings[0].accepted


def test_unknown_accept_rule_is_refused_by_name(good, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["check", str(good), "--accept", "sample-rate"])
    assert exc.value.code == 2
    assert "unknown rule 'sample-rate'" in capsys.readouterr().err
    meta = json.loads(good.with_suffix(".json").read_text())
    meta["accept_unusual"] = "pressure-span"
    good.with_suffix(".json").write_text(json.dumps(meta))
    problems = inspect_recording(good).problems
    assert len(problems) == 1 and "'accept_unusual'" in problems[0][0]
    assert "list of rule names" in problems[0][1]


def test_rig_findings_cover_every_rule_id_they_use():
    findings = rig_findings({"atmospheric_pressure_Pa": 1.0, "supply_pressure_Pa": 2e7,
                             "temperature_K": 20.0, "bore_m": 9.0, "stroke_m": 37.5}, "rig")
    assert {f.rule for f in findings} == {"atmosphere", "supply-pressure", "temperature",
                                          "bore", "stroke"}
    assert all(f.rule in RULES and f.severity == "error" for f in findings)
    assert rig_findings({"atmospheric_pressure_Pa": ATM, "supply_pressure_Pa": SUPPLY,
                         "temperature_K": 293.15, "bore_m": 0.009, "stroke_m": 0.0375},
                        "rig") == []


# ------------------------------------------------------------------ declared units
def test_unit_table_closed_forms():
    assert PRESSURE_UNITS["psi"] == pytest.approx(0.45359237 * 9.80665 / 0.0254 ** 2)
    assert PRESSURE_UNITS["cmH2O"] == pytest.approx(1000 * 9.80665 * 0.01)
    assert parse_declared("temperature_C").to_si(0.0) == pytest.approx(273.15)
    assert parse_declared("temperature_F").to_si(32.0) == pytest.approx(273.15)
    assert parse_declared("temperature_F").to_si(212.0) == pytest.approx(373.15)
    d = parse_declared("supply_pressure_psi_gauge")
    assert d.si_name == "supply_pressure_Pa" and d.gauge
    assert d.to_si(0.0, ATM) == ATM
    assert parse_declared("pressure_kpa") is None  # units are case-sensitive
    assert parse_declared("atmospheric_pressure_kPa_gauge") is None
    assert "bar (5.5 bar = 550000 Pa absolute)" in pressure_readings([5.5], 150e3, 1.6e6)


def _write_format2(tmp_path, rec: Recording, name="f2", **json_extra):
    md = rec.metadata
    rows = zip(rec.time_s * 1e3, rec.command_V, (rec.pressure_Pa - ATM) / 1e3,
               rec.position_m * 1e3)
    text = "time_ms,command_V,pressure_kPa_gauge,position_mm\n" + "".join(
        ",".join(repr(float(v)) for v in row) + "\n" for row in rows)
    (tmp_path / f"{name}.csv").write_text(text)
    meta = {"format": "pneubayes-recording/2", "cylinder": md.cylinder, "valve": md.valve,
            "bore_mm": md.bore_m * 1e3, "stroke_mm": md.stroke_m * 1e3,
            "atmospheric_pressure_kPa": ATM / 1e3,
            "supply_pressure_psi_gauge": (SUPPLY - ATM) / PRESSURE_UNITS["psi"],
            "temperature_C": md.temperature_K - 273.15, **json_extra}
    (tmp_path / f"{name}.json").write_text(json.dumps(meta))
    return tmp_path / f"{name}.csv"


def test_format2_declared_units_read_as_si(tmp_path, capsys):
    rec = chamber_recording()
    path = _write_format2(tmp_path, rec)
    got = read_recording(path)
    np.testing.assert_allclose(got.time_s, rec.time_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.pressure_Pa, rec.pressure_Pa, rtol=1e-12)
    np.testing.assert_allclose(got.position_m, rec.position_m, rtol=1e-12, atol=1e-15)
    for key in ("bore_m", "stroke_m", "atmospheric_pressure_Pa", "supply_pressure_Pa",
                "temperature_K"):
        assert getattr(got.metadata, key) == pytest.approx(getattr(rec.metadata, key),
                                                           rel=1e-12)
    assert len(got.conversions) == 8 and got.findings == ()
    rc, out = _check_output(capsys, path)
    assert rc == 0 and "converted" in out and "kPa gauge -> pressure_Pa (absolute)" in out
    # written back it is format-1 SI and reads the same
    write_recording(got, tmp_path / "si")
    again = read_recording(tmp_path / "si")
    np.testing.assert_array_equal(again.pressure_Pa, got.pressure_Pa)


def test_format2_errors_name_the_column_or_key(tmp_path):
    rec = chamber_recording()
    path = _write_format2(tmp_path, rec, pressure_Pa=1.0)  # a stray key is only extra
    assert inspect_recording(path).problems == []
    path = _write_format2(tmp_path, rec, name="twice", bore_m=0.009)
    problems = inspect_recording(path).problems
    assert any("'bore_mm'" in loc and "again" in why for loc, why in problems)
    path = _write_format2(tmp_path, rec, name="v3", format="pneubayes-recording/3")
    problems = inspect_recording(path).problems
    assert any("'format'" in loc and "unknown format" in why for loc, why in problems)
    meta = json.loads(path.with_suffix(".json").read_text())
    meta["format"] = "pneubayes-recording/1"
    path.with_suffix(".json").write_text(json.dumps(meta))
    problems = inspect_recording(path).problems
    assert any("missing required column 'pressure_Pa'" in why and "pneubayes-recording/2" in why
               for _, why in problems)
    meta["format"] = "pneubayes-recording/2"
    del meta["atmospheric_pressure_kPa"]
    path.with_suffix(".json").write_text(json.dumps(meta))
    problems = inspect_recording(path).problems
    assert any("'supply_pressure_psi_gauge'" in loc and "atmospheric" in why
               for loc, why in problems)


# ------------------------------------------------------------------ model cards
def _card(tmp_path, **changes):
    card = {"format": "pneubayes-model/1", "effects": ["tube_delay"],
            "parameters": {}, **changes}
    path = tmp_path / "card.json"
    path.write_text(json.dumps(card))
    return path


@pytest.mark.parametrize("options, fragment", [
    ({"tube_delay": 3}, "'effect_options' -> 'tube_delay' must be an object"),
    ({"tube_delay": [1, 2]}, "'effect_options' -> 'tube_delay' must be an object"),
    ({"tube_delay": {"segments": "3"}}, "option 'segments' must be an integer"),
    ({"tube_delay": {"segments": 2.0}}, "option 'segments' must be an integer"),
    ({"tube_delay": {"tube_diameter_m": "2 mm"}}, "option 'tube_diameter_m' must be a finite"),
    ({"tube_delay": {"form": 1}}, "option 'form' must be a string"),
    ({"tube_delay": {"colour": "red"}}, "unknown option 'colour'"),
])
def test_bad_effect_options_name_the_key(tmp_path, options, fragment):
    with pytest.raises(ModelCardError, match="card.json") as exc:
        Model.load_card(_card(tmp_path, effect_options=options))
    assert fragment in str(exc.value)


def test_simulate_with_an_integer_option_is_a_clean_error(good, tmp_path, capsys):
    card = _card(tmp_path, effect_options={"tube_delay": 3})
    rc = main(["simulate", str(good), "--model", str(card), "--out", str(tmp_path / "p.csv")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "effect_options" in err and "Traceback" not in err
    assert not (tmp_path / "p.csv").exists()


def test_runs_record_the_findings_of_their_recordings(tmp_path):
    path = _slip(tmp_path, "vent", ventilator_like())
    rec = read_recording(path, accept=["working-range"])
    doc = recorded_findings([rec, read_recording(_slip(tmp_path, "ok", chamber_recording()))])
    assert sorted((d["rule"], d["accepted"]) for d in doc) == [
        ("pressure-span", False), ("sample-interval", False), ("working-range", True)]
    assert all(d["recording"] == str(path) and d["severity"] == "warning" for d in doc)
    json.dumps(doc)  # as a run writes it


def test_unit_slips_experiment_smoke(tmp_path):
    from conftest import load_experiment

    mod = load_experiment("unit_slips")
    assert mod.main(["--smoke", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "unit_slips.json").read_text())
    table = doc["table"]["bench"]
    assert table["correct"]["caught"] == 0 and table["correct"]["n"] == 2
    for slip in mod.SLIPS:
        assert table[slip]["caught"] == table[slip]["named"] == 2, slip


def test_isolated_pressure_spikes_are_a_warning_naming_their_rows(tmp_path, capsys):
    """Three one-sample glitches of 8-20 kPa on a noisy chamber (300 Pa) are found with
    their rows; the clean recording, whose valve reversals bend the pressure at one
    sample, has none, and neither has one ringing at 0.4 x its sample rate (every sample
    departs: texture, not glitches)."""
    rec = chamber_recording(duration_s=3.0)
    assert not [f for f in read_recording(_slip(tmp_path, "clean", rec)).findings
                if f.rule == "pressure-spikes"]
    p = rec.pressure_Pa.copy()
    rows = (700, 1500, 2300)  # samples; rows of the CSV are one more than 1-based
    for k, h in zip(rows, (8e3, -12e3, 20e3)):
        p[k] += h
    rc, out = _check_output(capsys, _slip(tmp_path, "spiky", replace(rec, pressure_Pa=p)))
    line = next(x for x in out.splitlines() if "[pressure-spikes]" in x)
    assert rc == 0 and "3 isolated sample(s)" in line and "warning" in line
    assert "rows 702, 1502, 2302" in line, line
    ring = rec.pressure_Pa + 2e4 * np.sin(2 * np.pi * 0.4 * np.arange(p.size))
    assert not [f for f in read_recording(_slip(tmp_path, "ring", replace(
        rec, pressure_Pa=ring))).findings if f.rule == "pressure-spikes"]
