"""What an effect tells the discovery loop: its library terms and its candidate forms.

Each catalogue effect declares, in its own file,

- the terms it offers the dp/dt library (:meth:`Effect.library_terms`): one column per
  trial strength, each of one of the four kinds below, which the library
  (:mod:`pneubayes.discovery.library`) knows how to compute;
- the forms it is fitted in once the loop names it, with their start values
  (:meth:`Effect.candidate_forms`, given a :class:`CandidateContext`);
- which of its parameters a refinement fits first (:meth:`Effect.refine_first`).

The kinds of term (all are a change of the one-step predictions, Pa, except the last):

- :class:`TrialTerm`: the effect itself in the model at trial parameter values (all of
  an effect's trials, of every effect, are simulated in one batch);
- :class:`FormTrialTerm`: another form of the effect (the leak's laminar law), in the
  model on its own, at trial values;
- :class:`InputLagTerm`: the model driven by its command through a first-order lag;
- :class:`RelaxationTerm`: ``-(p - LP_r[p]) dt`` from the measured pressure alone, for
  an effect a one-step prediction cannot show (it starts each step at a measured state).

Every term carries ``start``: the effect's parameter values the term stands for, which
a candidate starts from when this term explains the residual best.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pneubayes.effects.path import SLOT_INDEX


@dataclass(frozen=True)
class LibraryTerm:
    """One candidate column: its label and the parameter values it stands for."""

    label: str
    start: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class TrialTerm(LibraryTerm):
    """The effect in the model at ``values`` (its other parameters neutral)."""

    values: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class FormTrialTerm(LibraryTerm):
    """``effect`` (another form of the named effect) alone beside the model, at
    ``values``."""

    effect: Any = None
    values: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class InputLagTerm(LibraryTerm):
    """The model's command through a first-order lag of ``lag_s`` (s)."""

    lag_s: float = 0.0


@dataclass(frozen=True)
class RelaxationTerm(LibraryTerm):
    """``-(p - LP_r[p]) dt`` for the measured pressure p and a first-order low-pass of
    rate ``rate_per_s`` (1/s): to first order the pressure error of a state relaxing at
    that rate after a fill or a vent (Pa)."""

    rate_per_s: float = 0.0


@dataclass(frozen=True)
class CandidateContext:
    """What an effect needs to propose its candidate forms beside a fitted model.

    model, params: the current fit; rig: the recordings' rig; term_start: the ``start``
    of the effect's library term that explained the residual best (None: no term);
    second_state_free: whether the model leaves room for the temperature and line
    states (no rig card's compliant chamber, supply tank or second compartment: the
    simulator steps those with the pressure alone); line_segments: the most cells of an
    acoustic line form (0: none); line_cutoff_Hz: the lumped cut-off frequency its cells
    should reach; dead_volume_m3: the fitted chamber volume at position 0; line_form:
    the outside tube's form, ``"line"`` (lumped cells) or ``"wave"`` (a transmission
    line); slots: the current fit's lowered slot row (:data:`~pneubayes.effects.path.
    SLOT_INDEX`), which an effect reads (:meth:`slot`) for what else the model holds;
    wave_grid: the transmission line's longest grid step (s) and steps per element transit
    (:meth:`~pneubayes.effects.TubeDelay.wave_grid_s`); wave_unsteady: whether the
    transmission line fits Zielke's unsteady wall shear's weight too.
    """

    model: Any
    params: dict
    rig: Any
    term_start: dict | None
    second_state_free: bool
    line_segments: int
    dead_volume_m3: float
    line_cutoff_Hz: float = 300.0
    line_form: str = "line"
    slots: Any = None
    wave_grid: tuple = (1e-4, 1)
    wave_unsteady: bool = False

    def slot(self, name: str) -> float:
        """The current fit's value of slot ``name`` (0 without ``slots``)."""
        if self.slots is None:
            return 0.0
        return float(self.slots[SLOT_INDEX[name]])

    def inside(self, effect, name: str, value: float) -> float:
        """``value`` moved just inside the bounds parameter ``name`` has in the model
        with ``effect`` added (a refiner's start)."""
        return inside_bounds(self.model.with_effect(effect), name, value)


def inside_bounds(model, name: str, value: float) -> float:
    """``value`` moved just inside ``model``'s bounds of parameter ``name`` (its bound
    overrides included): a refiner's start."""
    p = model.parameter(name)
    margin = 1e-6 * (p.upper - p.lower)
    return float(min(max(value, p.lower + margin), p.upper - margin))
