"""A model is the thin-port core plus any set of catalogue effects.

The model knows its parameters (names, units, bounds, priors), turns parameter values
into the slot matrix the compiled simulator reads (:meth:`Model.lower`), and reads and
writes the human-readable model card (``pneubayes-model/1``). An ablation is the same
model with an effect removed (:meth:`Model.without`); a discovered effect is one more
entry (:meth:`Model.with_effect`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import replace
from functools import cached_property
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.effects import CATALOGUE, Effect, Parameter, ThinPort, make_effect
from pneubayes.effects.path import N_SLOTS, SLOT_INDEX
from pneubayes.errors import FormCombinationError, ModelCardError, ParameterError
from pneubayes.rig import Rig

CARD_FORMAT = "pneubayes-model/1"


def check_bound_overrides(bounds, where: str) -> dict[str, tuple[float, float]]:
    """``{name: (lower, upper)}`` from a mapping of names to two finite numbers with
    lower < upper; raises ValueError naming ``where`` and the parameter otherwise."""
    if not isinstance(bounds, Mapping):
        raise ValueError(f"{where}: must be an object name -> [lower, upper], got {bounds!r}")
    out = {}
    for name, pair in bounds.items():
        ok = (isinstance(name, str) and isinstance(pair, (list, tuple)) and len(pair) == 2
              and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                      and math.isfinite(v) for v in pair) and pair[0] < pair[1])
        if not ok:
            raise ValueError(f"{where}: {name!r} must be [lower, upper], two finite numbers "
                             f"with lower < upper, got {pair!r}")
        out[name] = (float(pair[0]), float(pair[1]))
    return out


class Model:
    """The thin-port model (eqs. 1-5, 11) composed with effects.

    Parameters
    ----------
    effects : iterable of Effect or str
        Catalogue effects (objects, or names for default options). Each name at most once.
    bounds : mapping of str to (lower, upper), optional
        Bounds that replace a parameter's default ones (a rig unlike the paper's: a 1-L
        test lung's dead volume, a large valve's port area), in the parameter's unit; the
        default prior keeps its kind on the new bounds. Every name must be a parameter of
        the model. Recorded in the model card.
    rig_card : RigCard, optional
        A lab's own rig (:mod:`pneubayes.rigcard`): its valve, chamber and supply replace
        the thin-port core as the model's base, its ``bounds`` apply to effects' parameters
        (``bounds`` given here override them) and it gives effects its options (the
        tube's bore). Recorded in the model card. None: the paper's thin-port core.
    """

    def __init__(self, effects: Iterable[Effect | str] = (),
                 bounds: Mapping[str, tuple[float, float]] | None = None,
                 rig_card=None):
        self.rig_card = rig_card
        built = []
        for e in effects:
            built.append(make_effect(e, **self.effect_options(e)) if isinstance(e, str)
                         else e)
        names = [e.name for e in built]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"Model: effect(s) listed twice: {dupes}")
        for e in built:
            if not isinstance(e, Effect):
                raise TypeError(f"Model: {e!r} is not an Effect")
            if rig_card is not None and rig_card.covers(e.name):
                raise FormCombinationError(
                    f"Model: the rig card {rig_card.name!r} states what effect {e.name!r} "
                    "would fit (the ports' rating writes the same slots); give the card's "
                    "quantities as priors instead")
        # Canonical order: catalogue order, so equal models have equal parameter order
        # (an effect of the user's not registered in the catalogue after it, by name)
        order = list(CATALOGUE)
        self.effects: tuple[Effect, ...] = tuple(sorted(
            built, key=lambda e: (order.index(e.name) if e.name in order else len(order),
                                  e.name)))
        self.base: tuple = (ThinPort(),) if rig_card is None else rig_card.components
        card_bounds = {} if rig_card is None else {
            k: v for k, v in rig_card.bounds.items()
            if k in {p.name for c in self.base + self.effects for p in c.parameters()}}
        self.bound_overrides: dict[str, tuple[float, float]] = check_bound_overrides(
            {**card_bounds, **(bounds or {})}, "Model bounds")

    # ------------------------------------------------------------------ structure
    @property
    def components(self):
        return self.base + self.effects

    def effect_options(self, name: str) -> dict:
        """Options the rig card gives the named catalogue effect (``{}`` without one)."""
        return {} if self.rig_card is None else self.rig_card.effect_options(name)

    def base_start_values(self) -> dict[str, float] | None:
        """Start values of the rig card's fitted quantities (None for the thin-port
        core, whose start comes from the paper's least squares or the Table II maps)."""
        if self.rig_card is None:
            return None
        out = {}
        for c in self.base:
            out.update(c.start_values())
        return out

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @cached_property
    def parameters(self) -> tuple[Parameter, ...]:
        ps = tuple(p for c in self.components for p in c.parameters())
        unknown = sorted(set(self.bound_overrides) - {p.name for p in ps})
        if unknown:
            raise ParameterError(f"bounds for {unknown}, which the model does not have; its "
                                 f"parameters are {[p.name for p in ps]}")
        try:
            return tuple(replace(p, lower=self.bound_overrides[p.name][0],
                                 upper=self.bound_overrides[p.name][1])
                         if p.name in self.bound_overrides else p for p in ps)
        except ValueError as exc:  # e.g. a log-uniform prior's lower bound <= 0
            raise ParameterError(f"bounds: {exc}") from None

    @cached_property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @cached_property
    def _component_indices(self) -> tuple[tuple[tuple[str, int], ...], ...]:
        """Per component, its parameters' (name, column) pairs (a cache for :meth:`lower`)."""
        index = {n: j for j, n in enumerate(self.parameter_names)}
        return tuple(tuple((n, index[n]) for n in c.parameter_names())
                     for c in self.components)

    @cached_property
    def _checked_lowering(self) -> dict[int, tuple[str, ...]]:
        """Per component, the slots its lowering last wrote, checked against the slots it
        declares (:meth:`Component.check_lowering`): checked again when they change."""
        return {}

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise ParameterError(f"model has no parameter {name!r}; it has {self.parameter_names}")

    @cached_property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds, arrays in parameter order (read-only)."""
        ps = self.parameters
        lo, hi = np.array([p.lower for p in ps]), np.array([p.upper for p in ps])
        lo.flags.writeable = False
        hi.flags.writeable = False
        return lo, hi

    @cached_property
    def _bounds_finite(self) -> bool:
        lo, hi = self.bounds
        return bool(np.isfinite(lo).all() and np.isfinite(hi).all())

    def has(self, name: str) -> bool:
        return name in self.effect_names

    def covers(self, name: str) -> bool:
        """Whether the model has effect ``name`` or its rig card states what the effect
        would fit (:meth:`RigCard.covers`): the discovery loop proposes neither."""
        return self.has(name) or (self.rig_card is not None and self.rig_card.covers(name))

    def effect(self, name: str) -> Effect:
        for e in self.effects:
            if e.name == name:
                return e
        raise KeyError(f"model has no effect {name!r}; it has {self.effect_names}")

    def with_effect(self, effect: Effect | str) -> "Model":
        """A new model with one more effect (the bound overrides kept)."""
        return Model(self.effects + ((make_effect(effect, **self.effect_options(effect))
                                      if isinstance(effect, str) else effect),),
                     self.bound_overrides, self.rig_card)

    def without(self, name: str) -> "Model":
        """A new model with the named effect removed (an ablation); overrides of the
        removed effect's parameters go with it."""
        gone = set(self.effect(name).parameter_names())
        return Model((e for e in self.effects if e.name != name),
                     {k: v for k, v in self.bound_overrides.items() if k not in gone},
                     self.rig_card)

    def with_bounds(self, bounds: Mapping[str, tuple[float, float]]) -> "Model":
        """The same model with those of ``bounds`` that name its parameters overriding
        (others, for effects it does not have, are ignored: the discovery loop applies one
        set of overrides to every model it builds)."""
        names = {p.name for c in self.components for p in c.parameters()}
        return Model(self.effects, {**self.bound_overrides,
                                    **{k: v for k, v in bounds.items() if k in names}},
                     self.rig_card)

    def __repr__(self):
        extra = f", bounds={self.bound_overrides!r}" if self.bound_overrides else ""
        if self.rig_card is not None:
            extra += f", rig_card={self.rig_card.name!r}"
        return f"Model(effects={list(self.effects)!r}{extra})"

    def __eq__(self, other):
        return (isinstance(other, Model) and self.effects == other.effects
                and self.bound_overrides == other.bound_overrides
                and self.rig_card == other.rig_card)

    def __hash__(self):
        return hash((self.effects, tuple(sorted(self.bound_overrides.items())),
                     self.rig_card))

    # ------------------------------------------------------------------ values
    def vector(self, values: Mapping[str, float]) -> np.ndarray:
        """Parameter dict -> vector in :attr:`parameter_names` order (all names required)."""
        missing = [n for n in self.parameter_names if n not in values]
        unknown = [n for n in values if n not in self.parameter_names]
        if missing or unknown:
            msg = []
            if missing:
                msg.append(f"missing {missing}")
            if unknown:
                msg.append(f"unknown {unknown} (model effects: {list(self.effect_names)})")
            raise ParameterError("parameters: " + "; ".join(msg))
        return np.array([float(values[n]) for n in self.parameter_names])

    def as_dict(self, vector) -> dict[str, float]:
        """Parameter vector -> dict."""
        v = np.asarray(vector, dtype=np.float64)
        if v.shape != (self.n_parameters,):
            raise ParameterError(f"parameter vector has shape {v.shape}, "
                                 f"expected ({self.n_parameters},)")
        return {n: float(x) for n, x in zip(self.parameter_names, v)}

    def as_matrix(self, params) -> np.ndarray:
        """Accept a dict, a vector ``(P,)`` or a batch ``(B, P)``; return ``(B, P)`` float64."""
        if isinstance(params, Mapping):
            return self.vector(params)[None, :]
        m = np.asarray(params, dtype=np.float64)
        if m.ndim == 1:
            m = m[None, :]
        if m.ndim != 2 or m.shape[1] != self.n_parameters:
            raise ParameterError(f"parameters have shape {np.shape(params)}; expected "
                                 f"(B, {self.n_parameters}) for {self.parameter_names}")
        return m

    def out_of_bounds(self, params) -> list[str]:
        """Names of the parameters outside their bounds (or not finite), for any row."""
        m = self.as_matrix(params)
        lo, hi = self.bounds
        bad = ~np.isfinite(m) | (m < lo) | (m > hi)
        return [n for n, b in zip(self.parameter_names, bad.any(axis=0)) if b]

    def check_bounds(self, params) -> None:
        """Raise :class:`ParameterError` naming every parameter outside its bounds (or
        not finite) in any row."""
        m = self.as_matrix(params)
        lo, hi = self.bounds
        # the common case in one pass (a comparison with NaN is False; an infinite value
        # passes only an infinite bound, hence the second test)
        if ((m >= lo) & (m <= hi)).all() and (self._bounds_finite or np.isfinite(m).all()):
            return
        bad = self.out_of_bounds(m)
        if bad:
            details = []
            for n in bad:
                j = self.parameter_names.index(n)
                p = self.parameters[j]
                details.append(f"{n}={m[:, j].tolist() if m.shape[0] < 5 else '...'} "
                               f"(bounds [{p.lower:g}, {p.upper:g}] {p.unit})")
            raise ParameterError("parameters outside their bounds: " + "; ".join(details))

    def log_prior(self, params) -> np.ndarray:
        """Sum of the default priors, shape ``(B,)``; -inf outside the bounds."""
        m = self.as_matrix(params)
        return sum(p.log_prior(m[:, j]) for j, p in enumerate(self.parameters))

    def neutral_values(self) -> dict[str, float]:
        """Effect parameters at zero strength."""
        out = {}
        for e in self.effects:
            out.update(e.neutral_values())
        return out

    # ------------------------------------------------------------------ lowering
    def lower(self, params, rig: Rig) -> np.ndarray:
        """Parameter batch -> slot matrix ``(B, N_SLOTS)`` for the compiled simulator."""
        columns = self.as_matrix(params).T  # (P, B): a parameter's values are a row
        # built slot by slot as rows of the transpose: a row written once is assigned,
        # one several components write is summed (a numpy in-place add costs five
        # assignments; this runs on every simulation call)
        slots_t = np.zeros((N_SLOTS, columns.shape[1]))
        written = set()
        for i, (comp, names) in enumerate(zip(self.components, self._component_indices)):
            contrib = comp.lower({n: columns[j] for n, j in names}, rig)
            keys = tuple(contrib)
            if self._checked_lowering.get(i) != keys:
                comp.check_lowering(contrib)
                self._checked_lowering[i] = keys
            for slot, v in contrib.items():
                k = SLOT_INDEX[slot]
                if k in written:
                    slots_t[k] += v
                else:
                    slots_t[k] = v  # (B,) or scalar, broadcast
                    written.add(k)
        return np.ascontiguousarray(slots_t.T)

    @property
    def relaxes_reading(self) -> bool:
        """Whether an effect reads the pressure through a map after the kernel
        (:meth:`reading_relaxations`, :meth:`reading_plays`, :meth:`reading_commands`,
        :meth:`reading_flows`, :meth:`reading_hinges`)."""
        return any(e.relaxes_reading for e in self.effects)

    def reading_relaxations(self, params) -> tuple[np.ndarray, np.ndarray]:
        """``(gains (-), time constants (s))``, each ``(B, K)``: the relaxations of the
        reading of every effect that relaxes it, side by side (``K`` 0 without one)."""
        return self._reading_maps(params, "reading_relaxations")

    def reading_plays(self, params) -> tuple[np.ndarray, np.ndarray]:
        """``(gains (-), half-widths (Pa))``, each ``(B, J)``: the plays of the reading
        (:mod:`pneubayes.simulation.reading_play`) of every effect that has them, side
        by side (``J`` 0 without one)."""
        return self._reading_maps(params, "reading_plays")

    def reading_commands(self, params) -> tuple[np.ndarray, np.ndarray]:
        """``(gains (Pa per command unit), time constants (s))``, each ``(B, K)``: the
        lags of the command's magnitude in the reading
        (:mod:`pneubayes.simulation.reading_command`) of every effect that has them,
        side by side (``K`` 0 without one)."""
        return self._reading_maps(params, "reading_commands")

    def reading_hinges(self, params) -> tuple[np.ndarray, np.ndarray]:
        """``(gains (-), thresholds (Pa absolute))``, each ``(B, J)``: the hinges through
        which the reading is read last (:mod:`pneubayes.simulation.reading_hinge`) of
        every effect that has them, side by side (``J`` 0 without one)."""
        return self._reading_maps(params, "reading_hinges")

    def reading_flows(self, params) -> tuple[np.ndarray, tuple[str, ...]]:
        """``(gains (B, K) in Pa per feature unit, the K feature names)``: the terms of the
        ports' mass flows in the reading (:mod:`pneubayes.simulation.reading_flow`) of
        every effect that has them, side by side (``K`` 0 without one)."""
        theta, parts = self._reading_parts(params, "reading_flows")
        if not parts:
            return np.zeros((theta.shape[0], 0)), ()
        return (np.concatenate([g for g, _ in parts], axis=1),
                tuple(f for _, feats in parts for f in feats))

    def _reading_parts(self, params, method: str) -> tuple[np.ndarray, list]:
        """``(theta, what each reading effect's method returns)`` (an effect that returns
        None has none of that kind and is left out)."""
        theta = self.as_matrix(params)
        names = self.parameter_names
        parts = [getattr(e, method)({n: theta[:, names.index(n)] for n in e.parameter_names()})
                 for e in self.effects if e.relaxes_reading]
        return theta, [x for x in parts if x is not None]

    def _reading_maps(self, params, method: str) -> tuple[np.ndarray, np.ndarray]:
        """Every reading effect's ``method`` pairs side by side."""
        theta, parts = self._reading_parts(params, method)
        if not parts:
            return np.zeros((theta.shape[0], 0)), np.ones((theta.shape[0], 0))
        return (np.concatenate([a for a, _ in parts], axis=1),
                np.concatenate([b for _, b in parts], axis=1))

    # ------------------------------------------------------------------ model card
    def to_card(self, values: Mapping[str, float], extra: Mapping | None = None) -> dict:
        """The model card dict for these parameter values."""
        vec = self.vector(values)
        card = {"format": CARD_FORMAT, "effects": list(self.effect_names),
                "parameters": {n: float(v) for n, v in zip(self.parameter_names, vec)}}
        opts = {e.name: e.options() for e in self.effects if e.options()}
        if opts:
            card["effect_options"] = opts
        if self.bound_overrides:
            card["bounds"] = {k: list(v) for k, v in self.bound_overrides.items()}
        if self.rig_card is not None:
            card["rig"] = self.rig_card.to_dict()
        if extra:
            card.update(dict(extra))
        return card

    @classmethod
    def from_card(cls, card: Mapping, source: str = "model card") -> tuple["Model", dict]:
        """Build ``(model, parameter dict)`` from a card dict; errors name ``source``."""
        if not isinstance(card, Mapping):
            raise ModelCardError(f"{source}: expected a JSON object")
        if card.get("format") != CARD_FORMAT:
            raise ModelCardError(f"{source}: key 'format' must be {CARD_FORMAT!r}, "
                                 f"got {card.get('format')!r}")
        names = card.get("effects", [])
        params = card.get("parameters")
        options = card.get("effect_options", {})
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ModelCardError(f"{source}: key 'effects' must be a list of effect names")
        if not isinstance(params, Mapping):
            raise ModelCardError(f"{source}: key 'parameters' must be an object name -> value")
        if not isinstance(options, Mapping):
            raise ModelCardError(f"{source}: key 'effect_options' must be an object")
        stray = sorted(set(options) - set(names))
        if stray:
            raise ModelCardError(f"{source}: key 'effect_options' names effect(s) {stray} "
                                 f"that are not in 'effects' {names}")
        # (a card written before one of its effects' parameters existed)
        for n in names:
            if n in CATALOGUE:
                params = {**CATALOGUE[n].card_defaults(params), **params}
        rig_card = None
        if "rig" in card:
            from pneubayes.errors import RigCardError
            from pneubayes.rigcard import RigCard

            try:
                rig_card = RigCard.from_dict(card["rig"], f"{source} key 'rig'")
            except RigCardError as exc:
                raise ModelCardError(str(exc)) from None
        effects = []
        for n in names:
            opt = options.get(n, {})
            if not isinstance(opt, Mapping) or not all(isinstance(k, str) for k in opt):
                raise ModelCardError(f"{source}: key 'effect_options' -> {n!r} must be an "
                                     f"object option -> value, got {opt!r}")
            opt = {**({} if rig_card is None else rig_card.effect_options(n)), **opt}
            # an effect's form, when not given, follows from its parameter names
            if n in CATALOGUE and CATALOGUE[n].forms and "form" not in opt:
                opt["form"] = CATALOGUE[n].form_from_parameters(params)
            try:
                effects.append(make_effect(n, **opt))
            except ValueError as exc:
                raise ModelCardError(f"{source}: key 'effects': {exc}") from None
        try:
            bounds = check_bound_overrides(card.get("bounds", {}), "key 'bounds'")
            model = cls(effects, bounds, rig_card)
            for k, v in params.items():
                if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                    raise ParameterError(f"parameter {k!r} must be a finite number, got {v!r}")
            vec = model.vector(params)
            model.check_bounds(vec)
        except (ParameterError, ValueError) as exc:
            raise ModelCardError(f"{source}: {exc}") from None
        return model, model.as_dict(vec)

    def save_card(self, values: Mapping[str, float], path, extra: Mapping | None = None) -> None:
        """Write the card atomically (temp file + rename)."""
        write_json_atomic(path, self.to_card(values, extra))

    @staticmethod
    def read_card(path) -> dict:
        """A model card file's JSON (errors name the file), not yet checked."""
        from pneubayes.limits import input_file_problem

        path = Path(path)
        why = input_file_problem(path)
        if why is not None:
            raise ModelCardError(f"{path}: {why}")
        try:
            text = path.read_text()
        except OSError as exc:
            raise ModelCardError(f"{path}: cannot read ({exc.strerror})") from None
        except UnicodeDecodeError:
            raise ModelCardError(f"{path}: not a model card (not UTF-8 text)") from None
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelCardError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") \
                from None

    @classmethod
    def load_card(cls, path) -> tuple["Model", dict]:
        return cls.from_card(cls.read_card(path), source=str(path))
