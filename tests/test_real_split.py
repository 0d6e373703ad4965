"""The real-recording experiments' split: which trials or runs train and which are held
out (``--data``, ``--held-out``), on the shipped imports."""

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import load_experiment

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = str(ROOT / "experiments")


@pytest.fixture(scope="module")
def common():
    if EXPERIMENTS not in sys.path:  # the scripts import their siblings
        sys.path.insert(0, EXPERIMENTS)
    return load_experiment("real_common")


def test_a_named_unit_is_held_out_and_every_other_trains(common):
    items = ["run_1", "run_2", "run_10", "run_3"]
    train, held = common.split_held_out(items, ["run_1"], str, "here")
    assert held == ["run_1"] and train == ["run_2", "run_10", "run_3"]  # exact, not run_10
    train, held = common.split_held_out(items, ["run_1"], str, "here", prefix=True)
    assert held == ["run_1", "run_10"] and train == ["run_2", "run_3"]


def test_a_name_that_matches_nothing_or_a_split_that_leaves_no_side_is_named(common):
    items = ["run_1", "run_2"]
    with pytest.raises(SystemExit, match=r"here: --held-out run_7 matches no recording.*"
                                         r"run_1, run_2"):
        common.split_held_out(items, ["run_1", "run_7"], str, "here")
    with pytest.raises(SystemExit, match="leaves nothing to train on"):
        common.split_held_out(items, ["run_1", "run_2"], str, "here")
    with pytest.raises(SystemExit, match="leaves nothing held out"):
        common.split_held_out(items, [], str, "here")


def test_gtdynamics_holds_out_the_trials_named(common):
    gtd = load_experiment("real_gtdynamics")
    train, held = gtd.load(gtd.DATA)  # the default: two trials, four muscles each
    assert (len(train), len(held)) == (12, 8)
    assert {Path(r.source).parent.name.split("_2021")[0] for r in held} == set(gtd.HELD_OUT)
    train, held = gtd.load(gtd.DATA, ("0p00_0p12_hipknee-65source",))
    assert (len(train), len(held)) == (16, 4)
    assert all("0p00_0p12" in str(r.source) for r in held)
    assert not any("0p00_0p12" in str(r.source) for r in train)


def test_a_new_trial_in_a_copied_import_is_held_out_by_name(common, tmp_path):
    """A held-back trial imported beside the shared ones (here a copy under another
    name) is scored by naming it; nothing else moves and the source folder is not
    touched."""
    gtd = load_experiment("real_gtdynamics")
    data = tmp_path / "gtd"
    shutil.copytree(gtd.DATA, data)
    src = data / "0p00_0p06_hipknee-80source_2021-04-05_11-31-55"
    shutil.copytree(src, data / "0p02_knee-0p09_inf-80source_2021-04-05_12-00-00")
    train, held = gtd.load(data, ("0p02_knee-0p09_inf-80source",))
    assert (len(train), len(held)) == (20, 4)
    with pytest.raises(SystemExit, match="0p02_knee-0p09_inf-65source matches no"):
        gtd.load(data, ("0p02_knee-0p09_inf-65source",))


def test_a_muscle_whose_valve_never_closes_keeps_its_whole_record(common, tmp_path):
    """The fill phase ends 30 ms after each muscle's own close; a valve not closed
    within the record (a null close time in the import) keeps the whole recording."""
    gtd = load_experiment("real_gtdynamics")
    data = tmp_path / "gtd"
    trial = "0p00_0p06_hipknee-80source_2021-04-05_11-31-55"
    shutil.copytree(gtd.DATA / trial, data / trial)
    shutil.copy(gtd.DATA / "gtdynamics-muscle.rig.json", data)
    sidecar = data / trial / "knee_left.json"
    doc = json.loads(sidecar.read_text())
    doc["import"]["valve_close_s"] = None
    sidecar.write_text(json.dumps(doc))
    (data / "other").mkdir()
    for name in ("knee_right.csv", "knee_right.json"):  # something to train on
        shutil.copy(data / trial / name, data / "other" / name)
    _, held = gtd.load(data, (trial,))
    lengths = {Path(r.source).stem: len(r.time_s) for r in held}
    times = np.genfromtxt(data / trial / "knee_left.csv", delimiter=",", names=True)["time_s"]
    assert lengths["knee_left"] == times.size
    # the others: to 30 ms after their close (0.06 s)
    assert lengths["knee_right"] == lengths["hip_left"] == np.sum(times <= 0.09 + 1e-9) < 60


def test_respiraworks_runs_split_by_their_stems(common):
    rw = load_experiment("real_respiraworks")
    from pneubayes.io import read_recording

    recs = [read_recording(p) for p in sorted((rw.DATA / "OXY").glob("*.csv"))]
    train, held = rw.split_runs(recs, rw.HELD_OUT, rw.DATA / "OXY")
    assert [Path(r.source).stem for r in held] == ["covent_pc_5", "covent_pc_6"]
    assert len(train) == 4
    train, held = rw.split_runs(recs, ("covent_pc_1",), rw.DATA / "OXY")
    assert len(train) == 5 and [Path(r.source).stem for r in held] == ["covent_pc_1"]
    with pytest.raises(SystemExit, match=r"OXY: --held-out covent_pc_7 matches no"):
        rw.split_runs(recs, ("covent_pc_7",), rw.DATA / "OXY")


@pytest.mark.parametrize("script", ["real_respiraworks", "real_respiraworks_forms",
                                    "real_respiraworks_online",
                                    "real_respiraworks_population",
                                    "real_respiraworks_refit"])
def test_every_ventilator_script_names_a_held_out_run_it_does_not_have(common, script,
                                                                        tmp_path):
    """Each script takes ``--held-out`` and stops, before fitting anything, with the
    folder and the runs it has when a named run is not there."""
    mod = load_experiment(script)
    with pytest.raises(SystemExit, match=r"OXY: --held-out covent_pc_9 matches no "
                                         r"recording there \(they are: covent_pc_1,"):
        mod.main(["--out", str(tmp_path), "--sets", "OXY", "--held-out", "covent_pc_9"])
    assert not (tmp_path / f"{script}.json").exists() or json.loads(
        (tmp_path / f"{script}.json").read_text())["sets"] == {}


@pytest.mark.parametrize("script", ["real_gtdynamics", "real_gtdynamics_tank"])
def test_both_gtdynamics_scripts_name_a_held_out_trial_they_do_not_have(common, script,
                                                                        tmp_path):
    mod = load_experiment(script)
    with pytest.raises(SystemExit, match=r"--held-out 0p00_0p12_hipknee-80source matches "
                                         r"no recording there \(they are: 0p00_0p06"):
        mod.main(["--out", str(tmp_path), "--held-out", "0p00_0p12_hipknee-80source"])


def test_the_online_script_s_knobs_are_its_run_s_own(common, tmp_path):
    """``--set`` changes this run's tracker knobs, not the module's defaults (a second
    run in the same process starts from the defaults), and a value of the wrong type is
    named."""
    mod = load_experiment("real_respiraworks_online")
    before = dict(mod.TRACKER)
    with pytest.raises(SystemExit):  # the split's error, after the knobs were read
        mod.main(["--out", str(tmp_path), "--sets", "OXY", "--held-out", "covent_pc_9",
                  "--set", "temper=0.3"])
    assert mod.TRACKER == before
    with pytest.raises(SystemExit) as exc:
        mod.main(["--out", str(tmp_path), "--sets", "OXY", "--set", "temper=warm"])
    assert exc.value.code == 2
