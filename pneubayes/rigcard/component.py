"""The shared interface of a rig's components: one file per kind, one registry.

A rig component is a :class:`~pneubayes.effects.base.Component` (named parameters
lowered onto signal-path slots) that also reads itself from its table of a rig card and
writes itself back. Its known quantities are lowered as constants; its unknown ones
(priors in the card) are the model parameters the fit estimates.

Kinds register themselves with :func:`register`; :data:`KINDS` maps
``(role, kind)`` to the class. Roles: ``chamber``, ``valve``, ``supply`` (each card
has one), ``exhaust`` (optional: a separately commanded exhaust valve) and ``ports``
(optional: the valve's flow paths as a datasheet rates them).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from pneubayes.effects.base import Component, Parameter
from pneubayes.errors import RigCardError
from pneubayes.rigcard.values import Unknown, to_card

ROLES = ("chamber", "valve", "supply")
OPTIONAL_ROLES = ("exhaust", "ports")
KINDS: dict[tuple[str, str], type["RigComponent"]] = {}


def register(cls: type["RigComponent"]) -> type["RigComponent"]:
    """Class decorator: add a component kind to :data:`KINDS`."""
    key = (cls.role, cls.kind)
    if cls.role not in ROLES + OPTIONAL_ROLES:
        raise ValueError(f"{cls.__name__}: role {cls.role!r} is not one of "
                         f"{ROLES + OPTIONAL_ROLES}")
    if key in KINDS:
        raise ValueError(f"component kind {key} registered twice")
    KINDS[key] = cls
    return cls


def kinds_of(role: str) -> list[str]:
    return sorted(k for r, k in KINDS if r == role)


class RigComponent(Component):
    """A chamber, valve, supply or separate exhaust valve of a rig card.

    Subclasses declare ``role``, ``kind`` and ``quantities``: per quantity its card key
    (the parameter name when fitted), unit, description and whether it must be positive
    or non-negative; and implement :meth:`lower_all` on the full set of values (known
    and fitted).
    """

    role: ClassVar[str]
    kind: ClassVar[str]
    #: (card key, unit, description, sign) with sign "positive", "nonnegative" or "".
    quantities: ClassVar[tuple[tuple[str, str, str, str], ...]] = ()
    #: card key -> model parameter name where they differ (a fitted quantity's name must
    #: be unique in a model: ``open_area_m2`` -> ``valve_open_area_m2``)
    parameter_names_by_key: ClassVar[dict[str, str]] = {}
    #: card key -> the value (a number or an Unknown prior) of a quantity the card may
    #: leave out; a quantity not named here is required
    defaults: ClassVar[dict] = {}
    #: catalogue effects whose slots this component writes: a model with the component
    #: refuses them and the discovery loop does not propose them
    covers_effects: ClassVar[tuple[str, ...]] = ()
    #: the recording's ``position_m`` column is a coordinate this component maps to the
    #: equivalent piston's position and checks against its own range (``bind_columns``),
    #: so the reader's stroke rule, which reads a piston position, does not apply to it
    maps_position: ClassVar[bool] = False

    def parameter_name(self, key: str) -> str:
        return self.parameter_names_by_key.get(key, key)

    def __init__(self, values: Mapping[str, Any], options: Mapping[str, Any] | None = None):
        self.values = dict(values)       # key -> float (known) or Unknown (fitted)
        self.extra = dict(options or {})  # kind-specific non-quantity keys

    @property
    def name(self) -> str:  # Component.name, per instance
        return f"{self.role}:{self.kind}"

    # ---- card
    @classmethod
    def from_table(cls, table: Mapping, where: str) -> "RigComponent":
        """Read the component from its card table (``kind`` already checked)."""
        from pneubayes.rigcard.values import quantity

        known = {q[0] for q in cls.quantities} | set(cls.option_keys()) | {"kind"}
        stray = sorted(set(table) - known)
        if stray:
            raise RigCardError(f"{where}: unknown key(s) {stray} for kind {cls.kind!r}; its "
                               f"keys are {sorted(known)}")
        values = {key: quantity(table, key, where, positive=sign == "positive",
                                nonnegative=sign == "nonnegative",
                                required=key not in cls.defaults,
                                default=cls.defaults.get(key))
                  for key, _, _, sign in cls.quantities}
        obj = cls(values, cls.read_options(table, where))
        obj.check(where)
        return obj

    @classmethod
    def option_keys(cls) -> tuple[str, ...]:
        """Card keys besides the quantities (e.g. a polynomial's coefficients)."""
        return ()

    @classmethod
    def read_options(cls, table: Mapping, where: str) -> dict:
        return {}

    def check(self, where: str) -> None:
        """Checks across quantities and options (raise RigCardError naming ``where``)."""

    def check_beside(self, parts: Mapping[str, "RigComponent | None"], where: str) -> None:
        """Checks against the card's other components, by role (None: absent); raise
        RigCardError naming ``where``."""

    def to_table(self) -> dict:
        out = {"kind": self.kind}
        out.update({k: to_card(v) for k, v in self.values.items()})
        out.update(self.extra)
        return out

    # ---- Component interface
    def parameters(self) -> tuple[Parameter, ...]:
        return tuple(v.parameter(self.parameter_name(key), unit,
                                 f"{self.role} ({self.kind}): {desc}")
                     for key, unit, desc, _ in self.quantities
                     if isinstance(v := self.values[key], Unknown))

    def lower(self, values: Mapping[str, np.ndarray], rig) -> dict[str, np.ndarray]:
        full = {k: (values[self.parameter_name(k)] if isinstance(v, Unknown) else v)
                for k, v in self.values.items()}
        return self.lower_all(full, rig)

    def lower_all(self, values: Mapping, rig) -> dict:
        """Slot contributions from every quantity, by card key (arrays ``(B,)`` or
        floats)."""
        return {}

    def start_values(self) -> dict[str, float]:
        """Start values of the fitted quantities, by parameter name."""
        return {self.parameter_name(k): v.start_value() for k, v in self.values.items()
                if isinstance(v, Unknown)}

    def options(self) -> dict:
        return self.to_table()

    def __hash__(self) -> int:  # the table holds lists (a polynomial's coefficients)
        import json

        return hash((type(self).__name__, json.dumps(self.to_table(), sort_keys=True)))

    # ---- binding to a recording (chamber and supply kinds override)
    def without_exhaust(self, where: str) -> "RigComponent":
        """A valve whose exhaust port is closed, for a rig whose exhaust is a separate
        valve (valve kinds override; raise RigCardError naming ``where`` when the card
        also gives this valve an exhaust)."""
        raise RigCardError(f"{where}: a {self.role} of kind {self.kind!r} has no exhaust "
                           "port to hand to a separate exhaust valve")

    def metadata_defaults(self) -> dict:
        """Recording metadata this component supplies (e.g. an equivalent bore)."""
        return {}

    def bind_columns(self, recording, where: str) -> dict:
        """Columns of the recording as the model reads them (e.g. a coordinate mapped to
        an equivalent piston position); ``{}`` leaves them unchanged."""
        return {}

    @property
    def acts_on(self):  # type: ignore[override]
        return self.slots_written

    slots_written: ClassVar[tuple[str, ...]] = ()
