"""The likelihood of window predictions: AR(1) noise and the noisy window start.

Open-loop prediction errors are not independent, and treating them so makes the
posterior far too narrow. Two things correlate them:

* the sensor noise itself (anti-alias filtering), modelled as a stationary AR(1)
  process ``n_k = rho n_{k-1} + e_k``, ``e_k ~ N(0, sigma^2)``;
* the window start. A 2-s window starts at the *measured* pressure, which is the true
  pressure plus ``n_0``. That start error decays through the window as the start
  sensitivity ``S_k = dp_k / dp_0`` (1 at the start; in a closed or slowly filling
  chamber it lasts the whole window). So the residual is ``r_k = n_k - S_k n_0``: a
  per-window random offset that an AR(1) residual model alone takes for information.

:func:`start_noise_loglike` integrates ``n_0`` (its prior is the stationary
``N(0, sigma^2 / (1 - rho^2))``), sigma (prior ~ 1/sigma) and rho (uniform) out: the
first two in closed form, rho by quadrature around its mode. The sampler then sees only
the physical parameters; :func:`draw_start_noise` draws (sigma, rho) from their
conditional posterior afterwards, from a 5-number summary kept per draw (emcee blobs).
The sensitivities come from the compiled simulator at almost no cost.

We prefer this to inflating an i.i.d. likelihood by an effective sample size: it is a
proper density of the data-generating process, and the data set how much the
correlation discounts them. The earlier model (AR(1) residuals started at zero,
:func:`ar1_marginal_loglike`, exact in rho) is kept: it scores one-step and held-out
residuals, and it is the start-noise model's limit when every window's start error is
forgotten at once (the identification study showed it overconfident on slow chambers).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special, stats

from pneubayes.effects.base import Parameter
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

NOISE_PARAMETERS = (
    Parameter("noise_scale_Pa", "Pa", 1.0, 1e5, "log-uniform",
              "innovation std of the AR(1) prediction residual"),
    Parameter("noise_ar1", "-", -0.99, 0.999, "uniform",
              "lag-1 autocorrelation of the prediction residual"),
)


def ar1_loglike(residuals: np.ndarray, sigma: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Log-likelihood of residuals ``(B, W, K)`` under AR(1) from zero; returns ``(B,)``."""
    r = residuals
    e = r.copy()
    e[:, :, 1:] -= rho[:, None, None] * r[:, :, :-1]
    n = r.shape[1] * r.shape[2]
    ss = np.einsum("bwk,bwk->b", e, e)
    return -0.5 * ss / sigma**2 - n * np.log(sigma) - 0.5 * n * math.log(2 * math.pi)


def ar1_sums(residuals: np.ndarray) -> np.ndarray:
    """The sums ``(A, B, C)`` of residuals ``(B, W, K)`` that SS(rho) needs; ``(B, 3)``.

    ``A = sum r_k^2``, ``B = sum r_k r_{k-1}``, ``C = sum r_{k-1}^2`` (k >= 1 within a
    window; each window's AR(1) starts from zero).
    """
    r = residuals
    a = np.einsum("bwk,bwk->b", r, r)
    b = np.einsum("bwk,bwk->b", r[:, :, 1:], r[:, :, :-1])
    c = np.einsum("bwk,bwk->b", r[:, :, :-1], r[:, :, :-1])
    return np.column_stack([a, b, c])


def _rho_terms(sums: np.ndarray, rho_bounds: tuple[float, float], n: int):
    """rho*, S*, the t scale of rho and the standardised bounds, per row of ``sums``."""
    a, b, c = (np.asarray(sums, dtype=np.float64)[:, j] for j in range(3))
    c = np.maximum(c, 1e-300)
    rho_star = b / c
    s_star = np.maximum(a - b * b / c, 1e-300 * a + 1e-300)
    nu = n - 1
    scale = np.sqrt(s_star / (c * nu))
    t_lo = (rho_bounds[0] - rho_star) / scale
    t_hi = (rho_bounds[1] - rho_star) / scale
    return rho_star, s_star, c, scale, t_lo, t_hi, nu


def _log_t_mass(t_lo, t_hi, nu):
    """log(F(t_hi) - F(t_lo)) for Student-t with ``nu`` dof, accurate in both tails."""
    out = np.empty_like(t_lo)
    upper = t_lo > 0  # both in the upper tail: use survival functions
    lower = t_hi < 0  # both in the lower tail: use the cdf
    mid = ~(upper | lower)
    if upper.any():
        a, b = stats.t.logsf(t_lo[upper], nu), stats.t.logsf(t_hi[upper], nu)
        out[upper] = a + np.log1p(-np.exp(b - a))
    if lower.any():
        a, b = stats.t.logcdf(t_hi[lower], nu), stats.t.logcdf(t_lo[lower], nu)
        out[lower] = a + np.log1p(-np.exp(b - a))
    if mid.any():
        out[mid] = np.log1p(-stats.t.cdf(t_lo[mid], nu) - stats.t.sf(t_hi[mid], nu))
    return out


def ar1_marginal_loglike(sums: np.ndarray, n: int, sigma_bounds=(1.0, 1e5),
                         rho_bounds=(-0.99, 0.999)) -> np.ndarray:
    """log p(residuals) with sigma and rho integrated out; ``(B,)`` from ``(B, 3)`` sums.

    Priors: ``p(sigma) = 1 / (sigma ln(hi/lo))`` (log-uniform; the data pin sigma far
    inside its bounds, so the sigma-integral runs over (0, inf)) and rho uniform on
    ``rho_bounds``. ``n`` is the number of residuals. The result is the exact integral
    of ``exp(ar1_loglike)`` against that prior (tested by quadrature).
    """
    rho_star, s_star, c, scale, t_lo, t_hi, nu = _rho_terms(sums, rho_bounds, n)
    log_const = (special.gammaln(0.5 * n) - math.log(2.0) - 0.5 * n * math.log(math.pi)
                 - math.log(math.log(sigma_bounds[1] / sigma_bounds[0]))
                 - math.log(rho_bounds[1] - rho_bounds[0]))
    return (log_const - 0.5 * n * np.log(s_star) + 0.5 * np.log(s_star / c)
            + special.betaln(0.5, 0.5 * nu) + _log_t_mass(t_lo, t_hi, nu))


def draw_ar1_noise(sums: np.ndarray, n: int, rng: np.random.Generator,
                   rho_bounds=(-0.99, 0.999)) -> np.ndarray:
    """One exact draw of (sigma, rho) from p(sigma, rho | residuals) per row; ``(B, 2)``.

    rho follows a Student-t truncated to its bounds; given rho,
    ``sigma^2 = SS(rho) / (2 G)`` with ``G ~ Gamma(n / 2)``.
    """
    s = np.asarray(sums, dtype=np.float64)
    rho_star, s_star, c, scale, t_lo, t_hi, nu = _rho_terms(s, rho_bounds, n)
    f_lo, f_hi = stats.t.cdf(t_lo, nu), stats.t.cdf(t_hi, nu)
    u = f_lo + (f_hi - f_lo) * rng.uniform(size=s.shape[0])
    rho = np.clip(rho_star + scale * stats.t.ppf(u, nu), *rho_bounds)
    ss = s[:, 0] - 2 * rho * s[:, 1] + rho**2 * s[:, 2]
    sigma = np.sqrt(ss / (2.0 * rng.gamma(0.5 * n, size=s.shape[0])))
    return np.column_stack([sigma, rho])


#: Columns of the per-draw noise summary kept as emcee blobs (see start_noise_loglike).
N_NOISE_SUMMARY = 5
#: Gauss-Hermite rule for the rho-integral of the start-noise likelihood.
_GH_X, _GH_W = np.polynomial.hermite.hermgauss(11)


def start_noise_sums(residuals: np.ndarray, sensitivity: np.ndarray):
    """Sums of the start-noise likelihood: ``(B, 3)`` pooled and ``(B, W, 6)`` per window.

    ``residuals`` ``(B, W, K)`` are the window samples after the start (the start's own
    residual is 0 by construction); ``sensitivity`` ``(B, W, K + 1)`` is dp(t)/dp(start)
    including the start (1). Pooled: ``(A, B, C)`` as :func:`ar1_sums` but with the
    residual before the first sample taken as 0. Per window, with S the sensitivity and
    primes the previous sample: ``(sum S^2, sum S S', sum S'^2, sum r S,
    sum r S' + r' S, sum r' S')``.
    """
    r = residuals
    rp = np.concatenate([np.zeros(r.shape[:2] + (1,)), r[:, :, :-1]], axis=2)
    s, sp = sensitivity[:, :, 1:], sensitivity[:, :, :-1]
    pooled = np.column_stack([np.einsum("bwk,bwk->b", r, r),
                              np.einsum("bwk,bwk->b", r, rp),
                              np.einsum("bwk,bwk->b", rp, rp)])
    win = np.stack([np.einsum("bwk,bwk->bw", s, s), np.einsum("bwk,bwk->bw", s, sp),
                    np.einsum("bwk,bwk->bw", sp, sp), np.einsum("bwk,bwk->bw", r, s),
                    np.einsum("bwk,bwk->bw", r, sp) + np.einsum("bwk,bwk->bw", rp, s),
                    np.einsum("bwk,bwk->bw", rp, sp)], axis=2)
    return pooled, win


def _start_terms(pooled, win, rho):
    """``(Q, sum_w log a_w)`` at ``rho`` ``(B, M)``: the innovation sum of squares with
    each window's start noise integrated out, and its normalising terms."""
    r = rho[:, None, :]  # (B, 1, M)
    d, e, f, i, j, l_ = (win[:, :, k, None] for k in range(6))
    a_w = 1.0 - r * r + d - 2.0 * r * e + r * r * f
    h_w = i - r * j + r * r * l_
    ss = pooled[:, 0, None] - 2.0 * rho * pooled[:, 1, None] + rho**2 * pooled[:, 2, None]
    q = ss - np.sum(h_w * h_w / a_w, axis=1)
    return np.maximum(q, 1e-300 + 1e-12 * ss), np.sum(np.log(a_w), axis=1)


def _start_log_curve(pooled, win, rho, n: int):
    """log p(residuals | rho) up to constants, sigma integrated out, and Q; ``(B, M)``."""
    q, log_a = _start_terms(pooled, win, rho)
    n_w = win.shape[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return 0.5 * n_w * np.log1p(-rho * rho) - 0.5 * log_a - 0.5 * n * np.log(q), q


def start_noise_loglike(pooled, win, n: int, sigma_bounds=(1.0, 1e5),
                        rho_bounds=(-0.99, 0.999)):
    """log p(residuals) with each window's start noise, sigma and rho integrated out.

    The measurement noise is a stationary AR(1) process ``n_k`` (innovation ``sigma``,
    lag-1 correlation ``rho``). A window starts at the *measured* pressure, i.e. at the
    true one plus ``n_0``, and a start error decays through the window as the start
    sensitivity ``S_k`` (1 at the start; it lasts the whole window in a closed chamber).
    So the window residual is ``r_k = n_k - S_k n_0``. Given rho and sigma it is
    Gaussian in ``n_0`` (prior ``N(0, sigma^2 / (1 - rho^2))``), which is integrated out
    in closed form; the log-uniform sigma then gives a Gamma function as before, and
    rho (uniform on ``rho_bounds``) is integrated by an 11-point Gauss-Hermite rule
    around its mode (the rho-curve is within O(1/n) of Gaussian; tested against
    quadrature).

    Returns ``(loglike (B,), rho_summary (B, 5))``; the summary ``(rho mode, rho sd, Q,
    dQ/drho, d2Q/drho2)`` lets :func:`draw_start_noise` draw (sigma, rho) afterwards.
    """
    pooled = np.asarray(pooled, dtype=np.float64)
    win = np.asarray(win, dtype=np.float64)
    lo, hi = rho_bounds
    c = np.maximum(pooled[:, 2], 1e-300)
    rho = np.clip(pooled[:, 1] / c, lo + 1e-6, hi - 1e-6)
    eps = 1e-4
    for _ in range(4):  # Newton on the log rho-curve, central differences
        grid = rho[:, None] + eps * np.array([-1.0, 0.0, 1.0])
        fv, _ = _start_log_curve(pooled, win, grid, n)
        g1 = (fv[:, 2] - fv[:, 0]) / (2 * eps)
        g2 = (fv[:, 2] - 2 * fv[:, 1] + fv[:, 0]) / eps**2
        step = np.where(g2 < 0, -g1 / np.where(g2 < 0, g2, -1.0), np.sign(g1) * 0.01)
        step = np.where(np.isfinite(step), np.clip(step, -0.05, 0.05), 0.0)
        rho = np.clip(rho + step, lo + 1e-6, hi - 1e-6)
    grid = rho[:, None] + eps * np.array([-1.0, 0.0, 1.0])
    fv, qv = _start_log_curve(pooled, win, grid, n)
    g2 = (fv[:, 2] - 2 * fv[:, 1] + fv[:, 0]) / eps**2
    sd = 1.0 / np.sqrt(np.maximum(-g2, 1e-12))
    sd = np.minimum(sd, 0.5 * (hi - lo))
    nodes = rho[:, None] + np.sqrt(2.0) * sd[:, None] * _GH_X[None, :]
    inside = (nodes > lo) & (nodes < hi)
    fn, _ = _start_log_curve(pooled, win, np.clip(nodes, lo + 1e-9, hi - 1e-9), n)
    fn = np.where(inside, fn, -np.inf)
    f0 = fv[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_int = (f0 + np.log(np.sqrt(2.0) * sd)
                   + np.log(np.sum(_GH_W * np.exp(fn - f0[:, None] + _GH_X**2), axis=1)))
    log_const = (special.gammaln(0.5 * n) - math.log(2.0) - 0.5 * n * math.log(math.pi)
                 - math.log(math.log(sigma_bounds[1] / sigma_bounds[0]))
                 - math.log(hi - lo))
    summary = np.column_stack([rho, sd, qv[:, 1], (qv[:, 2] - qv[:, 0]) / (2 * eps),
                               (qv[:, 2] - 2 * qv[:, 1] + qv[:, 0]) / eps**2])
    return log_const + log_int, summary


def draw_start_noise(summary: np.ndarray, n: int, rng: np.random.Generator,
                     rho_bounds=(-0.99, 0.999)) -> np.ndarray:
    """One draw of (sigma, rho) per row from the Gaussian approximation of rho's
    conditional posterior and sigma's exact conditional given rho; ``(B, 2)``."""
    s = np.asarray(summary, dtype=np.float64)
    rho_hat, sd = s[:, 0], s[:, 1]
    lo, hi = rho_bounds
    a, b = stats.norm.cdf((lo - rho_hat) / sd), stats.norm.cdf((hi - rho_hat) / sd)
    u = a + (b - a) * rng.uniform(size=s.shape[0])
    rho = np.clip(rho_hat + sd * stats.norm.ppf(u), lo, hi)
    d = rho - rho_hat
    q = np.maximum(s[:, 2] + s[:, 3] * d + 0.5 * s[:, 4] * d * d, 1e-300)
    sigma = np.sqrt(q / (2.0 * rng.gamma(0.5 * n, size=s.shape[0])))
    return np.column_stack([sigma, rho])


class WindowLikelihood:
    """Posterior density over the model parameters, the noise integrated out.

    ``log_prob`` takes a batch ``(B, P)`` (emcee's ``vectorize=True``) and simulates all
    rows, with their start sensitivities, in one compiled call per recording; the
    likelihood is :func:`start_noise_loglike`. :meth:`emcee_target` also returns a noise
    summary per row (emcee blobs), from which :func:`draw_start_noise` later draws the
    noise parameters, so the posterior still covers ``noise_scale_Pa`` and
    ``noise_ar1``.

    Samplers work in *sampling coordinates* (:meth:`to_sampling`): log-uniform
    parameters as their logarithm, and each Gompertz ``b`` as ``ln b - c d``. Eq. 11
    depends on b and d only through that combination, so (b, d) is a curved ridge that
    random-walk ensembles cross slowly; sheared, it is straight and d's posterior is its
    prior (reported by the identifiability check). With an orifice leak, the leak column
    carries offset + leak area (eq. 10 sees only the sum). :meth:`log_prob_sampling`
    includes the Jacobian, so the target is the same posterior; :meth:`nuisance` lists
    the coordinates that only the prior informs.
    """

    def __init__(self, model: Model, data: WindowSet, solver: SolverConfig):
        self.model = model
        self.data = data
        self.solver = solver
        self.parameters = model.parameters
        self.names = tuple(p.name for p in self.parameters)
        self.noise_names = tuple(p.name for p in NOISE_PARAMETERS)
        self.n_model = model.n_parameters
        self.n_residuals = data.n_residuals
        sig, rho = NOISE_PARAMETERS
        self.sigma_bounds = (sig.lower, sig.upper)
        self.rho_bounds = (rho.lower, rho.upper)

    # ------------------------------------------------------------ sampling coordinates
    def _gompertz_columns(self):
        """(b, c, d) columns of each Gompertz port whose three are all fitted (a rig
        card may know some, or have a valve without Gompertz maps)."""
        names = self.names
        out = []
        for port in ("inlet", "exhaust"):
            cols = (f"{port}_b", f"{port}_c_per_V", f"{port}_d_V")
            if all(c in names for c in cols):
                out.append(tuple(names.index(c) for c in cols))
        return out

    def _log_columns(self) -> np.ndarray:
        return np.array([p.prior == "log-uniform" for p in self.parameters])

    def _leak_split(self):
        """(exhaust offset column, orifice leak column) when both are present."""
        if "leak_area_m2" in self.names and "exhaust_offset_m2" in self.names:
            return self.names.index("exhaust_offset_m2"), self.names.index("leak_area_m2")
        return None

    def nuisance(self) -> dict[int, tuple[float, float]]:
        """Sampling coordinates the likelihood does not depend on, with their ranges.

        Each Gompertz ``d`` (given ``ln b - c d``), and with an orifice leak the exhaust
        offset (given offset + leak area): their posterior is their prior.
        """
        out = {}
        for _, _, jd in self._gompertz_columns():
            p = self.parameters[jd]
            out[jd] = (p.lower, p.upper)
        split = self._leak_split()
        if split is not None:
            p = self.parameters[split[0]]
            out[split[0]] = (p.lower, p.upper)
        return out

    def nuisance_ranges(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where each nuisance coordinate may go given the others: ``(lo, hi)``, ``(B, K)``
        in the column order of ``sorted(nuisance())``.

        A Gompertz ``d`` must keep the natural ``b = exp(z_b + c d)`` inside b's bounds;
        the exhaust offset must keep the leak area (leak column minus offset) inside the
        leak's bounds. Within these ranges the posterior is flat in the coordinate.
        """
        z = np.atleast_2d(z)
        nuis = self.nuisance()
        cols = sorted(nuis)
        lo = np.array([[nuis[c][0] for c in cols]] * z.shape[0], dtype=np.float64)
        hi = np.array([[nuis[c][1] for c in cols]] * z.shape[0], dtype=np.float64)
        for jb, jc, jd in self._gompertz_columns():
            k = cols.index(jd)
            pb = self.parameters[jb]
            c = z[:, jc]
            with np.errstate(divide="ignore", invalid="ignore"):
                a = (math.log(pb.lower) - z[:, jb]) / c
                b = (math.log(pb.upper) - z[:, jb]) / c
            lo[:, k] = np.maximum(lo[:, k], np.where(c > 0, a, b))
            hi[:, k] = np.minimum(hi[:, k], np.where(c > 0, b, a))
        split = self._leak_split()
        if split is not None:
            jo, jl = split
            k = cols.index(jo)
            pl = self.parameters[jl]
            lo[:, k] = np.maximum(lo[:, k], z[:, jl] - pl.upper)
            hi[:, k] = np.minimum(hi[:, k], z[:, jl] - pl.lower)
        return lo, hi

    def to_sampling(self, batch: np.ndarray) -> np.ndarray:
        """Natural parameters ``(B, D)`` -> sampling coordinates."""
        x = np.array(np.atleast_2d(batch), dtype=np.float64)
        z = x.copy()
        logc = self._log_columns()
        z[:, logc] = np.log(x[:, logc])
        for jb, jc, jd in self._gompertz_columns():
            z[:, jb] = np.log(x[:, jb]) - x[:, jc] * x[:, jd]
        split = self._leak_split()
        if split is not None:  # the leak column carries offset + leak (unit Jacobian)
            z[:, split[1]] = x[:, split[0]] + x[:, split[1]]
        return z

    def from_sampling(self, batch: np.ndarray) -> np.ndarray:
        """Sampling coordinates ``(B, D)`` -> natural parameters."""
        z = np.array(np.atleast_2d(batch), dtype=np.float64)
        x = z.copy()
        logc = self._log_columns()
        with np.errstate(over="ignore"):
            x[:, logc] = np.exp(z[:, logc])
            for jb, jc, jd in self._gompertz_columns():
                x[:, jb] = np.exp(z[:, jb] + z[:, jc] * z[:, jd])
        split = self._leak_split()
        if split is not None:
            x[:, split[1]] = z[:, split[1]] - z[:, split[0]]
        return x

    def _evaluate_sampling(self, batch: np.ndarray):
        x = self.from_sampling(batch)
        logc = self._log_columns()
        # d(natural)/d(sampling) = natural value on every log column (b included: the
        # shear ln b -> ln b - c d has unit Jacobian)
        with np.errstate(divide="ignore", invalid="ignore"):
            jac = np.sum(np.log(np.where(x[:, logc] > 0, x[:, logc], np.nan)), axis=1)
        lp, sums = self.log_prob_and_sums(x)
        with np.errstate(invalid="ignore"):  # -inf + inf far outside: no density
            out = lp + jac
        out[~np.isfinite(out)] = -np.inf
        return out, sums

    def log_prob_sampling(self, batch: np.ndarray) -> np.ndarray:
        """Posterior log-density in sampling coordinates (Jacobian included)."""
        return self._evaluate_sampling(batch)[0]

    def emcee_target(self, batch: np.ndarray) -> np.ndarray:
        """``(B, 6)``: log-density in sampling coordinates, then the noise summary.

        emcee (``vectorize=True``) reads column 0 as the log-probability and the rest
        as blobs.
        """
        lp, sums = self._evaluate_sampling(batch)
        return np.column_stack([lp, sums])

    def draw_noise(self, sums: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(noise_scale_Pa, noise_ar1) drawn from their conditional posterior ``(B, 2)``."""
        return draw_start_noise(sums, self.n_residuals, rng, self.rho_bounds)

    @property
    def bounds(self):
        return (np.array([p.lower for p in self.parameters]),
                np.array([p.upper for p in self.parameters]))

    def log_prior(self, batch: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(batch)
        return sum(p.log_prior(x[:, j]) for j, p in enumerate(self.parameters))

    def log_prob_and_sums(self, batch: np.ndarray):
        """Log posterior ``(B,)`` of model parameters and the noise summary ``(B, 5)``.

        The likelihood is :func:`start_noise_loglike`: stationary AR(1) noise with each
        window's start error carried through the window by its start sensitivity.
        """
        x = np.atleast_2d(np.asarray(batch, dtype=np.float64))
        lp = self.log_prior(x)
        out = np.full(x.shape[0], -np.inf)
        sums = np.full((x.shape[0], N_NOISE_SUMMARY), np.nan)
        ok = np.isfinite(lp)
        if not ok.any():
            return out, sums
        r, sens = self.data.residuals_and_sensitivity(self.model, x[ok], self.solver,
                                                      on_failure="nan")
        pooled, win = start_noise_sums(r, sens)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            ll, summary = start_noise_loglike(pooled, win, self.n_residuals,
                                              self.sigma_bounds, self.rho_bounds)
        ll[~np.isfinite(ll)] = -np.inf
        out[ok] = lp[ok] + ll
        sums[ok] = summary
        return out, sums

    def log_prob(self, batch: np.ndarray) -> np.ndarray:
        """Log posterior (up to the evidence) of model parameter rows ``(B, P)``."""
        return self.log_prob_and_sums(batch)[0]
