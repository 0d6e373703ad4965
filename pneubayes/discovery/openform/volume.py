"""The open-form search on the chamber's volume: hinges of the volume in the pressure in
the prediction windows' residual.

A volume closure (:class:`~pneubayes.effects.volume_closure.VolumeClosure`) adds ``C
max(0, p - theta)`` to the chamber's volume. A hinge that matters changes the chamber's
capacity by a sizeable share (an accumulator can hold several times the dead volume),
so its effect on a window is far from linear in ``C``: the search simulates instead of
linearising. And a model fitted without the hinge has taken a dead volume between the
chamber's volumes below and above it, which the hinge's own volume must replace: the
grid scales the dead volume too. :class:`VolumeSearch` scores a grid of thresholds,
compliances and dead-volume scales in one batch of window simulations
(:class:`VolumeProblem`), keeps the set with the least sum of squares, and then, beside
it, the best second hinge (which may take growth away: a volume that saturates). A
hinge is kept when it removes at least ``min_explained_fraction`` of the residual's sum
of squares and the windows' reductions are ``min_t`` standard errors above zero (a
window's residual is one correlated trace: the windows are the independent units).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import astuple, dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np

from pneubayes.effects.path import SLOT_INDEX
from pneubayes.effects.volume_closure import (
    COMPLIANCE_BOUNDS_M3_PER_PA,
    THRESHOLD_BOUNDS_PA,
    VOLUME_MAX_TERMS,
    VolumeClosure,
    compliance_name,
    threshold_name,
)


@dataclass(frozen=True)
class VolumeTerm:
    """A kept hinge: ``compliance_m3_per_Pa``, ``threshold_Pa``, the share of the
    residual's sum of squares it removes beside the hinges kept before it
    (``explained``), the windows' mean reduction over its standard error (``t``) and the
    dead volume's scale it was found with (``dead_volume_scale``)."""

    compliance_m3_per_Pa: float
    threshold_Pa: float
    explained: float
    t: float
    dead_volume_scale: float = 1.0

    def __str__(self) -> str:
        scaled = ("" if self.dead_volume_scale == 1.0 else
                  f", the dead volume x {self.dead_volume_scale:g}")
        return (f"{self.compliance_m3_per_Pa * 1e11:.4g} cm^3/bar above "
                f"{self.threshold_Pa / 1e5:.4g} bar{scaled}")


def threshold_grid(window_set, count: int = 16) -> np.ndarray:
    """``count`` thresholds (Pa absolute) over the windows' measured pressures: one below
    them all (a compliance at every pressure) and the rest evenly spaced between the
    pressures' 2 % and 98 % quantiles (a recording that dwells at the supply and the
    atmosphere still has its thresholds spread over the range it crosses)."""
    p = np.asarray(window_set.measured, dtype=np.float64)
    p = p[np.isfinite(p)]
    lo, hi = THRESHOLD_BOUNDS_PA
    q_lo, q_hi = np.quantile(p, [0.02, 0.98])
    below = max(lo, float(p.min()) - 1e4)
    return np.unique(np.clip(np.concatenate([[below], np.linspace(q_lo, q_hi, count - 1)]),
                             lo, hi))


@dataclass(frozen=True)
class VolumeProblem:
    """What the search simulates: the training windows, the current model and its
    parameters, and the solver. The component a term joins as, and a term's parameter
    names, are class attributes (a subclass searches another volume component)."""

    window_set: object
    model: object
    params: dict
    solver: object

    #: The component the terms join as, and term k's (strength, shape) parameter names
    #: (a subclass's term may have more).
    component: ClassVar[type] = VolumeClosure
    term_names: ClassVar[tuple] = (compliance_name, threshold_name)
    #: An unused term's values under ``term_names``.
    unused_term: ClassVar[tuple[float, float]] = (0.0, THRESHOLD_BOUNDS_PA[0])

    @cached_property
    def _slots(self) -> np.ndarray:
        """The current model's lowered slots at its parameters."""
        return self.model.lower(self.model.vector(self.params)[None], self.rig)[0]

    def check(self) -> None:
        """Raise ValueError where a volume component cannot join the model."""
        for name, what in (("volume_closure", "a volume closure"),
                           ("volume_play", "a volume play")):
            if self.model.has(name):
                raise ValueError(f"the model already has {what}")
        base = self._slots
        if base[SLOT_INDEX["volume_table_points"]] > 0 \
                or base[SLOT_INDEX["compliance_m3_per_Pa"]] > 0:
            raise ValueError("the model's chamber is already compliant (its rig card's); a "
                             "volume component would replace its table")

    @property
    def rig(self):
        return self.window_set.blocks[0].rig

    def volume_scale_m3_per_Pa(self) -> float:
        """The chamber's volume per the supply's pressure over the heat capacity ratio
        (m^3/Pa): a compliance of this size doubles the chamber's capacity at the
        supply."""
        rig = self.rig
        return float(self._slots[SLOT_INDEX["volume_m3"]]
                     / (rig.gas.heat_capacity_ratio * rig.supply_pressure_Pa))

    @property
    def scales_dead_volume(self) -> bool:
        """Whether the model fits the dead volume (``dead_volume_m3``), which the grid
        may then scale."""
        return "dead_volume_m3" in self.model.parameter_names

    def window_sse(self, hinges: Sequence[Sequence[tuple[float, float]]],
                   scales: Sequence[float] | None = None) -> np.ndarray:
        """Each window's sum of squared residuals ``(S, W)`` (Pa^2; inf where a
        simulation failed) for ``S`` sets of terms, each a sequence of ``(strength,
        shape)`` (a hinge's compliance and threshold; a subclass's values under its
        ``term_names``; an empty one: the current model),
        each with the dead volume times its entry of ``scales`` (None: all 1)."""
        resid = self.window_residuals(hinges, scales)
        sse = np.sum(resid**2, axis=2)
        return np.where(np.isfinite(sse), sse, np.inf)

    def window_residuals(self, hinges: Sequence[Sequence[tuple[float, float]]],
                         scales: Sequence[float] | None = None) -> np.ndarray:
        """Each window's residual ``(S, W, L)`` (Pa; NaN where a simulation failed) for
        the sets of terms and scales :meth:`window_sse` takes."""
        k = max(1, max(len(h) for h in hinges))
        trial = self.model.with_effect(self.component(terms=k))
        rows = []
        for i, h in enumerate(hinges):
            values = dict(self.params)
            if scales is not None and scales[i] != 1.0:
                values["dead_volume_m3"] = values["dead_volume_m3"] * scales[i]
            for j in range(k):
                for name, v in zip(self.term_names, h[j] if j < len(h) else self.unused_term):
                    values[name(j)] = v
            rows.append(trial.vector(values))
        return self.window_set.residuals(trial, np.stack(rows), self.solver, on_failure="nan")


class VolumeSearch:
    """Grid search of volume hinges in the windows' residual (scikit-learn contract:
    settings in the constructor, :meth:`fit` sets the ``_`` attributes).

    Parameters
    ----------
    thresholds : int
        How many thresholds are tried (:func:`threshold_grid`).
    compliance_shares : sequence of float
        The compliances tried, as multiples of the chamber's volume per the supply's
        pressure (:meth:`VolumeProblem.volume_scale_m3_per_Pa`).
    dead_volume_scales : sequence of float
        The dead volume's scales tried with the first hinge (where the model fits it).
    max_terms : int
        Most hinges kept (1..2, the volume closure's room).
    min_explained_fraction : float
        A kept hinge's least share of the residual's sum of squares.
    min_t : float
        A kept hinge's least mean window reduction over its standard error.

    Attributes
    ----------
    terms_ : list of VolumeTerm
        Kept hinges, in the order found.
    explained_fraction_ : float
        Share of the residual's sum of squares the kept hinges remove together.
    best_ : VolumeTerm or None
        The best first hinge, kept or not (what the search saw).
    """

    def __init__(self, thresholds: int = 16,
                 compliance_shares: Sequence[float] = tuple(np.geomspace(0.03, 30.0, 13)),
                 dead_volume_scales: Sequence[float] = (0.35, 0.5, 0.7, 1.0),
                 max_terms: int = VOLUME_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0):
        self.thresholds = thresholds
        self.compliance_shares = compliance_shares
        self.dead_volume_scales = dead_volume_scales
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"thresholds": self.thresholds, "compliance_shares": self.compliance_shares,
                "dead_volume_scales": self.dead_volume_scales, "max_terms": self.max_terms,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t}

    def _validate(self, problem):
        if isinstance(self.thresholds, bool) or not isinstance(self.thresholds, int) \
                or self.thresholds < 2:
            raise ValueError(f"thresholds must be an integer >= 2, got {self.thresholds!r}")
        shares = np.asarray(self.compliance_shares, dtype=np.float64)
        if shares.ndim != 1 or not shares.size or not np.all(shares > 0):
            raise ValueError(f"compliance_shares must be positive numbers, got "
                             f"{self.compliance_shares!r}")
        scales = np.asarray(self.dead_volume_scales, dtype=np.float64)
        if scales.ndim != 1 or not scales.size or not np.all(scales > 0):
            raise ValueError(f"dead_volume_scales must be positive numbers, got "
                             f"{self.dead_volume_scales!r}")
        if not (isinstance(self.max_terms, int) and 1 <= self.max_terms <= VOLUME_MAX_TERMS):
            raise ValueError(f"max_terms must be an integer in 1..{VOLUME_MAX_TERMS}, got "
                             f"{self.max_terms!r}")
        if not 0.0 < self.min_explained_fraction < 1.0 or not self.min_t > 0.0:
            raise ValueError("min_explained_fraction must be in (0, 1) and min_t > 0, got "
                             f"{self.min_explained_fraction!r}, {self.min_t!r}")
        if not isinstance(problem, VolumeProblem) or problem.component is not VolumeClosure:
            raise ValueError("fit takes a VolumeProblem (of hinges: a VolumeClosure's)")
        problem.check()
        return shares

    def fit(self, problem: VolumeProblem) -> "VolumeSearch":
        """Search the training windows of ``problem``."""
        shares = self._validate(problem)
        comps = np.clip(shares * problem.volume_scale_m3_per_Pa(), 0.0,
                        COMPLIANCE_BOUNDS_M3_PER_PA[1])
        ths = threshold_grid(problem.window_set, self.thresholds)
        scales = (tuple(float(v) for v in self.dead_volume_scales)
                  if problem.scales_dead_volume else (1.0,))
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        kept: list[tuple[float, float]] = []
        scale = 1.0
        current = problem.window_sse([()])[0]
        total = float(np.sum(current))
        if not np.isfinite(total) or total <= 0.0:
            return self
        for _ in range(self.max_terms):
            # the first hinge with each dead-volume scale; a second beside it at its scale
            # (a second hinge may also take the first's growth away, up to all of it:
            # a saturating volume)
            grid = ([(float(c), float(th), v) for v in scales for th in ths for c in comps]
                    if not kept else
                    [(float(c), float(th), scale) for th in ths for c in comps]
                    + [(-float(c), float(th), scale) for th in ths if th > kept[0][1]
                       for c in comps if c <= kept[0][0]])
            sse = problem.window_sse([kept + [(c, th)] for c, th, _ in grid],
                                     [v for *_, v in grid])
            j = int(np.argmin(np.sum(sse, axis=1)))
            if not np.isfinite(sse[j]).all():
                break
            explained, t = window_reduction(current, sse[j], total)
            term = VolumeTerm(grid[j][0], grid[j][1], explained, t, grid[j][2])
            if self.best_ is None:
                self.best_ = term
            if explained < self.min_explained_fraction or t < self.min_t:
                break
            kept.append(grid[j][:2])
            scale = grid[j][2]
            self.terms_.append(term)
            current = sse[j]
        if kept:
            self.explained_fraction_ = 1.0 - float(np.sum(current)) / total
        return self


def window_reduction(current: np.ndarray, trial: np.ndarray, total: float,
                     relative: bool = False) -> tuple[float, float]:
    """``(explained, t)``: the share of ``total`` (the current model's sum of squares,
    Pa^2) that a trial's windows' sums of squares ``trial`` remove below ``current``
    (each ``(W,)``), and their mean reduction over its standard error (a window's
    residual is one correlated trace: the windows are the independent units); with
    ``relative``, of each window's reduction as a share of its own sum of squares (a
    term that removes a like share everywhere is not judged by the spread of the
    windows' sizes)."""
    d = current - trial
    explained = float(np.sum(d)) / total
    if relative:
        d = d / np.maximum(current, np.finfo(float).tiny)
    se = float(np.std(d, ddof=1)) / np.sqrt(d.size) if d.size > 1 else 0.0
    return explained, float(np.mean(d)) / se if se > 0 else np.inf


def searched_values(terms: Sequence, params: dict,
                    term_names: tuple = (compliance_name, threshold_name)) -> dict[str, float]:
    """The parameter values the kept ``terms`` (each a dataclass whose first fields are
    its values under ``term_names``: its strength and shape) stand for beside the current
    ``params``: the component's, under ``term_names`` (a :class:`VolumeProblem`'s; default
    the volume closure's), and the dead volume scaled as the first was found."""
    out = {}
    for k, t in enumerate(terms):
        for name, v in zip(term_names, astuple(t)[:len(term_names)]):
            out[name(k)] = v
    if terms and "dead_volume_m3" in params:
        out["dead_volume_m3"] = params["dead_volume_m3"] * terms[0].dead_volume_scale
    return out


__all__ = ["VolumeProblem", "VolumeSearch", "VolumeTerm", "searched_values",
           "threshold_grid", "window_reduction"]
