"""Bayesian identification with emcee: posteriors over the thin-port parameters.

The walkers start around the log-posterior's centre, spread as the refined point's
Laplace approximation says (:mod:`pneubayes.inference.walker_start`); the log-probability
is vectorised (one batched simulation per recording per move); an HDF5 backend makes a
killed run resume where it stopped.

With thousands of residuals the posterior is close to Gaussian in the sampling
coordinates, and a random-walk ensemble mixes slowly there (tau ~ 100 steps in 12
dimensions). So the run adapts: an independence Metropolis-Hastings move whose
Student-t proposal is the posterior's Laplace approximation in the first round (which
also places the walkers) and is refitted to the round before in each later one, then
production with that proposal frozen (a fixed proposal keeps the chain Markov and the
posterior invariant). Differential evolution and a Gibbs move for
the coordinates only the prior informs stay in the mixture for robustness.
The run ends when the production chain is longer than ``tau_factor`` integrated
autocorrelation times and every parameter has split R-hat <= ``max_rhat`` (over groups
of walkers, see ``SamplerSettings.rhat_groups``) and bulk and tail ESS >= ``target_ess``
(arviz), or at ``max_steps``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from pneubayes import interrupt
from pneubayes.evaluation import PAPER_HORIZON_S
from pneubayes.inference.chain_store import open_chain, store_burn, stored_burn
from pneubayes.inference.likelihood import WindowLikelihood
from pneubayes.inference.moves import StudentTProposal, moved_fraction, nuisance_gibbs_move
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.inference.walker_start import posterior_centre, walker_ball, with_density
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig


def arviz():
    """Import arviz without its import-time notice about the 1.0 refactor."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=FutureWarning, module="arviz")
        import arviz as az
    return az


def settle_solver(model: Model, data: WindowSet, solver: SolverConfig, z: np.ndarray,
                  max_jitter_nats: float, max_tightenings: int):
    """Tighten ``solver`` until the log-density's numerical roughness is small.

    The roughness is the SD, across the points ``z`` (sampling coordinates, e.g. the
    starting walkers), of the difference between the log-density with the solver and
    with one 10x tighter (:meth:`SolverConfig.tightened`). While it exceeds
    ``max_jitter_nats`` the solver is tightened 10x, at most ``max_tightenings`` times.
    Returns (likelihood, solver, roughness in nats).
    """
    like = WindowLikelihood(model, data, solver)
    lp = like.log_prob_sampling(z)
    for k in range(max_tightenings + 1):
        finer = solver.tightened(10.0)
        like_f = WindowLikelihood(model, data, finer)
        lp_f = like_f.log_prob_sampling(z)
        ok = np.isfinite(lp) & np.isfinite(lp_f)
        jitter = float(np.std(lp[ok] - lp_f[ok])) if ok.sum() > 1 else float("inf")
        if jitter <= max_jitter_nats or k == max_tightenings:
            return like, solver, jitter
        solver, like, lp = finer, like_f, lp_f
    raise AssertionError("unreachable")


def _walkers(settings: SamplerSettings, ndim: int) -> int:
    n = settings.n_walkers or max(32, 4 * ndim)
    step = int(np.lcm(2, max(settings.rhat_groups, 1)))
    return -(-n // step) * step


class ChainDraws:
    """The draws a fitted posterior holds in ``chain_`` ``(steps or draws, chains, D)``:
    the model's parameters, then the noise's (emcee's post-burn chain, the Laplace
    approximation's draws)."""

    def samples(self) -> np.ndarray:
        """The draws, flattened ``(S, D)``."""
        c = self.chain_
        return c.reshape(-1, c.shape[-1])

    def model_samples(self) -> np.ndarray:
        """Draws of the model parameters only ``(S, P)``."""
        return self.samples()[:, : self.model.n_parameters]

    def median_params(self) -> dict:
        return self.model.as_dict(np.median(self.model_samples(), axis=0))


class BayesianIdentification(ChainDraws):
    """emcee posterior of a model's parameters from recordings (scikit-learn contract).

    The noise scale and AR(1) coefficient are integrated out of the likelihood
    (:mod:`pneubayes.inference.likelihood`) and drawn afterwards from their exact
    conditional, one draw per stored sample; results cover both.

    Parameters
    ----------
    model : Model
    solver : SolverConfig
    settings : SamplerSettings
    horizon_s, stride_s : float
        Likelihood windows (non-overlapping 2-s windows by default).
    backend_path : path or None
        HDF5 file for the chain (:mod:`pneubayes.inference.chain_store`). A chain there
        of the same posterior is resumed; one of another posterior is an error (it is
        never overwritten).
    progress : bool
        Show emcee's progress bar.
    log : callable or None
        Receives a line after every block of steps: the step, the diagnostics and an
        estimate of the time left (None: silent).
    """

    def __init__(self, model: Model, solver: SolverConfig, settings: SamplerSettings,
                 horizon_s: float = PAPER_HORIZON_S, stride_s: float = PAPER_HORIZON_S,
                 backend_path=None,
                 progress: bool = True, log=None):
        self.model = model
        self.solver = solver
        self.settings = settings
        self.horizon_s = horizon_s
        self.stride_s = stride_s
        self.backend_path = backend_path
        self.progress = progress
        self.log = log

    def _advance(self, sampler, state, n: int):
        """``n`` steps, as ``run_mcmc`` takes them (the same draws), stopping cleanly
        between steps when a stop is requested (:mod:`pneubayes.interrupt`); every step
        is already in the chain file then."""
        start = sampler.get_last_sample() if state is None else state  # None: resumed
        last = start
        for step in sampler.sample(start, iterations=n, progress=self.progress,
                                   skip_initial_state_check=True):
            last = step
            interrupt.check()
        return last

    def _report(self, backend, burn: int, diag: dict | None, t0: float, start_step: int):
        """One progress line: where the run is and how long it may still take."""
        if self.log is None:
            return
        s = self.settings
        n = backend.iteration
        done = n - start_step
        per_step = (time.perf_counter() - t0) / done if done > 0 else float("nan")
        if not diag or n <= burn:
            left = max(burn - n, 0) + s.check_every
            what = f"adapting (production from step {burn} at the latest)"
        else:
            ess = min(min(diag["ess"].values()), min(diag["ess_tail"].values()))
            rhat = max(diag["rhat"].values())
            prod = n - burn
            # ESS grows about linearly with the production length
            need = prod * (s.target_ess / ess - 1.0) if ess > 0 else float("inf")
            need = max(need, s.tau_factor * diag["tau_max"] - prod, 0.0)
            left = min(need, s.max_steps - n)
            what = f"R-hat {rhat:.3f}, min ESS {ess:.0f} of {s.target_ess:.0f}"
        eta = left * per_step
        eta_text = f"about {eta / 60:.1f} min left" if np.isfinite(eta) else "time left unknown"
        self.log(f"emcee: step {n} of at most {s.max_steps}; {what}; "
                 f"{per_step:.2f} s/step, {eta_text}")

    def _moves(self, like: WindowLikelihood, proposal: StudentTProposal | None):
        import emcee

        rest = [(emcee.moves.DEMove(), 0.8)]
        rest.append((nuisance_gibbs_move(like), 0.2) if like.nuisance()
                    else (emcee.moves.DESnookerMove(), 0.2))
        if proposal is None:
            return rest
        w = self.settings.independence_weight
        return [(proposal.move(like), w)] + [(m, (1 - w) * p) for m, p in rest]

    def _laplace_start(self, like: WindowLikelihood, x0: np.ndarray, information,
                       rng: np.random.Generator, nw: int):
        """``(proposal, walkers)`` from the posterior's Laplace approximation
        (``SamplerSettings.laplace_start``), or ``(None, None)`` where it cannot be taken."""
        # laplace builds on this module (the draws' container): imported where used
        from pneubayes.inference.laplace import laplace_approximation, truncated_draws

        s = self.settings
        try:
            fit = laplace_approximation(like, x0, information, s.centre_iterations,
                                        s.centre_tolerance_nats)
            z = with_density(like, truncated_draws(like, fit.mean_z, fit.ident, fit.cov_z,
                                                   rng, nw), rng)
        except FloatingPointError as exc:
            if self.log is not None:
                self.log(f"emcee: no Laplace start ({exc}); the walker ball instead")
            return None, None
        proposal = StudentTProposal.from_gaussian(fit.mean_z[fit.ident], fit.cov_z,
                                                  fit.ident, like.nuisance(),
                                                  s.proposal_df, s.proposal_scale)
        if self.log is not None:
            self.log(f"emcee: walkers from the posterior's Laplace approximation "
                     f"({fit.eigenvalues.size} identified directions"
                     + (f", mode on the bound of {', '.join(fit.bounded)}" if fit.bounded
                        else "") + ")")
        return proposal, z

    def _proposal(self, chain: np.ndarray, like: WindowLikelihood, end: int):
        """The independence proposal fitted to the last ``proposal_fit_fraction`` of the
        ``adapt_steps`` steps before ``end``."""
        s = self.settings
        n = max(1, int(round(s.proposal_fit_fraction * s.adapt_steps)))
        seg = chain[max(0, end - n): end]
        return StudentTProposal.fit(seg.reshape(-1, chain.shape[-1]), like.nuisance(),
                                    s.proposal_df, s.proposal_scale)

    def fit(self, recordings, start: dict, information=None) -> "BayesianIdentification":
        """Sample the posterior starting around ``start`` (refined parameter dict).

        ``information`` (optional): the Fisher information of the model parameters at
        ``start`` (:attr:`TrajectoryRefiner.information_
        <pneubayes.inference.refine.TrajectoryRefiner>`); it sizes the walker ball.
        """
        import emcee

        s = self.settings
        data = recordings if isinstance(recordings, WindowSet) else WindowSet(
            recordings, self.horizon_s, self.stride_s)
        like = WindowLikelihood(self.model, data, self.solver)
        x0 = self.model.vector(start)
        ndim = x0.size
        nw = _walkers(s, ndim)
        rng = np.random.default_rng(s.seed)
        backend, resume = open_chain(self.backend_path, self.model, data, nw, ndim)
        # the starting walkers are drawn (seeded) on a resume too: the solver check runs
        # on them, so a resumed chain continues with the solver it was started with
        state = walker_ball(like, x0, information, rng, nw, s.init_scale)
        like, solver, jitter = settle_solver(self.model, data, self.solver, state,
                                             s.max_solver_jitter_nats,
                                             s.max_solver_tightenings)
        first = None  # the first round's proposal (None: differential evolution only)
        if resume:
            state = None
        elif information is not None and s.laplace_start:
            first, state = self._laplace_start(like, x0, information, rng, nw)
        if (not resume and first is None and information is not None
                and s.centre_iterations > 0):
            # the refined point is a least-squares optimum, not the posterior's centre:
            # move the ball to the posterior's own Newton centre (few batched calls)
            x0 = posterior_centre(like, x0, information, s.centre_iterations,
                                  s.centre_tolerance_nats).x
            state = walker_ball(like, x0, information, rng, nw, s.init_scale)
        t0 = time.perf_counter()
        start_step = backend.iteration
        self.resumed_from_step_ = start_step if resume else 0
        if resume and self.log is not None:
            self.log(f"emcee: resumed from step {start_step} ({self.backend_path})")
        converged = False
        diag: dict = {}
        # emcee draws from its own RandomState: seeded here, handed from one sampler
        # object to the next (never numpy's global state)
        random_state = np.random.RandomState(s.seed).get_state()

        def sampler_for(proposal):
            smp = emcee.EnsembleSampler(nw, ndim, like.emcee_target, vectorize=True,
                                        backend=backend, moves=self._moves(like, proposal))
            smp.random_state = random_state
            return smp

        # adaptation: rounds of adapt_steps, each with the proposal of the round before;
        # it ends after the first round with a proposal that accepts adapt_acceptance
        end = stored_burn(backend, s.burn) if resume else s.burn
        while backend.iteration < min(end, s.max_steps):
            r = backend.iteration // s.adapt_steps
            proposal = (first if r == 0 else
                        self._proposal(backend.get_chain(), like, r * s.adapt_steps))
            sampler = sampler_for(proposal)
            n = min((r + 1) * s.adapt_steps, s.max_steps) - backend.iteration
            state = self._advance(sampler, state, n)
            random_state = sampler.random_state
            self._report(backend, end, None, t0, start_step)
            if ((r >= 1 or first is not None)
                    and backend.iteration == (r + 1) * s.adapt_steps < end
                    and moved_fraction(backend.get_chain()[-s.adapt_steps - 1:])
                    >= s.adapt_acceptance):
                end = backend.iteration
                store_burn(backend, end)
        # production with the proposal frozen (refitted if it proves stale, see settings)
        burn = end
        adapted = backend.iteration >= burn
        readapts = 0 if burn <= s.burn else None  # None: unknown after a resume
        sampler = sampler_for(self._proposal(backend.get_chain(), like, burn)
                              if adapted else None)
        while True:
            if backend.iteration > burn:
                diag = self._diagnose(backend, like, burn)
                self._report(backend, burn, diag, t0, start_step)
                if diag["converged"]:
                    converged = True
                    break
                acc = moved_fraction(backend.get_chain()[-s.check_every - 1:])
                if (acc < s.readapt_below_acceptance and (readapts or 0) < s.max_readapts
                        and backend.iteration - burn >= s.check_every
                        and backend.iteration + s.check_every < s.max_steps):
                    burn = backend.iteration
                    readapts = (readapts or 0) + 1
                    store_burn(backend, burn)
                    random_state = sampler.random_state
                    sampler = sampler_for(self._proposal(backend.get_chain(), like, burn))
            if backend.iteration >= s.max_steps:
                break
            n = min(s.check_every, s.max_steps - backend.iteration)
            state = self._advance(sampler, state, n)
        if not diag:
            diag = self._diagnose(backend, like, burn)
        diag["readapts"] = readapts
        diag["solver"] = solver.to_dict()
        diag["solver_jitter_nats"] = jitter
        self.wall_time_s_ = time.perf_counter() - t0
        self.resumed_ = resume
        self.names_ = like.names + like.noise_names
        self.sampler_ = sampler
        self.likelihood_ = like
        self.solver_ = solver
        self.converged_ = converged
        self.diagnostics_ = diag
        self.burn_ = diag["burn"]
        self.chain_ = self._natural_chain(backend, like, self.burn_)
        self.acceptance_fraction_ = float(np.mean(backend.accepted / backend.iteration))
        return self

    def _natural_chain(self, backend, like: WindowLikelihood, burn: int) -> np.ndarray:
        """Post-burn draws in natural parameters, noise draws appended ``(S, W, P + 2)``."""
        z = backend.get_chain(discard=burn)
        sums = backend.get_blobs(discard=burn)
        shape = z.shape
        x = like.from_sampling(z.reshape(-1, shape[-1]))
        noise = like.draw_noise(sums.reshape(-1, sums.shape[-1]), np.random.default_rng(
            [self.settings.seed, 1]))
        return np.concatenate([x, noise], axis=1).reshape(shape[0], shape[1], -1)

    def _diagnose(self, backend, like: WindowLikelihood, burn: int) -> dict:
        """Autocorrelation time (sampling coordinates), R-hat and ESS (natural ones) of
        the chain after ``burn`` (production start)."""
        import emcee

        s = self.settings
        names = like.names + like.noise_names
        n = backend.iteration
        adapted = n > burn
        if n - burn < min(s.check_every, n // 2):
            # stopped (max_steps) before production really began: report the last half,
            # never converged (adaptation unfinished or too short for the tau criterion)
            burn = n // 2
        post = backend.get_chain(discard=burn)
        with np.errstate(invalid="ignore", divide="ignore"):  # a walker that never moved
            tau = np.asarray(emcee.autocorr.integrated_time(post, tol=0), dtype=np.float64)
        tau_max = float(np.nanmax(tau)) if np.all(np.isfinite(tau)) else float("inf")
        nat = self._natural_chain(backend, like, burn)
        rhat, ess, ess_tail = self.rhat_ess(nat, names, s.rhat_groups)
        ok = (adapted and np.isfinite(tau_max) and post.shape[0] >= s.tau_factor * tau_max
              and max(rhat.values()) <= s.max_rhat
              and min(min(ess.values()), min(ess_tail.values())) >= s.target_ess)
        tau_d = dict(zip(like.names, tau.tolist()))
        tau_d.update({k: float("nan") for k in like.noise_names})
        return {"steps": n, "tau": tau_d, "tau_max": tau_max,
                "burn": burn, "rhat": rhat, "rhat_groups": s.rhat_groups, "ess": ess,
                "ess_tail": ess_tail, "converged": bool(ok)}

    @staticmethod
    def rhat_ess(post: np.ndarray, names, groups: int = 0) -> tuple[dict, dict, dict]:
        """Per parameter of ``post`` (steps, walkers, parameters): rank-normalised split
        R-hat over ``groups`` chains of pooled walkers (0: walkers as chains), and bulk
        and tail ESS with the walkers as chains."""
        az = arviz()
        s, w, _ = post.shape
        if groups and w % groups:
            raise ValueError(f"rhat_ess: {w} walkers do not split into {groups} groups")
        # a group's chain takes its walkers step by step (time order kept, so the split
        # halves are the run's halves); ESS needs single-walker autocorrelations
        pooled = (post if not groups else
                  post.reshape(s, groups, w // groups, -1).transpose(1, 0, 2, 3)
                  .reshape(groups, s * (w // groups), -1))
        with warnings.catch_warnings():
            # walkers are the chains by design, even when a short run has fewer draws
            warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
            idata = az.from_dict(posterior={n: post[:, :, j].T for j, n in enumerate(names)})
            rh = az.rhat(idata if not groups else az.from_dict(
                posterior={n: pooled[:, :, j] for j, n in enumerate(names)}))
            es = az.ess(idata, method="bulk")
            et = az.ess(idata, method="tail")
        return ({n: float(rh[n]) for n in names}, {n: float(es[n]) for n in names},
                {n: float(et[n]) for n in names})

    # ------------------------------------------------------------------ results
    def summary(self) -> dict:
        """Per parameter: median, 5 % and 95 % quantiles, R-hat, bulk ESS, tau."""
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
