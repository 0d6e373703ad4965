"""A declarative ablation study read from TOML, expanded into cells.

A study file has a ``[grid]`` table, whose axes are crossed (cartesian product), and a
``[settings]`` table of scalars shared by every cell::

    name = "leak"
    description = "Fig. 12a: modelling the leak reduces the error"

    [grid]
    rigs = ["AIR37:valve1", "SMC:valve2"]          # CYLINDER:VALVE (Tables I and II)
    data_effects = [[], ["cylinder_leak"]]         # effects present in the data
    data_forms = ["catalogue"]                     # "catalogue" and/or "realistic"
    model_effects = [[], ["cylinder_leak"], "discover"]
    command_ranges_V = [5.0]                       # held-out recordings' command range
    protocols = ["moving"]                         # held-out protocol: fixed and/or moving
    seeds = [0, 1]

    [settings]
    duration_s = 20.0
    method = "refine"
    eval_command_bands_V = [0.1, 3.0]

    [settings.fit.sampler]                         # FitSettings -> SamplerSettings
    max_steps = 4000

    [settings.discovery.rounds]                    # DiscoverySettings -> RoundSettings
    max_effects = 4

``data_forms``: ``"catalogue"`` plants the catalogue's effects in the bench's model,
``"realistic"`` the independent plant's forms (:func:`pneubayes.bench.forms.forms_from_names`).
``model_effects`` entries are lists of catalogue names, ``"discover"`` (the loop from the
plain model) or ``"tassa"`` (the Tassa et al. 2013 baseline). Each cell is fitted on a
fixed design and scored on held-out recordings of its own protocol and command range
(:mod:`pneubayes.ablation.cell`). ``[settings]`` holds the keys of :class:`Settings`,
``[settings.fit]`` and ``[settings.discovery]`` those of the library's ``FitSettings``
and ``DiscoverySettings``; unknown keys and bad values are errors naming the file and
the key (:mod:`pneubayes.settings_tree`). A cell's id ends in a hash of everything that
defines its result (:meth:`Cell.content`): a changed setting reuses no cached result.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

from pneubayes.ablation.settings import (
    CELL_OWNED,
    MAX_COMMAND_V,
    Settings,
    check_number,
    table_at,
)
from pneubayes.effects import CATALOGUE
from pneubayes.errors import PneubayesError
from pneubayes.physics.cylinder import CYLINDERS
from pneubayes.physics.valve import VALVES
from pneubayes.settings_tree import FieldError, SettingsError, override

#: Bump when :func:`pneubayes.ablation.cell.run_cell` changes what a cell computes: every
#: cell id changes with it, so no stale cached result is reused.
CELL_VERSION = 4  # 4: sensor_lag in the catalogue, line cells follow the tube

DATA_FORMS = ("catalogue", "realistic")
PROTOCOLS = ("fixed", "moving")
DISCOVER = "discover"
#: The peer baseline (Tassa et al. 2013, :mod:`pneubayes.baselines.tassa`) as a model.
TASSA = "tassa"
#: ``model_effects`` entries that are not effect lists.
SPECIAL_MODELS = (DISCOVER, TASSA)
#: Bench sample rate, Hz (the SensorChain default): used to check that windows fit.
SAMPLE_RATE_HZ = 1000.0


class StudyError(PneubayesError, ValueError):
    """A study file is not valid; the message names the file and the key."""


GRID_KEYS = ("rigs", "data_effects", "data_forms", "model_effects", "command_ranges_V",
             "protocols", "seeds")
#: Grid axes that may be omitted, and their values then.
GRID_DEFAULTS = {"data_forms": ("catalogue",), "command_ranges_V": (5.0,),
                 "protocols": ("moving",)}
TOP_KEYS = ("name", "description", "grid", "settings")


@dataclass(frozen=True)
class Grid:
    """The study's axes, validated and canonical (effects in catalogue order)."""

    rigs: tuple[tuple[str, str], ...]
    data_effects: tuple[tuple[str, ...], ...]
    data_forms: tuple[str, ...]
    model_effects: tuple[tuple[str, ...] | str, ...]
    command_ranges_V: tuple[float, ...]
    protocols: tuple[str, ...]
    seeds: tuple[int, ...]

    def to_dict(self) -> dict:
        return {"rigs": [f"{c}:{v}" for c, v in self.rigs],
                "data_effects": [list(e) for e in self.data_effects],
                "data_forms": list(self.data_forms),
                "model_effects": [m if isinstance(m, str) else list(m)
                                  for m in self.model_effects],
                "command_ranges_V": list(self.command_ranges_V),
                "protocols": list(self.protocols), "seeds": list(self.seeds)}


def _label(names: tuple[str, ...], empty: str) -> str:
    return "+".join(names) if names else empty


def _number_label(value: float) -> str:
    return f"{value:g}".replace(".", "p").replace("-", "m")


@dataclass(frozen=True)
class Cell:
    """One cell of a study: a rig, the data, the fitted model and the held-out protocol.

    ``kind`` is ``"effects"`` (the thin-port model with ``model_effects``),
    ``"discover"`` (the discovery loop from the plain model) or ``"tassa"`` (the peer
    baseline); ``model_effects`` is empty for the last two. ``id`` is stable and
    readable; its last part is :attr:`digest`.
    """

    cylinder: str
    valve: str
    data_effects: tuple[str, ...]
    data_form: str
    model_effects: tuple[str, ...]
    kind: str
    command_range_V: float
    protocol: str
    seed: int
    settings: Settings

    @property
    def discover(self) -> bool:
        return self.kind == DISCOVER

    @property
    def model_label(self) -> str:
        """``"discover"``, ``"tassa"``, ``"plain"`` or the effects joined by ``+``."""
        if self.kind in SPECIAL_MODELS:
            return self.kind
        return _label(self.model_effects, "plain")

    def axes(self) -> dict:
        """The cell's grid coordinates (JSON-ready)."""
        return {"cylinder": self.cylinder, "valve": self.valve,
                "data_effects": list(self.data_effects), "data_form": self.data_form,
                "model": self.model_label, "model_effects": list(self.model_effects),
                "discover": self.discover, "command_range_V": self.command_range_V,
                "protocol": self.protocol, "seed": self.seed}

    def content(self) -> dict:
        """Everything that defines the cell's result (the hash covers exactly this).

        Settings that cannot change this cell (e.g. the sampler's and its solver's without
        ``method = "mcmc"``, the discovery loop's without ``"discover"``, the held-out
        design of the other protocol, ``smoke_duration_s``) are left out, so changing them
        does not invalidate its cached result.
        """
        s = self.settings.to_dict()
        s.pop("smoke_duration_s")
        for table, key in CELL_OWNED:  # the cell sets these (axes, horizon_s)
            table_at(s, table).pop(key)
        if self.settings.method != "mcmc":  # nothing is sampled: neither can matter
            s["fit"].pop("sampler")
            s["fit"].pop("sample_solver")
        if not self.discover:
            s.pop("discovery")
        if "cylinder_leak" not in self.model_effects:
            s.pop("leak_form")  # the discovery loop picks its own leak law (graded laminar)
        if not ("cylinder_leak" in self.data_effects and self.data_form == "catalogue"):
            s.pop("data_leak_form")
        if not self.settings.fit_moving_count:
            s.pop("fit_moving_range_V")
        s.pop("eval_positions" if self.protocol == "moving" else "eval_moving_count")
        return {"cell_version": CELL_VERSION, **self.axes(), "settings": s}

    @property
    def digest(self) -> str:
        """8 hex digits of the sha256 of :meth:`content`."""
        text = json.dumps(self.content(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:8]

    @property
    def id(self) -> str:
        """E.g. ``AIR37-valve1.data-tube_delay.catalogue.model-plain.u5.moving.s0.1a2b3c4d``."""
        return (f"{self.cylinder}-{self.valve}.data-{_label(self.data_effects, 'none')}."
                f"{self.data_form}.model-{self.model_label}.u{_number_label(self.command_range_V)}"
                f".{self.protocol}.s{self.seed}.{self.digest}")

    def to_dict(self) -> dict:
        return {"id": self.id, **self.axes(), "settings": self.settings.to_dict()}


@dataclass(frozen=True)
class Study:
    """A validated study: name, grid, settings and the TOML it came from."""

    name: str
    description: str
    grid: Grid
    settings: Settings
    source: str
    text: str

    def cells(self) -> tuple[Cell, ...]:
        """The grid's cells in a fixed order (rigs outermost, seeds innermost)."""
        g, out = self.grid, []
        for (cyl, valve), data, form, model, rng, proto, seed in itertools.product(
                g.rigs, g.data_effects, g.data_forms, g.model_effects, g.command_ranges_V,
                g.protocols, g.seeds):
            kind = model if model in SPECIAL_MODELS else "effects"
            out.append(Cell(cyl, valve, data, form, () if kind != "effects" else model, kind,
                            rng, proto, seed, self.settings))
        return tuple(out)

    @property
    def n_cells(self) -> int:
        return math.prod(len(getattr(self.grid, k)) for k in GRID_KEYS)

    def smoke(self) -> Study:
        """One cell (the first value of every axis) with ``smoke_duration_s`` recordings."""
        g = self.grid
        grid = Grid(*(getattr(g, k)[:1] for k in GRID_KEYS))
        dur = min(self.settings.duration_s, self.settings.smoke_duration_s)
        settings = replace(self.settings, duration_s=dur)
        try:
            _check_consistency(self.source, grid, settings)
        except StudyError as exc:
            raise StudyError(f"{exc} (smoke mode: recordings of settings.smoke_duration_s = "
                             f"{self.settings.smoke_duration_s:g} s)") from None
        return replace(self, name=f"{self.name} (smoke)", grid=grid, settings=settings)

    def to_dict(self) -> dict:
        return {"name": self.name, "description": self.description, "source": self.source,
                "grid": self.grid.to_dict(), "settings": self.settings.to_dict(),
                "n_cells": self.n_cells, "toml": self.text}


# ---------------------------------------------------------------- reading and checking
def load_study(path) -> Study:
    """Read and validate a study TOML file (errors name the file and the key)."""
    from pneubayes.limits import input_file_problem

    p = Path(path)
    why = input_file_problem(p)
    if why is not None:
        raise StudyError(f"{p}: {why}")
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StudyError(f"{p}: study file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{p}: cannot read the study file ({exc})") from None
    return parse_study(text, str(p))


def parse_study(text: str, source: str = "<study>") -> Study:
    """Validate a study from TOML ``text``; ``source`` names it in error messages."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{source}: not valid TOML: {exc}") from None
    _unknown(source, "", doc, TOP_KEYS)
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name.strip():
        raise StudyError(f"{source}: name: expected a non-empty string, got {name!r}")
    description = doc.get("description", "")
    if not isinstance(description, str):
        raise StudyError(f"{source}: description: expected a string, got {description!r}")
    grid_doc = _table(source, doc, "grid", required=True)
    settings_doc = _table(source, doc, "settings", required=False)
    grid = _grid(source, grid_doc)
    settings = _settings(source, settings_doc)
    _check_consistency(source, grid, settings)
    return Study(name.strip(), description, grid, settings, source, text)


def _table(source, doc, key, required):
    if key not in doc:
        if required:
            raise StudyError(f"{source}: missing the [{key}] table")
        return {}
    if not isinstance(doc[key], dict):
        raise StudyError(f"{source}: {key}: expected a table ([{key}]), got "
                         f"{type(doc[key]).__name__}")
    return doc[key]


def _unknown(source, prefix, table, known):
    bad = [k for k in table if k not in known]
    if bad:
        where = f"{prefix}{bad[0]}"
        raise StudyError(f"{source}: {where}: unknown key; known keys"
                         f"{' in [' + prefix.rstrip('.') + ']' if prefix else ''}: "
                         f"{', '.join(known)}")


def _type_name(v) -> str:
    return type(v).__name__


def _list(source, key, value, allow_empty=False) -> list:
    if not isinstance(value, list):
        raise StudyError(f"{source}: {key}: expected a list, got {_type_name(value)} {value!r}")
    if not value and not allow_empty:
        raise StudyError(f"{source}: {key}: the list is empty; give at least one value")
    return value


def _number(source, key, v, lo=None, hi=None, closed_lo=False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise StudyError(f"{source}: {key}: expected a number, got {_type_name(v)} {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise StudyError(f"{source}: {key}: expected a finite number, got {v!r}")
    try:
        check_number(key, v, lo, hi, closed_lo)
    except FieldError as exc:
        raise StudyError(f"{source}: {exc}") from None
    return v


def _integer(source, key, v, lo=None) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise StudyError(f"{source}: {key}: expected an integer, got {_type_name(v)} {v!r}")
    if lo is not None and v < lo:
        raise StudyError(f"{source}: {key}: must be >= {lo}, got {v}")
    return v


def _string(source, key, v, choices) -> str:
    if not isinstance(v, str):
        raise StudyError(f"{source}: {key}: expected a string, got {_type_name(v)} {v!r}")
    if v not in choices:
        raise StudyError(f"{source}: {key}: unknown value {v!r}; choose from "
                         f"{', '.join(choices)}")
    return v


def _no_duplicates(source, key, values):
    seen = []
    for i, v in enumerate(values):
        if v in seen:
            raise StudyError(f"{source}: {key}[{i}]: duplicate value {v!r}")
        seen.append(v)
    return tuple(values)


def _effects(source, key, value) -> tuple[str, ...]:
    names = _list(source, key, value, allow_empty=True)
    for i, n in enumerate(names):
        if not isinstance(n, str):
            raise StudyError(f"{source}: {key}[{i}]: expected an effect name (string), got "
                             f"{_type_name(n)} {n!r}")
        if n not in CATALOGUE:
            raise StudyError(f"{source}: {key}[{i}]: unknown effect {n!r}; the catalogue has "
                             f"{', '.join(CATALOGUE)}")
    _no_duplicates(source, key, names)
    order = list(CATALOGUE)
    return tuple(sorted(names, key=order.index))


def _grid(source, doc) -> Grid:
    _unknown(source, "grid.", doc, GRID_KEYS)
    missing = [k for k in GRID_KEYS if k not in doc and k not in GRID_DEFAULTS]
    if missing:
        raise StudyError(f"{source}: grid.{missing[0]}: missing (required grid axes: "
                         f"{', '.join(k for k in GRID_KEYS if k not in GRID_DEFAULTS)})")
    values = {}
    for key in GRID_KEYS:
        if key not in doc:
            values[key] = GRID_DEFAULTS[key]
            continue
        full = f"grid.{key}"
        items = _list(source, full, doc[key])
        out = []
        for i, v in enumerate(items):
            at = f"{full}[{i}]"
            if key == "rigs":
                out.append(_rig(source, at, v))
            elif key == "data_effects":
                out.append(_effects(source, at, v))
            elif key == "model_effects":
                if isinstance(v, str):
                    if v not in SPECIAL_MODELS:
                        raise StudyError(f"{source}: {at}: expected a list of effect names, "
                                         f"\"{DISCOVER}\" or \"{TASSA}\", got {v!r}")
                    out.append(v)
                else:
                    out.append(_effects(source, at, v))
            elif key == "data_forms":
                out.append(_string(source, at, v, DATA_FORMS))
            elif key == "protocols":
                out.append(_string(source, at, v, PROTOCOLS))
            elif key == "command_ranges_V":
                out.append(_number(source, at, v, 0.0, MAX_COMMAND_V))
            elif key == "seeds":
                out.append(_integer(source, at, v, 0))
        values[key] = _no_duplicates(source, full, out)
    return Grid(**values)


def _rig(source, key, v) -> tuple[str, str]:
    if not isinstance(v, str):
        raise StudyError(f"{source}: {key}: expected \"CYLINDER:VALVE\", got "
                         f"{_type_name(v)} {v!r}")
    cyl, sep, valve = v.partition(":")
    if not sep:
        raise StudyError(f"{source}: {key}: expected \"CYLINDER:VALVE\" "
                         f"(e.g. \"AIR37:valve1\"), got {v!r}")
    if cyl not in CYLINDERS:
        raise StudyError(f"{source}: {key}: unknown cylinder {cyl!r} in {v!r}; known: "
                         f"{', '.join(CYLINDERS)}")
    if valve not in VALVES:
        raise StudyError(f"{source}: {key}: unknown valve {valve!r} in {v!r}; known: "
                         f"{', '.join(VALVES)}")
    return cyl, valve


def _settings(source, doc) -> Settings:
    """The ``[settings]`` table over the defaults, checked by the settings dataclasses
    themselves (:func:`pneubayes.settings_tree.override`)."""
    for (table, key), owner in CELL_OWNED.items():
        if key in (table_at(doc, table) or {}):
            raise StudyError(f"{source}: settings.{table}.{key}: set by each cell, not the "
                             f"study ({owner})")
    try:
        return override(Settings(), doc, "settings")
    except SettingsError as exc:
        raise StudyError(f"{source}: {exc}") from None


def _check_consistency(source, grid: Grid, s: Settings) -> None:
    """Checks across keys: windows fit the recordings, seeds differ, the fit method and
    the discovery loop have the data they need."""
    from pneubayes.bench.bench import BenchConfig
    from pneubayes.limits import MAX_BENCH_SAMPLES

    fine = BenchConfig.fine_rate_Hz  # the bench's truth grid, Hz
    recordings = (len(s.fit_positions) * len(s.fit_command_ranges_V) + s.fit_moving_count
                  + max(s.eval_moving_count, 1))
    if recordings * s.duration_s * fine > MAX_BENCH_SAMPLES:
        raise StudyError(f"{source}: settings.duration_s: {s.duration_s:g} s recordings, "
                         f"{recordings} per cell on the bench's {fine:g}-Hz grid, are "
                         f"{recordings * s.duration_s * fine:.3g} simulated samples per "
                         f"cell, over the bench's limit of {MAX_BENCH_SAMPLES:.3g}")
    if s.horizon_s + 1.0 / SAMPLE_RATE_HZ > s.duration_s:
        raise StudyError(f"{source}: settings.horizon_s: {s.horizon_s:g} s windows do not fit "
                         f"in settings.duration_s = {s.duration_s:g} s recordings")
    if s.heldout_seed_offset == 500:
        raise StudyError(f"{source}: settings.heldout_seed_offset: 500 is the fitting "
                         "recordings' moving-piston seed offset; choose another")
    if s.method == "lsq" and len(s.fit_positions) < 2:
        raise StudyError(f"{source}: settings.fit_positions: method \"lsq\" (the paper's "
                         "eq.-10 least squares) needs fixed-volume recordings at two or more "
                         "positions")
    if DISCOVER in grid.model_effects:
        _check_discovery_data(source, s)


def _check_discovery_data(source, s: Settings) -> None:
    """The discovery loop holds out the last third of every fitting recording and needs
    enough whole windows there for its signed-rank test (as ``Discovery.fit`` checks)."""
    d = s.discovery
    n = int(round(s.duration_s * SAMPLE_RATE_HZ)) + 1
    cut = int(round(n * (1.0 - d.data.holdout_fraction)))
    need = int(round(s.horizon_s * SAMPLE_RATE_HZ)) + 1
    per_recording = 0 if n - cut < need else (n - cut - need) // (need - 1) + 1
    recordings = len(s.fit_positions) * len(s.fit_command_ranges_V) + s.fit_moving_count
    windows = per_recording * recordings
    if 0.5 ** windows > d.verify.max_p_value:
        minimum = math.ceil(math.log(d.verify.max_p_value) / math.log(0.5))
        raise StudyError(
            f"{source}: settings.duration_s: \"discover\" cells hold out the last "
            f"{d.data.holdout_fraction:.2g} of each of the {recordings} fitting recordings, which "
            f"gives {windows} whole {s.horizon_s:g}-s windows; its significance test needs "
            f"at least {minimum} (p <= {d.verify.max_p_value:g}): give longer recordings "
            f"(duration_s = {s.duration_s:g} s) or more fitting recordings")
