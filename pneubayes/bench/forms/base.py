"""The bench forms' shared base: :class:`PlantForm` and its field checks."""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import ClassVar

#: Dynamic viscosity of air at 20 degC, Pa s (the catalogue's tube_delay uses the same).
AIR_VISCOSITY_PA_S = 1.81e-5


def _positive(obj, *names):
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                math.isfinite(v) and v > 0):
            raise ValueError(f"{type(obj).__name__}.{n} must be a finite number > 0, got {v!r}")


def _finite(obj, *names):
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{type(obj).__name__}.{n} must be a finite number, got {v!r}")


def _non_negative(obj, *names):
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                math.isfinite(v) and v >= 0):
            raise ValueError(f"{type(obj).__name__}.{n} must be a finite number >= 0, "
                             f"got {v!r}")


class PlantForm:
    """Base of the realistic forms: a frozen dataclass naming its catalogue effect."""

    #: The catalogue effect this form is a realistic version of; None for an effect
    #: outside the catalogue (discovery should name no catalogue effect for it).
    catalogue_name: ClassVar[str | None]
    #: Whether a valve driver's ``switches`` takes the supply (``supply_gauge_at``).
    reads_supply: ClassVar[bool] = False

    def to_dict(self) -> dict:
        """``{"form": class name, "catalogue_name": ..., **fields}`` (JSON-ready)."""
        return {"form": type(self).__name__, "catalogue_name": self.catalogue_name,
                **asdict(self)}


def _smoothstep(z: float) -> float:
    """C1 ramp: 0 for z <= 0, 3 z^2 - 2 z^3 on (0, 1), 1 for z >= 1 (the plant's own
    copy is compiled in :mod:`pneubayes.bench.plant`)."""
    z = min(max(z, 0.0), 1.0)
    return z * z * (3.0 - 2.0 * z)
