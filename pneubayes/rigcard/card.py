"""The rig card (``pneubayes-rig/1``): a lab's own chamber, valve and supply.

A JSON or TOML file (see the README's "Your own rig")::

    format = "pneubayes-rig/1"
    name = "GTDynamics knee muscle"
    atmospheric_pressure_Pa = 101325.0
    temperature_K = 296.15
    [command]                  # unit "V", "duty" or "binary"; range [lower, upper]
    unit = "binary"
    [chamber]                  # kind: see rigcard.KINDS (README "Your own rig")
    kind = "polynomial"
    dead_volume_m3 = {prior = "log-uniform", bounds = [1e-5, 3e-4]}
    coefficients_m3_per_m = [3.141e-3, -3.251e-2, 0.128]
    coordinate_range_m = [0.0, 0.04]
    [valve]                    # kind "gompertz", "switching" or "table"
    kind = "switching"
    open_area_m2 = {prior = "log-uniform", bounds = [1e-7, 1e-4]}
    exhaust_area_m2 = 0.0
    opening_delay_s = 0.0
    opening_time_constant_s = 1e-3
    [supply]                   # kind "measured", "constant" or "tank"
    kind = "measured"
    [ports]                    # optional: the valve's ISO 6358 rating
    kind = "iso6358"
    inlet_critical_ratio = 0.32
    exhaust_critical_ratio = {prior = "uniform", bounds = [0.2, 0.45]}
    [tube]                     # optional: the valve-chamber tube
    length_m = 1.88
    inner_diameter_m = 0.004
    [bounds]                   # optional: bounds of effects' parameters on this rig
    tube_delay_s = [0.0, 0.1]

Each component is a plug-in (:mod:`pneubayes.rigcard.component`, one file per kind).
A recording names its card with the sidecar key ``"rig"`` (a path relative to the
sidecar) or is given one (``--rig``); :meth:`RigCard.bind` then completes its metadata
from the card, maps its columns as the chamber kind reads them and checks its commands
against the declared range.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from pneubayes.errors import RigCardError
from pneubayes.rigcard.command import CommandSpec, read_command
from pneubayes.rigcard.component import KINDS, OPTIONAL_ROLES, ROLES, RigComponent, kinds_of
from pneubayes.rigcard.values import real

RIG_FORMAT = "pneubayes-rig/1"
_TOP_KEYS = ("format", "name", "atmospheric_pressure_Pa", "temperature_K", "command",
             "tube", "bounds", "notes") + ROLES + OPTIONAL_ROLES


@dataclass(frozen=True)
class Tube:
    """The tube between valve and chamber (its volume belongs to the dead volume)."""

    length_m: float
    inner_diameter_m: float

    @property
    def volume_m3(self) -> float:
        return math.pi / 4.0 * self.inner_diameter_m ** 2 * self.length_m


@dataclass(frozen=True, eq=False)
class RigCard:
    """A rig described by its components; see the module docstring for the card."""

    name: str
    atmospheric_pressure_Pa: float
    temperature_K: float
    command: CommandSpec
    chamber: RigComponent
    valve: RigComponent
    supply: RigComponent
    tube: Tube | None = None
    bounds: dict = field(default_factory=dict)
    notes: str = ""
    source: str = "rig card"
    exhaust: RigComponent | None = None
    ports: RigComponent | None = None

    @property
    def components(self) -> tuple[RigComponent, ...]:
        """The model's base components: valve, chamber, supply (and a separate exhaust
        valve, the ports' rating)."""
        extra = tuple(c for c in (self.exhaust, self.ports) if c is not None)
        return (self.valve, self.chamber, self.supply) + extra

    def covers(self, name: str) -> bool:
        """Whether a component of this card writes the slots of catalogue effect
        ``name`` (the ports' rating those of ``critical_ratio``): a model with the card
        refuses that effect."""
        return any(name in c.covers_effects for c in self.components)

    def effect_options(self, name: str) -> dict:
        """Options this rig gives a catalogue effect (the tube's bore for tube_delay)."""
        if name == "tube_delay" and self.tube is not None:
            return {"tube_diameter_m": self.tube.inner_diameter_m}
        return {}

    # ------------------------------------------------------------------ card
    def to_dict(self) -> dict:
        out = {"format": RIG_FORMAT, "name": self.name,
               "atmospheric_pressure_Pa": self.atmospheric_pressure_Pa,
               "temperature_K": self.temperature_K, "command": self.command.to_card(),
               "chamber": self.chamber.to_table(), "valve": self.valve.to_table(),
               "supply": self.supply.to_table()}
        if self.exhaust is not None:
            out["exhaust"] = self.exhaust.to_table()
        if self.ports is not None:
            out["ports"] = self.ports.to_table()
        if self.tube is not None:
            out["tube"] = {"length_m": self.tube.length_m,
                           "inner_diameter_m": self.tube.inner_diameter_m}
        if self.bounds:
            out["bounds"] = {k: list(v) for k, v in self.bounds.items()}
        if self.notes:
            out["notes"] = self.notes
        return out

    def known_at(self, params: Mapping[str, float], keep_unknown=()) -> "RigCard":
        """The card with its unknown quantities made known at ``params`` (by model
        parameter name), except those named in ``keep_unknown``, which stay priors: a
        fit's valve seeding another fit, or a shared fit whose lung is recalibrated per
        recording. Raises RigCardError naming a parameter ``params`` lacks."""
        from pneubayes.rigcard.values import Unknown

        keep = set(keep_unknown)
        d = self.to_dict()
        for role in ROLES + OPTIONAL_ROLES:
            comp = getattr(self, role)
            if comp is None:
                continue
            for key, value in comp.values.items():
                name = comp.parameter_name(key)
                if not isinstance(value, Unknown) or name in keep:
                    continue
                if name not in params:
                    raise RigCardError(f"{self.source}: known_at needs a value for the "
                                       f"fitted quantity {name!r} (key {role!r} -> {key!r})")
                d[role][key] = float(params[name])
        return RigCard.from_dict(d, f"{self.source} (known at given values)")

    def __eq__(self, other):
        return isinstance(other, RigCard) and self.to_dict() == other.to_dict()

    def __hash__(self):
        return hash(json.dumps(self.to_dict(), sort_keys=True))

    @classmethod
    def from_dict(cls, card: Mapping, source: str = "rig card") -> "RigCard":
        """Read and check a card dict; every error names ``source`` and the key."""
        from pneubayes.io.plausibility import rig_findings
        from pneubayes.model import check_bound_overrides

        if not isinstance(card, Mapping):
            raise RigCardError(f"{source}: expected a table (JSON object)")
        if card.get("format") != RIG_FORMAT:
            raise RigCardError(f"{source} key 'format': must be {RIG_FORMAT!r}, got "
                               f"{card.get('format')!r}")
        stray = sorted(set(card) - set(_TOP_KEYS))
        if stray:
            raise RigCardError(f"{source}: unknown key(s) {stray}; a rig card has "
                               f"{sorted(_TOP_KEYS)}")
        name = card.get("name")
        if not (isinstance(name, str) and name.strip()):
            raise RigCardError(f"{source} key 'name': must be a non-empty string, got "
                               f"{name!r}")
        atm = real(card.get("atmospheric_pressure_Pa"),
                   f"{source} key 'atmospheric_pressure_Pa'", positive=True)
        temp = real(card.get("temperature_K"), f"{source} key 'temperature_K'", positive=True)
        errors = [f for f in rig_findings({"atmospheric_pressure_Pa": atm,
                                           "temperature_K": temp}, source)
                  if f.severity == "error"]
        if errors:
            raise RigCardError(f"{errors[0].location}: {errors[0].message}")
        parts = {role: _component(card, role, source) for role in ROLES}
        exhaust = None
        if "exhaust" in card:  # a separate exhaust valve: the valve keeps no exhaust
            exhaust = _component(card, "exhaust", source)
            parts["valve"] = parts["valve"].without_exhaust(f"{source} key 'valve'")
        ports = _component(card, "ports", source) if "ports" in card else None
        every = {**parts, "exhaust": exhaust, "ports": ports}
        for role, comp in every.items():
            if comp is not None:
                comp.check_beside(every, f"{source} key {role!r}")
        tube = None
        if "tube" in card:
            t = card["tube"]
            at = f"{source} key 'tube'"
            if not isinstance(t, Mapping) or set(t) != {"length_m", "inner_diameter_m"}:
                raise RigCardError(f"{at}: must be a table with length_m and "
                                   f"inner_diameter_m (m), got {t!r}")
            tube = Tube(real(t["length_m"], f"{at} -> 'length_m'", positive=True),
                        real(t["inner_diameter_m"], f"{at} -> 'inner_diameter_m'",
                             positive=True))
        try:
            bounds = check_bound_overrides(card.get("bounds", {}), f"{source} key 'bounds'")
        except ValueError as exc:
            raise RigCardError(str(exc)) from None
        notes = card.get("notes", "")
        if not isinstance(notes, str):
            raise RigCardError(f"{source} key 'notes': must be a string")
        made = cls(name, atm, temp, read_command(card.get("command"), f"{source} key 'command'"),
                   parts["chamber"], parts["valve"], parts["supply"], tube, bounds, notes,
                   source, exhaust, ports)
        if bounds:
            from pneubayes.effects import catalogue_parameter_names

            own = sorted(p.name for c in made.components for p in c.parameters())
            unknown = sorted(set(bounds) - set(catalogue_parameter_names()) - set(own))
            if unknown:
                raise RigCardError(
                    f"{source} key 'bounds': {unknown} name no parameter of this rig card "
                    f"or of any effect; its are {own} and the effects' (e.g. tube_delay_s)")
        return made

    # ------------------------------------------------------------------ recordings
    def metadata_defaults(self) -> dict:
        """Recording metadata the card supplies where a sidecar leaves it out."""
        out = {"cylinder": f"{self.name} ({self.chamber.kind} chamber)",
               "valve": f"{self.valve.kind} valve",
               "atmospheric_pressure_Pa": self.atmospheric_pressure_Pa,
               "temperature_K": self.temperature_K}
        for c in self.components:
            out.update(c.metadata_defaults())
        return out

    def bind(self, recording):
        """The recording as this rig's model reads it: the command checked against the
        declared range, columns mapped by the chamber kind (its ``position_m`` becomes
        the equivalent piston position), and the card attached (``rig_card``)."""
        where = f"{self.source} (for {recording.source})"
        self.command.check(recording.command_V, str(recording.source))
        if recording.command_before_start is not None:
            self.command.check([recording.command_before_start],
                               f"{recording.source} key 'command_before_start'")
        columns = {}
        for c in self.components:
            columns.update(c.bind_columns(recording, where))
        return replace(recording, **columns, rig_card=self)


def _component(card: Mapping, role: str, source: str) -> RigComponent:
    at = f"{source} key {role!r}"
    table = card.get(role)
    if not isinstance(table, Mapping):
        raise RigCardError(f"{at}: missing or not a table; give its 'kind' "
                           f"(one of {kinds_of(role)})")
    kind = table.get("kind")
    cls = KINDS.get((role, kind))
    if cls is None:
        raise RigCardError(f"{at} -> 'kind': unknown {role} kind {kind!r}; known kinds are "
                           f"{kinds_of(role)}")
    return cls.from_table(table, at)


def load_rig_card(path) -> RigCard:
    """Read a rig card from a .json or .toml file; errors name the file and key."""
    from pneubayes.limits import input_file_problem

    path = Path(path)
    why = input_file_problem(path)
    if why is not None:
        raise RigCardError(f"{path}: {why}")
    try:
        text = path.read_text()
    except OSError as exc:
        raise RigCardError(f"{path}: cannot read the rig card ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise RigCardError(f"{path}: not a rig card (not UTF-8 text: {exc.reason} at byte "
                           f"{exc.start})") from None
    if path.suffix == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RigCardError(f"{path}: not valid TOML ({exc})") from None
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise RigCardError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") \
                from None
    return RigCard.from_dict(data, str(path))
