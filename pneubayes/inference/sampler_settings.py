"""The settings of an emcee run (:class:`~pneubayes.inference.sampler.BayesianIdentification`),
saved with its results."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class SamplerSettings:
    """Every setting of an emcee run (saved with its results).

    Attributes
    ----------
    n_walkers, max_steps, seed : int
        Ensemble size (0: max(32, 4 x dimensions); rounded up to a multiple of 2 and of
        ``rhat_groups``); steps per walker at most, adaptation included; the run's seed.
    check_every, tau_factor : int, float
        Production steps between convergence checks; the production chain must be this
        many autocorrelation times long.
    target_ess, max_rhat, rhat_groups : float, float, int
        Convergence floors for every parameter (bulk and tail ESS; split R-hat over this
        many groups of walkers, pooled step by step; 0: every walker a chain).
    adapt_rounds, adapt_steps, adapt_acceptance : int, int, float
        Adaptation (discarded as burn-in): at most this many rounds of this many steps,
        ending after the first round with a proposal whose acceptance reaches the
        fraction (> 1: never early). Round 0 runs differential-evolution moves; each
        later round adds an independence proposal fitted to the round before.
    proposal_df, proposal_scale, proposal_fit_fraction : float
        The independence proposal: a multivariate Student-t with these degrees of
        freedom and this inflation of the covariance fitted to this last fraction of
        the round before.
    independence_weight : float
        Probability of the independence move in a step once fitted.
    readapt_below_acceptance, max_readapts : float, int
        An unconverged check with acceptance below this refits the proposal and
        restarts production there (everything before discarded), at most this often.
    init_scale, laplace_start : float, bool
        Walker ball size in the Laplace approximation's SDs; or start from the
        posterior's own Laplace draws (:func:`~pneubayes.inference.laplace.laplace_approximation`).
    centre_iterations, centre_tolerance_nats : int, float
        Newton steps moving the start from the refined point towards the posterior's
        mode (0: none), stopping once a step's predicted rise is under this, nats.
    max_solver_jitter_nats, max_solver_tightenings : float, int
        While the SD across the starting walkers of the log-density's change under a
        10x tighter solver exceeds this, nats, the solver is tightened 10x, at most this
        many times.
    """

    n_walkers: int = 0
    max_steps: int = 20000
    check_every: int = 50
    tau_factor: float = 50.0
    target_ess: float = 400.0
    max_rhat: float = 1.01
    rhat_groups: int = 4
    adapt_rounds: int = 3
    adapt_steps: int = 150
    adapt_acceptance: float = 0.35
    proposal_df: float = 5.0
    proposal_scale: float = 1.2
    proposal_fit_fraction: float = 0.5
    independence_weight: float = 0.6
    readapt_below_acceptance: float = 0.35
    max_readapts: int = 3
    init_scale: float = 1.0
    laplace_start: bool = True
    centre_iterations: int = 3
    centre_tolerance_nats: float = 0.01
    max_solver_jitter_nats: float = 0.3
    max_solver_tightenings: int = 3
    seed: int = 0

    def __post_init__(self):
        for name in ("max_steps", "check_every", "adapt_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"SamplerSettings.{name} must be >= 1, "
                                 f"got {getattr(self, name)}")
        for name in ("n_walkers", "seed"):
            if getattr(self, name) < 0:
                raise ValueError(f"SamplerSettings.{name} must be >= 0 (n_walkers 0: "
                                 f"automatic), got {getattr(self, name)}")
        if self.adapt_rounds < 1:
            raise ValueError(f"SamplerSettings.adapt_rounds must be >= 1, "
                             f"got {self.adapt_rounds}")
        if not self.max_solver_jitter_nats > 0.0 or self.max_solver_tightenings < 0:
            raise ValueError("SamplerSettings: max_solver_jitter_nats must be > 0 and "
                             "max_solver_tightenings >= 0")
        if self.rhat_groups < 0:
            raise ValueError(f"SamplerSettings.rhat_groups must be >= 0, got {self.rhat_groups}")
        if self.centre_iterations < 0:
            raise ValueError("SamplerSettings.centre_iterations must be >= 0, "
                             f"got {self.centre_iterations}")
        if not self.centre_tolerance_nats >= 0.0:
            raise ValueError("SamplerSettings.centre_tolerance_nats must be >= 0, "
                             f"got {self.centre_tolerance_nats}")
        if not 0.0 < self.proposal_fit_fraction <= 1.0:
            raise ValueError("SamplerSettings.proposal_fit_fraction must be in (0, 1], "
                             f"got {self.proposal_fit_fraction}")
        if not 0.0 <= self.independence_weight < 1.0:
            raise ValueError("SamplerSettings.independence_weight must be in [0, 1), "
                             f"got {self.independence_weight}")

    @property
    def burn(self) -> int:
        """Most steps of adaptation, all discarded (fewer if it ends early)."""
        return self.adapt_rounds * self.adapt_steps

    def to_dict(self) -> dict:
        return asdict(self)
