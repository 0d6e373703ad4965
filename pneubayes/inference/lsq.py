"""The paper's identification (section VI-B): equation-error least squares on dp/dt.

1. dp/dt from the noisy pressure (:class:`~pneubayes.inference.derivative.SavitzkyGolay`),
   samples near command switches left out.
2. Eq. 10 at each command level: on every hold of a fixed-volume recording,
   ``dp/dt = n Rs T / V (a_c f(P_c, p) - (a_a + a_l) f(p, P_r))`` is linear in the two
   areas over V; a non-negative least-squares fit gives them (with standard errors).
   An effect of the model may add a column of its own per recording, shared by its
   holds (:meth:`~pneubayes.effects.Effect.eq10_column`; a laminar leak does).
3. The volume map: area points from recordings at different fixed positions must lie on
   one curve, which fixes the dead volume V0 (profiled). With a single position, V0 is
   confounded with the area scale and must be given.
4. Gompertz curves (eq. 11) fitted to the area-vs-command points, as in Table II.

Each effect of the model then estimates its own parameters from what was found
(:meth:`~pneubayes.effects.Effect.eq10_estimate`): its column's coefficients, or the
port curve its law is lumped with (the paper's orifice leak has the exhaust port's law,
so eq. 10 sees ``a_a + a_l``; ``known={"exhaust_offset_m2": ...}`` from a valve
characterisation separates them). This module names no particular effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, sparse

from pneubayes.effects.base import Eq10Fit
from pneubayes.inference.derivative import SavitzkyGolay, consistency_mask, switch_mask
from pneubayes.model import Model
from pneubayes.physics.orifice import flow_function
from pneubayes.physics.valve import gompertz_area, gompertz_partials

_PORTS = ("inlet", "exhaust")
_GOMPERTZ = ("offset_m2", "a_m2", "b", "c_per_V", "d_V")
#: Rows of the design densified at a time when it is reduced to its triangular factor.
_QR_BLOCK_ROWS = 4096


def _nonnegative_least_squares(A, y) -> np.ndarray:
    """``argmin |A x - y|`` over ``x >= 0`` for a tall sparse ``A``: the design is reduced
    block by block (Householder QR of the running factor stacked on the next rows) to a
    square factor ``R`` and ``z`` with ``|A x - y|^2 = |R x - z|^2 + const``, and the
    small problem is solved exactly by the Lawson-Hanson active set (``nnls``)."""
    A = sparse.csr_matrix(A)
    n = A.shape[1]
    r = np.zeros((0, n + 1))
    for start in range(0, A.shape[0], _QR_BLOCK_ROWS):
        rows = slice(start, start + _QR_BLOCK_ROWS)
        block = np.column_stack([A[rows].toarray(), y[rows]])
        r = np.linalg.qr(np.vstack([r, block]), mode="r")[: n + 1]
    r = np.vstack([r, np.zeros((max(n + 1 - r.shape[0], 0), n + 1))])
    return optimize.nnls(r[:n, :n], r[:n, n])[0]


@dataclass(frozen=True)
class HoldArea:
    """Areas identified on one command hold (eq. 10)."""

    recording: int
    command_V: float
    inlet_per_volume: float       # a_c / V, 1/m
    exhaust_per_volume: float     # (a_a + a_l) / V, 1/m
    inlet_se: float
    exhaust_se: float
    n_samples: int


def _fixed_position(rec) -> float:
    if rec.position_m is not None:
        if np.ptp(rec.position_m) > 0.02 * rec.metadata.stroke_m + 1e-4:
            raise ValueError(f"{rec.source}: the paper's least squares needs fixed-volume "
                             "recordings; this one's position moves")
        return float(np.mean(rec.position_m))
    return float(rec.position_or_fixed()[0])


def _fit_gompertz(u, area, se, port: str, model: Model, rng: np.random.Generator,
                  warm: dict | None = None, tolerance: float = 1e-8, max_nfev: int = 2000):
    """Weighted Gompertz fit (eq. 11) to area points, within model bounds.

    Multi-start from typical shapes, or a single start from ``warm`` (a previous fit);
    each start a bounded trust-region least squares stopped by ``tolerance`` (its
    ``ftol``, ``xtol`` and ``gtol``) or ``max_nfev``. Returns the parameters and the
    weighted cost."""
    names = [f"{port}_{g}" for g in _GOMPERTZ]
    lo = np.array([model.parameter(n).lower for n in names])
    hi = np.array([model.parameter(n).upper for n in names])
    scale = np.array([1e-7, 1e-6, 1.0, 1.0, 1.0])
    w = 1.0 / se
    amax = float(np.max(area))

    def resid(z):
        th = z * scale
        return w * (gompertz_area(u, *th) - area)

    def jac(z):
        return w[:, None] * gompertz_partials(u, *(z * scale)) * scale

    best = None
    sign = 1.0 if port == "inlet" else -1.0
    if warm is not None:
        starts = [tuple(warm[n] for n in names)]
    else:
        starts = [(max(float(np.min(area)), 0.0), amax, 3.5, sign * 1.5, 0.0)]
    for _ in range(0 if warm is not None else 8):
        starts.append((rng.uniform(0, 5e-8), amax * rng.uniform(0.7, 1.3), rng.uniform(0.5, 8),
                       sign * rng.uniform(0.3, 4), rng.uniform(-1, 1)))
    for s in starts:
        z0 = np.clip(np.array(s), lo + 1e-12 * np.abs(lo), hi) / scale
        try:
            r = optimize.least_squares(resid, z0, jac=jac, bounds=(lo / scale, hi / scale),
                                       x_scale="jac", max_nfev=max_nfev, ftol=tolerance,
                                       xtol=tolerance, gtol=tolerance)
        except ValueError:
            continue
        if best is None or r.cost < best.cost:
            best = r
    return dict(zip(names, (best.x * scale).tolist())), float(best.cost)


class PaperLeastSquares:
    """Equation-error identification of the thin-port model (eq. 10, Table II).

    Parameters
    ----------
    model : Model
        The model whose parameters to estimate. Its base parameters are estimated, and
        each effect's that it estimates from eq. 10
        (:meth:`~pneubayes.effects.Effect.eq10_estimate`); others are left at their
        neutral values.
    differentiator : SavitzkyGolay
        dp/dt estimator.
    min_hold_samples : int
        Holds with fewer usable samples are skipped.
    max_condition : float
        Holds whose two eq.-10 columns are more collinear than this (the pressure hardly
        moved) are skipped: they fix only the ratio of the areas.
    relative_area_error : float
        Floor on each area point's relative standard error in the Gompertz fits (the
        derivative's bias at this level dominates the statistical error).
    noise_std_Pa : float or None
        Pressure noise level; when given, samples where a differentiator with twice the
        window disagrees beyond noise are dropped (unresolved fast transients).
    use_measured_supply : bool
        Use the supply column in f(P_c, p) (else the nominal supply of the JSON).
    known : dict, optional
        Parameters known from elsewhere (e.g. ``dead_volume_m3`` when all recordings
        share one position, ``exhaust_offset_m2`` from a valve characterisation).
    seed : int
        Seed of the multi-start Gompertz fits.
    curve_tolerance, curve_max_nfev : float, int
        Each Gompertz start's stopping rule: scipy's ``least_squares`` with ``ftol``,
        ``xtol`` and ``gtol`` all ``curve_tolerance`` (default 1e-8, scipy's own), at most
        ``curve_max_nfev`` evaluations (default 2000).
    """

    def __init__(self, model: Model, differentiator: SavitzkyGolay, min_hold_samples: int = 8,
                 max_condition: float = 200.0, relative_area_error: float = 0.005,
                 noise_std_Pa: float | None = None,
                 use_measured_supply: bool = False, known: dict | None = None, seed: int = 0,
                 curve_tolerance: float = 1e-8, curve_max_nfev: int = 2000):
        if not (isinstance(curve_tolerance, (int, float)) and 0.0 < curve_tolerance < 1.0):
            raise ValueError(f"curve_tolerance must be a number in (0, 1), got "
                             f"{curve_tolerance!r}")
        if int(curve_max_nfev) != curve_max_nfev or curve_max_nfev < 1:
            raise ValueError(f"curve_max_nfev must be an integer >= 1, got {curve_max_nfev!r}")
        self.model = model
        self.differentiator = differentiator
        self.min_hold_samples = min_hold_samples
        self.max_condition = max_condition
        self.relative_area_error = relative_area_error
        self.noise_std_Pa = noise_std_Pa
        self.use_measured_supply = use_measured_supply
        self.known = known
        self.seed = seed
        self.curve_tolerance = float(curve_tolerance)
        self.curve_max_nfev = int(curve_max_nfev)

    # -------------------------------------------------------------- eq. 10 per hold
    def _design(self, recs):
        """Stack eq. 10 over holds: sparse design, target dp/dt, hold bookkeeping.

        Columns: two per hold (a_c / V and (a_a + a_l) / V), then one per recording for
        each effect with a column (:meth:`~pneubayes.effects.Effect.eq10_column`), shared
        by that recording's holds; ``effect_cols`` maps (effect index, recording) to it.
        """
        effects = self.model.effects
        rows, cols, vals, target, holds = [], [], [], [], []
        effect_rows: dict[tuple[int, int], list] = {}
        n_col = row0 = 0
        for j, rec in enumerate(recs):
            g = rec.rig().gas
            rs_t = g.specific_gas_constant_J_per_kg_K * g.temperature_K
            k = g.heat_capacity_ratio * rs_t
            t, p, u = rec.time_s, rec.pressure_Pa, rec.command_V
            dt = float(np.median(np.diff(t)))
            half = self.differentiator.window_samples(dt) // 2 + 1
            dpdt = self.differentiator.derivative(t, p)
            ps = self.differentiator.smooth(t, p)
            p_atm = rec.metadata.atmospheric_pressure_Pa
            supply = rec.supply_or_nominal() if self.use_measured_supply else np.full(
                p.size, rec.metadata.supply_pressure_Pa)
            f_in = k * flow_function(supply, ps, g)
            f_out = k * flow_function(ps, p_atm, g)
            own = {e: c for e, c in ((e, eff.eq10_column(ps, p_atm, g))
                                     for e, eff in enumerate(effects)) if c is not None}
            ok = switch_mask(u, half)
            if self.noise_std_Pa is not None:
                coarse = SavitzkyGolay(2.0 * self.differentiator.window_s,
                                       self.differentiator.polyorder)
                ok &= consistency_mask(t, p, self.differentiator, coarse, self.noise_std_Pa)
            edges = np.concatenate([[0], np.nonzero(np.diff(u) != 0)[0] + 1, [u.size]])
            for a, b in zip(edges[:-1], edges[1:]):
                idx = np.arange(a, b)[ok[a:b]]
                if idx.size < self.min_hold_samples:
                    continue
                r = row0 + np.arange(idx.size)
                rows += [r, r]
                cols += [np.full(idx.size, n_col), np.full(idx.size, n_col + 1)]
                vals += [f_in[idx], -f_out[idx]]
                for e, column in own.items():
                    effect_rows.setdefault((e, j), []).append((r, column[idx]))
                target.append(dpdt[idx])
                holds.append((j, float(u[a]), n_col, idx.size))
                n_col += 2
                row0 += idx.size
        if not holds:
            raise ValueError("no usable command holds: recordings too short or switches too "
                             "frequent for the differentiator window")
        effect_cols = {}
        for key, pieces in effect_rows.items():
            effect_cols[key] = n_col
            for r, v in pieces:
                rows.append(r)
                cols.append(np.full(r.size, n_col))
                vals.append(v)
            n_col += 1
        A = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))),
                              shape=(row0, n_col))
        return A, np.concatenate(target), holds, effect_cols

    def _solve_holds(self, recs):
        """The holds' area points, each effect's column coefficients as ``{effect index:
        {recording: (coefficient, standard error)}}``, and the equation error's RMS."""
        A, y, holds, effect_cols = self._design(recs)
        # column scaling for conditioning, non-negative areas
        norms = np.sqrt(np.asarray(A.multiply(A).sum(axis=0))).ravel()
        norms[norms == 0] = 1.0
        As = (A @ sparse.diags(1.0 / norms)).tocsc()
        if effect_cols:
            x = _nonnegative_least_squares(As, y) / norms
        else:  # block diagonal: one 2-column NNLS per hold
            x = np.zeros(A.shape[1])
            row = 0
            for _, _, c, n in holds:
                blk = As[row:row + n, c:c + 2].toarray()
                x[c:c + 2] = optimize.nnls(blk, y[row:row + n])[0] / norms[c:c + 2]
                row += n
        resid = y - A @ x
        out = []
        row = 0
        info = dict.fromkeys(effect_cols, 0.0)
        for j, u, c, n in holds:
            blk = As[row:row + n, c:c + 2].toarray()
            rr = resid[row:row + n]
            for (e, jj), col in effect_cols.items():
                if jj != j:
                    continue
                # the effect column's information in this hold, after the hold's own
                # two area columns: |lam - proj(lam)|^2 / s^2
                lam = A[row:row + n, col].toarray().ravel()
                coef = np.linalg.lstsq(blk, lam, rcond=None)[0]
                free = lam - blk @ coef
                info[e, j] += float(free @ free) / max(float(rr @ rr) / max(n - 3, 1), 1e-300)
            row += n
            sv = np.linalg.svd(blk, compute_uv=False)
            if sv[-1] <= self.max_condition ** -1 * sv[0]:
                # pressure (nearly) constant over the hold: only the ratio of the two
                # areas is seen, not their scale; such a hold carries no area point.
                continue
            s2 = float(rr @ rr) / max(n - 2, 1)
            cov = s2 * np.linalg.inv(blk.T @ blk)
            se = np.sqrt(np.maximum(np.diag(cov), 0.0)) / norms[c:c + 2]
            out.append(HoldArea(j, u, x[c], x[c + 1], se[0], se[1], n))
        if not out:
            raise ValueError("no command hold moved the pressure enough to identify areas")
        per_effect: dict[int, dict] = {}
        for (e, j), c in effect_cols.items():
            per_effect.setdefault(e, {})[j] = (
                x[c], 1.0 / np.sqrt(info[e, j]) if info[e, j] > 0 else np.inf)
        return out, per_effect, float(np.sqrt(np.mean(resid**2)))

    # -------------------------------------------------------------- volume + Gompertz
    def _areas(self, holds, volumes):
        vj = np.array([volumes[h.recording] for h in holds])
        u = np.array([h.command_V for h in holds])
        a_in = np.array([h.inlet_per_volume for h in holds]) * vj
        a_ex = np.array([h.exhaust_per_volume for h in holds]) * vj
        se_in = np.hypot(np.array([h.inlet_se for h in holds]) * vj,
                         self.relative_area_error * a_in + 1e-10)
        se_ex = np.hypot(np.array([h.exhaust_se for h in holds]) * vj,
                         self.relative_area_error * a_ex + 1e-10)
        return u, a_in, a_ex, se_in, se_ex

    def fit(self, recordings) -> "PaperLeastSquares":
        """Identify from fixed-volume recordings (:class:`pneubayes.io.Recording`)."""
        recs = list(recordings)
        if not recs:
            raise ValueError("fit: no recordings given")
        known = dict(self.known or {})
        unknown = set(known) - set(self.model.parameter_names)
        if unknown:
            raise ValueError(f"known: {sorted(unknown)} are not parameters of {self.model}")
        rng = np.random.default_rng(self.seed)
        positions = np.array([_fixed_position(r) for r in recs])
        bores = np.array([r.rig().bore_area_m2 for r in recs])
        holds, columns, rms = self._solve_holds(recs)
        self.holds_ = holds
        self.equation_error_rms_Pa_per_s_ = rms

        warm: dict = {}

        def total_cost(v0):
            vol = v0 + bores * positions
            u, a_in, a_ex, se_in, se_ex = self._areas(holds, vol)
            cost = 0.0
            for port, a, se in (("inlet", a_in, se_in), ("exhaust", a_ex, se_ex)):
                p, c = _fit_gompertz(u, a, se, port, self.model, rng, warm.get(port),
                                     self.curve_tolerance, self.curve_max_nfev)
                warm[port] = p
                cost += c
            return cost

        distinct = np.unique(np.round(bores * positions, 12)).size
        if "dead_volume_m3" in known:
            v0 = float(known["dead_volume_m3"])
            self.dead_volume_identified_ = False
        elif distinct < 2:
            raise ValueError(
                "fit: every recording is at the same fixed position, so the dead volume is "
                "confounded with the area scale (eq. 10 identifies a/V only). Record at two "
                "or more positions, or pass known={'dead_volume_m3': ...}.")
        else:
            lo, hi = (self.model.parameter("dead_volume_m3").lower,
                      self.model.parameter("dead_volume_m3").upper)
            grid = np.geomspace(lo, min(hi, 1e-4), 31)
            total_cost(float(np.sqrt(lo * hi)))  # multi-start once; warm starts after
            costs = [total_cost(v) for v in grid]
            i = int(np.argmin(costs))
            a, b = np.log(grid[max(i - 1, 0)]), np.log(grid[min(i + 1, grid.size - 1)])
            r = optimize.minimize_scalar(lambda z: total_cost(np.exp(z)), bounds=(a, b),
                                         method="bounded", options={"xatol": 1e-3})
            v0 = float(np.exp(r.x))
            self.dead_volume_identified_ = True
        volumes = v0 + bores * positions
        u, a_in, a_ex, se_in, se_ex = self._areas(holds, volumes)
        p_in, _ = _fit_gompertz(u, a_in, se_in, "inlet", self.model, rng,
                                tolerance=self.curve_tolerance, max_nfev=self.curve_max_nfev)
        p_ex, _ = _fit_gompertz(u, a_ex, se_ex, "exhaust", self.model, rng,
                                tolerance=self.curve_tolerance, max_nfev=self.curve_max_nfev)
        self.area_points_ = {"command_V": u, "inlet_m2": a_in, "exhaust_m2": a_ex,
                             "inlet_se_m2": se_in, "exhaust_se_m2": se_ex,
                             "recording": np.array([h.recording for h in holds])}
        params = dict(self.model.neutral_values())
        params.update(p_in)
        params.update(p_ex)
        params["dead_volume_m3"] = v0
        notes = []
        for e, effect in enumerate(self.model.effects):
            values, said = effect.eq10_estimate(Eq10Fit(
                self.model, recs, volumes, positions, columns.get(e, {}), {**p_in, **p_ex},
                known))
            params.update(values)
            notes += said
        params.update(known)
        lo, hi = self.model.bounds
        vec = np.clip(self.model.vector(params), lo, hi)
        self.params_ = self.model.as_dict(vec)
        self.notes_ = notes
        return self
