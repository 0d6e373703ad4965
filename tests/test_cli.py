"""The pneubayes command line: check, bench, simulate."""

import json

import numpy as np
import pytest

from pneubayes.cli import main
from pneubayes.io import read_recording


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli_bench")
    rc = main(["bench", "--cylinder", "AIR37", "--valve", "valve1", "--effects",
               "tube_delay,spool_lag", "--protocol", "fixed", "--duration", "2", "--seed", "7",
               "--positions", "0.1", "--out", str(out), "-q"])
    assert rc == 0
    return out


def test_bench_command_writes_recordings_and_truth(bench_dir):
    csvs = sorted(bench_dir.glob("*.csv"))
    assert len(csvs) == 3
    truth = json.loads((bench_dir / "truth.json").read_text())
    assert truth["effects"] == ["tube_delay", "spool_lag"]
    assert truth["parameters"]["spool_time_constant_s"] == pytest.approx(1 / (2 * np.pi * 125))


def test_check_ok_and_bad(bench_dir, tmp_path, capsys):
    assert main(["check", *map(str, bench_dir.glob("*.csv"))]) == 0
    bad = tmp_path / "bad.csv"
    src = (bench_dir / "fixed_u5_x10.csv").read_text().splitlines()
    src[5] = src[5].replace(src[5].split(",")[2], "nan", 1)
    bad.write_text("\n".join(src) + "\n")
    (tmp_path / "bad.json").write_text((bench_dir / "fixed_u5_x10.json").read_text())
    capsys.readouterr()
    assert main(["check", str(bad)]) == 1
    out = capsys.readouterr().out
    assert "bad.csv" in out and "6" in out


def test_simulate_writes_prediction(bench_dir, tmp_path, capsys):
    out = tmp_path / "pred.csv"
    rec = bench_dir / "fixed_u5_x10.csv"
    assert main(["simulate", str(rec), "--model", str(bench_dir / "truth.json"),
                 "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "time_s,pressure_Pa"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    r = read_recording(rec)
    assert data.shape == (r.n_samples, 2)
    assert data[0, 1] == pytest.approx(r.pressure_Pa[0])
    rmse = np.sqrt(np.mean((data[:, 1] - r.pressure_Pa) ** 2))
    assert rmse < 3000.0  # true model, open loop over the whole recording
    # refuses to overwrite
    assert main(["simulate", str(rec), "--model", str(bench_dir / "truth.json"),
                 "--out", str(out)]) == 2


def test_simulate_reports_a_bad_model_card(bench_dir, tmp_path, capsys):
    card = json.loads((bench_dir / "truth.json").read_text())
    card["parameters"]["inlet_c_per_V"] = -1.0  # inlet map must grow with command
    path = tmp_path / "bad_model.json"
    path.write_text(json.dumps(card))
    rc = main(["simulate", str(bench_dir / "fixed_u5_x10.csv"), "--model", str(path),
               "--out", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "bad_model.json" in err and "inlet_c_per_V" in err


def test_bench_rejects_unknown_effect(tmp_path, capsys):
    rc = main(["bench", "--cylinder", "AIR37", "--valve", "valve1", "--effects", "magic",
               "--seed", "1", "--out", str(tmp_path)])
    assert rc == 2 and "magic" in capsys.readouterr().err


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for sub in ("check", "bench", "simulate"):
        assert sub in out


@pytest.mark.parametrize("spec, why", [("1000", "ORDER:CUTOFF_HZ"), ("9:1000", "1..8"),
                                       ("2:-5", "cutoff_Hz")])
def test_fit_and_discover_reject_a_bad_pressure_filter(bench_dir, tmp_path, capsys, spec, why):
    for cmd in ("fit", "discover"):
        with pytest.raises(SystemExit) as exc:
            main([cmd, str(bench_dir / "fixed_u5_x10.csv"), "--out", str(tmp_path / cmd),
                  "--pressure-filter", spec])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert "--pressure-filter" in err and why in err
        assert not (tmp_path / cmd).exists()


@pytest.mark.parametrize("entries, why", [
    (["sensor_calibration=a"], "EFFECT=S1,S2"), (["=5"], "EFFECT=S1,S2"),
    (["nothing=1"], "unknown effect 'nothing'"),
    (["sensor_calibration=1,2", "sensor_calibration=3"], "given more than once")])
def test_discover_rejects_a_bad_library_entry_before_reading(bench_dir, tmp_path, capsys,
                                                             entries, why):
    """``--library EFFECT=S1,S2`` (how the loop is asked to search for
    sensor_calibration): a bad entry is an error naming it, before any work."""
    args = ["discover", str(bench_dir / "fixed_u5_x10.csv"), "--out", str(tmp_path / "d")]
    for e in entries:
        args += ["--library", e]
    try:
        rc = main(args)
    except SystemExit as exc:  # argparse's own usage error
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err
    assert "--library" in err and why in err
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("command", ["fit", "discover"])
def test_no_dense_output_gives_the_fits_the_stepping_at_every_sample(command):
    from pneubayes import cli
    from pneubayes.cli_args import build_parser
    from pneubayes.inference.fit import FitSettings
    from pneubayes.simulation import SolverConfig

    parser = build_parser()
    plain = parser.parse_args([command, "r.csv", "--out", "o"])
    stepped = parser.parse_args([command, "r.csv", "--out", "o", "--no-dense-output"])
    assert FitSettings(**cli._sampling(plain)).sample_solver == SolverConfig.sampling()
    assert FitSettings(**cli._sampling(stepped)).sample_solver == SolverConfig.standard()
