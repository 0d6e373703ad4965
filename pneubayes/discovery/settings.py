"""Every setting of the discovery loop (``pneubayes discover``), saved with its result."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from pneubayes.discovery.disagreement import RegimeSettings
from pneubayes.discovery.library import LibraryGrid
from pneubayes.effects import catalogue_parameter_names
from pneubayes.effects.path import LINE_MAX_SEGMENTS
from pneubayes.inference.importance import IMPORTANCE_CHECK_DRAWS
from pneubayes.inference.laplace import LAPLACE_DRAWS, check_draw_counts
from pneubayes.inference.pipeline import FitSettings
from pneubayes.model import Model, check_bound_overrides
from pneubayes.simulation import SolverConfig


@dataclass(frozen=True)
class DiscoverySettings:
    """Every setting of ``pneubayes discover`` (saved in discovery.json).

    ``docs/discovery.md`` explains each stage these steer; ``docs/history.md`` the cases
    behind the defaults. Errors are held-out 2-s RMSEs, the *gap* the error above the
    noise floor; a model is *far* above ``gap_fallback_ratio`` x the floor (0: never).

    Attributes
    ----------
    holdout_fraction, holdout_recordings, bounds
        The last fraction of each recording is held out, or (> 0) the last recordings
        whole; parameter name -> [lower, upper] in every model the loop fits.
    block, threshold_t, n_bags, chunk_rows, min_inclusion, grid, regimes, seed
        The search (:class:`GroupedSINDy`: rows of ``block`` one-step errors, bagged); a
        group is supported at ``min_inclusion``; the candidates' strengths; regime bins.
    library_solver : SolverConfig
        The solver of the search's one-step errors.
    max_p_value, score_dof, min_gain_noise_share, min_gain_gap_share : float
        A trial passes the signed-rank test at this level, raises the Student-t log
        predictive density, and gains these shares of the noise floor and of the gap.
    max_effects, max_trials_per_round : int
        Rounds that add (a pair is one); supported groups refitted per round.
    max_refine_restarts, refine_restart_min_gain : int, float
        Restarts of a refinement its budget ended, while its second half gains this share.
    gap_fallback_ratio, fallback_min_inclusion, try_all_supported, try_all_on_gap
        When far, groups of this inclusion are tried too; MoreSupported; LastResort.
    last_resort_min_gap_closed, last_resort_best_gap_closed : float
        The gap share a last resort, runner-up or pair must close; LastResort also runs
        when the best passing trial closes less than the second (0: only if none passed).
    revisit_runner_ups, pair_members, max_form_swaps, open_form_min_noise_ratio
        RunnerUps; Pairs of at most this many trials (0: off); OtherForms' swaps at most;
        OpenForm while above this x the noise floor (0: off).
    tube_line_segments, tube_line_cutoff_Hz, tube_line_form : int, float, str
        A tube's outside form: ``"wave"``, or ``"line"`` with the fewest cells (3 to the
        segments) whose cut-off n / (pi T) reaches this; 0 segments: transport only.
    form_settled_ratio, later_forms_min_share, later_form_screen_share : float
        Later forms are fitted while no trial is within this x the noise floor, if the
        first form gains this share of the round's best; the line's screen share.
    fit, posterior, posterior_method, laplace_draws, laplace_check_draws
        Every fit's settings; the final model's posterior, ``"emcee"`` or ``"laplace"``.
    """

    holdout_fraction: float = 1.0 / 3.0
    holdout_recordings: int = 0
    bounds: dict = field(default_factory=dict)
    block: int = 5
    grid: LibraryGrid = field(default_factory=LibraryGrid)
    regimes: RegimeSettings = field(default_factory=RegimeSettings)
    threshold_t: float = 5.0
    n_bags: int = 40
    chunk_rows: int = 200
    min_inclusion: float = 0.6
    max_effects: int = 4
    max_trials_per_round: int = 3
    max_refine_restarts: int = 3
    refine_restart_min_gain: float = 1e-4
    max_p_value: float = 0.01
    gap_fallback_ratio: float = 2.0
    fallback_min_inclusion: float = 0.25
    try_all_supported: bool = True
    try_all_on_gap: bool = True
    last_resort_min_gap_closed: float = 0.25
    last_resort_best_gap_closed: float = 0.25
    min_gain_noise_share: float = 0.01
    min_gain_gap_share: float = 0.01
    revisit_runner_ups: bool = True
    pair_members: int = 3
    max_form_swaps: int = 2
    open_form_min_noise_ratio: float = 1.5
    score_dof: float = 4.0
    tube_line_segments: int = 8
    tube_line_cutoff_Hz: float = 300.0
    tube_line_form: str = "wave"
    form_settled_ratio: float = 1.05
    later_forms_min_share: float = 0.25
    later_form_screen_share: float = 0.5
    fit: FitSettings = field(default_factory=FitSettings)
    posterior: bool = True
    posterior_method: str = "emcee"
    laplace_draws: int = LAPLACE_DRAWS
    laplace_check_draws: int = IMPORTANCE_CHECK_DRAWS
    library_solver: SolverConfig = field(default_factory=SolverConfig.standard)
    seed: int = 0

    def __post_init__(self):
        if not 0.0 < self.holdout_fraction < 1.0:
            raise ValueError(f"holdout_fraction must be in (0, 1), got {self.holdout_fraction}")
        bounds = check_bound_overrides(self.bounds, "DiscoverySettings.bounds")
        unknown = sorted(set(bounds) - set(Model().parameter_names)
                         - catalogue_parameter_names())
        if unknown:
            raise ValueError(f"DiscoverySettings.bounds: {unknown} name no parameter of the "
                             "thin-port model or of any catalogue effect")
        object.__setattr__(self, "bounds", {k: list(v) for k, v in bounds.items()})
        if isinstance(self.holdout_recordings, bool) or not isinstance(
                self.holdout_recordings, int) or self.holdout_recordings < 0:
            raise ValueError("holdout_recordings must be an integer >= 0, got "
                             f"{self.holdout_recordings!r}")
        if (isinstance(self.pair_members, bool) or not isinstance(self.pair_members, int)
                or self.pair_members < 0 or self.pair_members == 1):
            raise ValueError("pair_members must be 0 (off) or an integer >= 2, got "
                             f"{self.pair_members!r}")
        if (isinstance(self.max_form_swaps, bool) or not isinstance(self.max_form_swaps, int)
                or self.max_form_swaps < 0):
            raise ValueError("max_form_swaps must be an integer >= 0, got "
                             f"{self.max_form_swaps!r}")
        if not (self.open_form_min_noise_ratio == 0.0
                or self.open_form_min_noise_ratio >= 1.0):
            raise ValueError("open_form_min_noise_ratio must be 0 (off) or >= 1, got "
                             f"{self.open_form_min_noise_ratio}")
        if not 0.0 < self.min_inclusion <= 1.0:
            raise ValueError(f"min_inclusion must be in (0, 1], got {self.min_inclusion}")
        if not 0.0 < self.fallback_min_inclusion <= 1.0:
            raise ValueError(f"fallback_min_inclusion must be in (0, 1], got "
                             f"{self.fallback_min_inclusion}")
        if not (self.gap_fallback_ratio == 0.0 or self.gap_fallback_ratio >= 1.0):
            raise ValueError(f"gap_fallback_ratio must be 0 (off) or >= 1, got "
                             f"{self.gap_fallback_ratio}")
        if not self.score_dof > 2.0:
            raise ValueError(f"score_dof must be > 2 (a finite variance), got "
                             f"{self.score_dof}")
        if not 0.0 <= self.last_resort_best_gap_closed <= 1.0:
            raise ValueError("last_resort_best_gap_closed must be in [0, 1], got "
                             f"{self.last_resort_best_gap_closed}")
        if not 0.0 <= self.last_resort_min_gap_closed <= 1.0:
            raise ValueError("last_resort_min_gap_closed must be in [0, 1], got "
                             f"{self.last_resort_min_gap_closed}")
        if not 0.0 <= self.min_gain_noise_share <= 1.0:
            raise ValueError("min_gain_noise_share must be in [0, 1], got "
                             f"{self.min_gain_noise_share}")
        if not 0.0 <= self.min_gain_gap_share <= 1.0:
            raise ValueError("min_gain_gap_share must be in [0, 1], got "
                             f"{self.min_gain_gap_share}")
        if self.block < 1:
            raise ValueError(f"block must be >= 1, got {self.block}")
        if not (self.form_settled_ratio == 0.0 or self.form_settled_ratio >= 1.0):
            raise ValueError(f"form_settled_ratio must be 0 (fit every form) or >= 1, got "
                             f"{self.form_settled_ratio}")
        if not 0.0 <= self.refine_restart_min_gain < 1.0:
            raise ValueError(f"refine_restart_min_gain must be in [0, 1), got "
                             f"{self.refine_restart_min_gain}")
        if not 0.0 <= self.later_form_screen_share <= 1.0:
            raise ValueError(f"later_form_screen_share must be in [0, 1], got "
                             f"{self.later_form_screen_share}")
        if not 0.0 <= self.later_forms_min_share <= 1.0:
            raise ValueError(f"later_forms_min_share must be in [0, 1], got "
                             f"{self.later_forms_min_share}")
        if not (math.isfinite(self.tube_line_cutoff_Hz) and self.tube_line_cutoff_Hz > 0):
            raise ValueError(f"tube_line_cutoff_Hz must be finite and > 0, got "
                             f"{self.tube_line_cutoff_Hz}")
        if self.posterior_method not in ("emcee", "laplace"):
            raise ValueError(f"posterior_method must be 'emcee' or 'laplace', got "
                             f"{self.posterior_method!r}")
        check_draw_counts(self.laplace_draws, self.laplace_check_draws,
                          ("laplace_draws", "laplace_check_draws"))
        if self.tube_line_form not in ("line", "wave"):
            raise ValueError(f"tube_line_form must be 'line' or 'wave', got "
                             f"{self.tube_line_form!r}")
        if not 0 <= self.tube_line_segments <= LINE_MAX_SEGMENTS:
            raise ValueError(f"tube_line_segments must be in 0..{LINE_MAX_SEGMENTS} "
                             f"(0: no line form), got {self.tube_line_segments}")

    def to_dict(self) -> dict:
        return asdict(self)
