"""Candidate models for a named group: the catalogue effect's form(s) and start values.

A named group becomes the current model plus that group's catalogue effect, in each
form the effect proposes (:meth:`~pneubayes.effects.Effect.candidate_forms`: the leak's
graded laminar law, the heat exchange's rate and convective forms, the tube's transport
delay and acoustic line), started where the effect says -- usually at the strength of
the group's best library term. This module only gathers what the candidates need from
the current fit and moves the start values inside the bounds.
"""

from __future__ import annotations

from pneubayes.discovery.settings import FormSettings
from pneubayes.discovery.verification import StepFit
from pneubayes.effects import make_effect
from pneubayes.effects.discovery import CandidateContext, inside_bounds
from pneubayes.effects.path import SLOT_INDEX, VOLUME_PLAY_COMPLIANCE_SLOTS
from pneubayes.model import Model
from pneubayes.rig import Rig

#: Slots whose non-zero value gives the chamber a state besides its pressure, or a
#: pressure law the temperature and line states do not cover (a rig card's compliant
#: chamber, supply tank, second compartment or tabulated V(p), and a volume play, whose
#: table the simulator lays itself).
_STATE_SLOTS = ("compliance_m3_per_Pa", "tank_volume_m3", "lung_volume_m3",
                "volume_table_points") + VOLUME_PLAY_COMPLIANCE_SLOTS


def candidate_context(fit: StepFit, group: str, evidence: dict, rig: Rig,
                      forms: FormSettings | None = None) -> CandidateContext:
    """What the named group's effect needs to propose its candidates beside ``fit``;
    ``forms``: the tube's outside form, its line's cells and cut-off and the
    transmission line's grid (None: :class:`~pneubayes.discovery.settings.FormSettings`'
    defaults)."""
    forms = FormSettings() if forms is None else forms
    slots = fit.model.lower(fit.model.vector(fit.params)[None, :], rig)[0]
    taken = any(slots[SLOT_INDEX[s]] > 0 for s in _STATE_SLOTS)
    line_segments = forms.tube_line_segments
    if not all(e.beside_tube(forms.tube_line_form) for e in fit.model.effects):
        line_segments = 0  # the simulator cannot carry the tube's line beside one of them
    return CandidateContext(model=fit.model, params=dict(fit.params), rig=rig,
                            term_start=evidence.get("best_term_start"),
                            second_state_free=not taken, line_segments=line_segments,
                            dead_volume_m3=float(slots[SLOT_INDEX["volume_m3"]]),
                            line_cutoff_Hz=forms.tube_line_cutoff_Hz,
                            line_form=forms.tube_line_form, slots=slots,
                            wave_grid=forms.tube_wave_grid,
                            wave_unsteady=forms.tube_wave_unsteady)


def effect_candidates(fit: StepFit, group: str, evidence: dict, rig: Rig,
                      forms: FormSettings | None = None):
    """``[(model, start), ...]``: the group's effect form(s) beside ``fit.model``, each
    with start values (the fit's, the effect's neutral values, then the effect's own
    starts moved just inside the bounds); ``forms`` as :func:`candidate_context`."""
    ctx = candidate_context(fit, group, evidence, rig, forms)
    effect = make_effect(group, **fit.model.effect_options(group))
    return [_started(fit, form, {**fit.params, **form.neutral_values()}, values)
            for form, values in effect.candidate_forms(ctx)]


def _started(fit: StepFit, effect, base: dict, values: dict):
    """``(model, start)``: ``fit.model`` with ``effect``, started at ``base`` (its
    parameters' values) with ``values`` moved just inside the bounds."""
    model = fit.model.with_effect(effect)
    start = {k: base[k] for k in model.parameter_names if k in base}
    start.update({k: inside_bounds(model, k, v) for k, v in values.items()})
    return model, start


def follow_up(fit: StepFit, group: str, evidence: dict, rig: Rig, model, params: dict,
              forms: FormSettings | None = None):
    """``(model, start)`` of the form the named group's effect asks to fit next from
    ``model`` fitted at ``params`` beside ``fit`` (:meth:`~pneubayes.effects.Effect.
    form_after_fit`), started at ``params`` (a parameter the new form adds and the
    effect gives no start for: neutral); None when it asks for none; ``forms`` as
    :func:`candidate_context`."""
    ctx = candidate_context(fit, group, evidence, rig, forms)
    nxt = model.effect(group).form_after_fit(params, ctx)
    if nxt is None:
        return None
    effect, values = nxt
    return _started(fit, effect, {**effect.neutral_values(), **params}, values)


def form_label(model: Model, group: str) -> str:
    """The form of a model's effect (``"-"`` for an effect with one form; an acoustic
    line's with its cells, ``"line/8"``; a sensor lag on every channel
    ``"first_order/all"``)."""
    opts = model.effect(group).options()
    return (str(opts.get("form", "-")) + (f"/{opts['segments']}" if "segments" in opts else "")
            + (f"/{opts['channels']}" if "channels" in opts else ""))


def first_free(model, group: str):
    """Parameters of ``model`` to refine on their own before all of them, or None (the
    named effect's :meth:`~pneubayes.effects.Effect.refine_first`)."""
    names = model.effect(group).refine_first()
    if names is None:
        return None
    return tuple(n for n in names if n in model.parameter_names)
