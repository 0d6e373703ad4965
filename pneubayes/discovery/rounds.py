"""One round's trials: the candidate effects' forms, fitted cheapest first, stopping
once a trial fits at the noise floor (:class:`~pneubayes.discovery.settings.DiscoverySettings`
``form_settled_ratio``)."""

from __future__ import annotations

from pneubayes.errors import SimulationError


def fit_round_forms(options: dict, fit, settled_Pa: float, follow=None):
    """Fit a round's candidate forms: ``options`` maps each effect to its forms
    ``[(model, start), ...]`` in order; ``fit(effect, model, start)`` fits one.
    ``follow(effect, model, fit)`` (optional) gives a form to fit next from a fitted
    one, ``(model, start)``, or None (an acoustic line's cells re-chosen from its
    fitted transit time); it is fitted at once, under the same settling rule.

    Every effect's first form is fitted; the later (costlier) forms only while no fit of
    the round has a training RMSE at most ``settled_Pa`` (0: fit every form). At the
    noise floor the training fit, which picks among the trials, cannot tell them apart,
    and an acoustic-line form costs minutes. A form that cannot be simulated from its
    start or at its fitted point (``FloatingPointError`` from the refinement,
    :class:`~pneubayes.errors.SimulationError`) is a failed trial, not a failed loop.

    Returns ``({effect: [(fit, model, start), ...]}`` in form order, the ``(effect,
    model, fit)`` that settled the round or None, ``{effect: [(model, why), ...]}`` of
    the failed forms).
    """
    fitted: dict = {g: [] for g in options}
    failed: dict = {g: [] for g in options}
    settled = None

    def run(g, model, start):
        nonlocal settled
        try:
            f = fit(g, model, start)
        except (FloatingPointError, SimulationError) as exc:
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
    for g, forms in options.items():
        for model, start in forms[1:]:
            if settled is not None:
                break
            run(g, model, start)
    return fitted, settled, failed
