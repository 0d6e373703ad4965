"""Property-based: mutated recordings, model cards and study files never make the command
line raise (a traceback); it answers with a clean error or a clean success, and touches no
file outside ``--out``.

Hypothesis runs derandomized (a fixed seed), so the examples are the same on every run.
"""

import hashlib
import json
import shutil
import tempfile
import tomllib
from contextlib import contextmanager
from pathlib import Path

import pytest
from conftest import chamber_recording
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pneubayes.cli import main
from pneubayes.io import write_recording

ROOT = Path(__file__).resolve().parents[1]
CARD = ROOT / "data" / "air37_leak_tube" / "moving" / "truth.json"
STUDY = ROOT / "experiments" / "studies" / "smoke.toml"

FUZZ = settings(derandomize=True, max_examples=100, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

NASTY_CELLS = ["", " ", "nan", "inf", "-inf", "1e400", "1e300", "-1e300", "-1", "0", "-0",
               "1e-400", "abc", "5,5", '"', "1_000", "0x10", "١", "5e", "--1", "1e6", "-5.000001",
               "101325", "0.001", "3.5e5"]
JSON_SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                         st.floats(allow_nan=False), st.text(max_size=8),
                         st.sampled_from(["Pa", "pneubayes-recording/2", "pneubayes-model/1"]))
JSON_VALUES = st.recursive(JSON_SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6)


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _run(argv, capsys) -> int:
    """The command's exit code; argparse's usage errors count as a clean exit 2."""
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return rc


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    base = tmp_path_factory.mktemp("fuzz_seeds")
    write_recording(chamber_recording(duration_s=0.5, seed=3), base / "rec")
    card = json.loads(CARD.read_text())
    card.pop("bench")  # the bench's own record: no reader's concern
    (base / "card.json").write_text(json.dumps(card))
    shutil.copy(STUDY, base / "study.toml")
    return base


@contextmanager
def fresh(seeds):
    """A fresh copy of the seed inputs for one example: ``(inputs, out)`` folders."""
    with tempfile.TemporaryDirectory() as tmp:
        inputs = Path(tmp) / "inputs"
        shutil.copytree(seeds, inputs)
        yield inputs, Path(tmp) / "out"


def _mutate_csv(text: str, data) -> str:
    lines = text.splitlines()
    kind = data.draw(st.sampled_from(["cell", "cell", "header", "row", "truncate", "blank"]))
    if kind == "truncate":
        cut = data.draw(st.integers(0, len(text)))
        return text[:cut]
    i = data.draw(st.integers(0, len(lines) - 1))
    fields = lines[i].split(",")
    if kind == "cell":
        j = data.draw(st.integers(0, len(fields) - 1))
        fields[j] = data.draw(st.one_of(st.sampled_from(NASTY_CELLS), st.text(max_size=5)))
        lines[i] = ",".join(fields)
    elif kind == "header":
        j = data.draw(st.integers(0, len(fields) - 1))
        head = lines[0].split(",")
        head[j] = data.draw(st.sampled_from(
            ["", "time_ms", "pressure_kPa_gauge", "pressure_psi", "time_s", "position_mm",
             "command_V", "supply_pressure_bar", "pressure_kpa"]))
        lines[0] = ",".join(head)
    elif kind == "row":
        lines.insert(i, lines[data.draw(st.integers(0, len(lines) - 1))])
    else:
        lines[i] = ""
    return "\n".join(lines) + "\n"


def _paths(doc, prefix=()):
    """Every key path of nested JSON objects, parents before children."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    return out


def _at(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _mutate_json(doc, data):
    """Replace the value at a uniformly drawn key path (or delete it, or add a key), or
    the whole document (1 in 10)."""
    if not isinstance(doc, dict) or data.draw(st.integers(0, 9)) == 0:
        return data.draw(JSON_VALUES)
    doc = json.loads(json.dumps(doc))
    paths = _paths(doc)
    # hypothesis favours small indices; a drawn Random picks every path alike, and half
    # the time among the paths to objects (the structure a reader walks)
    rnd = data.draw(st.randoms(use_true_random=False))
    objects = [q for q in paths if isinstance(_at(doc, q), dict)]
    path = rnd.choice(objects if objects and rnd.random() < 0.5 else paths or [("x",)])
    *parents, key = path
    node = _at(doc, parents)
    action = data.draw(st.sampled_from(["replace", "replace", "delete", "add"]))
    if action == "delete":
        node.pop(key, None)
    elif action == "add":
        node[data.draw(st.one_of(st.text(max_size=8), st.sampled_from(
            ["format", "accept_unusual", "bore_mm", "supply_pressure_psi_gauge",
             "temperature_C", "time_ms"])))] = data.draw(JSON_VALUES)
    else:
        node[key] = data.draw(JSON_VALUES)
    return doc


@FUZZ
@given(data=st.data())
def test_mutated_recordings_never_raise(seeds, data, capsys):
    with fresh(seeds) as (inputs, out):
        rec = inputs / "rec.csv"
        if data.draw(st.booleans()):
            rec.write_text(_mutate_csv(rec.read_text(), data))
        else:
            meta = json.loads(rec.with_suffix(".json").read_text())
            rec.with_suffix(".json").write_text(json.dumps(_mutate_json(meta, data)))
        before = _snapshot(inputs)
        assert _run(["check", str(rec)], capsys) in (0, 1)
        assert _run(["simulate", str(rec), "--model", str(inputs / "card.json"),
                     "--out", str(out / "p.csv")], capsys) in (0, 2)
        assert _snapshot(inputs) == before


@FUZZ
@given(data=st.data())
def test_mutated_model_cards_never_raise(seeds, data, capsys):
    with fresh(seeds) as (inputs, out):
        card = inputs / "card.json"
        doc = json.loads(card.read_text())
        for _ in range(data.draw(st.integers(1, 3))):
            doc = _mutate_json(doc, data)
        card.write_text(json.dumps(doc) if data.draw(st.integers(0, 9)) else "{not json")
        before = _snapshot(inputs)
        assert _run(["simulate", str(inputs / "rec.csv"), "--model", str(card),
                     "--out", str(out / "p.csv")], capsys) in (0, 2)
        assert _snapshot(inputs) == before


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v) if v == v and abs(v) != float("inf") else "nan"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"


TOML_VALUES = st.recursive(
    st.one_of(st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=False),
              st.text(max_size=8), st.sampled_from(["AIR37:valve1", "discover", "moving",
                                                    "tube_delay", "realistic"])),
    lambda inner: st.lists(inner, max_size=3), max_leaves=5)


@FUZZ
@given(data=st.data())
def test_mutated_study_files_never_raise(seeds, data, capsys):
    with fresh(seeds) as (inputs, out):
        study = inputs / "study.toml"
        doc = tomllib.loads(study.read_text())
        table = data.draw(st.sampled_from(["grid", "settings", None]))
        target = doc if table is None else doc[table]
        key = data.draw(st.one_of(st.sampled_from(sorted(target)), st.text(max_size=6)))
        if data.draw(st.integers(0, 3)) == 0:
            target.pop(key, None)
        else:
            target[key] = data.draw(TOML_VALUES)
        lines = [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in doc.items()
                 if not isinstance(v, dict)]
        for name, tab in doc.items():
            if isinstance(tab, dict):
                lines.append(f"[{json.dumps(name)}]")
                lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in tab.items()]
        study.write_text("\n".join(lines) + "\n")
        before = _snapshot(inputs)
        assert _run(["ablate", str(study), "--out", str(out / "abl"), "--dry-run"],
                    capsys) in (0, 2)
        assert _snapshot(inputs) == before
        assert not (out / "abl").exists()


OPTION_VALUES = ["-1", "0", "-0", "nan", "inf", "-inf", "1e400", "abc", "", " ", "3.5",
                 "2", "1e-300", "0x10", "1_0", "--", "5,5"]


@FUZZ
@given(data=st.data())
def test_mutated_options_never_raise(seeds, data, capsys):
    with fresh(seeds) as (inputs, out):
        rec, card, study = (str(inputs / n) for n in ("rec.csv", "card.json", "study.toml"))
        commands = {
            "check": (["check", rec], ["--accept"]),
            "simulate": (["simulate", rec, "--model", card, "--out", str(out / "p.csv")],
                         ["--rtol", "--atol", "--max-step", "--accept"]),
            "predict": (["predict", str(inputs), rec, "--out", str(out / "p.csv")],
                        ["--horizon", "--stride", "--draws", "--seed"]),
            "ablate": (["ablate", study, "--out", str(out / "abl"), "--dry-run"],
                       ["--workers"]),
            # one recording: --method lsq refuses it once the options have passed
            "fit": (["fit", rec, "--out", str(out / "fit"), "--method", "lsq"],
                    ["--walkers", "--max-steps", "--seed", "--supply-cutoff",
                     "--pressure-filter", "--jacobian-refresh"]),
        }
        name = data.draw(st.sampled_from(sorted(commands)))
        argv, options = commands[name]
        option = data.draw(st.sampled_from(options))
        value = data.draw(st.one_of(st.sampled_from(OPTION_VALUES), st.text(max_size=4)))
        before = _snapshot(inputs)
        assert _run([*argv, f"{option}={value}"], capsys) in (0, 1, 2)
        assert _snapshot(inputs) == before
