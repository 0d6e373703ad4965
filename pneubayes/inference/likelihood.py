"""The likelihood of window predictions, with AR(1) residuals.

Open-loop prediction errors are smooth: a residual at one sample predicts the next.
Treating them as independent would make the posterior far too narrow. We model each
window's residual sequence as an AR(1) process started at zero (the window starts at
the measured pressure):

    r_k = rho r_{k-1} + e_k,   e_k ~ N(0, sigma^2),   r_0 = 0,

with the innovation scale ``sigma`` (``noise_scale_Pa``) and ``rho`` (``noise_ar1``)
sampled with the physical parameters. We prefer this to inflating an i.i.d. likelihood
by an effective sample size: it is still a proper density, costs one subtraction, and
the data themselves set how much the correlation discounts them.
"""

from __future__ import annotations

import math

import numpy as np

from pneubayes.effects.base import Parameter
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig

NOISE_PARAMETERS = (
    Parameter("noise_scale_Pa", "Pa", 1.0, 1e5, "log-uniform",
              "innovation std of the AR(1) prediction residual"),
    Parameter("noise_ar1", "-", 0.0, 0.999, "uniform",
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


class WindowLikelihood:
    """Posterior density over model parameters plus the two noise parameters.

    ``log_prob`` takes a batch ``(B, D)`` (emcee's ``vectorize=True``) and simulates all
    rows in one compiled call per recording.

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
        self.parameters = model.parameters + NOISE_PARAMETERS
        self.names = tuple(p.name for p in self.parameters)
        self.n_model = model.n_parameters

    # ------------------------------------------------------------ sampling coordinates
    def _gompertz_columns(self):
        names = self.names
        return [(names.index(f"{port}_b"), names.index(f"{port}_c_per_V"),
                 names.index(f"{port}_d_V")) for port in ("inlet", "exhaust")]

    def _log_columns(self) -> np.ndarray:
        return np.array([p.prior == "log-uniform" for p in self.parameters])

    def _leak_split(self):
        """(exhaust offset column, orifice leak column) when both are present."""
        if "leak_area_m2" in self.names:
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

    def log_prob_sampling(self, batch: np.ndarray) -> np.ndarray:
        """Posterior log-density in sampling coordinates (Jacobian included)."""
        x = self.from_sampling(batch)
        logc = self._log_columns()
        # d(natural)/d(sampling) = natural value on every log column (b included: the
        # shear ln b -> ln b - c d has unit Jacobian)
        with np.errstate(divide="ignore", invalid="ignore"):
            jac = np.sum(np.log(np.where(x[:, logc] > 0, x[:, logc], np.nan)), axis=1)
        lp = self.log_prob(x)
        out = lp + jac
        out[~np.isfinite(out)] = -np.inf
        return out

    @property
    def bounds(self):
        return (np.array([p.lower for p in self.parameters]),
                np.array([p.upper for p in self.parameters]))

    def log_prior(self, batch: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(batch)
        return sum(p.log_prior(x[:, j]) for j, p in enumerate(self.parameters))

    def log_prob(self, batch: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(batch, dtype=np.float64))
        lp = self.log_prior(x)
        out = np.full(x.shape[0], -np.inf)
        ok = np.isfinite(lp)
        if not ok.any():
            return out
        xs = x[ok]
        r = self.data.residuals(self.model, xs[:, : self.n_model], self.solver,
                                on_failure="nan")
        ll = ar1_loglike(r, xs[:, self.n_model], xs[:, self.n_model + 1])
        ll[~np.isfinite(ll)] = -np.inf
        out[ok] = lp[ok] + ll
        return out
