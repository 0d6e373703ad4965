"""A rig card's quantities: a known value, or a prior over an unknown one to be fitted.

In a card a quantity is either a number in the unit its key names (known; never fitted)
or a table ``{"prior": "uniform" | "log-uniform", "bounds": [lower, upper]}`` with an
optional ``"start"`` inside the bounds (unknown: a model parameter, fitted, reported in
the posterior).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from pneubayes.effects.base import Parameter
from pneubayes.errors import RigCardError

PRIORS = ("uniform", "log-uniform")


def real(value, where: str, positive: bool = False, nonnegative: bool = False) -> float:
    """``value`` as a finite float; raises RigCardError naming ``where`` otherwise."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok:
        raise RigCardError(f"{where}: must be a finite number, got {value!r}")
    if positive and not value > 0:
        raise RigCardError(f"{where}: must be > 0, got {value!r}")
    if nonnegative and value < 0:
        raise RigCardError(f"{where}: must be >= 0, got {value!r}")
    return float(value)


#: order name -> (sign of each step, whether a zero step is allowed, the word for it)
_ORDERS = {"increasing": (1.0, False, "strictly increasing"),
           "non-decreasing": (1.0, True, "non-decreasing"),
           "non-increasing": (-1.0, True, "non-increasing")}


def table_column(table: Mapping, key: str, where: str, *, order: str,
                 length: int | None = None, per: str = "point",
                 max_points: int | None = None, nonnegative: bool = False) -> list[float]:
    """A rig card's table column ``table[key]``: a list of finite numbers in ``order``
    (``"increasing"`` strictly, ``"non-decreasing"`` or ``"non-increasing"``), of
    ``length`` values (one per ``per``) or else 2 to ``max_points``; errors name the key
    and the point (``valve key 'inlet_area_m2' [2]: the table must be non-decreasing``)."""
    at = f"{where} key {key!r}"
    v = table.get(key)
    if not isinstance(v, list):
        raise RigCardError(f"{at}: must be a list of numbers, got {v!r}")
    if length is not None and len(v) != length:
        raise RigCardError(f"{at}: must have one value per {per} ({length}), got {len(v)}")
    if length is None and len(v) < 2:
        raise RigCardError(f"{at}: a table has at least 2 points, got {len(v)}")
    if length is None and max_points is not None and len(v) > max_points:
        raise RigCardError(f"{at}: a table has 2 to {max_points} points, got {len(v)} "
                           "(resample a longer one)")
    out = [real(x, f"{at} [{i}]", nonnegative=nonnegative) for i, x in enumerate(v)]
    sign, flat_ok, word = _ORDERS[order]
    for i in range(1, len(out)):
        step = (out[i] - out[i - 1]) * sign
        if step < 0 or (step == 0 and not flat_ok):
            raise RigCardError(f"{at} [{i}]: the table must be {word}: {out[i]!r} follows "
                               f"{out[i - 1]!r}")
    return out


@dataclass(frozen=True)
class Unknown:
    """A quantity to be fitted: its prior kind, bounds and optional start value."""

    prior: str
    lower: float
    upper: float
    start: float | None = None

    def parameter(self, name: str, unit: str, description: str) -> Parameter:
        return Parameter(name, unit, self.lower, self.upper, self.prior, description)

    def start_value(self) -> float:
        """The card's start, else the prior's centre (geometric for log-uniform)."""
        if self.start is not None:
            return self.start
        if self.prior == "log-uniform":
            return math.sqrt(self.lower * self.upper)
        return 0.5 * (self.lower + self.upper)

    def to_card(self) -> dict:
        out = {"prior": self.prior, "bounds": [self.lower, self.upper]}
        if self.start is not None:
            out["start"] = self.start
        return out


def quantity(table: Mapping, key: str, where: str, *, positive: bool = False,
             nonnegative: bool = False, required: bool = True, default=None):
    """A known float or an :class:`Unknown` from ``table[key]``; errors name the key."""
    at = f"{where} key {key!r}"
    if key not in table:
        if required:
            raise RigCardError(f"{at}: missing (a number, or a prior "
                               "{\"prior\": ..., \"bounds\": [lower, upper]})")
        return default
    v = table[key]
    if not isinstance(v, Mapping):
        return real(v, at, positive=positive, nonnegative=nonnegative)
    stray = sorted(set(v) - {"prior", "bounds", "start"})
    if stray:
        raise RigCardError(f"{at}: unknown key(s) {stray}; a prior has 'prior', 'bounds' "
                           "and an optional 'start'")
    prior = v.get("prior")
    if prior not in PRIORS:
        raise RigCardError(f"{at} -> 'prior': must be one of {list(PRIORS)}, got {prior!r}")
    b = v.get("bounds")
    if not (isinstance(b, (list, tuple)) and len(b) == 2):
        raise RigCardError(f"{at} -> 'bounds': must be [lower, upper], got {b!r}")
    lo, hi = real(b[0], f"{at} -> 'bounds'"), real(b[1], f"{at} -> 'bounds'")
    if not lo < hi:
        raise RigCardError(f"{at} -> 'bounds': lower {lo!r} must be below upper {hi!r}")
    if (positive or prior == "log-uniform") and not lo > 0:
        why = "a log-uniform prior" if prior == "log-uniform" else "the quantity is positive"
        raise RigCardError(f"{at} -> 'bounds': lower must be > 0 ({why}), got {lo!r}")
    if nonnegative and lo < 0:
        raise RigCardError(f"{at} -> 'bounds': lower must be >= 0, got {lo!r}")
    start = v.get("start")
    if start is not None:
        start = real(start, f"{at} -> 'start'")
        if not lo <= start <= hi:
            raise RigCardError(f"{at} -> 'start': {start!r} is outside the bounds "
                               f"[{lo!r}, {hi!r}]")
    return Unknown(prior, lo, hi, start)


def to_card(value) -> float | dict:
    """A quantity as the card writes it."""
    return value.to_card() if isinstance(value, Unknown) else value
