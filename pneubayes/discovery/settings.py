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

    holdout_fraction: the last fraction of every recording is held out for verification.
    bounds: parameter name -> [lower, upper] replacing the default bounds in every model
    the loop fits (a rig unlike the paper's); names of effects a model does not have wait
    until the loop adds them.
    holdout_recordings: when > 0, the last this many recordings given are held out whole
    instead (triggered trials: the end of a trial holds no valve event to verify on), and
    holdout_fraction is not used.
    block: one-step errors summed per regression row. threshold_t, n_bags, chunk_rows:
    the grouped SINDy (:class:`GroupedSINDy`). min_inclusion: a group is *supported*
    when its bagged inclusion probability reaches this. max_p_value: the one-sided
    Wilcoxon signed-rank test of the per-window squared-error reductions must reach
    this level. max_effects: stop after this many rounds that add (a pair is one).
    max_trials_per_round: supported groups refitted per round. max_refine_restarts:
    refinement is restarted from where it stopped until it converges, at most this many
    times.
    refine_restart_min_gain: a refinement that its evaluation budget ended is
    restarted only if its best training RMSE fell by at least this share over the second
    half of its points (:func:`~pneubayes.inference.refine.late_gain`); one that crawls
    is not: on the four-effect benchmark (AIR37/valve1, 6 x 20 s) sensor-lag forms in
    round 3 ended their 60 evaluations at 2256 and 2404 Pa and each of their three
    restarts moved them by 0.0 Pa, 30-40 s apiece. 0 restarts while the budget ends the
    fit (the loop before this setting).
    gap_fallback_ratio, fallback_min_inclusion: the one-step search has little power for
    slow effects (a small leak in a large chamber changes dp/dt by less than the noise
    per step, yet its 2-s error is many times the noise). So in any round where the
    current model's held-out 2-s RMSE exceeds ``gap_fallback_ratio`` x the noise floor,
    the best-ranked unsupported groups with inclusion at least ``fallback_min_inclusion``
    (at most ``max_trials_per_round``) are refitted as tentative candidates beside the
    supported ones; held-out verification decides, as for any candidate, and the best
    that passes is added. ``gap_fallback_ratio = 0`` disables it.
    try_all_supported: when none of the round's first ``max_trials_per_round`` supported
    groups passes verification, the round's other supported groups are tried before the
    loop stops (ledger action ``more supported``): the ranking orders the search's
    evidence, not the 2-s gain, and a supported effect that was never tried is not an
    effect the data rule out (a small clearance leak beside a dead zone ranked 4th with
    inclusion 0.75 and the loop stopped at 1.6 x the noise floor without trying it).
    try_all_on_gap: when the fallback applies and no candidate of the round passes
    verification, every other group of the library is refitted and verified as well
    (ledger action ``last resort``). A slow effect's one-step inclusion can be near 0
    while its 2-s error is large: a laminar leak planted in AIR37 on seed 1 had 0.07
    with the plain model's 2-s RMSE at 3.1 x the noise floor. last_resort_min_gap_closed:
    such a group must also close this fraction of the held-out RMSE's gap above the
    noise floor (the last resort is there to explain a large gap; on that case a tube
    delay passed the signed-rank test while closing 1 % of it).
    score_dof: degrees of freedom of the Student-t that scores each held-out sample in
    the cross-fitted log predictive density (verification's second test; see
    :func:`~pneubayes.discovery.verification.crossfit_window_lpd`). Its tails keep one
    window that no model explains from outweighing the others.
    last_resort_best_gap_closed: the last resort also runs when candidates passed but
    the best of them closes less than this share of the gap (0: only when none passed);
    the best of all that passed is added. A dead zone's one-step inclusion can be 0
    beside faster effects: on a four-effect AIR37 rig (tube, dead zone, droop, leak) the
    round's three saturated candidates closed at most 14 % of the gap, the leak was
    added, and the dead zone (58 %) waited for a round in which nothing passed.
    revisit_runner_ups: before the loop stops (a round in which nothing passed), the
    groups whose trial in an earlier round beat that round's model significantly (the
    verification test, beyond its control) but that were not added -- another gained
    more, or the last resort's gap share turned them away -- and that no later trial
    failed are tried again beside the current model (ledger action ``revisit``); as the
    search no longer supports them, they must also close ``last_resort_min_gap_closed``
    of the gap (a clearance leak revisited beside the tube that explained a case gained
    0.2 Pa of held-out RMSE at p = 0.012, near the test's level). The
    one-step search ranks what the *current* residual shows: on a four-effect SMC rig
    (tube, dead zone, droop, clearance leak) the leak passed the signed-rank test in
    round 1 (p = 0.006) beside the dead zone's larger gain, its inclusion fell to 0 once
    the other three were added, and the loop stopped at 1.7 x the noise floor without
    trying it again.
    pair_members: before the loop stops (a round in which nothing passed, revisits
    included) while the held-out error is above ``gap_fallback_ratio`` x the noise
    floor, the round's trials with the largest training gains (at most this many, each
    gaining at least the ``min_gain_*`` floor in training) are fitted in pairs, each pair
    jointly from its members' fitted values (ledger action ``pair``). A pair passes as a
    single trial does, beyond its control and closing ``last_resort_min_gap_closed`` of
    the gap, and it must also beat each member's own trial (each member carries a gain
    the other cannot); the passing pair with the lowest held-out RMSE adds both. Two
    effects can each fail alone where together they pass: on a blind case with a rounded
    dead zone and a clearance leak (SMC, valve 2) the dead zone alone improved 17 of 18
    held-out windows but left the wrong leak to drift (pooled RMSE 20.0 -> 21.5 kPa), the
    leak alone closed 86 % of the gap at p = 0.11, and the pair fitted jointly took the
    held-out RMSE to 1.0 kPa, better in 18 of 18 windows. 0 switches the stage off; 1 is
    refused (no pair).
    max_form_swaps: then, while the held-out error is still above ``gap_fallback_ratio``
    x the noise floor, each named effect is refitted in the other forms it proposes
    beside the rest of the model (ledger action ``form``); the form that beats the
    current fit as a trial must (the signed-rank test, the log predictive density, the
    gain floors) with the lowest held-out RMSE replaces it (``swap form``) and the loop
    searches again; at most this many swaps (0: none). A form chosen on training error
    beside fewer effects need not be the one beside more: a tube named with heat
    transfer in one pair is a transport delay or a lumped line (the wave tube has no
    temperature state), and only its transport delay had been fitted alone.
    open_form_min_noise_ratio: the open-form stage
    (:class:`~pneubayes.discovery.stages.OpenForm`) runs while the held-out error is
    above this x the noise floor and no catalogue trial closes half the gap; 0: no
    open-form stage.
    min_gain_noise_share: every trial that passes verification must also lower the
    held-out 2-s RMSE by at least this share of the noise floor (0: any significant
    gain). The signed-rank test finds a gain consistent across windows however small,
    and a gain of a few Pa on a 500-Pa floor is not an effect a 2-s prediction can show:
    beside a transmission-line tube at 0.97 x the noise floor (a spent bench case, an
    8-cell plant tube) a spool lag gained 1.8 Pa at p < 1e-4, standing in for the tube
    form's own small error. Default 0.01.
    min_gain_gap_share: and, where the held-out RMSE is above the noise floor, by at
    least this share of that gap (0: no such floor). Where a structural misfit far above
    the noise remains, a consistent gain of under 0.1 % of it is no effect either: on
    RespiraWorks' OXY runs (428 Pa held-out, a 7-Pa noise floor) a leak gained 0.3 Pa at
    p = 1e-6 over 20 of 22 windows. Default 0.01.
    tube_line_segments: the most cells of the acoustic-line form tried for a named tube;
    0 tries the transport delay only. A line step costs tens of times a plain one, and
    more with more cells. tube_line_cutoff_Hz: the line gets the fewest cells, at least
    3 and at most ``tube_line_segments``, whose lumped cut-off n / (pi T) reaches this
    frequency for the tube's transit time T (the start delay): the cells follow the
    tube's length. 300 Hz gives the 1-m bench tube (2.9 ms) its 3 cells, which come
    within 1.2 x the noise of an 8-cell line there; a 3-m tube of 4 mm bore (8.7 ms,
    behind an undeclared causal DAQ filter) ended at 1.68 x the noise floor with 3
    cells and at 1.40 x with 8 (held-out RMSE 860 -> 718 Pa).
    tube_line_form: the outside-tube form tried for a named tube: ``"line"`` (the lumped
    acoustic line, its cells as above) or ``"wave"`` (the transmission-line tube,
    ``tube_delay`` form ``"wave"`` with 8 elements: no cells, closer to a continuous
    tube than an 8-cell line, at 1.0-1.7 x a 3-cell line's cost on 1-kHz recordings,
    ``benchmarks/tube_forms.py``; never beside heat transfer: the line is tried there).
    Default ``"wave"``: on a near-continuous tube (2.5 m x 3.64 mm in 32 plant cells into
    a 0.15-cm^3 chamber, ``experiments/tube_form_study.py``) the loop with the line
    fitted a 3-cell line into a 1.5-ms basin (the tube's transit time is 7.3 ms), named a
    sensor lag in its place and ended at 3.62 x the noise floor; with the wave, from the
    same 2-ms start, it fitted 7.16 ms and the bore to 0.1 %, named the tube and ended at
    1.38 x. On two spent bench cases (the bench's 8-cell tubes) it did as well as the
    line (0.97 and 1.05 x against 1.02 and 1.04 x), in 1-2.3 x the line's time.
    ``tube_line_segments`` 0 tries neither.
    form_settled_ratio: an effect with several forms (heat, tube) has its first form
    fitted, and its later ones only while no trial of the round (of any effect) has a
    training RMSE at most this x the noise floor (at the noise floor the training fit,
    which picks the form, cannot tell trials apart, and a line fit costs minutes). 0
    fits every form.
    later_forms_min_share: an effect's later forms are fitted only if its first form's
    training gain over the current model is at least this share of the largest
    first-form gain of the round (0: always). A later form refines an effect's shape;
    an acoustic line for a tube that was not planted (a dead zone and a drooping supply
    on SMC/valve2) ran 40 minutes on one core without finishing. On a 3-m tube the
    transport form's gain was 0.75 and 0.84 of the round's best (a sensor or spool lag
    standing in) while the line cut the training RMSE from 1936 to 827 Pa, so the
    default is low (0.25).
    later_form_screen_share: a later form with parameters to fit first (the line's own
    and the dead volume) is screened: if that first stage does not gain, over the
    current model in training, at least this share of its effect's first form's gain,
    it is not refined further (1: it must beat the first form). The first stage moves
    three parameters where the first form was refitted in all of them: on a spent
    blind case (a 2.9-m, 1.8-mm tube) the line's first stage reached 4191-4279 Pa
    against the transport form's 4178 and was screened out at share 1, while its full
    refit reached 1919-2074 Pa. Default 0.5.
    posterior: the final model gets a posterior on the training windows (False: the
    refined point only). posterior_method: ``"emcee"`` (the sampler, ``fit.sampler``'s
    settings; the default) or ``"laplace"`` (:mod:`pneubayes.inference.laplace`: a
    Gaussian at the posterior's mode, ``laplace_draws`` draws, the first
    ``laplace_check_draws`` checked against the posterior's density, seeded and with the solver
    settings of ``fit.sampler`` as emcee's would be, in a few hundred posterior
    evaluations; it does not see skew or several modes). An emcee chain on a model with
    a transmission-line tube and 80 s of windows takes hours; its Laplace posterior takes
    minutes.
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
