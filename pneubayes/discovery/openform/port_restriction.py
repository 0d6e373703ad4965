"""The open-form search at the chamber's port: a restriction in series with the valve
(a fitting, a flow-control needle, a one-way flow control) in the prediction windows'
residual.

A restriction (:class:`~pneubayes.effects.port_restriction.PortRestriction`) slows the
fill where it is narrower than the valve's inlet and the vent where it is narrower than
its exhaust, each direction with its own area. No term of the closure's library
expresses two orifices in series: a capped area (``inlet_area_hinge``) is its hard-edged
limit, and the node's pressure between them, which the valve's ports see, none.

The search simulates the training windows (:class:`PortRestrictionProblem`, the volume
forms' :class:`~pneubayes.discovery.openform.volume.VolumeProblem` with another
component): each direction alone over areas from a tenth to six times the valve's
largest port and over the dead volume's scales, then the best few of each together, and
a compass refinement of the best; it is kept by the gate the volume's forms use
(:func:`~pneubayes.discovery.openform.gate.earns_trial`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pneubayes.discovery.openform.gate import check_gate, earns_trial
from pneubayes.discovery.openform.volume import VolumeProblem, window_reduction
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.effects.port_restriction import (
    FILL,
    INVERSE_AREA_BOUNDS_PER_M2,
    VENT,
    PortRestriction,
)
from pneubayes.simulation.rates import port_areas


@dataclass(frozen=True)
class RestrictionTerm:
    """A kept restriction: its inverse areas ``fill_per_m2`` and ``vent_per_m2`` (1/m^2,
    0 none), the share of the residual's sum of squares it removes (``explained``), the
    windows' mean relative reduction over its standard error (``t``) and the dead
    volume's scale it was found with (``dead_volume_scale``)."""

    fill_per_m2: float
    vent_per_m2: float
    explained: float
    t: float
    dead_volume_scale: float = 1.0

    def __str__(self) -> str:
        def side(k):
            return "open" if k <= 0.0 else f"{1e6 / k:.3g} mm^2"

        scaled = ("" if self.dead_volume_scale == 1.0 else
                  f", the dead volume x {self.dead_volume_scale:.3g}")
        return (f"a restriction at the port (fill through {side(self.fill_per_m2)}, vent "
                f"through {side(self.vent_per_m2)}{scaled})")


@dataclass(frozen=True)
class PortRestrictionProblem(VolumeProblem):
    """What the search simulates (as :class:`VolumeProblem`), a term joining as a port
    restriction: ``(fill inverse area, vent inverse area)``."""

    component: ClassVar[type] = PortRestriction
    term_names: ClassVar[tuple] = (lambda k: FILL, lambda k: VENT)
    unused_term: ClassVar[tuple[float, float]] = (0.0, 0.0)

    def check(self) -> None:
        """Raise ValueError where a port restriction cannot join the model."""
        if self.model.has("port_restriction"):
            raise ValueError("the model already has a port restriction")
        base = self._slots
        for slot, what in (("line_length_m", "the tube's acoustic line"),
                           ("wave_length_m", "the tube's transmission line"),
                           ("tank_volume_m3", "a supply tank"),
                           ("lung_volume_m3", "a second compartment")):
            if base[SLOT_INDEX[slot]] > 0:
                raise ValueError(f"a port restriction cannot sit beside {what}")

    def largest_port_area_m2(self) -> float:
        """The valve's largest port area (inlet or exhaust) over the windows' commands
        (m^2)."""
        best = 0.0
        for block in self.window_set.blocks:
            u = np.asarray(block.inputs.command_V, dtype=np.float64)
            ue = block.inputs.exhaust_command
            a_in, a_ex = port_areas(self._slots, u, None if ue is None else np.asarray(ue))
            best = max(best, float(np.max(a_in)), float(np.max(a_ex)))
        return best


class PortRestrictionSearch:
    """Grid search of a restriction at the chamber's port in the windows' residual
    (scikit-learn contract: settings in the constructor, :meth:`fit` sets the ``_``
    attributes).

    Parameters
    ----------
    area_shares : sequence of float
        The restriction's areas tried in each direction, as multiples of the valve's
        largest port area over the windows' commands.
    shortlist : int
        How many of each direction's best areas (besides none) the joint grid pairs.
    dead_volume_scales : sequence of float
        The dead volume's scales tried with each restriction (where the model fits it).
    min_explained_fraction, min_t, strong_explained_fraction : float
        The gate (:func:`~pneubayes.discovery.openform.gate.earns_trial`).
    refine_passes : int
        Rounds of local refinement of the grid's best (a compass search).

    Attributes
    ----------
    terms_ : list of RestrictionTerm
        The kept restriction (none or one).
    explained_fraction_ : float
        Share of the residual's sum of squares the kept restriction removes.
    best_ : RestrictionTerm or None
        The best restriction, kept or not (what the search saw).
    port_area_m2_ : float
        The valve's largest port area over the windows' commands (m^2), which the areas
        tried are shares of.
    """

    def __init__(self, area_shares: Sequence[float] = tuple(np.geomspace(0.1, 6.0, 9)),
                 shortlist: int = 3,
                 dead_volume_scales: Sequence[float] = tuple(np.geomspace(0.2, 1.25, 6)),
                 min_explained_fraction: float = 0.02, min_t: float = 4.0,
                 strong_explained_fraction: float = 0.3, refine_passes: int = 6):
        self.area_shares = area_shares
        self.shortlist = shortlist
        self.dead_volume_scales = dead_volume_scales
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t
        self.strong_explained_fraction = strong_explained_fraction
        self.refine_passes = refine_passes

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"area_shares": self.area_shares, "shortlist": self.shortlist,
                "dead_volume_scales": self.dead_volume_scales,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t,
                "strong_explained_fraction": self.strong_explained_fraction,
                "refine_passes": self.refine_passes}

    def _validate(self, problem):
        out = []
        for name in ("area_shares", "dead_volume_scales"):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.ndim != 1 or not v.size or not np.all(np.isfinite(v) & (v > 0.0)):
                raise ValueError(f"{name} must be a non-empty sequence of positive numbers, "
                                 f"got {getattr(self, name)!r}")
            out.append(v)
        for name in ("shortlist", "refine_passes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (name == "shortlist"):
                raise ValueError(f"{name} must be an integer >= {int(name == 'shortlist')}, "
                                 f"got {v!r}")
        check_gate(self.min_explained_fraction, self.min_t, self.strong_explained_fraction)
        if not isinstance(problem, PortRestrictionProblem):
            raise ValueError("fit takes a PortRestrictionProblem")
        problem.check()
        return out

    def fit(self, problem: PortRestrictionProblem) -> "PortRestrictionSearch":
        """Search the training windows of ``problem``."""
        shares, scales = self._validate(problem)
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        self.port_area_m2_ = a_max = problem.largest_port_area_m2()
        current = problem.window_sse([()])[0]
        total = float(np.sum(current))
        if not np.isfinite(total) or total <= 0.0 or not a_max > 0.0:
            return self
        ks = np.clip(1.0 / (shares * a_max), *INVERSE_AREA_BOUNDS_PER_M2)
        ks = tuple(float(k) for k in ks if k > 0.0)
        # each direction alone over the dead volume's scales (a base fit without the
        # restriction slows the chamber by growing its dead volume, severalfold)
        scales = tuple(float(v) for v in scales) if problem.scales_dead_volume else (1.0,)
        alone = [((k, 0.0), s) for s in scales for k in ks] + [
            ((0.0, k), s) for s in scales for k in ks]
        sse = np.sum(problem.window_sse([[a] for a, _ in alone], [s for _, s in alone]),
                     axis=1)
        n = len(alone) // 2
        fills = _shortlist(alone[:n], sse[:n], 0, self.shortlist)
        vents = _shortlist(alone[n:], sse[n:], 1, self.shortlist)
        # together
        grid = [((f, v), s) for s in scales for f in (0.0, *fills) for v in (0.0, *vents)
                if f > 0.0 or v > 0.0]
        got = problem.window_sse([[g[0]] for g in grid], [g[1] for g in grid])
        j = int(np.argmin(np.sum(got, axis=1)))
        if not np.isfinite(got[j]).all():
            return self
        best, best_sse = grid[j], got[j]
        if self.refine_passes:
            step = float(shares[1] / shares[0]) if shares.size > 1 else 2.0
            best, best_sse = _refined(problem, best, best_sse, step,
                                      0.15 if len(scales) > 1 else 0.0, self.refine_passes)
        explained, t = window_reduction(current, best_sse, total, relative=True)
        self.best_ = RestrictionTerm(*best[0], explained, t, best[1])
        if earns_trial(explained, t, self.min_explained_fraction, self.min_t,
                       self.strong_explained_fraction):
            self.terms_ = [self.best_]
            self.explained_fraction_ = explained
        return self


def _shortlist(trials, sse, side, count):
    """The ``count`` best distinct inverse areas on ``side`` (0 fill, 1 vent) of the
    one-direction ``trials`` (each ``((fill, vent), dead-volume scale)``) by their
    ``sse``."""
    out = []
    for i in np.argsort(sse, kind="stable"):
        k = trials[i][0][side]
        if np.isfinite(sse[i]) and k not in out:
            out.append(k)
        if len(out) == count:
            break
    return out


def _refined(problem, centre, sse, step, d_v, passes):
    """Local refinement of the grid's best ``centre`` = ((fill, vent), dead-volume
    scale): ``passes`` rounds of its neighbours, each restricted direction's inverse area
    times ``step`` or over it (an open direction stays open) and the scale by ``d_v``
    relative, moving to the best where it is better and else taking the steps' square
    roots (a compass search). Returns ``(centre, sse)``."""
    lo, hi = INVERSE_AREA_BOUNDS_PER_M2
    for _ in range(passes):
        (f0, v0), s0 = centre
        cand = [((float(np.clip(f0 * a, lo, hi)), float(np.clip(v0 * b, lo, hi))),
                 s0 * (1.0 + d))
                for a in ((1.0 / step, 1.0, step) if f0 > 0 else (1.0,))
                for b in ((1.0 / step, 1.0, step) if v0 > 0 else (1.0,))
                for d in ((-d_v, 0.0, d_v) if d_v else (0.0,))]
        got = problem.window_sse([[c[0]] for c in cand], [c[1] for c in cand])
        j = int(np.argmin(np.sum(got, axis=1)))
        if np.isfinite(got[j]).all() and np.sum(got[j]) < np.sum(sse) \
                and cand[j] != centre:
            centre, sse = cand[j], got[j]
        else:
            step, d_v = float(np.sqrt(step)), 0.5 * d_v
    return centre, sse


__all__ = ["PortRestrictionProblem", "PortRestrictionSearch", "RestrictionTerm"]
