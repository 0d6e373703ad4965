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
a compass refinement of the best; then a one-way flow control's check valve, its
cracking drops a few hundredths of the supply's gauge pressure beside wider areas of the
wider direction, refined with it where it is better; it is kept by the gate the
volume's forms use (:func:`~pneubayes.discovery.openform.gate.earns_trial`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pneubayes.discovery.openform.compass import compass_refine
from pneubayes.discovery.openform.gate import check_gate, earns_trial
from pneubayes.discovery.openform.volume import VolumeProblem, window_reduction
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.effects.port_restriction import (
    CRACK,
    CRACK_BOUNDS_PA,
    FILL,
    INVERSE_AREA_BOUNDS_PER_M2,
    VENT,
    PortRestriction,
)
from pneubayes.simulation.rates import port_areas


@dataclass(frozen=True)
class RestrictionTerm:
    """A kept restriction: its inverse areas ``fill_per_m2`` and ``vent_per_m2`` (1/m^2,
    0 none), its check valve's cracking drop ``crack_Pa`` (0 none), the share of the
    residual's sum of squares it removes (``explained``), the windows' mean relative
    reduction over its standard error (``t``) and the dead volume's scale it was found
    with (``dead_volume_scale``)."""

    fill_per_m2: float
    vent_per_m2: float
    crack_Pa: float
    explained: float
    t: float
    dead_volume_scale: float = 1.0

    def __str__(self) -> str:
        def side(k):
            return "open" if k <= 0.0 else f"{1e6 / k:.3g} mm^2"

        scaled = ("" if self.dead_volume_scale == 1.0 else
                  f", the dead volume x {self.dead_volume_scale:.3g}")
        crack = (f", its check valve cracking at {self.crack_Pa:.3g} Pa" if self.crack_Pa > 0.0
                 else "")
        return (f"a restriction at the port (fill through {side(self.fill_per_m2)}, vent "
                f"through {side(self.vent_per_m2)}{crack}{scaled})")


@dataclass(frozen=True)
class PortRestrictionProblem(VolumeProblem):
    """What the search simulates (as :class:`VolumeProblem`), a term joining as a port
    restriction: ``(fill inverse area, vent inverse area, crack)``."""

    component: ClassVar[type] = PortRestriction
    term_names: ClassVar[tuple] = (lambda k: FILL, lambda k: VENT, lambda k: CRACK)
    unused_term: ClassVar[tuple[float, float, float]] = (0.0, 0.0, 0.0)

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

    def supply_gauge_Pa(self) -> float:
        """The rig's supply pressure above the atmosphere (Pa)."""
        rig = self.rig
        return float(rig.supply_pressure_Pa - rig.atmospheric_pressure_Pa)


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
    crack_shares : sequence of float
        The check valve's cracking drops tried, as shares of the supply's gauge pressure
        (empty: no check valve).
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
                 crack_shares: Sequence[float] = (0.01, 0.02, 0.04, 0.08),
                 min_explained_fraction: float = 0.02, min_t: float = 4.0,
                 strong_explained_fraction: float = 0.3, refine_passes: int = 6):
        self.area_shares = area_shares
        self.shortlist = shortlist
        self.dead_volume_scales = dead_volume_scales
        self.crack_shares = crack_shares
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t
        self.strong_explained_fraction = strong_explained_fraction
        self.refine_passes = refine_passes

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"area_shares": self.area_shares, "shortlist": self.shortlist,
                "dead_volume_scales": self.dead_volume_scales,
                "crack_shares": self.crack_shares,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t,
                "strong_explained_fraction": self.strong_explained_fraction,
                "refine_passes": self.refine_passes}

    def _validate(self, problem):
        out = []
        for name in ("area_shares", "dead_volume_scales", "crack_shares"):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            empty_ok = name == "crack_shares"
            if v.ndim != 1 or not (v.size or empty_ok) \
                    or not np.all(np.isfinite(v) & (v > 0.0)):
                raise ValueError(f"{name} must be a {'' if empty_ok else 'non-empty '}"
                                 f"sequence of positive numbers, got {getattr(self, name)!r}")
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
        shares, scales, cracks = self._validate(problem)
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
        alone = [((k, 0.0, 0.0), s) for s in scales for k in ks] + [
            ((0.0, k, 0.0), s) for s in scales for k in ks]
        sse = np.sum(problem.window_sse([[a] for a, _ in alone], [s for _, s in alone]),
                     axis=1)
        n = len(alone) // 2
        fills = _shortlist(alone[:n], sse[:n], 0, self.shortlist)
        vents = _shortlist(alone[n:], sse[n:], 1, self.shortlist)
        # together
        grid = [((f, v, 0.0), s) for s in scales for f in (0.0, *fills)
                for v in (0.0, *vents) if f > 0.0 or v > 0.0]
        got = problem.window_sse([[g[0]] for g in grid], [g[1] for g in grid])
        j = int(np.argmin(np.sum(got, axis=1)))
        if not np.isfinite(got[j]).all():
            return self
        best, best_sse = grid[j], got[j]
        step = float(shares[1] / shares[0]) if shares.size > 1 else 2.0
        d_v = 0.15 if len(scales) > 1 else 0.0
        bounds = (INVERSE_AREA_BOUNDS_PER_M2, INVERSE_AREA_BOUNDS_PER_M2, CRACK_BOUNDS_PA)
        if self.refine_passes:
            best, best_sse = compass_refine(problem, best, best_sse, (step, step, 1.0),
                                            bounds, d_v, self.refine_passes)
        cracked, cracked_sse = with_check_valve(problem, best, cracks, step)
        if cracked is not None and np.sum(cracked_sse) < np.sum(best_sse):
            best, best_sse = cracked, cracked_sse
            if self.refine_passes:
                best, best_sse = compass_refine(problem, best, best_sse, (step, step, 2.0),
                                                bounds, d_v, self.refine_passes)
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


def with_check_valve(problem, centre, cracks, step):
    """The best of ``centre`` = ((fill, vent, 0), dead-volume scale) with a check valve
    cracking at each share of ``cracks`` of the supply's gauge pressure, the wider
    direction's area (the check's) times 1, ``step`` or ``step^2`` (an open one stays
    open): ``(centre, sse)``, or ``(None, None)`` where no check valve can act (both
    directions alike) or every simulation failed."""
    (f, v, _), scale = centre
    if f == v or not cracks.size:
        return None, None
    wide = 0 if f < v else 1
    gauge = problem.supply_gauge_Pa()
    cand = []
    for c in cracks:
        for m in (1.0, step, step * step) if (f, v)[wide] > 0.0 else (1.0,):
            ks = [f, v]
            ks[wide] = max(ks[wide] / m, INVERSE_AREA_BOUNDS_PER_M2[0])
            cand.append(((ks[0], ks[1], float(min(c * gauge, CRACK_BOUNDS_PA[1]))), scale))
    got = problem.window_sse([[c[0]] for c in cand], [c[1] for c in cand])
    j = int(np.argmin(np.sum(got, axis=1)))
    if not np.isfinite(got[j]).all():
        return None, None
    return cand[j], got[j]


__all__ = ["PortRestrictionProblem", "PortRestrictionSearch", "RestrictionTerm",
           "with_check_valve"]
