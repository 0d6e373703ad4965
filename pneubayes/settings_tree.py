"""Settings dataclasses from nested tables (a TOML file's, a JSON document's).

The library declares each job's settings once, as frozen dataclasses that nest
(:class:`~pneubayes.inference.fit.FitSettings` holds the sampler's and the solvers',
:class:`~pneubayes.discovery.settings.DiscoverySettings` the fit's, ...). A file that
changes some of them names the same keys in the same nesting; :func:`override` applies
such a table to a settings object and lets the dataclasses check the result:

- a key that names no field is an error listing the fields;
- a value is checked against its field's type hint (a number for ``float``, an integer
  for ``int``, a list for ``tuple[...]``, a table for a nested settings dataclass, ...):
  nothing is converted that could be a mistake (``"20"`` is not 20, ``true`` is not 1);
- a table for a nested settings dataclass is applied to that field's current value, so
  keys not named keep the defaults of the level above;
- the dataclass's own ``__post_init__`` then validates the values.

Every error is a :class:`SettingsError` naming ``where`` and the key's path.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path

from pneubayes.errors import PneubayesError
from pneubayes.limits import check_input_file


class SettingsError(PneubayesError, ValueError):
    """A settings table is not valid; the message names where and the key."""


class FieldError(ValueError):
    """Raised by a settings dataclass's ``__post_init__`` for one field: ``key`` (the
    field, with an index for a list item, e.g. ``fit_positions[1]``) and what is wrong.
    :func:`override` and :func:`build` report it at the key's path."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key, self.message = key, message


def _type_name(v) -> str:
    return type(v).__name__


def _convert(hint, value, current, where: str):
    """``value`` checked against ``hint`` (``current`` is the field's present value)."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            return _convert(rest[0], value, current, where)
        return value  # a union of several types: the dataclass checks it
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, Mapping):
            raise SettingsError(f"{where}: expected a table of {hint.__name__} settings, got "
                                f"{_type_name(value)} {value!r}")
        if dataclasses.is_dataclass(current) and not isinstance(current, type):
            return override(current, value, where)
        return build(hint, value, where)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SettingsError(f"{where}: expected a number, got {_type_name(value)} "
                                f"{value!r}")
        if not math.isfinite(value):
            raise SettingsError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SettingsError(f"{where}: expected an integer, got {_type_name(value)} "
                                f"{value!r}")
        return value
    if hint in (bool, str):
        if not isinstance(value, hint):
            kind = "true or false" if hint is bool else "a string"
            raise SettingsError(f"{where}: expected {kind}, got {_type_name(value)} "
                                f"{value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise SettingsError(f"{where}: expected a list, got {_type_name(value)} {value!r}")
        args = typing.get_args(hint)
        item = args[0] if len(args) == 2 and args[1] is Ellipsis else None
        if item is None:
            return tuple(value)
        return tuple(_convert(item, v, None, f"{where}[{i}]") for i, v in enumerate(value))
    if hint is dict or origin is dict:
        if not isinstance(value, Mapping):
            raise SettingsError(f"{where}: expected a table, got {_type_name(value)} {value!r}")
        return dict(value)
    return value


def _fields(cls) -> dict:
    """The type hint of each of ``cls``'s constructor fields."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if f.init}


def _values(cls, table, where: str, current=None) -> dict:
    if not isinstance(table, Mapping):
        raise SettingsError(f"{where}: expected a table, got {_type_name(table)} {table!r}")
    known = _fields(cls)
    out = {}
    for key, value in table.items():
        path = f"{where}.{key}" if where else str(key)
        if key not in known:
            raise SettingsError(f"{path}: unknown key; {cls.__name__} has "
                                f"{', '.join(known)}")
        now = getattr(current, key) if current is not None else None
        out[key] = _convert(known[key], value, now, path)
    return out


def _construct(make, cls, where: str):
    try:
        return make()
    except FieldError as exc:
        raise SettingsError(f"{where + '.' if where else ''}{exc.key}: {exc.message}") \
            from None
    except SettingsError:
        raise
    except (TypeError, ValueError) as exc:
        raise SettingsError(f"{where or cls.__name__}: {exc}") from None


def override(settings, table: Mapping, where: str = ""):
    """A copy of the settings dataclass ``settings`` with ``table``'s keys replaced
    (nested tables applied to nested settings); errors name ``where`` and the key."""
    values = _values(type(settings), table, where, settings)
    return _construct(lambda: dataclasses.replace(settings, **values), type(settings), where)


def build(cls, table: Mapping, where: str = ""):
    """A new ``cls`` from ``table`` (fields not named take their defaults)."""
    values = _values(cls, table, where)
    return _construct(lambda: cls(**values), cls, where)


def assignment(text: str) -> tuple[tuple[str, ...], object]:
    """``KEY.PATH=VALUE`` (a command line's ``--set``) as ``(key path, value)``: the value
    is read as a TOML value (``2``, ``1e-3``, ``true``, ``[1, 2]``, ``{order = 2,
    cutoff_Hz = 1000}``, ``"wave"``), a bare word that is not one as that text. The
    settings' type checks then refuse a value of the wrong kind."""
    key, sep, raw = text.partition("=")
    path = tuple(k.strip() for k in key.split("."))
    if not sep or not all(path):
        raise SettingsError(f"{text!r}: expected KEY=VALUE with a dotted KEY, e.g. "
                            "rounds.max_effects=2")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return path, value


def table_of(assignments) -> dict:
    """The nested table that ``(key path, value)`` pairs describe; a key given twice,
    or both as a value and as a table, is an error naming it."""
    out: dict = {}
    for path, value in assignments:
        node = out
        for i, key in enumerate(path[:-1]):
            node = node.setdefault(key, {})
            if not isinstance(node, dict):
                raise SettingsError(f"{'.'.join(path[:i + 1])}: given as a value and as a "
                                    "table")
        if path[-1] in node:
            raise SettingsError(f"{'.'.join(path)}: given more than once")
        node[path[-1]] = value
    return out


def read_table(path) -> dict:
    """A settings file's table (TOML); errors name the file."""
    p = Path(path)
    if not p.exists():
        raise SettingsError(f"{p}: no such settings file")
    check_input_file(p, "--settings")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SettingsError(f"{p}: not a TOML settings file ({exc})") from None
