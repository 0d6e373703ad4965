"""A valve command's declared unit and range (a rig card's ``command`` table, and a
separate exhaust valve's): volts, duty 0..1 or binary; never assumed to be +-5 V."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pneubayes.errors import RigCardError
from pneubayes.rigcard.values import real

COMMAND_UNITS = ("V", "duty", "binary")


@dataclass(frozen=True)
class CommandSpec:
    """The command's unit and range: volts (any declared range), duty 0..1, or binary
    (0 = closed, 1 = open)."""

    unit: str
    lower: float
    upper: float

    def check(self, command, source: str) -> None:
        """Raise RigCardError naming the first row outside the declared range."""
        u = np.asarray(command, dtype=np.float64)
        bad = (u < self.lower) | (u > self.upper)
        if self.unit == "binary":
            bad |= (u != 0.0) & (u != 1.0)
        if bad.any():
            i = int(np.argmax(bad))
            what = "0 or 1" if self.unit == "binary" else f"[{self.lower:g}, {self.upper:g}]"
            raise RigCardError(f"{source} row {i + 1}: command {u[i]:g} is outside the rig "
                               f"card's declared range ({self.unit}: {what})")

    def to_card(self) -> dict:
        out = {"unit": self.unit}
        if self.unit != "binary":
            out["range"] = [self.lower, self.upper]
        return out



def read_command(spec, at: str) -> CommandSpec:
    """A command table ``{unit, range}``; errors name ``at`` (the table's place)."""
    if not isinstance(spec, Mapping):
        raise RigCardError(f"{at}: missing; declare the command's unit, e.g. "
                           "{\"unit\": \"V\", \"range\": [-5, 5]} or {\"unit\": \"binary\"}")
    unit = spec.get("unit")
    if unit not in COMMAND_UNITS:
        raise RigCardError(f"{at} -> 'unit': must be one of {list(COMMAND_UNITS)}, got "
                           f"{unit!r}")
    stray = sorted(set(spec) - {"unit", "range"})
    if stray:
        raise RigCardError(f"{at}: unknown key(s) {stray}; it has 'unit' and 'range'")
    if unit == "binary":
        if "range" in spec and list(spec["range"]) != [0, 1]:
            raise RigCardError(f"{at} -> 'range': a binary command is 0 or 1")
        return CommandSpec(unit, 0.0, 1.0)
    r = spec.get("range", [0.0, 1.0] if unit == "duty" else None)
    if not (isinstance(r, (list, tuple)) and len(r) == 2):
        raise RigCardError(f"{at} -> 'range': must be [lower, upper], got {r!r}")
    lo, hi = real(r[0], f"{at} -> 'range'"), real(r[1], f"{at} -> 'range'")
    if not lo < hi:
        raise RigCardError(f"{at} -> 'range': lower {lo!r} must be below upper {hi!r}")
    if unit == "duty" and not (0.0 <= lo and hi <= 1.0):
        raise RigCardError(f"{at} -> 'range': a duty lies within [0, 1], got [{lo!r}, {hi!r}]")
    return CommandSpec(unit, lo, hi)
