"""The open-form search on the chamber's volume with inertia: a wall that carries a load
(a mass on a spring driven by the pressure) in the prediction windows' residual.

A loaded wall (:class:`~pneubayes.effects.loaded_wall.LoadedWall`) adds ``C x`` to the
chamber's volume, ``x`` the pressure's response through a second-order system of natural
frequency ``f`` and damping ratio ``z``: the volume lags the pressure and, lightly
damped, rings. No function of the pressure (the volume's hinges), no rate-independent
loop (its plays) and no first-order relaxation has a ring.

A lightly damped ring is a needle in the frequency: a wall a fifth off its frequency
rings out of phase within its decay, and predicts worse than no ring at all. So the
search first screens a fine grid of frequencies and damping ratios by linearising: each
pair's response to a small compliance, and the dead volume's, fitted to the residual by
least squares (one simulation per pair). As with the hinges
(:mod:`pneubayes.discovery.openform.volume`), a wall that matters changes the chamber's
capacity by a sizeable share, so the best few pairs then go through a simulated grid of
compliances and dead-volume scales (:class:`LoadedWallProblem`); the best is refined
locally and kept by the gate the volume's plays use
(:func:`~pneubayes.discovery.openform.gate.earns_trial`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pneubayes.discovery.openform.compass import compass_refine
from pneubayes.discovery.openform.gate import check_gate, earns_trial
from pneubayes.discovery.openform.volume import VolumeProblem, window_reduction
from pneubayes.effects.loaded_wall import (
    COMPLIANCE,
    COMPLIANCE_BOUNDS_M3_PER_PA,
    DAMPING,
    DAMPING_BOUNDS,
    DAMPING_START,
    FREQUENCY,
    FREQUENCY_BOUNDS_HZ,
    FREQUENCY_START_HZ,
    LoadedWall,
)


@dataclass(frozen=True)
class LoadedWallTerm:
    """A kept wall: ``compliance_m3_per_Pa``, ``frequency_Hz``, ``damping_ratio``, the
    share of the residual's sum of squares it removes (``explained``), the windows' mean
    relative reduction over its standard error (``t``) and the dead volume's scale it was
    found with (``dead_volume_scale``)."""

    compliance_m3_per_Pa: float
    frequency_Hz: float
    damping_ratio: float
    explained: float
    t: float
    dead_volume_scale: float = 1.0

    def __str__(self) -> str:
        scaled = ("" if self.dead_volume_scale == 1.0 else
                  f", the dead volume x {self.dead_volume_scale:.3g}")
        return (f"a loaded wall giving {self.compliance_m3_per_Pa * 1e11:.4g} cm^3/bar at "
                f"{self.frequency_Hz:.4g} Hz, damping ratio {self.damping_ratio:.3g}"
                f"{scaled}")


@dataclass(frozen=True)
class LoadedWallProblem(VolumeProblem):
    """What the search simulates (as :class:`VolumeProblem`), a term joining as a loaded
    wall: ``(compliance, frequency, damping ratio)``."""

    component: ClassVar[type] = LoadedWall
    term_names: ClassVar[tuple] = (lambda k: COMPLIANCE, lambda k: FREQUENCY,
                                   lambda k: DAMPING)
    unused_term: ClassVar[tuple[float, float, float]] = (0.0, FREQUENCY_START_HZ,
                                                         DAMPING_START)

    def check(self) -> None:
        """Raise ValueError where a loaded wall cannot join the model."""
        if self.model.has("loaded_wall"):
            raise ValueError("the model already has a loaded wall")
        super().check()


class LoadedWallSearch:
    """Grid search of a loaded wall in the windows' residual (scikit-learn contract:
    settings in the constructor, :meth:`fit` sets the ``_`` attributes).

    Parameters
    ----------
    frequencies_Hz : sequence of float
        The natural frequencies screened (Hz).
    damping_ratios : sequence of float
        The damping ratios screened.
    shortlist : int
        How many of the screen's best (frequency, damping) pairs the simulated grid
        tries.
    probe_share : float
        The screen's small compliance, as a multiple of the chamber's volume per the
        supply's pressure.
    compliance_shares : sequence of float
        The compliances tried, as multiples of the chamber's volume per the supply's
        pressure (:meth:`VolumeProblem.volume_scale_m3_per_Pa`).
    dead_volume_scales : sequence of float
        The dead volume's scales tried (where the model fits it).
    min_explained_fraction, min_t, strong_explained_fraction : float
        The gate (as :class:`~pneubayes.discovery.openform.volume_play.VolumePlaySearch`),
        its strong share 0.3: a ring shows only in the windows whose pressure swings, so
        the windows' relative reductions scatter even where a wall explains a large
        share.
    refine_passes : int
        Rounds of local refinement of the grid's best (a compass search,
        :func:`~pneubayes.discovery.openform.compass.compass_refine`).

    Attributes
    ----------
    terms_ : list of LoadedWallTerm
        The kept wall (none or one).
    explained_fraction_ : float
        Share of the residual's sum of squares the kept wall removes.
    best_ : LoadedWallTerm or None
        The best wall, kept or not (what the search saw).
    """

    def __init__(self, frequencies_Hz: Sequence[float] = tuple(np.geomspace(1.0, 100.0, 25)),
                 damping_ratios: Sequence[float] = (0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2),
                 shortlist: int = 4, probe_share: float = 0.01,
                 compliance_shares: Sequence[float] = tuple(np.geomspace(0.03, 10.0, 8)),
                 dead_volume_scales: Sequence[float] = (0.5, 0.7, 1.0),
                 min_explained_fraction: float = 0.02, min_t: float = 4.0,
                 strong_explained_fraction: float = 0.3, refine_passes: int = 8):
        self.frequencies_Hz = frequencies_Hz
        self.damping_ratios = damping_ratios
        self.shortlist = shortlist
        self.probe_share = probe_share
        self.compliance_shares = compliance_shares
        self.dead_volume_scales = dead_volume_scales
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t
        self.strong_explained_fraction = strong_explained_fraction
        self.refine_passes = refine_passes

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"frequencies_Hz": self.frequencies_Hz, "damping_ratios": self.damping_ratios,
                "shortlist": self.shortlist, "probe_share": self.probe_share,
                "compliance_shares": self.compliance_shares,
                "dead_volume_scales": self.dead_volume_scales,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t,
                "strong_explained_fraction": self.strong_explained_fraction,
                "refine_passes": self.refine_passes}

    def _validate(self, problem):
        out = []  # each a non-empty sequence of positive numbers within its bounds
        for name, (lo, hi) in (("frequencies_Hz", FREQUENCY_BOUNDS_HZ),
                               ("damping_ratios", DAMPING_BOUNDS),
                               ("compliance_shares", (0.0, np.inf)),
                               ("dead_volume_scales", (0.0, np.inf))):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.ndim != 1 or not v.size or not np.all((v > 0.0) & (v >= lo) & (v <= hi)):
                raise ValueError(f"{name} must be a non-empty sequence of positive numbers "
                                 f"in [{lo:g}, {hi:g}], got {getattr(self, name)!r}")
            out.append(v)
        if isinstance(self.shortlist, bool) or not isinstance(self.shortlist, int) \
                or self.shortlist < 1:
            raise ValueError(f"shortlist must be an integer >= 1, got {self.shortlist!r}")
        if not 0.0 < self.probe_share <= 1.0:
            raise ValueError(f"probe_share must be in (0, 1], got {self.probe_share!r}")
        check_gate(self.min_explained_fraction, self.min_t, self.strong_explained_fraction)
        if isinstance(self.refine_passes, bool) or not isinstance(self.refine_passes, int) \
                or self.refine_passes < 0:
            raise ValueError(f"refine_passes must be an integer >= 0, got "
                             f"{self.refine_passes!r}")
        if not isinstance(problem, LoadedWallProblem):
            raise ValueError("fit takes a LoadedWallProblem")
        problem.check()
        return out

    def _screen(self, problem, freqs, zetas):
        """The screen's shortlist of ``(frequency, damping)`` pairs (:func:`_screened`)."""
        probe = self.probe_share * problem.volume_scale_m3_per_Pa()
        return _screened(problem, freqs, zetas, probe, self.shortlist)

    def fit(self, problem: LoadedWallProblem) -> "LoadedWallSearch":
        """Search the training windows of ``problem``."""
        freqs, zetas, shares, scales = self._validate(problem)
        comps = np.clip(shares * problem.volume_scale_m3_per_Pa(), 0.0,
                        COMPLIANCE_BOUNDS_M3_PER_PA[1])
        scales = tuple(float(v) for v in scales) if problem.scales_dead_volume else (1.0,)
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        current = problem.window_sse([()])[0]
        total = float(np.sum(current))
        if not np.isfinite(total) or total <= 0.0:
            return self
        pairs = self._screen(problem, freqs, zetas)
        if not pairs:  # (no pair's wall gives volume where the residual asks for it)
            return self
        grid = [((float(c), f, z), v) for v in scales for f, z in pairs for c in comps]
        sse = problem.window_sse([[w] for w, _ in grid], [v for _, v in grid])
        j = int(np.argmin(np.sum(sse, axis=1)))
        if not np.isfinite(sse[j]).all():
            return self
        steps = tuple(float(g[1] / g[0]) if g.size > 1 else 2.0 for g in (comps, freqs, zetas))
        best, best_sse = grid[j], sse[j]
        if self.refine_passes:
            best, best_sse = compass_refine(
                problem, best, best_sse, steps,
                (COMPLIANCE_BOUNDS_M3_PER_PA, FREQUENCY_BOUNDS_HZ, DAMPING_BOUNDS),
                0.15 if len(scales) > 1 else 0.0, self.refine_passes)
        explained, t = window_reduction(current, best_sse, total, relative=True)
        self.best_ = LoadedWallTerm(*best[0], explained, t, best[1])
        if earns_trial(explained, t, self.min_explained_fraction, self.min_t,
                       self.strong_explained_fraction):
            self.terms_ = [self.best_]
            self.explained_fraction_ = explained
        return self


def _screened(problem, freqs, zetas, probe, shortlist):
    """The ``shortlist`` best ``(frequency, damping)`` pairs of the grid ``freqs`` x
    ``zetas``, each scored by the least squares of the windows' residual on the pair's
    response to the compliance ``probe`` (m^3/Pa) and, where the model fits it, the dead
    volume's response (both linearised about the current model)."""
    pairs = [(float(f), float(z)) for f in freqs for z in zetas]
    fits_volume = problem.scales_dead_volume
    sets = [()] + [[(probe, f, z)] for f, z in pairs] + ([()] if fits_volume else [])
    scales = [1.0] * (len(pairs) + 1) + ([0.99] if fits_volume else [])
    resid = problem.window_residuals(sets, scales)
    base = resid[0].ravel()
    ok = np.isfinite(base)
    cols = [resid[1 + i].ravel() - base for i in range(len(pairs))]
    vol = resid[-1].ravel() - base if fits_volume else None
    scores = []
    for g in cols:
        a = np.stack([g, vol], axis=1) if vol is not None else g[:, None]
        good = ok & np.all(np.isfinite(a), axis=1)
        if not good.any():
            scores.append(np.inf)
            continue
        coef = np.linalg.lstsq(a[good], -base[good], rcond=None)[0]
        if coef[0] <= 0.0:  # a wall that takes volume away
            scores.append(np.inf)
            continue
        scores.append(float(np.sum((base[good] + a[good] @ coef) ** 2)))
    order = np.argsort(scores, kind="stable")[:shortlist]
    return [pairs[i] for i in order if np.isfinite(scores[i])]


__all__ = ["LoadedWallProblem", "LoadedWallSearch", "LoadedWallTerm"]
