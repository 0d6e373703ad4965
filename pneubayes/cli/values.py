"""The command line's option value types: each parses one option's text and raises
:class:`argparse.ArgumentTypeError` naming what is wrong, so a bad value is a usage
error before any work starts (:mod:`pneubayes.cli.args` builds the parser with them).
"""

from __future__ import annotations

import argparse
import math


def floats(text: str, what: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what}: expected comma-separated numbers, "
                                         f"got {text!r}") from None


def _number(kind: str, low: float, strict: bool):
    """An argparse type: a finite number > low (strict) or >= low, named in errors."""
    def parse(text: str):
        try:
            v = int(text) if kind == "integer" else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an' if kind == 'integer' else 'a'} "
                                             f"{kind}, got {text!r}") from None
        if not math.isfinite(v) or (v <= low if strict else v < low):
            raise argparse.ArgumentTypeError(
                f"must be {'>' if strict else '>='} {low:g}, got {text!r}")
        return v
    return parse


POSITIVE = _number("number", 0.0, strict=True)
NON_NEGATIVE = _number("number", 0.0, strict=False)
POSITIVE_INT = _number("integer", 0, strict=True)
NON_NEGATIVE_INT = _number("integer", 0, strict=False)


def share(text: str) -> float:
    v = NON_NEGATIVE(text)
    if v > 1.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {text!r}")
    return v


def bound(text: str) -> tuple[str, tuple[float, float]]:
    """NAME=LOWER:UPPER, two finite numbers with lower < upper."""
    name, sep, rest = text.partition("=")
    lo, colon, hi = rest.partition(":")
    try:
        if not (sep and colon and name.strip()):
            raise ValueError
        pair = (float(lo), float(hi))
        if not (all(math.isfinite(v) for v in pair) and pair[0] < pair[1]):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"--bounds expects NAME=LOWER:UPPER with finite "
                                         f"LOWER < UPPER, got {text!r}") from None
    return name.strip(), pair


def setting(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--set expects NAME=VALUE, got {text!r}") from None


def assignment(text: str):
    from pneubayes.settings_tree import SettingsError, assignment

    try:
        return assignment(text)
    except SettingsError as exc:
        raise argparse.ArgumentTypeError(f"--set {exc}") from None


def parameter_names(text: str) -> tuple[str, ...]:
    names = tuple(v.strip() for v in text.split(",") if v.strip())
    if not names:
        raise argparse.ArgumentTypeError("give one or more parameter names, comma-separated")
    return names


def accepted_rules(text: str) -> tuple[str, ...]:
    from pneubayes.io.plausibility import check_accept

    try:
        return check_accept([v.strip() for v in text.split(",") if v.strip()], "--accept")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def rig_card(text: str):
    from pneubayes.errors import RigCardError
    from pneubayes.rigcard import load_rig_card

    try:
        return load_rig_card(text)
    except RigCardError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def pressure_filter(text: str):
    from pneubayes.physics.sensor_filter import PressureFilter

    try:
        return PressureFilter.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--pressure-filter: {exc}") from None
