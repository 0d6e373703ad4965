"""The open-form search's candidate library: closure terms with their thresholds.

A candidate is a :class:`~pneubayes.effects.closure_terms.Term` with the thresholds
of its hinge features. The library (:func:`candidate_terms`) holds

- every base feature that is not a hinge (``one`` included);
- every hinge feature at each threshold of a grid: the two pressure hinges at quantiles
  of the measured ``p / P_atm``, the two spool hinges at quantiles of the spool, the two
  volume hinges at quantiles of the volume (none where it is fixed), the inlet's drop
  hinge at quantiles of ``|p_s - p| / P_atm``, the spool's null hinge at quantiles of
  ``|s|``, the port-area hinges at quantiles of their port's area;
- the products of every pair of non-constant, non-hinge base features (squares
  included: a laminar leak is ``p^2``) but the ports' flow functions, which enter
  alone (an extra port area) and with the spool's hinges only: beside the port flows
  their products with the other signals are near copies of the flows' products, and
  a greedy pick then settles on the copy;
- each hinge (at each of its thresholds) times ``pressure_ratio``, ``inlet_flow`` and
  ``exhaust_flow``, and the spool's three hinges also times the ports' flow functions
  ``inlet_flux``, ``exhaust_flux`` and ``net_flux`` (a port area, or an equal area at
  both ports, that opens with the spool), but the port-area hinges, which enter times
  their own port's flow function only (a port capped by a restriction in series);
- the low-passes ``pressure_relaxation`` and ``net_flow_lag`` at each time constant of a
  fixed grid (:data:`RELAXATION_TIMES_S`, those the recordings resolve), alone and times
  the same three partners (a time constant is its feature's "threshold": a family keeps
  one); ``command_lag`` likewise, times the ports' flow functions and flows
  (:data:`COMMAND_LAG_PARTNERS`: a port that lags the command), and its one-way parts
  ``command_lag_fall`` and ``command_lag_rise`` times the ports' flow functions only (a
  port that lags after a fall or a rise only);
- a late valve's areas (``*_area_late_fall``, ``*_area_late_rise``) at each dead time
  of :data:`DEAD_TIMES_S` the recordings resolve, each times its own port's flow
  function only (at coefficient 1, -1 at the exhaust, that port's late area exactly).

Hinges enter only at a grid of quantiles (``quantiles``, every 5 % from 5 to 95 % by
default, repeated values merged) and only with the partners above: about a thousand
candidates at most. Columns that are zero or repeat an earlier column (a constant
supply's ``supply_ratio`` is ``one`` again) are dropped by :func:`design_matrix`.

A candidate's *family* is its term without thresholds (``"inlet_flow*pressure_hinge"``):
the search keeps at most one threshold per family.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pneubayes.effects.closure_features import (
    DEAD_TIME_FEATURES,
    FEATURES,
    LOW_PASS_HISTORIES,
    evaluate_feature,
)
from pneubayes.effects.closure_terms import Term

#: Hinge features and the signal their thresholds are quantiles of (the null hinge's:
#: of the spool's magnitude, :func:`hinge_source_values`).
HINGE_SOURCES = {"pressure_hinge": "pressure_ratio", "spool_hinge_up": "spool",
                 "spool_hinge_down": "spool", "pressure_hinge_down": "pressure_ratio",
                 "volume_hinge_up": "volume", "volume_hinge_down": "volume",
                 "inlet_drop_hinge": "inlet_drop", "spool_null_hinge": "spool",
                 "inlet_area_hinge": "inlet_area", "exhaust_area_hinge": "exhaust_area"}
#: Hinges whose threshold is compared with their source's magnitude.
MAGNITUDE_HINGES = frozenset({"spool_null_hinge"})
#: The time constants (s) a relaxation (``pressure_relaxation``) is tried at, those
#: that the recordings resolve (:func:`relaxation_times`).
RELAXATION_TIMES_S = (0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)
#: A relaxation's time constant is tried from this many sample intervals ...
RELAXATION_MIN_INTERVALS = 3.0
#: ... to this share of the shortest recording (a slower one is a constant offset there).
RELAXATION_MAX_SHARE = 0.25
#: The partners each hinge is multiplied with.
HINGE_PARTNERS = ("pressure_ratio", "inlet_flow", "exhaust_flow")
#: The further partners of the spool's hinges: the ports' flow functions, so that a
#: term is a port area that opens with the spool (an area map's error, an underlap).
SPOOL_HINGE_PARTNERS = ("inlet_flux", "exhaust_flux", "net_flux")
SPOOL_HINGES = frozenset({"spool_hinge_up", "spool_hinge_down", "spool_null_hinge"})
#: The port-area hinges' only partner: their own port's flow function (a port capped
#: by a restriction in series; with the pressure or the flows they would copy the port
#: flows' products).
AREA_HINGE_PARTNERS = {"inlet_area_hinge": ("inlet_flux",),
                       "exhaust_area_hinge": ("exhaust_flux",)}


#: The command lag's partners: the ports' flow functions (an area that lags the command)
#: and their flows (a port whose flow lags it); its one-way parts' (which enter only
#: with them): the ports' flow functions.
COMMAND_LAG_PARTNERS = ("inlet_flux", "exhaust_flux", "net_flux", "inlet_flow",
                        "exhaust_flow")
ONE_WAY_LAG_PARTNERS = ("inlet_flux", "exhaust_flux")
#: Hinges that enter only with their partners (a mass flow in proportion to them alone
#: means nothing).
PAIRED_ONLY = frozenset({"command_lag_fall", "command_lag_rise", *DEAD_TIME_FEATURES})
#: The dead times (s) a late valve's features are tried at, those the recordings
#: resolve (:func:`dead_time_range`).
DEAD_TIMES_S = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)


def hinge_partners(hinge: str) -> tuple[str, ...]:
    """The features a hinge is multiplied with in the library."""
    if hinge in AREA_HINGE_PARTNERS:
        return AREA_HINGE_PARTNERS[hinge]
    if hinge in DEAD_TIME_FEATURES:  # its own port's flow function
        return ("inlet_flux",) if hinge.startswith("inlet") else ("exhaust_flux",)
    if hinge == "command_lag":
        return COMMAND_LAG_PARTNERS
    if hinge in PAIRED_ONLY:
        return ONE_WAY_LAG_PARTNERS
    return HINGE_PARTNERS + (SPOOL_HINGE_PARTNERS if hinge in SPOOL_HINGES else ())
#: The default quantiles of the hinge thresholds.
DEFAULT_QUANTILES = tuple(round(0.05 * k, 2) for k in range(1, 20))


@dataclass(frozen=True)
class Candidate:
    """One column of the library: a term and its hinge thresholds (0 where none)."""

    term: Term
    threshold_a: float = 0.0
    threshold_b: float = 0.0

    @property
    def family(self) -> str:
        """The term without its thresholds, e.g. ``"inlet_flow*pressure_hinge"``."""
        return str(self.term)

    @property
    def label(self) -> str:
        """The term with its thresholds, e.g. ``"inlet_flow*pressure_hinge[3.2]"``."""
        marks = {"a": self.threshold_a, "b": self.threshold_b}
        parts = []
        for k, n in (("a", self.term.a), ("b", self.term.b)):
            if k == "b" and n == "one":
                continue
            parts.append(f"{n}[{marks[k]:.4g}]" if k in self.term.hinges() else n)
        return "*".join(parts)

    def evaluate(self, signals: dict) -> np.ndarray:
        """The term's value on ``signals`` (coefficient 1)."""
        return self.term.evaluate(signals, self.threshold_a, self.threshold_b)


#: A hinge's threshold lies at least this share of its signal's range inside it.
INTERIOR_MARGIN = 1e-3


def relaxation_range(signals_list: Sequence[dict]) -> tuple[float, float]:
    """The time constants (s) the recordings resolve: from
    :data:`RELAXATION_MIN_INTERVALS` median sample intervals to
    :data:`RELAXATION_MAX_SHARE` of the shortest recording (their signals'
    ``"interval_s"``, as :func:`~pneubayes.discovery.openform.signals.path_signals`
    gives them); ``(0, 0)``, none, when a recording's signals carry no intervals."""
    h = [np.asarray(s.get("interval_s", ()), dtype=np.float64) for s in signals_list]
    if not h or not all(x.size for x in h):
        return (0.0, 0.0)
    return (RELAXATION_MIN_INTERVALS * max(float(np.median(x)) for x in h),
            RELAXATION_MAX_SHARE * min(float(np.sum(x)) for x in h))


def relaxation_times(signals_list: Sequence[dict]) -> np.ndarray:
    """The grid of :data:`RELAXATION_TIMES_S` inside :func:`relaxation_range`, s."""
    lo, hi = relaxation_range(signals_list)
    g = np.asarray(RELAXATION_TIMES_S, dtype=np.float64)
    return g[(g >= lo) & (g <= hi)]


def dead_time_range(signals_list: Sequence[dict]) -> tuple[float, float]:
    """The dead times (s) the recordings resolve: from one median sample interval to
    :data:`RELAXATION_MAX_SHARE` of the shortest recording, at most the grid's
    longest; ``(0, 0)`` when a recording's signals carry no intervals."""
    lo, hi = relaxation_range(signals_list)
    if hi <= 0.0:
        return (0.0, 0.0)
    return (lo / RELAXATION_MIN_INTERVALS, min(hi, max(DEAD_TIMES_S)))


def hinge_thresholds(signals_list: Sequence[dict], quantiles: Sequence[float]
                     ) -> dict[str, np.ndarray]:
    """Per hinge feature, its grid of thresholds: the ``quantiles`` of its source
    signal (:data:`HINGE_SOURCES`) pooled over the recordings, repeated values merged,
    those not inside the signal's range by :data:`INTERIOR_MARGIN` of it left out.

    Parameters
    ----------
    signals_list : sequence of dict
        Signals of each recording (:data:`~pneubayes.effects.closure_features.SIGNALS`).
    quantiles : sequence of float
        In (0, 1).

    Returns
    -------
    dict
        Hinge name -> increasing thresholds (``p / P_atm`` or the command's unit), each
        low-pass feature (``LOW_PASS_HISTORIES``) -> its time constants (s,
        :func:`relaxation_times`) and each dead-time feature -> its dead times (s).
    """
    q = np.asarray(quantiles, dtype=np.float64)
    if q.size == 0 or np.any(~((q > 0) & (q < 1))):
        raise ValueError(f"hinge quantiles must lie in (0, 1), got {list(quantiles)}")
    out = {}
    for hinge in HINGE_SOURCES:
        vals = np.concatenate([hinge_source_values(hinge, s) for s in signals_list])
        vals = vals[np.isfinite(vals)]
        grid = np.unique(np.quantile(vals, q)) if vals.size else np.zeros(0)
        # only thresholds inside the signal's range: at its ends a hinge is the signal
        # itself or (nearly) zero (a switching valve's 0/1 spool has no inside)
        lo, hi = (vals.min(), vals.max()) if vals.size else (0.0, 0.0)
        margin = INTERIOR_MARGIN * (hi - lo)
        out[hinge] = grid[(grid > lo + margin) & (grid < hi - margin)]
    taus = relaxation_times(signals_list)
    for name in LOW_PASS_HISTORIES:
        out[name] = taus
    lo, hi = dead_time_range(signals_list)
    g = np.asarray(DEAD_TIMES_S, dtype=np.float64)
    for name in DEAD_TIME_FEATURES:
        out[name] = g[(g >= lo) & (g <= hi)]
    return out


def hinge_source_values(hinge: str, signals: dict) -> np.ndarray:
    """The signal a hinge's threshold is compared with on one recording's ``signals``:
    its :data:`HINGE_SOURCES` feature (its magnitude for :data:`MAGNITUDE_HINGES`)."""
    values = evaluate_feature(HINGE_SOURCES[hinge], signals)
    return np.abs(values) if hinge in MAGNITUDE_HINGES else values


def candidate_terms(signals_list: Sequence[dict],
                    quantiles: Sequence[float] = DEFAULT_QUANTILES) -> list[Candidate]:
    """The library's candidates (module doc), in a fixed order.

    Parameters
    ----------
    signals_list : sequence of dict
        Signals of each recording; the hinges' thresholds come from them.
    quantiles : sequence of float
        Quantiles of the hinge thresholds (:func:`hinge_thresholds`).

    Returns
    -------
    list of Candidate
    """
    plain = [f.name for f in FEATURES if not f.hinge]
    varying = [n for n in plain if n != "one"]
    out = [Candidate(Term(n)) for n in plain]
    paired = [n for n in varying if n not in SPOOL_HINGE_PARTNERS]
    out += [Candidate(Term(a, b)) for i, a in enumerate(paired) for b in paired[i:]]
    grid = hinge_thresholds(signals_list, quantiles)
    for hinge, thresholds in grid.items():
        if hinge not in PAIRED_ONLY:
            out += [Candidate(Term(hinge), float(th)) for th in thresholds]
    for hinge, thresholds in grid.items():
        out += [Candidate(Term(partner, hinge), 0.0, float(th))
                for partner in hinge_partners(hinge) for th in thresholds]
    return out


#: Columns whose cosines :func:`distinct_columns` takes from one matrix product.
DISTINCT_BLOCK = 256


def design_matrix(candidates: Sequence[Candidate], signals: dict) -> np.ndarray:
    """The candidates' values on one recording's signals, ``(M, n_candidates)``."""
    return np.column_stack([c.evaluate(signals) for c in candidates])


def distinct_columns(x: np.ndarray, duplicate_tolerance: float) -> np.ndarray:
    """Which columns of ``x`` to keep: not zero, and not a multiple of an earlier kept
    column (``|cos| > 1 - duplicate_tolerance`` between the uncentred columns).

    The cosines come a block of columns at a time from one matrix product (a column's
    cosines against every later column), so the cost is the Gram matrix's, not one pass
    over the rows per column.

    Parameters
    ----------
    x : (n, m) array
    duplicate_tolerance : float
        How close to 1 the cosine of two columns counts as the same column.

    Returns
    -------
    (m,) bool array
    """
    norms = np.linalg.norm(x, axis=0)
    keep = (norms > 0) & np.all(np.isfinite(x), axis=0)
    unit = np.where(keep, x / np.where(norms > 0, norms, 1.0), 0.0)
    same = 1.0 - duplicate_tolerance
    m = keep.size
    for start in range(0, m, DISTINCT_BLOCK):
        stop = min(start + DISTINCT_BLOCK, m)
        cos = np.abs(unit[:, start:stop].T @ unit[:, start:])  # (block, m - start)
        for i in range(stop - start):
            if keep[start + i]:  # kept: every later column this close is a duplicate
                later = cos[i, i + 1:] > same
                keep[start + i + 1:] &= ~later
    return keep
