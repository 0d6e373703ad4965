"""The open-form search on the chamber's volume with memory: friction-held walls (plays
of the volume) in the prediction windows' residual.

A volume play (:class:`~pneubayes.effects.volume_play.VolumePlay`) adds ``C (w - P_atm) +
H (p - w)`` to the chamber's volume, ``w`` the play of the pressure of half-width ``r``:
as a play (``H = 0``), a wall that gives only once the pressure has moved ``r`` past
where it stuck; as a stop (``C = 0``), an elastic give that saturates there. As with the
volume's hinges (:mod:`pneubayes.discovery.openform.volume`), a wall that matters changes
the chamber's capacity by a sizeable share, so the search simulates a grid instead of
linearising: both kinds, half-widths, compliances and dead-volume scales in one batch of
window simulations (:class:`VolumePlayProblem`); it refines the set with the least sum of
squares locally and then, beside it, looks for the best second wall (an elastic give
beside a saturating loop is a stop and a narrow play). A wall is kept
when it removes at least ``min_explained_fraction`` of the residual's sum of squares and
the windows' reductions, each as a share of the window's own sum of squares, are
``min_t`` standard errors above zero (a wall acts on every window that swings the
pressure, while the windows' residuals differ in size by orders), or when it removes at
least ``strong_explained_fraction`` of it and the windows' mean reduction is above zero
(a term that removes most of the residual earns the held-out test, whose verdict is the
one that counts, however unevenly the windows share the gain).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pneubayes.discovery.openform.gate import check_gate, earns_trial
from pneubayes.discovery.openform.volume import VolumeProblem, window_reduction
from pneubayes.effects.path import VOLUME_PLAY_MAX_TERMS
from pneubayes.effects.volume_play import (
    COMPLIANCE_BOUNDS_M3_PER_PA,
    HALF_WIDTH_BOUNDS_PA,
    HALF_WIDTH_START_PA,
    KINDS,
    VolumePlay,
    compliance_name,
    half_width_name,
    held_compliance_name,
)


@dataclass(frozen=True)
class WallTerm:
    """A kept wall: ``compliance_m3_per_Pa`` (sliding), ``half_width_Pa``,
    ``held_compliance_m3_per_Pa``, the share of the residual's sum of squares it removes
    beside the walls kept before it (``explained``), the windows' mean reduction over its
    standard error (``t``) and the dead volume's scale it was found with
    (``dead_volume_scale``)."""

    compliance_m3_per_Pa: float
    half_width_Pa: float
    held_compliance_m3_per_Pa: float
    explained: float
    t: float
    dead_volume_scale: float = 1.0

    def __str__(self) -> str:
        scaled = ("" if self.dead_volume_scale == 1.0 else
                  f", the dead volume x {self.dead_volume_scale:g}")
        width = f"{self.half_width_Pa / 1e5:.4g} bar"
        held = self.held_compliance_m3_per_Pa * 1e11
        if self.compliance_m3_per_Pa == 0.0:
            return (f"a give of {held:.4g} cm^3/bar saturating {width} past where it "
                    f"stuck{scaled}")
        what = "" if held == 0.0 else f" ({held:.4g} cm^3/bar while held)"
        return (f"a wall giving {self.compliance_m3_per_Pa * 1e11:.4g} cm^3/bar once "
                f"{width} past where it stuck{what}{scaled}")


def half_width_grid(window_set, count: int = 8) -> np.ndarray:
    """``count`` half-widths (Pa), log-spaced from 0.3 % to 30 % of the windows' measured
    pressure range (between its 2 % and 98 % quantiles), inside the component's bounds."""
    p = np.asarray(window_set.measured, dtype=np.float64)
    p = p[np.isfinite(p)]
    q_lo, q_hi = np.quantile(p, [0.02, 0.98])
    span = max(float(q_hi - q_lo), 1e3)
    return np.unique(np.clip(span * np.geomspace(0.003, 0.3, count), *HALF_WIDTH_BOUNDS_PA))


@dataclass(frozen=True)
class VolumePlayProblem(VolumeProblem):
    """What the search simulates (as :class:`VolumeProblem`), a term joining as a volume
    play: ``(compliance, half-width, held compliance)``."""

    component: ClassVar[type] = VolumePlay
    term_names: ClassVar[tuple] = (compliance_name, half_width_name, held_compliance_name)
    unused_term: ClassVar[tuple[float, float, float]] = (0.0, HALF_WIDTH_START_PA, 0.0)


class VolumePlaySearch:
    """Grid search of friction-held walls in the windows' residual (scikit-learn
    contract: settings in the constructor, :meth:`fit` sets the ``_`` attributes).

    Parameters
    ----------
    kinds : sequence of str
        The kinds of wall tried (``"play"``: its give once freed; ``"stop"``: its give
        while held, saturating).
    half_widths : int
        How many half-widths are tried (:func:`half_width_grid`).
    compliance_shares : sequence of float
        The compliances tried, as multiples of the chamber's volume per the supply's
        pressure (:meth:`VolumeProblem.volume_scale_m3_per_Pa`).
    dead_volume_scales : sequence of float
        The dead volume's scales tried with the first wall (where the model fits it).
    max_terms : int
        Most walls kept (1..2, the volume play's room).
    min_explained_fraction : float
        A kept wall's least share of the residual's sum of squares.
    min_t : float
        A kept wall's least mean relative window reduction over its standard error.
    strong_explained_fraction : float
        A wall that removes this share of the residual's sum of squares is kept at any
        ``t`` above 0.
    refine_passes : int
        Rounds of local refinement of the grid's best (its compliance, half-width and
        dead-volume scale, each round's steps halved; 0: the grid's best as it is): a
        wall that matters is sharp, and the grid's steps leave most of its gain.

    Attributes
    ----------
    terms_ : list of WallTerm
        Kept walls, in the order found.
    explained_fraction_ : float
        Share of the residual's sum of squares the kept walls remove together.
    best_ : WallTerm or None
        The best first wall, kept or not (what the search saw).
    """

    def __init__(self, kinds: Sequence[str] = KINDS, half_widths: int = 8,
                 compliance_shares: Sequence[float] = tuple(np.geomspace(0.03, 30.0, 13)),
                 dead_volume_scales: Sequence[float] = (0.35, 0.5, 0.7, 1.0),
                 max_terms: int = VOLUME_PLAY_MAX_TERMS,
                 min_explained_fraction: float = 0.02, min_t: float = 4.0,
                 strong_explained_fraction: float = 0.5, refine_passes: int = 3):
        self.kinds = kinds
        self.half_widths = half_widths
        self.refine_passes = refine_passes
        self.compliance_shares = compliance_shares
        self.dead_volume_scales = dead_volume_scales
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t
        self.strong_explained_fraction = strong_explained_fraction

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"kinds": self.kinds, "half_widths": self.half_widths,
                "compliance_shares": self.compliance_shares,
                "dead_volume_scales": self.dead_volume_scales, "max_terms": self.max_terms,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t,
                "strong_explained_fraction": self.strong_explained_fraction,
                "refine_passes": self.refine_passes}

    def _validate(self, problem):
        if isinstance(self.kinds, str) or not len(self.kinds) \
                or any(k not in KINDS for k in self.kinds):
            raise ValueError(f"kinds must be a non-empty sequence of {KINDS}, got "
                             f"{self.kinds!r}")
        if isinstance(self.half_widths, bool) or not isinstance(self.half_widths, int) \
                or self.half_widths < 1:
            raise ValueError(f"half_widths must be an integer >= 1, got {self.half_widths!r}")
        shares = np.asarray(self.compliance_shares, dtype=np.float64)
        scales = np.asarray(self.dead_volume_scales, dtype=np.float64)
        for name, v in (("compliance_shares", shares), ("dead_volume_scales", scales)):
            if v.ndim != 1 or not v.size or not np.all(v > 0):
                raise ValueError(f"{name} must be positive numbers, got "
                                 f"{getattr(self, name)!r}")
        if not (isinstance(self.max_terms, int) and not isinstance(self.max_terms, bool)
                and 1 <= self.max_terms <= VOLUME_PLAY_MAX_TERMS):
            raise ValueError(f"max_terms must be an integer in 1..{VOLUME_PLAY_MAX_TERMS}, "
                             f"got {self.max_terms!r}")
        check_gate(self.min_explained_fraction, self.min_t, self.strong_explained_fraction)
        if isinstance(self.refine_passes, bool) or not isinstance(self.refine_passes, int) \
                or self.refine_passes < 0:
            raise ValueError(f"refine_passes must be an integer >= 0, got "
                             f"{self.refine_passes!r}")
        if not isinstance(problem, VolumePlayProblem):
            raise ValueError("fit takes a VolumePlayProblem")
        problem.check()
        return shares

    def _refine(self, problem, kept, centre, sse, steps):
        """The grid's best refined locally (:func:`_refined`, ``refine_passes`` rounds)."""
        if not self.refine_passes:
            return centre, sse
        return _refined(problem, kept, centre, sse, steps, self.refine_passes)

    def fit(self, problem: VolumePlayProblem) -> "VolumePlaySearch":
        """Search the training windows of ``problem``."""
        shares = self._validate(problem)
        comps = np.clip(shares * problem.volume_scale_m3_per_Pa(), 0.0,
                        COMPLIANCE_BOUNDS_M3_PER_PA[1])
        widths = half_width_grid(problem.window_set, self.half_widths)
        scales = (tuple(float(v) for v in self.dead_volume_scales)
                  if problem.scales_dead_volume else (1.0,))
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        kept: list[tuple[float, float, float]] = []
        scale = 1.0
        current = problem.window_sse([()])[0]
        total = float(np.sum(current))
        if not np.isfinite(total) or total <= 0.0:
            return self
        for _ in range(self.max_terms):
            # the first wall with each dead-volume scale; a second beside it at its scale
            grid = [(_term(kind, float(c), float(r)), v)
                    for v in (scales if not kept else (scale,))
                    for kind in self.kinds for r in widths for c in comps]
            sse = problem.window_sse([kept + [w] for w, _ in grid], [v for _, v in grid])
            j = int(np.argmin(np.sum(sse, axis=1)))
            if not np.isfinite(sse[j]).all():
                break
            steps = (float(comps[1] / comps[0]) if comps.size > 1 else 2.0,
                     float(widths[1] / widths[0]) if widths.size > 1 else 2.0,
                     0.15 if not kept and len(scales) > 1 else 0.0)
            best, best_sse = self._refine(problem, kept, grid[j], sse[j], steps)
            explained, t = window_reduction(current, best_sse, total, relative=True)
            term = WallTerm(*best[0], explained, t, best[1])
            if self.best_ is None:
                self.best_ = term
            if not earns_trial(explained, t, self.min_explained_fraction, self.min_t,
                               self.strong_explained_fraction):
                break
            kept.append(best[0])
            scale = best[1]
            self.terms_.append(term)
            current = best_sse
        if kept:
            self.explained_fraction_ = 1.0 - float(np.sum(current)) / total
        return self


def _term(kind: str, compliance: float, half_width: float) -> tuple[float, float, float]:
    """A wall of ``kind`` as ``(compliance, half-width, held compliance)``: a play gives
    ``compliance`` once freed, a stop while held."""
    return ((compliance, half_width, 0.0) if kind == "play"
            else (0.0, half_width, compliance))


def _refined(problem, kept, centre, sse, steps, passes):
    """Local refinement of a grid's best wall ``centre`` = ((compliance, half-width, held
    compliance), dead-volume scale) with windows' sums of squares ``sse``: ``passes``
    rounds of the 3 x 3 (x 3) neighbours at ``steps`` (the compliances' and the
    half-width's factors, the scale's relative step; 0: held), each round's steps halved
    in log; the best kept. Returns ``(centre, sse)``."""
    f_c, f_r, d_v = steps
    lo, hi = COMPLIANCE_BOUNDS_M3_PER_PA
    for _ in range(passes):
        (c0, r0, h0), v0 = centre
        cand = [((float(np.clip(c0 * a, lo, hi)), float(np.clip(r0 * b, *HALF_WIDTH_BOUNDS_PA)),
                  float(np.clip(h0 * a, lo, hi))), v0 * (1.0 + d))
                for a in (1.0 / f_c, 1.0, f_c) for b in (1.0 / f_r, 1.0, f_r)
                for d in ((-d_v, 0.0, d_v) if d_v else (0.0,))]
        got = problem.window_sse([kept + [w] for w, _ in cand], [v for _, v in cand])
        j = int(np.argmin(np.sum(got, axis=1)))
        if np.isfinite(got[j]).all() and np.sum(got[j]) < np.sum(sse):
            centre, sse = cand[j], got[j]
        f_c, f_r, d_v = np.sqrt(f_c), np.sqrt(f_r), 0.5 * d_v
    return centre, sse


__all__ = ["VolumePlayProblem", "VolumePlaySearch", "WallTerm", "half_width_grid"]
