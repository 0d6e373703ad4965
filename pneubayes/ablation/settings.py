"""The settings every cell of a study shares: the data design, the scoring, and the
library's own fit and discovery settings nested as ``[settings.fit]`` and
``[settings.discovery]`` (:mod:`pneubayes.ablation.study` reads them from a study file,
:func:`pneubayes.settings_tree.override` applies them over the defaults, and
:meth:`Settings.__post_init__` checks them)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.evaluation import PAPER_HORIZON_S
from pneubayes.inference.fit import FitSettings
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.settings_tree import FieldError

METHODS = ("lsq", "refine", "mcmc")
SUPPLIES = ("measured", "nominal")
LEAK_FORMS = ("orifice", "laminar", "graded")
#: Largest valve command magnitude, V (paper section V: -5..+5).
MAX_COMMAND_V = 5.0


def _study_fit() -> FitSettings:
    """The study's fit settings: the library's, with a shorter emcee run (4000 steps)."""
    return FitSettings(sampler=SamplerSettings(max_steps=4000))


#: Keys of the nested tables the cell sets itself, and what sets them: naming them in a
#: study is an error, not an ignored setting.
CELL_OWNED = {("fit", "horizon_s"): "the study's settings.horizon_s",
              ("fit", "stride_s"): "fits use non-overlapping windows of settings.horizon_s",
              ("fit.sampler", "seed"): "the cell's seed",
              ("discovery", "fit"): "discover cells fit with [settings.fit]",
              ("discovery", "posterior"): "settings.method = \"mcmc\" samples the posterior",
              ("discovery", "seed"): "the cell's seed"}


def table_at(doc, table: str):
    """The nested table at the dotted path ``table`` of ``doc``, or None."""
    for part in table.split("."):
        doc = doc.get(part) if isinstance(doc, dict) else None
    return doc if isinstance(doc, dict) else None


def check_number(key, v, lo=None, hi=None, closed_lo=False):
    if lo is not None and (v < lo if closed_lo else v <= lo):
        raise FieldError(key, f"must be {'>=' if closed_lo else '>'} {lo:g}, got {v:g}")
    if hi is not None and v > hi:
        raise FieldError(key, f"must be <= {hi:g}, got {v:g}")


def _check_list(key, values, lo, hi, closed_lo=False, allow_empty=False):
    if not values and not allow_empty:
        raise FieldError(key, "the list is empty; give at least one value")
    for i, v in enumerate(values):
        check_number(f"{key}[{i}]", v, lo, hi, closed_lo)
        if v in values[:i]:
            raise FieldError(f"{key}[{i}]", f"duplicate value {v!r}")


def _check_choice(key, v, choices):
    if v not in choices:
        raise FieldError(key, f"unknown value {v!r}; choose from {', '.join(choices)}")


@dataclass(frozen=True)
class Settings:
    """Settings shared by every cell of a study (SI units in the names).

    duration_s: length of every bench recording, s. method: ``"lsq"`` (the paper's
    eq.-10 least squares), ``"refine"`` (then 2-s multiple shooting; default) or
    ``"mcmc"`` (then the emcee posterior, scored at its median). horizon_s, stride_s:
    prediction windows, s (stride defaults to the horizon: non-overlapping); the fits
    use the same horizon, as windows that do not overlap.
    eval_command_bands_V: besides the overall RMSE, the RMSE over predicted samples whose
    command (held over the preceding interval) satisfies ``|u| <= band``, V.
    supply: ``"measured"`` gives the fitted model the recorded supply column,
    ``"nominal"`` the nominal constant of the recording's JSON (the column is dropped);
    the thin-port core always uses the nominal, so this matters only for a model with
    ``supply_fluctuation`` (paper IV-F).
    fit_positions (fractions of the stroke) x fit_command_ranges_V (V): the fixed-volume
    fitting recordings (seed); fit_moving_count moving-piston recordings at
    fit_moving_range_V are added (seed + 500). eval_positions / eval_moving_count: the
    held-out recordings of a fixed / moving cell (seed + heldout_seed_offset).
    leak_form: law of ``cylinder_leak`` in fitted models (the paper's orifice by
    default; ``laminar``, or ``graded`` along the stroke); data_leak_form: law of a
    planted catalogue leak (laminar by default: an orifice leak is the exhaust port's
    own law and is absorbed by the exhaust offset).
    smoke_duration_s: recording length of ``--smoke`` runs, s.
    fit: the library's :class:`~pneubayes.inference.fit.FitSettings` (a
    ``[settings.fit]`` table, its sampler ``[settings.fit.sampler]``), except its
    windows (``horizon_s`` above) and seed (the cell's); its ``position_cutoff_Hz``
    low-passes the position for scoring too. discovery: the library's
    :class:`~pneubayes.discovery.settings.DiscoverySettings` of ``"discover"`` cells
    (``[settings.discovery]``), except its fit (``fit`` above), posterior (``method``)
    and seed (the cell's).
    """

    duration_s: float = 20.0
    method: str = "refine"
    horizon_s: float = PAPER_HORIZON_S
    stride_s: float | None = None
    eval_command_bands_V: tuple[float, ...] = ()
    supply: str = "measured"
    fit_positions: tuple[float, ...] = (0.5, 0.9)
    fit_command_ranges_V: tuple[float, ...] = (5.0, 0.5)
    fit_moving_count: int = 2
    fit_moving_range_V: float = 5.0
    eval_positions: tuple[float, ...] = (0.5, 0.9)
    eval_moving_count: int = 2
    heldout_seed_offset: int = 1000
    leak_form: str = "orifice"
    data_leak_form: str = "laminar"
    smoke_duration_s: float = 14.0
    fit: FitSettings = field(default_factory=_study_fit)
    discovery: DiscoverySettings = field(default_factory=DiscoverySettings)

    def __post_init__(self):
        for key in ("duration_s", "horizon_s", "smoke_duration_s"):
            check_number(key, getattr(self, key), 0.0)
        if self.stride_s is not None:
            check_number("stride_s", self.stride_s, 0.0)
        check_number("fit_moving_range_V", self.fit_moving_range_V, 0.0, MAX_COMMAND_V)
        _check_choice("method", self.method, METHODS)
        _check_choice("supply", self.supply, SUPPLIES)
        _check_choice("leak_form", self.leak_form, LEAK_FORMS)
        _check_choice("data_leak_form", self.data_leak_form, LEAK_FORMS)
        _check_list("eval_command_bands_V", self.eval_command_bands_V, 0.0, MAX_COMMAND_V,
                    allow_empty=True)
        _check_list("fit_command_ranges_V", self.fit_command_ranges_V, 0.0, MAX_COMMAND_V)
        _check_list("fit_positions", self.fit_positions, 0.0, 1.0, closed_lo=True)
        _check_list("eval_positions", self.eval_positions, 0.0, 1.0, closed_lo=True)
        for key, lo in (("fit_moving_count", 0), ("eval_moving_count", 1),
                        ("heldout_seed_offset", 1)):
            if getattr(self, key) < lo:
                raise FieldError(key, f"must be >= {lo}, got {getattr(self, key)}")
        if self.fit.position_cutoff_Hz is None:
            raise FieldError("fit.position_cutoff_Hz", "a study scores with the position "
                             "low-passed as it fits: give a cutoff, Hz")

    @property
    def effective_stride_s(self) -> float:
        return self.horizon_s if self.stride_s is None else self.stride_s

    def to_dict(self) -> dict:
        return asdict(self)
