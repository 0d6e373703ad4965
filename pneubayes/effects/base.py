"""The one interface every model component follows: named parameters lowered onto
signal-path slots (see :mod:`pneubayes.effects.path`)."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from pneubayes.effects.discovery import CandidateContext, LibraryTerm
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.rig import Rig


@dataclass(frozen=True)
class Parameter:
    """A named model parameter with unit, physical bounds and a default prior.

    ``prior`` is ``"uniform"`` on [lower, upper] or ``"log-uniform"`` (lower > 0).
    ``neutral`` is the value at which the component has no effect (None for the base).
    ``limit`` (``"lower"``, ``"upper"`` or None) names a bound where the physics itself
    ends (a knee's gain at a flat rail), kept a little inside for the numerics: a fit
    there is that limit, not a sign that the component stands in for something else.
    """

    name: str
    unit: str
    lower: float
    upper: float
    prior: str
    description: str
    neutral: float | None = None
    limit: str | None = None

    def __post_init__(self):
        if not self.lower < self.upper:
            raise ValueError(f"Parameter {self.name}: lower {self.lower} >= upper {self.upper}")
        if self.limit not in (None, "lower", "upper"):
            raise ValueError(f"Parameter {self.name}: limit must be 'lower', 'upper' or None, "
                             f"got {self.limit!r}")
        if self.prior not in ("uniform", "log-uniform"):
            raise ValueError(f"Parameter {self.name}: unknown prior {self.prior!r}")
        if self.prior == "log-uniform" and self.lower <= 0:
            raise ValueError(f"Parameter {self.name}: log-uniform prior needs lower > 0")

    def log_prior(self, value):
        """Log density of the default prior (unnormalised), -inf outside the bounds."""
        v = np.asarray(value, dtype=np.float64)
        inside = (v >= self.lower) & (v <= self.upper)
        if self.prior == "uniform":
            dens = np.zeros_like(v)
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                dens = -np.log(np.where(v > 0, v, 1.0))
        return np.where(inside, dens, -np.inf)

    def sample_prior(self, rng: np.random.Generator, size=None):
        """Draw from the default prior."""
        if self.prior == "uniform":
            return rng.uniform(self.lower, self.upper, size)
        return np.exp(rng.uniform(math.log(self.lower), math.log(self.upper), size))


@dataclass(frozen=True)
class Eq10Fit:
    """What the paper's least squares on dp/dt (eq. 10, :mod:`pneubayes.inference.lsq`)
    found, as an effect reads it to estimate its own parameters
    (:meth:`Effect.eq10_estimate`).

    Attributes
    ----------
    model : Model
        The model fitted (its parameters' bounds, with any overrides).
    recordings : sequence of Recording
        The fixed-volume recordings, in the order the indices below use.
    volumes_m3 : ndarray
        Each recording's chamber volume at its fixed position, dead volume included, m^3.
    positions_m : ndarray
        Each recording's fixed position, m.
    column : dict
        Recording index -> (coefficient, standard error) of the effect's own column
        (:meth:`Effect.eq10_column`), for the recordings with usable holds; empty for an
        effect without one.
    ports : dict
        The fitted Gompertz parameters of both ports (``inlet_*``, ``exhaust_*``); an
        effect with a port's law is lumped with that port's offset.
    known : dict
        Parameters given as known (from a valve characterisation, say).
    """

    model: Any
    recordings: Any
    volumes_m3: np.ndarray
    positions_m: np.ndarray
    column: Mapping[int, tuple[float, float]]
    ports: Mapping[str, float]
    known: Mapping[str, float]


class Component(ABC):
    """Base of the thin-port core and of every effect.

    A component declares its parameters and lowers a batch of their values onto
    signal-path slots. Constructors only store options; they never compute.
    """

    #: Catalogue name, e.g. ``"tube_delay"``.
    name: ClassVar[str]
    #: Signal-path slots this component writes (documentation and checks).
    acts_on: ClassVar[tuple[str, ...]]

    @abstractmethod
    def parameters(self) -> tuple[Parameter, ...]:
        """The component's parameters, in order."""

    @abstractmethod
    def lower(self, values: Mapping[str, np.ndarray], rig: Rig) -> dict[str, np.ndarray]:
        """Map parameter arrays (each shape ``(B,)``) to slot contributions ``(B,)``."""

    def options(self) -> dict[str, Any]:
        """Constructor options, as stored in a model card."""
        return {}

    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters())

    def check_lowering(self, contributions: Mapping[str, np.ndarray]) -> None:
        unknown = set(contributions) - set(self.acts_on)
        if unknown:
            raise RuntimeError(f"{self.name} wrote slots it does not declare: {sorted(unknown)}")
        for slot in contributions:
            if slot not in SLOT_INDEX:
                raise RuntimeError(f"{self.name} wrote unknown slot {slot!r}")

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self.options() == other.options()

    def __hash__(self) -> int:
        return hash((type(self).__name__, tuple(sorted(self.options().items()))))


class Effect(Component):
    """A switchable physical effect: one entry of the catalogue.

    Besides the component interface, an effect carries realistic default strengths for
    the virtual bench (:meth:`bench_defaults`) and may perturb the drive signals the
    bench generates (:meth:`perturb_inputs`), so the same object plants the effect in
    synthetic data and fits it in a model. It also tells the discovery loop how to look
    for it (:meth:`library_terms`) and how to fit it once named
    (:meth:`candidate_forms`, :meth:`refine_first`); see :mod:`pneubayes.effects.discovery`.
    """

    #: The forms of an effect with a ``form`` option (empty: one form only).
    forms: ClassVar[tuple[str, ...]] = ()
    #: Option sets beside the forms that add parameters (every parameter name the effect
    #: can have: :func:`pneubayes.effects.catalogue_parameter_names`).
    option_variants: ClassVar[tuple[dict, ...]] = ()
    #: Default trial strengths of the effect's library terms (the unit of the
    #: parameter its terms vary; a :class:`~pneubayes.discovery.library.LibraryGrid`
    #: may replace them).
    library_strengths: ClassVar[tuple[float, ...]] = ()
    #: For an effect the library leaves out unless asked (``library_strengths`` empty):
    #: the strengths to give it in a :class:`~pneubayes.discovery.library.LibraryGrid`
    #: (the library never uses them on its own).
    opt_in_strengths: ClassVar[tuple[float, ...]] = ()
    #: False for an effect the discovery library never searches for, whatever the
    #: strengths asked (the open-form closure, whose terms another search proposes): it
    #: offers no library terms.
    library_searched: ClassVar[bool] = True
    #: Where a named effect's candidate starts when no library term of it explained the
    #: residual (parameter -> value; missing parameters start neutral).
    discovery_fallback: ClassVar[dict[str, float]] = {}
    #: True for an effect with a state the recordings do not measure and a window does
    #: not know at its start (the chamber temperature): fits simulate warm-up windows
    #: before the scored ones to settle it.
    needs_warmup: ClassVar[bool] = False
    #: False for an effect the simulator cannot carry beside a tube's acoustic line
    #: (the loop then proposes no line form beside it).
    beside_line: ClassVar[bool] = True
    #: True for an effect whose every form costs a fit about what its first form costs
    #: (no state, no finer time grid: a map of the reading or of a slot). The loop fits
    #: such an effect's later forms even when its first form gained little beside the
    #: round's best (:func:`~pneubayes.discovery.rounds.fit_round_forms`), a rule that
    #: is there to spare minutes-long forms (an acoustic line), not a second parameter.
    cheap_forms: ClassVar[bool] = False
    #: True for an effect that reads the pressure through a map after the kernel (it
    #: defines :meth:`reading_relaxations`, :meth:`reading_plays`,
    #: :meth:`reading_commands`, :meth:`reading_flows` or :meth:`reading_hinges`; it
    #: writes no slot of the kernel).
    relaxes_reading: ClassVar[bool] = False

    def beside_tube(self, form: str) -> bool:
        """Whether the simulator carries this effect beside a tube simulated as ``form``
        (``"line"``: an acoustic line; ``"wave"``: the transmission-line tube); by
        default :attr:`beside_line` for both."""
        return self.beside_line

    def _check(self):
        """Raise ValueError unless the effect's options are valid: its ``form`` one of
        :attr:`forms` (an effect with more options extends this)."""
        if self.forms and getattr(self, "form", None) not in self.forms:
            raise ValueError(f"{self.name}: form must be one of {self.forms}, got "
                             f"{getattr(self, 'form', None)!r}")

    def reading_relaxations(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray] | None:
        """For an effect that relaxes the reading, ``r = p + sum_k g_k (p - p_bar_k)``
        with ``tau_k dp_bar_k/dt = p - p_bar_k``: ``(gains (-), time constants (s))``,
        each ``(B, K)``, at a batch of its parameter ``values``; None (the default) for
        an effect that does not. The simulator reads every window's pressure through
        the relaxations of all such effects (:mod:`pneubayes.simulation.reading_closure`)."""
        return None

    def reading_plays(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray] | None:
        """For an effect that adds plays to the reading, ``r = p + sum_j h_j (p - y_j)``
        with ``y_j`` the play of half-width ``w_j`` of ``p``: ``(gains (-), half-widths
        (Pa))``, each ``(B, J)``; None (the default) for an effect that does not
        (:mod:`pneubayes.simulation.reading_play`; such an effect sets
        :attr:`relaxes_reading` too)."""
        return None

    def reading_commands(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray] | None:
        """For an effect that adds lags of the command's magnitude to the reading, ``r =
        p + sum_k c_k l_k`` with ``tau_k dl_k/dt = |u| - l_k``: ``(gains (Pa per command
        unit), time constants (s))``, each ``(B, K)``; None (the default) for an effect
        that does not (:mod:`pneubayes.simulation.reading_command`; such an effect sets
        :attr:`relaxes_reading` too)."""
        return None

    def reading_flows(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, tuple[str, ...]] | None:
        """For an effect that adds terms of the ports' mass flows to the reading, ``r = p +
        sum_k c_k F_k``: ``(gains (B, K) in Pa per feature unit, the K feature names)``;
        None (the default) for an effect that does not
        (:mod:`pneubayes.simulation.reading_flow`; such an effect sets
        :attr:`relaxes_reading` too)."""
        return None

    def reading_hinges(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, np.ndarray] | None:
        """For an effect that reads the reading through hinges last, ``r = z + sum_j c_j
        max(0, z - theta_j)``: ``(gains (-), thresholds (Pa absolute))``, each ``(B,
        J)``; None (the default) for an effect that does not
        (:mod:`pneubayes.simulation.reading_hinge`; such an effect sets
        :attr:`relaxes_reading` too)."""
        return None

    def reading_lead_parameter(self) -> str | None:
        """The parameter that is a lagged reading's group delay at DC, s (how far the
        chamber leads the reading), for an effect that lags the reading; None (the
        default) for others."""
        return None

    def eq10_column(self, pressure_Pa: np.ndarray, atmospheric_Pa: float, gas):
        """This effect's column in the paper's least squares on dp/dt (eq. 10,
        :mod:`pneubayes.inference.lsq`): on a fixed-volume recording's smoothed
        ``pressure_Pa``, dp/dt per unit of one coefficient the recording's holds share
        (the effect's flow over the chamber volume); None (the default) for an effect
        that adds no column.

        Parameters
        ----------
        pressure_Pa : ndarray
            The smoothed chamber pressure, Pa absolute.
        atmospheric_Pa : float
            The recording's atmospheric pressure, Pa.
        gas : Gas
            The rig's gas (specific gas constant, temperature, heat capacity ratio).

        Returns
        -------
        ndarray or None
            The column, shaped as ``pressure_Pa``.
        """
        return None

    def eq10_estimate(self, fit: Eq10Fit) -> tuple[dict[str, float], list[str]]:
        """The effect's parameter values from the paper's least squares.

        Parameters
        ----------
        fit : Eq10Fit
            What the least squares found (the effect's column coefficients, the ports'
            curves, the volumes).

        Returns
        -------
        values : dict
            Parameter values; they may include a base parameter the effect's law is
            lumped with (a port's offset). Empty (the default): the effect starts at
            its neutral values.
        notes : list of str
            What the user should know about the estimate.
        """
        return {}, []

    @classmethod
    def card_defaults(cls, params: Mapping) -> dict[str, float]:
        """Values for parameters a card written before they existed lacks, as that card
        meant them (``params``: the card's parameters); none by default."""
        return {}

    @classmethod
    def form_from_parameters(cls, names) -> str | None:
        """The form a card with these parameter names describes: of the forms whose
        parameters are all among ``names``, the one with the most parameters (the
        first form if none is; None for an effect with one form)."""
        if not cls.forms:
            return None
        names = set(names)
        best, best_n = cls.forms[0], -1
        for form in cls.forms:
            own = cls(form=form).parameter_names()
            if set(own) <= names and len(own) > best_n:
                best, best_n = form, len(own)
        return best

    def library_terms(self, strengths: tuple[float, ...]) -> tuple[LibraryTerm, ...]:
        """The terms this effect offers the discovery library at these trial strengths
        (none: the effect is never searched for)."""
        return ()

    def candidate_start(self, term_start: dict | None) -> dict[str, float]:
        """Start values of a named effect's candidate: the best term's, or
        :attr:`discovery_fallback` without one (parameters not given start neutral)."""
        return dict(term_start) if term_start else dict(self.discovery_fallback)

    def candidate_forms(self, ctx: CandidateContext) -> list[tuple["Effect", dict]]:
        """``[(effect, start values), ...]``: the form(s) the loop fits once this effect
        is named beside ``ctx.model`` (empty: none fits there). Start values name only
        the parameters not started neutral; the loop moves them inside the bounds."""
        return [(self, self.candidate_start(ctx.term_start))]

    def form_after_fit(self, params: dict, ctx: CandidateContext
                       ) -> tuple["Effect", dict] | None:
        """A form to fit next once this one is fitted at ``params`` (the model's and
        the effect's fitted values), with start values for its own parameters; None
        (the default) for none."""
        return None

    def refine_first(self) -> tuple[str, ...] | None:
        """Parameters (of this effect and the model) a refinement fits on their own
        before all of them, or None."""
        return None

    def volume_taken_m3(self, values: Mapping[str, np.ndarray], rig: Rig):
        """The part of ``dead_volume_m3`` this effect takes out of the chamber at the
        parameter ``values``, m^3 (an acoustic line's: the chamber behind it is the rest,
        which must stay positive); None (the default) for none."""
        return None

    def neutral_values(self) -> dict[str, float]:
        """Parameter values at which the effect vanishes (zero strength)."""
        return {p.name: float(p.neutral) for p in self.parameters()}

    @abstractmethod
    def bench_defaults(self) -> dict[str, float]:
        """Realistic true values for the virtual bench."""

    def start_values(self) -> dict[str, float]:
        """Where a fit starts this effect when the data allow no better start (the
        paper's least squares does not apply): zero strength, unless the effect says
        otherwise."""
        return self.neutral_values()

    def perturb_inputs(self, time_s: np.ndarray, supply_pressure_Pa: np.ndarray,
                       rig: Rig, rng: np.random.Generator) -> np.ndarray:
        """Return the true supply pressure the bench should use (default: unchanged)."""
        return supply_pressure_Pa


class DirectEffect(Effect):
    """An effect whose single parameter sets one signal-path slot unchanged.

    Subclasses declare ``parameter`` (its neutral value is the slot's 0), ``slot`` and
    ``bench_value`` (the realistic true value for the bench).
    """

    parameter: ClassVar[Parameter]
    slot: ClassVar[str]
    bench_value: ClassVar[float]

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "slot" in cls.__dict__:
            cls.acts_on = (cls.slot,)

    def parameters(self) -> tuple[Parameter, ...]:
        return (self.parameter,)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig) -> dict[str, np.ndarray]:
        return {self.slot: values[self.parameter.name]}

    def bench_defaults(self) -> dict[str, float]:
        return {self.parameter.name: float(self.bench_value)}
