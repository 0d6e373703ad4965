"""Every setting of the discovery loop (``pneubayes discover``), saved with its result.

One tree, nested by what each part steers: the data split, the residual search, the
verification test, the rounds, an effect's forms, the stages, the fits and the final
posterior. The same names serve the Python API (``DiscoverySettings(rounds=
RoundSettings(max_effects=2))``), a settings file (``[rounds] max_effects = 2``, read by
``pneubayes discover --settings FILE.toml``) and the command line (``--set
rounds.max_effects=2``); :mod:`pneubayes.settings_tree` applies a table to the tree.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from pneubayes.discovery.disagreement import RegimeSettings
from pneubayes.discovery.library import LibraryGrid
from pneubayes.effects import TubeDelay, catalogue_parameter_names
from pneubayes.effects.path import LINE_MAX_SEGMENTS
from pneubayes.inference.importance import IMPORTANCE_CHECK_DRAWS
from pneubayes.inference.laplace import LAPLACE_DRAWS, check_draw_counts
from pneubayes.inference.pipeline import FitSettings
from pneubayes.model import Model, check_bound_overrides
from pneubayes.simulation import SolverConfig


def _int_at_least(value, low: int) -> bool:
    return not isinstance(value, bool) and isinstance(value, int) and value >= low


def _check_shares(settings, *names: str) -> None:
    """ValueError naming the first of ``names`` whose value on ``settings`` is not a
    share in [0, 1]."""
    for name in names:
        if not 0.0 <= getattr(settings, name) <= 1.0:
            raise ValueError(f"{name} must be in [0, 1], got {getattr(settings, name)}")


@dataclass(frozen=True)
class DataSettings:
    """Which data the loop fits and which it holds out.

    Attributes
    ----------
    holdout_fraction : float
        The last fraction of each recording held out (when ``holdout_recordings`` is 0).
    holdout_recordings : int
        > 0: the last this many recordings are held out whole.
    bounds : dict
        Parameter name -> [lower, upper] in every model the loop fits.
    """

    holdout_fraction: float = 1.0 / 3.0
    holdout_recordings: int = 0
    bounds: dict = field(default_factory=dict)

    def __post_init__(self):
        if not 0.0 < self.holdout_fraction < 1.0:
            raise ValueError(f"holdout_fraction must be in (0, 1), got {self.holdout_fraction}")
        if not _int_at_least(self.holdout_recordings, 0):
            raise ValueError("holdout_recordings must be an integer >= 0, got "
                             f"{self.holdout_recordings!r}")
        bounds = check_bound_overrides(self.bounds, "DataSettings.bounds")
        unknown = sorted(set(bounds) - set(Model().parameter_names)
                         - catalogue_parameter_names())
        if unknown:
            raise ValueError(f"DataSettings.bounds: {unknown} name no parameter of the "
                             "thin-port model or of any catalogue effect")
        object.__setattr__(self, "bounds", {k: list(v) for k, v in bounds.items()})


@dataclass(frozen=True)
class SearchSettings:
    """The residual search (:class:`~pneubayes.discovery.sindy.GroupedSINDy`) and the
    disagreement map.

    Attributes
    ----------
    block : int
        One-step errors summed over this many samples per regression row.
    grid : LibraryGrid
        The candidate terms' trial strengths.
    regimes : RegimeSettings
        The disagreement map's bins and flags.
    threshold_t, n_bags, chunk_rows : float, int, int
        The sequential threshold (on the coefficients' t statistics), bags and rows
        per resampled chunk.
    min_inclusion : float
        A group is supported at this inclusion probability.
    fallback_min_inclusion : float
        Far above the noise floor (``rounds.gap_fallback_ratio``), groups of this
        inclusion are tried too.
    solver : SolverConfig
        The solver of the one-step errors.
    """

    block: int = 5
    grid: LibraryGrid = field(default_factory=LibraryGrid)
    regimes: RegimeSettings = field(default_factory=RegimeSettings)
    threshold_t: float = 5.0
    n_bags: int = 40
    chunk_rows: int = 200
    min_inclusion: float = 0.6
    fallback_min_inclusion: float = 0.25
    solver: SolverConfig = field(default_factory=SolverConfig.standard)

    def __post_init__(self):
        if not _int_at_least(self.block, 1):
            raise ValueError(f"block must be an integer >= 1, got {self.block!r}")
        if not 0.0 < self.min_inclusion <= 1.0:
            raise ValueError(f"min_inclusion must be in (0, 1], got {self.min_inclusion}")
        if not 0.0 < self.fallback_min_inclusion <= 1.0:
            raise ValueError(f"fallback_min_inclusion must be in (0, 1], got "
                             f"{self.fallback_min_inclusion}")


@dataclass(frozen=True)
class VerifySettings:
    """The test a trial (a named effect or an open-form closure) must pass on the held-out
    windows to be added.

    Attributes
    ----------
    max_p_value : float
        The paired signed-rank test's level against the current model.
    remove_max_p_value : float
        An added effect is removed again (the backward step, once a later one is added)
        only when its gain's p-value exceeds this level (at least ``max_p_value``: a
        stepwise search enters at a stricter level than it removes, so an effect is not
        dropped on the noise of one refit).
    score_dof : float
        The Student-t degrees of freedom of the log predictive density it must raise.
    min_gain_noise_share, min_gain_gap_share : float
        It must gain these shares of the noise floor and of the gap (the error above it).
    """

    max_p_value: float = 0.01
    remove_max_p_value: float = 0.05
    score_dof: float = 4.0
    min_gain_noise_share: float = 0.01
    min_gain_gap_share: float = 0.01

    def __post_init__(self):
        if not 0.0 < self.max_p_value < 1.0:
            raise ValueError(f"max_p_value must be in (0, 1), got {self.max_p_value}")
        if not self.max_p_value <= self.remove_max_p_value < 1.0:
            raise ValueError(f"remove_max_p_value must be in [max_p_value, 1) = "
                             f"[{self.max_p_value}, 1), got {self.remove_max_p_value}")
        if not self.score_dof > 2.0:
            raise ValueError(f"score_dof must be > 2 (a finite variance), got "
                             f"{self.score_dof}")
        _check_shares(self, "min_gain_noise_share", "min_gain_gap_share")


@dataclass(frozen=True)
class RoundSettings:
    """How many rounds the loop runs and how hard each fits.

    Attributes
    ----------
    max_effects : int
        Rounds that add (a pair is one).
    max_trials_per_round : int
        Supported groups refitted per round.
    max_refine_restarts, refine_restart_min_gain : int, float
        Restarts of a refinement its budget ended, while its second half gains this share.
    gap_fallback_ratio : float
        A model is *far* above this x the noise floor (0: never): less supported groups
        are tried (``search.fallback_min_inclusion``).
    max_seconds : float
        Time budget of the loop, s of this process's wall clock (0: none). Once spent, no
        further stage or round starts: the round under way adds what its trials passed,
        and the loop ends with the model it has (the ledger records the stop); no
        trial's form starts fitting either. A fit that has started runs to its end; a
        resumed run's replayed steps cost next to nothing.
    """

    max_effects: int = 4
    max_trials_per_round: int = 3
    max_refine_restarts: int = 3
    refine_restart_min_gain: float = 1e-4
    gap_fallback_ratio: float = 2.0
    max_seconds: float = 0.0

    def __post_init__(self):
        if not _int_at_least(self.max_effects, 0):
            raise ValueError(f"max_effects must be an integer >= 0, got {self.max_effects!r}")
        if not _int_at_least(self.max_trials_per_round, 1):
            raise ValueError("max_trials_per_round must be an integer >= 1, got "
                             f"{self.max_trials_per_round!r}")
        if not _int_at_least(self.max_refine_restarts, 0):
            raise ValueError("max_refine_restarts must be an integer >= 0, got "
                             f"{self.max_refine_restarts!r}")
        if not 0.0 <= self.refine_restart_min_gain < 1.0:
            raise ValueError(f"refine_restart_min_gain must be in [0, 1), got "
                             f"{self.refine_restart_min_gain}")
        if not (self.gap_fallback_ratio == 0.0 or self.gap_fallback_ratio >= 1.0):
            raise ValueError(f"gap_fallback_ratio must be 0 (off) or >= 1, got "
                             f"{self.gap_fallback_ratio}")
        if isinstance(self.max_seconds, bool) or not isinstance(self.max_seconds, (int, float)) \
                or not (math.isfinite(self.max_seconds) and self.max_seconds >= 0.0):
            raise ValueError(f"max_seconds must be a finite number of seconds >= 0 (0: no "
                             f"budget), got {self.max_seconds!r}")


@dataclass(frozen=True)
class FormSettings:
    """Which forms of an effect a round fits.

    Attributes
    ----------
    tube_line_segments, tube_line_cutoff_Hz, tube_line_form : int, float, str
        A tube's outside form: ``"wave"``, or ``"line"`` with the fewest cells (3 to the
        segments) whose cut-off n / (pi T) reaches this; 0 segments: transport only.
    tube_wave_grid_s, tube_wave_grid_per_element : float, int
        The transmission-line tube's grid (``tube_delay``'s ``grid_s``), fixed when its
        trial starts: the start's element transit time over this count, between 0.1 ms
        and this step (s); a coarser grid is faster and smears the waves more
        (docs/discovery.md).
    tube_wave_unsteady : bool
        The transmission-line tube also fits the weight of Zielke's unsteady wall shear
        (``tube_delay``'s ``unsteady_friction``; from 0, its quasi-steady tube): a line
        that rings after a sharp switch and damps faster than steady friction says.
    settled_ratio : float
        Later forms are fitted while no trial is within this x the noise floor (0: every
        form always).
    later_min_share, later_screen_share : float
        ... if the first form gains this share of the round's best; the line's screen
        share.
    nested_min_gain_share : float
        A form with more parameters is taken over a simpler form of its effect only if
        its training RMSE is lower by this x the noise floor
        (:func:`~pneubayes.discovery.rounds.choose_form`).
    """

    tube_line_segments: int = 8
    tube_line_cutoff_Hz: float = 300.0
    tube_line_form: str = "wave"
    tube_wave_grid_s: float = 1e-4
    tube_wave_grid_per_element: int = 1
    tube_wave_unsteady: bool = False
    settled_ratio: float = 1.05
    later_min_share: float = 0.25
    later_screen_share: float = 0.5
    nested_min_gain_share: float = 0.02

    def __post_init__(self):
        if not 0 <= self.tube_line_segments <= LINE_MAX_SEGMENTS:
            raise ValueError(f"tube_line_segments must be in 0..{LINE_MAX_SEGMENTS} "
                             f"(0: no line form), got {self.tube_line_segments}")
        if not (math.isfinite(self.tube_line_cutoff_Hz) and self.tube_line_cutoff_Hz > 0):
            raise ValueError(f"tube_line_cutoff_Hz must be finite and > 0, got "
                             f"{self.tube_line_cutoff_Hz}")
        if self.tube_line_form not in ("line", "wave"):
            raise ValueError(f"tube_line_form must be 'line' or 'wave', got "
                             f"{self.tube_line_form!r}")
        # (the tube's own check of the step)
        TubeDelay(form="wave", grid_s=self.tube_wave_grid_s).parameters()
        if isinstance(self.tube_wave_grid_per_element, bool) or not isinstance(
                self.tube_wave_grid_per_element, int) or not 1 <= self.tube_wave_grid_per_element:
            raise ValueError(f"tube_wave_grid_per_element must be an integer >= 1, got "
                             f"{self.tube_wave_grid_per_element!r}")
        if not isinstance(self.tube_wave_unsteady, bool):
            raise ValueError(f"tube_wave_unsteady must be true or false, got "
                             f"{self.tube_wave_unsteady!r}")
        if not (self.settled_ratio == 0.0 or self.settled_ratio >= 1.0):
            raise ValueError(f"settled_ratio must be 0 (fit every form) or >= 1, got "
                             f"{self.settled_ratio}")
        _check_shares(self, "later_min_share", "later_screen_share", "nested_min_gain_share")

    @property
    def tube_wave_grid(self) -> tuple[float, int]:
        """``(tube_wave_grid_s, tube_wave_grid_per_element)``."""
        return self.tube_wave_grid_s, self.tube_wave_grid_per_element


@dataclass(frozen=True)
class StageSettings:
    """The stages a round runs after its search's own trials
    (:func:`~pneubayes.discovery.stages.default_stages`; ``docs/discovery.md``).

    Attributes
    ----------
    more_supported : bool
        MoreSupported: every supported group, not only the best few.
    last_resort : bool
        LastResort: every catalogue group when nothing (or little) passed.
    last_resort_min_gap_closed, last_resort_best_gap_closed : float
        The gap share a last resort, runner-up, pair or a round's tentative trial (tried
        on weak evidence) must close; the last resort and the catalogue sweep also run
        when the best passing trial closes less than this (0: only if none passed).
    catalogue_sweep_min_noise_ratio, catalogue_sweep_min_gap_closed : float
        CatalogueSweep: the untried groups above this x the floor (0: off), each to
        close this share of the gap.
    runner_ups : bool
        RunnerUps: passing trials not added are revisited before the loop stops.
    pair_members, max_form_swaps : int
        Pairs of at most this many trials; OtherForms: at most this many swaps (0: off).
    open_form_min_noise_ratio : float
        OpenForm: an open-form closure while above this x the noise floor (0: off).
    reading_hinge_min_noise_ratio, reading_form_min_noise_ratio, \
    reading_play_min_noise_ratio, reading_command_min_noise_ratio, \
    reading_flow_min_noise_ratio : float
        ReadingHingeForm, ReadingForm, ReadingPlayForm, ReadingCommandForm,
        ReadingFlowForm: open-form knees (a static map read last), relaxations, plays
        (backlash), lags of the command's magnitude and terms of the valve's port flows
        in the reading while above this x the noise floor (0: off).
    port_restriction_min_noise_ratio, volume_form_min_noise_ratio, \
    volume_play_min_noise_ratio, loaded_wall_min_noise_ratio : float
        PortRestrictionForm, VolumeForm, VolumePlayForm, LoadedWallForm: an open-form
        restriction in series at the chamber's port, hinges of the chamber's volume in its
        pressure, friction-held walls (plays of the volume) and a wall that carries a load
        (the volume as a mass on a spring) while above this x the noise floor (0: off).
    command_clock_min_noise_ratio, valve_dead_time_min_noise_ratio : float
        CommandClockForm, ValveDeadTimeForm: a valve driver on its own clock, a dead time
        that depends on the supply (recordings at different supplies) while above this x
        the noise floor (0: off).
    """

    more_supported: bool = True
    last_resort: bool = True
    last_resort_min_gap_closed: float = 0.25
    last_resort_best_gap_closed: float = 0.25
    catalogue_sweep_min_noise_ratio: float = 1.1
    catalogue_sweep_min_gap_closed: float = 0.5
    runner_ups: bool = True
    pair_members: int = 3
    max_form_swaps: int = 2
    open_form_min_noise_ratio: float = 1.5
    reading_hinge_min_noise_ratio: float = 1.5
    reading_form_min_noise_ratio: float = 1.5
    reading_play_min_noise_ratio: float = 1.5
    reading_command_min_noise_ratio: float = 1.5
    reading_flow_min_noise_ratio: float = 1.5
    volume_form_min_noise_ratio: float = 1.5
    volume_play_min_noise_ratio: float = 1.5
    loaded_wall_min_noise_ratio: float = 1.5
    command_clock_min_noise_ratio: float = 1.5
    valve_dead_time_min_noise_ratio: float = 1.5
    port_restriction_min_noise_ratio: float = 1.5

    def __post_init__(self):
        _check_shares(self, "last_resort_min_gap_closed", "last_resort_best_gap_closed",
                      "catalogue_sweep_min_gap_closed")
        if not _int_at_least(self.pair_members, 0) or self.pair_members == 1:
            raise ValueError("pair_members must be 0 (off) or an integer >= 2, got "
                             f"{self.pair_members!r}")
        if not _int_at_least(self.max_form_swaps, 0):
            raise ValueError("max_form_swaps must be an integer >= 0, got "
                             f"{self.max_form_swaps!r}")
        for name in ("catalogue_sweep_min_noise_ratio",
                     "open_form_min_noise_ratio", "reading_hinge_min_noise_ratio",
                     "reading_form_min_noise_ratio",
                     "reading_play_min_noise_ratio", "reading_command_min_noise_ratio",
                     "reading_flow_min_noise_ratio",
                     "volume_form_min_noise_ratio", "volume_play_min_noise_ratio",
                     "loaded_wall_min_noise_ratio", "command_clock_min_noise_ratio",
                     "valve_dead_time_min_noise_ratio", "port_restriction_min_noise_ratio"):
            v = getattr(self, name)
            if not (v == 0.0 or v >= 1.0):
                raise ValueError(f"{name} must be 0 (off) or >= 1, got {v}")


@dataclass(frozen=True)
class PosteriorSettings:
    """The final model's posterior.

    Attributes
    ----------
    method : str
        ``"emcee"`` (the chain, with ``fit.sampler``), ``"laplace"`` (a Gaussian at the
        mode, importance-checked) or ``"none"`` (the refined point only).
    laplace_draws, laplace_check_draws : int
        The Laplace approximation's draws and the importance check's (0: no check).
    """

    method: str = "emcee"
    laplace_draws: int = LAPLACE_DRAWS
    laplace_check_draws: int = IMPORTANCE_CHECK_DRAWS

    def __post_init__(self):
        if self.method not in ("emcee", "laplace", "none"):
            raise ValueError(f"method must be 'emcee', 'laplace' or 'none', got "
                             f"{self.method!r}")
        check_draw_counts(self.laplace_draws, self.laplace_check_draws,
                          ("laplace_draws", "laplace_check_draws"))

    @property
    def sampled(self) -> bool:
        """Whether a posterior is computed (``method`` is not ``"none"``)."""
        return self.method != "none"


@dataclass(frozen=True)
class DiscoverySettings:
    """Every setting of ``pneubayes discover`` (saved in discovery.json), one table per
    part of the loop.

    ``docs/discovery.md`` explains each stage these steer; ``docs/history.md`` the cases
    behind the defaults. Errors are held-out 2-s RMSEs, the *gap* the error above the
    noise floor.

    Attributes
    ----------
    data : DataSettings
        The held-out split and parameter bounds.
    search : SearchSettings
        The residual search and the disagreement map.
    verify : VerifySettings
        The test a trial must pass to be added.
    rounds : RoundSettings
        Rounds, trials per round and refinement restarts.
    forms : FormSettings
        An effect's forms a round fits.
    stages : StageSettings
        The stages after a round's own trials.
    fit : FitSettings
        Every fit's settings (windows, refinement, sampler).
    posterior : PosteriorSettings
        The final model's posterior.
    seed : int
        The search's bags and the open-form search's.
    """

    data: DataSettings = field(default_factory=DataSettings)
    search: SearchSettings = field(default_factory=SearchSettings)
    verify: VerifySettings = field(default_factory=VerifySettings)
    rounds: RoundSettings = field(default_factory=RoundSettings)
    forms: FormSettings = field(default_factory=FormSettings)
    stages: StageSettings = field(default_factory=StageSettings)
    fit: FitSettings = field(default_factory=FitSettings)
    posterior: PosteriorSettings = field(default_factory=PosteriorSettings)
    seed: int = 0

    def __post_init__(self):
        for name, kind in (("data", DataSettings), ("search", SearchSettings),
                           ("verify", VerifySettings), ("rounds", RoundSettings),
                           ("forms", FormSettings), ("stages", StageSettings),
                           ("fit", FitSettings), ("posterior", PosteriorSettings)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"DiscoverySettings.{name} must be a {kind.__name__}, got "
                                 f"{type(getattr(self, name)).__name__}")
        if not _int_at_least(self.seed, 0):
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")

    def to_dict(self) -> dict:
        """The tree as nested plain values (the keys a settings file names)."""
        return asdict(self)
