"""One round's trials: the candidate effects' forms, fitted cheapest first, stopping
once a trial fits at the noise floor (:class:`~pneubayes.discovery.settings.FormSettings`
``settled_ratio``); an effect's later forms only while its first form keeps up with
the round's best (``later_min_share``); whether a trial that passed gains enough
to be added (:func:`gain_shortfall`); whether a round's results call for the last resort
(:func:`last_resort_reason`); which earlier trials to revisit before the loop stops
(:func:`runner_ups`); and which of the round's trials to fit in pairs when none passed
alone (:func:`pairs_to_try`)."""

from __future__ import annotations

from itertools import combinations

from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.errors import FIT_FAILURES


class TrialFitFailed(Exception):
    """A trial's refinement ended worse in training than the model it contains (the
    current model, its effect at zero strength), from every start: a failed fit, not
    evidence against the effect."""


def fit_round_forms(options: dict, fit, settled_Pa: float, follow=None,
                    current_Pa: float | None = None, min_share: float = 0.0,
                    screen_share: float = 1.0, cheap=frozenset(), passed=frozenset()):
    """Fit a round's candidate forms: ``options`` maps each effect to its forms
    ``[(model, start), ...]`` in order; ``fit(effect, model, start, beat_Pa)`` fits one;
    for a later form ``beat_Pa`` is the training RMSE a fit may stop early above
    (screening), else None: with ``current_Pa``, the current model's less
    ``screen_share`` x its effect's first form's gain (when positive; 1: the first
    form's own RMSE), without it the first form's RMSE.
    ``follow(effect, model, fit)`` (optional) gives a form to fit next from a fitted
    one, ``(model, start)``, or None (an acoustic line's cells re-chosen from its
    fitted transit time); it is fitted at once, under the same settling rule.

    Every effect's first form is fitted; the later (costlier) forms only while no fit of
    the round has a training RMSE at most ``settled_Pa`` (0: fit every form). At the
    noise floor the training fit, which picks among the trials, cannot tell them apart,
    and an acoustic-line form costs minutes. With ``current_Pa`` (the current model's
    training RMSE) and ``min_share`` > 0, an effect's later forms are fitted only if its
    first form's gain ``current_Pa - training RMSE`` is at least ``min_share`` x the
    largest first-form gain of the round: a later form refines the shape of an effect,
    and one whose plainest form explains a small share of what another explains is not
    where the round's misfit is (on a dead zone and a drooping supply, an acoustic line
    for a tube that is not there cost 40 minutes). The effects in ``cheap`` (whose later
    forms cost a fit about what the first does: a curvature with a gain beside it) are
    never skipped so. The effects in ``passed`` (which passed verification in an earlier
    round and were not added) have every form fitted in full, neither skipped nor
    screened: an effect added before them may have taken what their plainest form
    explained (a spool lag what a tube's delay did), not what their fuller form does (the
    tube's waves). A form that cannot be simulated from its start or at its fitted
    point, or beside the model's other forms (:data:`~pneubayes.errors.FIT_FAILURES`),
    is a failed trial, not a failed loop.

    Returns ``({effect: [(fit, model, start), ...]}`` in form order, the ``(effect,
    model, fit)`` that settled the round or None, ``{effect: [(model, why), ...]}`` of
    the failed forms, ``{effect: (its first-form gain, the round's largest), Pa}`` of the
    effects whose later forms were skipped for a small share).
    """
    if not 0.0 <= min_share <= 1.0:
        raise ValueError(f"min_share must be in [0, 1], got {min_share}")
    if not 0.0 <= screen_share <= 1.0:
        raise ValueError(f"screen_share must be in [0, 1], got {screen_share}")
    fitted: dict = {g: [] for g in options}
    failed: dict = {g: [] for g in options}
    settled = None

    def run(g, model, start, beat_Pa=None):
        nonlocal settled
        try:
            f = fit(g, model, start, beat_Pa)
        except (*FIT_FAILURES, TrialFitFailed) as exc:
            failed[g].append((model, f"{type(exc).__name__}: {str(exc).splitlines()[0]}"))
            return
        fitted[g].append((f, model, start))
        if settled is None and f.train_rmse_Pa <= settled_Pa:
            settled = (g, model, f)
        nxt = None if follow is None or settled is not None else follow(g, model, f)
        if nxt is not None:
            run(g, *nxt)

    for g, forms in options.items():
        if forms:
            run(g, *forms[0])
    # each effect's first form's training RMSE (None: it failed)
    first_Pa = {g: fitted[g][0][0].train_rmse_Pa if fitted[g] else None for g in options}
    outpaced: dict = {}
    if current_Pa is not None and min_share > 0:
        gain = {g: 0.0 if v is None else current_Pa - v for g, v in first_Pa.items()}
        best = max(gain.values(), default=0.0)
        if best > 0:
            outpaced = {g: (gain[g], best) for g, forms in options.items()
                        if len(forms) > 1 and g not in cheap and g not in passed
                        and gain[g] < min_share * best}
    def screen(g):
        if first_Pa[g] is None or current_Pa is None:
            return first_Pa[g]
        return current_Pa - screen_share * max(current_Pa - first_Pa[g], 0.0)
    for g, forms in options.items():
        if g in outpaced:
            continue
        for model, start in forms[1:]:
            if settled is not None:
                break
            run(g, model, start, None if g in passed else screen(g))
    return fitted, settled, failed, outpaced


def choose_form(forms, margin_Pa: float):
    """The form of one effect a round takes on to verification, from its fitted
    ``(fit, model, start)`` triples: the one with the fewest parameters among those
    whose training RMSE is within ``margin_Pa`` of the best (then the lower RMSE).

    A form that nests another (a speed-limited spool lag at an unreachable limit is the
    first-order lag) fits the training data at least as well; without the margin it
    would always be taken, with a parameter the data do not determine."""
    best = min(f[0].train_rmse_Pa for f in forms)
    near = [f for f in forms if f[0].train_rmse_Pa <= best + margin_Pa]
    return min(near, key=lambda f: (len(f[1].parameter_names), f[0].train_rmse_Pa))


def gain_shortfall(drop_Pa: float, gap_Pa: float, min_gap_closed: float,
                   min_gain_Pa: float):
    """Whether a trial that passed verification gains too little to be added:
    ``(closed, short_of_gap, under_floor)``. ``closed`` is the share of the held-out
    RMSE's gap above the noise floor (``gap_Pa``) its drop ``drop_Pa`` closes, None with
    no gap left; ``short_of_gap``: it closes under ``min_gap_closed`` (with no gap left,
    any positive share is out of reach); ``under_floor``: the drop is under
    ``min_gain_Pa``."""
    closed = drop_Pa / gap_Pa if gap_Pa > 0 else None
    short = (min_gap_closed > 0) if closed is None else closed < min_gap_closed
    return closed, short, drop_Pa < min_gain_Pa


def min_gain_Pa(noise_Pa: float, gap_Pa: float, settings: DiscoverySettings) -> float:
    """The least held-out gain (Pa) an added effect must bring: ``min_gain_noise_share``
    of the noise floor ``noise_Pa``, or ``min_gain_gap_share`` of the gap above it
    (``gap_Pa``; none when negative), whichever is larger."""
    return max(settings.verify.min_gain_noise_share * noise_Pa,
               settings.verify.min_gain_gap_share * max(gap_Pa, 0.0))


def last_resort_reason(passed_rmse_Pa, heldout_rmse_Pa: float, noise_Pa: float,
                       best_gap_closed: float) -> tuple[str | None, float]:
    """Why a round with a large gap should try the rest of the library (None: it need
    not), and the share of the held-out gap above the noise floor the best trial that
    passed (held-out RMSEs ``passed_rmse_Pa``, Pa) closes: none passed, or the best
    closes less than ``best_gap_closed``."""
    if not len(passed_rmse_Pa):
        return "no candidate passed", 0.0
    closed = (heldout_rmse_Pa - min(passed_rmse_Pa)) / max(heldout_rmse_Pa - noise_Pa, 1e-12)
    if closed < best_gap_closed:
        return f"the best candidate closes {closed:.0%} of its gap", closed
    return None, closed


def runner_ups(ledger: list, current_effects, round_step: int,
               max_p_value: float) -> list[str]:
    """Groups to try again before the loop stops, from its ``ledger``: each had a trial
    that beat the model of its round significantly (p <= ``max_p_value``, log predictive
    gain > 0, lower held-out RMSE, beyond its control), whether it was not added because
    another gained more or because the last resort's gap share turned it away, and no
    later trial of it failed; never added, not in ``current_effects`` and not tried since
    ``round_step`` (this round). In the order they were first tried."""
    latest: dict[str, bool] = {}
    tried_now, ever_added = set(), set()
    for e in ledger:
        if e["action"] == "add":
            ever_added.add(e["effect"])
        if e["action"] not in ("pass", "reject"):
            continue
        g = e["effect"]
        latest[g] = (e["score_p_value"] <= max_p_value
                     and e["score_gain"] > 0
                     and e["heldout_rmse_after_Pa"] < e["heldout_rmse_before_Pa"]
                     and not e["not_better_than_control"])
        if e["step"] >= round_step:
            tried_now.add(g)
    return [g for g, ok in latest.items()
            if ok and g not in set(current_effects) | ever_added | tried_now]


def pairs_to_try(train_rmse_Pa: dict, current_Pa: float, least_Pa: float,
                 members: int) -> list[tuple[str, str]]:
    """The pairs of a round's trials to fit jointly: of the effects whose trial lowered
    the training RMSE (``train_rmse_Pa``: effect -> its trial's training RMSE, Pa) below
    the current model's (``current_Pa``) by at least ``least_Pa``, the ``members`` with
    the largest gains, every pair of them, the pair with the larger summed gain first
    (ties in the members' order of gain)."""
    gain = {g: current_Pa - v for g, v in train_rmse_Pa.items() if current_Pa - v >= least_Pa}
    top = sorted(gain, key=lambda g: -gain[g])[:members]
    pairs = list(combinations(top, 2))
    return sorted(pairs, key=lambda ab: -(gain[ab[0]] + gain[ab[1]]))
