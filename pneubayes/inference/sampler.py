"""Bayesian identification with emcee: posteriors over the thin-port parameters.

The walkers start in a small ball around the refined point; the log-probability is
vectorised (one batched simulation per recording for half the ensemble); an HDF5
backend makes a killed run resume where it stopped; the run ends when the chain is
longer than ``tau_factor`` integrated autocorrelation times and every parameter has
split R-hat <= ``max_rhat`` and bulk ESS >= ``target_ess`` (arviz), or at ``max_steps``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pneubayes.inference.likelihood import WindowLikelihood
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


def arviz():
    """Import arviz without its import-time notice about the 1.0 refactor."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=FutureWarning, module="arviz")
        import arviz as az
    return az


@dataclass(frozen=True)
class SamplerSettings:
    """Every setting of an emcee run (saved with its results).

    n_walkers: ensemble size (0 = max(32, 4 x dimensions), rounded up to even).
    max_steps: hard limit on steps per walker. check_every: steps between checks.
    tau_factor: the chain must be this many autocorrelation times long.
    target_ess, max_rhat: convergence floors for every parameter.
    burn_taus: discard this many autocorrelation times at the start.
    init_scale: walker ball size relative to the refined covariance's std.
    """

    n_walkers: int = 0
    max_steps: int = 20000
    check_every: int = 250
    tau_factor: float = 50.0
    target_ess: float = 400.0
    max_rhat: float = 1.01
    burn_taus: float = 3.0
    init_scale: float = 1.0
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def prior_refresh_move(nuisance: dict[int, tuple[float, float]]):
    """An emcee MH move that redraws the nuisance coordinates uniformly in their ranges.

    The likelihood does not depend on them and their prior is uniform in sampling
    coordinates, so the proposal is symmetric and the move leaves the posterior
    invariant; it mixes those flat directions in one step instead of a random walk.
    """
    import emcee

    cols = np.array(sorted(nuisance))
    lo = np.array([nuisance[c][0] for c in cols])
    hi = np.array([nuisance[c][1] for c in cols])

    def propose(x0, random):
        x = x0.copy()
        x[:, cols] = lo + (hi - lo) * random.random_sample((x.shape[0], cols.size))
        return x, np.zeros(x.shape[0])

    return emcee.moves.MHMove(propose)


def _walkers(settings: SamplerSettings, ndim: int) -> int:
    n = settings.n_walkers or max(32, 4 * ndim)
    return n + (n % 2)


class BayesianIdentification:
    """emcee posterior of a model's parameters from recordings (scikit-learn contract).

    Parameters
    ----------
    model : Model
    solver : SolverConfig
    settings : SamplerSettings
    horizon_s, stride_s : float
        Likelihood windows (non-overlapping 2-s windows by default).
    backend_path : path or None
        HDF5 file for the chain; an existing compatible chain is resumed.
    progress : bool
        Show emcee's progress bar.
    """

    def __init__(self, model: Model, solver: SolverConfig, settings: SamplerSettings,
                 horizon_s: float = 2.0, stride_s: float = 2.0, backend_path=None,
                 progress: bool = True):
        self.model = model
        self.solver = solver
        self.settings = settings
        self.horizon_s = horizon_s
        self.stride_s = stride_s
        self.backend_path = backend_path
        self.progress = progress

    def _initial(self, like: WindowLikelihood, start: np.ndarray, cov, rng, n: int):
        lo, hi = like.bounds
        d = start.size
        if cov is None:
            std = 1e-3 * np.maximum(np.abs(start), 1e-2 * (hi - lo))
            draws = start + rng.normal(size=(n, d)) * std
        else:
            c = np.asarray(cov, dtype=np.float64)
            c = 0.5 * (c + c.T) + np.diag(1e-12 * np.maximum(np.abs(start), 1e-30) ** 2)
            draws = rng.multivariate_normal(start, c * self.settings.init_scale**2, size=n,
                                            method="eigh")
        eps = 1e-9 * (hi - lo)
        draws = np.clip(draws, lo + eps, hi - eps)
        z = like.to_sampling(draws)
        lp = like.log_prob_sampling(z)
        bad = ~np.isfinite(lp)
        if bad.all():
            raise FloatingPointError("no walker has a finite posterior density at the start")
        good = z[~bad]
        z[bad] = good[rng.integers(0, good.shape[0], bad.sum())]
        return z

    def fit(self, recordings, start: dict, noise_start: tuple[float, float] | None = None,
            covariance=None) -> "BayesianIdentification":
        """Sample the posterior starting around ``start`` (refined parameter dict).

        ``noise_start`` = (noise_scale_Pa, noise_ar1); estimated from the residuals at
        ``start`` when None. ``covariance`` (model parameters plus noise, optional) sizes
        the walker ball.
        """
        import emcee

        s = self.settings
        data = recordings if isinstance(recordings, WindowSet) else WindowSet(
            recordings, self.horizon_s, self.stride_s)
        like = WindowLikelihood(self.model, data, self.solver)
        theta = self.model.vector(start)
        if noise_start is None:
            r = data.residuals(self.model, theta[None], self.solver)[0]
            rho = float(np.clip(np.sum(r[:, 1:] * r[:, :-1]) / np.sum(r[:, :-1] ** 2), 0, 0.99))
            sig = float(np.std(r[:, 1:] - rho * r[:, :-1]))
            noise_start = (max(sig, 2.0), rho)
        x0 = np.concatenate([theta, np.asarray(noise_start, dtype=np.float64)])
        ndim = x0.size
        nw = _walkers(s, ndim)
        rng = np.random.default_rng(s.seed)
        cov = None
        if covariance is not None:
            cov = np.zeros((ndim, ndim))
            c = np.asarray(covariance)
            cov[: c.shape[0], : c.shape[1]] = c
            for j, v in zip(range(c.shape[0], ndim), noise_start):
                cov[j, j] = (0.05 * max(abs(v), 1e-3)) ** 2
        backend = None
        resume = False
        if self.backend_path is not None:
            path = Path(self.backend_path)
            path.parent.mkdir(parents=True, exist_ok=True)
            backend = emcee.backends.HDFBackend(str(path), name="pneubayes")
            if path.exists():
                try:
                    it = backend.iteration
                    shape = backend.shape
                except (OSError, KeyError, AttributeError):
                    it, shape = 0, None
                resume = it > 0 and shape == (nw, ndim)
            if not resume:
                backend.reset(nw, ndim)
        moves = [(emcee.moves.DEMove(), 0.7), (emcee.moves.DESnookerMove(), 0.1)]
        nuisance = like.nuisance()
        moves.append((prior_refresh_move(nuisance), 0.2) if nuisance
                     else (emcee.moves.DEMove(), 0.2))
        sampler = emcee.EnsembleSampler(nw, ndim, like.log_prob_sampling, vectorize=True,
                                        backend=backend, moves=moves)
        # emcee draws from its own RandomState; seed it (never numpy's global state)
        sampler.random_state = np.random.RandomState(s.seed).get_state()
        if resume:
            state = None
        else:
            state = self._initial(like, x0, cov, rng, nw)
        t0 = time.perf_counter()
        converged = False
        diag: dict = {}
        while sampler.iteration < s.max_steps:
            n = min(s.check_every, s.max_steps - sampler.iteration)
            state = sampler.run_mcmc(state, n, progress=self.progress,
                                     skip_initial_state_check=True)
            diag = self._diagnose(sampler, like)
            if diag["converged"]:
                converged = True
                break
        self.wall_time_s_ = time.perf_counter() - t0
        self.resumed_ = resume
        self.names_ = like.names
        self.sampler_ = sampler
        self.likelihood_ = like
        self.converged_ = converged
        self.diagnostics_ = diag
        self.burn_ = diag["burn"]
        z = sampler.get_chain(discard=self.burn_)  # (steps, walkers, D), sampling coords
        self.chain_ = like.from_sampling(z.reshape(-1, ndim)).reshape(z.shape)
        self.acceptance_fraction_ = float(np.mean(sampler.acceptance_fraction))
        return self

    def _diagnose(self, sampler, like: WindowLikelihood) -> dict:
        """Autocorrelation time (sampling coordinates), R-hat and ESS (natural ones)."""
        names = like.names
        s = self.settings
        chain = sampler.get_chain()
        n = chain.shape[0]
        tau = np.asarray(sampler.get_autocorr_time(tol=0), dtype=np.float64)
        tau_max = float(np.nanmax(tau)) if np.all(np.isfinite(tau)) else float("inf")
        burn = int(min(n // 2, np.ceil(s.burn_taus * tau_max))) if np.isfinite(tau_max) \
            else n // 2
        post = chain[burn:]
        nat = like.from_sampling(post.reshape(-1, post.shape[-1]))
        rhat, ess = self.rhat_ess(nat.reshape(post.shape), names)
        ok = (np.isfinite(tau_max) and n >= s.tau_factor * tau_max
              and max(rhat.values()) <= s.max_rhat and min(ess.values()) >= s.target_ess)
        return {"steps": n, "tau": dict(zip(names, tau.tolist())), "tau_max": tau_max,
                "burn": burn, "rhat": rhat, "ess": ess, "converged": bool(ok)}

    @staticmethod
    def rhat_ess(post: np.ndarray, names) -> tuple[dict, dict]:
        """Rank-normalised split R-hat and bulk ESS per parameter (walkers as chains)."""
        az = arviz()
        with warnings.catch_warnings():
            # walkers are the chains by design, even when a short run has fewer draws
            warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
            idata = az.from_dict(posterior={n: post[:, :, j].T for j, n in enumerate(names)})
            rh = az.rhat(idata)
            es = az.ess(idata, method="bulk")
        return ({n: float(rh[n]) for n in names}, {n: float(es[n]) for n in names})

    # ------------------------------------------------------------------ results
    def samples(self) -> np.ndarray:
        """Posterior draws after burn-in, flattened ``(S, D)``."""
        c = self.chain_
        return c.reshape(-1, c.shape[-1])

    def model_samples(self) -> np.ndarray:
        """Draws of the model parameters only ``(S, P)``."""
        return self.samples()[:, : self.model.n_parameters]

    def median_params(self) -> dict:
        return self.model.as_dict(np.median(self.model_samples(), axis=0))

    def summary(self) -> dict:
        """Per parameter: median, 5 % and 95 % quantiles, R-hat, ESS, tau."""
        x = self.samples()
        q = np.quantile(x, [0.05, 0.5, 0.95], axis=0)
        d = self.diagnostics_
        return {n: {"median": float(q[1, j]), "q05": float(q[0, j]), "q95": float(q[2, j]),
                    "rhat": d["rhat"][n], "ess": d["ess"][n], "tau": d["tau"][n]}
                for j, n in enumerate(self.names_)}

    def inference_data(self, attrs: dict | None = None):
        """The post-burn chain as arviz InferenceData (walkers as chains)."""
        az = arviz()
        c = self.chain_
        lp = self.sampler_.get_log_prob(discard=self.burn_)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
            return self._to_idata(az, c, lp, attrs)

    def _to_idata(self, az, c, lp, attrs):
        return az.from_dict(
            posterior={n: c[:, :, j].T for j, n in enumerate(self.names_)},
            sample_stats={"lp": lp.T},
            attrs={**(attrs or {}), "sampler": "emcee", "burn": int(self.burn_),
                   "n_walkers": int(c.shape[1])})
