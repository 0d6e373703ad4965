"""The pneubayes command line: check, bench, simulate."""

import json

import numpy as np
import pytest

from pneubayes.cli import main
from pneubayes.errors import PneubayesError
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


G = "search.grid.strengths."


@pytest.mark.parametrize("entries, why", [
    ([G + "sensor_calibration=a"], "non-empty list of finite numbers > 0, got 'a'"),
    (["=5"], "expected KEY=VALUE"), ([G + "nothing=[1]"], "unknown effect 'nothing'"),
    ([G + "sensor_calibration=[1,2]", G + "sensor_calibration=[3]"], "given more than once"),
    ([G + "tube_delay=[-1,-2]"], "finite numbers > 0"),
    (["rounds.max_effects=two"], "rounds.max_effects: expected an integer, got str 'two'"),
    (["rounds.max_efects=2"], "rounds.max_efects: unknown key; RoundSettings has"),
    (["seed.x=1"], "seed: expected an integer")])
def test_discover_rejects_a_bad_setting_before_reading(bench_dir, tmp_path, capsys, entries,
                                                       why):
    """``--set KEY=VALUE`` (how the loop is asked to search for sensor_calibration, among
    every other setting of the tree): a bad entry is an error naming it, before any work."""
    args = ["discover", str(bench_dir / "fixed_u5_x10.csv"), "--out", str(tmp_path / "d")]
    for e in entries:
        args += ["--set", e]
    try:
        rc = main(args)
    except SystemExit as exc:  # argparse's own usage error
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err
    assert "--set" in err and why in err, err
    assert not (tmp_path / "d").exists()


def test_discover_reads_one_tree_from_file_options_and_set_in_that_order(tmp_path):
    """The settings file, then the options, then ``--set``; the same names all the way
    down (a study's ``[settings.discovery]`` table is the same tree)."""
    from pneubayes.cli import settings as cli_settings
    from pneubayes.cli.args import build_parser

    f = tmp_path / "s.toml"
    f.write_text('seed = 5\n[rounds]\nmax_effects = 2\n[stages]\npair_members = 0\n'
                 '[fit]\nhorizon_s = 0.5\n[fit.sampler]\nn_walkers = 48\n')
    args = build_parser().parse_args(["discover", "r.csv", "--out", "o", "--settings", str(f),
                                      "--posterior", "none",
                                      "--set", "rounds.max_effects=1",
                                      "--set", "forms.tube_line_form=line"])
    s = cli_settings.discovery_settings(args)
    assert s.rounds.max_effects == 1 and s.stages.pair_members == 0 and s.seed == 5
    assert s.fit.horizon_s == 0.5 and s.fit.sampler.n_walkers == 48
    assert s.posterior.method == "none" and s.forms.tube_line_form == "line"
    args = build_parser().parse_args(["discover", "r.csv", "--out", "o", "--horizon", "0.2",
                                      "--seed", "7"])
    s = cli_settings.discovery_settings(args)
    assert (s.fit.horizon_s, s.fit.stride_s, s.seed, s.fit.sampler.seed) == (0.2, 0.2, 7, 7)
    with pytest.raises(PneubayesError, match="s.toml: .*rounds.nope: unknown key"):
        f.write_text("[rounds]\nnope = 1\n")
        cli_settings.discovery_settings(build_parser().parse_args(
            ["discover", "r.csv", "--out", "o", "--settings", str(f)]))
    with pytest.raises(PneubayesError, match="no such settings file"):
        cli_settings.discovery_settings(build_parser().parse_args(
            ["discover", "r.csv", "--out", "o", "--settings", str(tmp_path / "none.toml")]))


def test_no_dense_output_gives_the_fits_the_stepping_at_every_sample():
    from pneubayes.cli import settings as cli_settings
    from pneubayes.cli.args import build_parser
    from pneubayes.simulation import SolverConfig

    parser = build_parser()
    plain = parser.parse_args(["fit", "r.csv", "--out", "o"])
    stepped = parser.parse_args(["fit", "r.csv", "--out", "o", "--no-dense-output"])
    assert cli_settings.fit_settings(plain).sample_solver == SolverConfig.sampling()
    assert cli_settings.fit_settings(stepped).sample_solver == SolverConfig.standard()


def test_fit_reads_its_settings_file_and_its_options_override_it(tmp_path):
    from pneubayes.cli import settings as cli_settings
    from pneubayes.cli.args import build_parser

    f = tmp_path / "fit.toml"
    f.write_text("horizon_s = 0.5\nposition_cutoff_Hz = 20.0\n[sampler]\nmax_steps = 300\n")
    parser = build_parser()
    s = cli_settings.fit_settings(parser.parse_args(["fit", "r.csv", "--out", "o", "--settings",
                                             str(f)]))
    assert (s.horizon_s, s.stride_s, s.position_cutoff_Hz) == (0.5, 2.0, 20.0)
    assert s.sampler.max_steps == 300
    s = cli_settings.fit_settings(parser.parse_args(["fit", "r.csv", "--out", "o", "--settings",
                                             str(f), "--horizon", "0.3", "--max-steps",
                                             "50", "--position-cutoff", "0"]))
    assert (s.horizon_s, s.stride_s, s.position_cutoff_Hz) == (0.3, 0.3, None)
    assert s.sampler.max_steps == 50


DISCOVER_OPTIONS_FLOOR = 15  # issue 66: discover keeps about twelve flags


def _visible_options(command: str) -> list[str]:
    import argparse

    from pneubayes.cli.args import build_parser

    sub = next(a for a in build_parser()._actions
               if isinstance(a, argparse._SubParsersAction)).choices[command]
    return [a.option_strings[-1] for a in sub._actions
            if a.option_strings and a.help is not argparse.SUPPRESS
            and not isinstance(a, argparse._HelpAction)]


def test_discover_help_keeps_to_the_floor_of_options(capsys):
    """``pneubayes discover --help`` lists at most 15 options besides -h; everything
    else is a key of the settings tree (``--settings``, ``--set``)."""
    options = _visible_options("discover")
    assert len(options) <= DISCOVER_OPTIONS_FLOOR, options
    with pytest.raises(SystemExit):
        main(["discover", "--help"])
    out = capsys.readouterr().out
    assert all(o in out for o in options) and "--max-effects" not in out
    assert "--resume" not in out


@pytest.mark.parametrize("argv, says", [
    (["discover", "r.csv", "--max-effects", "2"], "--max-effects is now --set "
                                                   "rounds.max_effects=N"),
    (["discover", "r.csv", "--max-effects=2"], "--set rounds.max_effects=N"),
    (["discover", "r.csv", "--resume"], "pneubayes resume RUN"),
    (["fit", "r.csv", "--resume"], "pneubayes resume RUN"),
    (["ablate", "s.toml", "--resume"], "pneubayes resume RUN"),
])
def test_a_removed_option_says_what_replaces_it(argv, says, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--out", str(tmp_path / "o")])
    assert exc.value.code == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_resume_reruns_the_stamped_command_and_never_starts_anew(tmp_path, monkeypatch,
                                                                  capsys):
    """``pneubayes resume RUN``: the command in RUN/run.json again, insisting on a resume
    (what ``--resume`` guaranteed)."""
    import shutil

    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--cylinder", "AIR37", "--valve", "valve1", "--protocol",
                 "fixed", "--duration", "3", "--seed", "7", "--positions", "0.25,0.75",
                 "--ranges", "5", "--out", "b", "-q"]) == 0
    recs = sorted(str(p.relative_to(tmp_path)) for p in (tmp_path / "b").glob("*.csv"))
    # (3-s recordings: on 2-s ones the exhaust's Gompertz curve runs to its slope's bound
    # and the least squares takes ten times as long)
    assert main(["fit", *recs, "--method", "lsq", "--no-figures", "--out", "F"]) == 0
    capsys.readouterr()
    assert main(["resume", "F"]) == 0
    assert "fit: resuming the run in F" in capsys.readouterr().err
    # nothing there: an error, nothing started
    assert main(["resume", "G"]) == 2
    assert "nothing to resume" in capsys.readouterr().err and not (tmp_path / "G").exists()
    # relative paths from another folder: said, not run elsewhere
    monkeypatch.chdir(tmp_path / "b")
    assert main(["resume", "../F"]) == 2
    assert "started in" in capsys.readouterr().err
    monkeypatch.chdir(tmp_path)
    # a recording changed since: the run is not that command's any more
    shutil.copy(tmp_path / recs[1], tmp_path / recs[0])
    shutil.copy((tmp_path / recs[1]).with_suffix(".json"),
                (tmp_path / recs[0]).with_suffix(".json"))
    before = sorted(p.name for p in (tmp_path / "F").iterdir())
    assert main(["resume", "F"]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "F").iterdir()) == before
