"""Realistic alternative forms of the catalogue effects, for the high-fidelity plant.

The catalogue effects (:mod:`pneubayes.effects`) are the forms the models fit. A
discovery loop tuned on data planted with exactly those forms may not recognise an
effect built differently, as it is in outside recordings. Each class here is a
physically different, more detailed form of one catalogue effect, simulated by the
independent plant of :mod:`pneubayes.bench.plant`; ``catalogue_name`` names the effect
a discovery run should report for it.

The *out-of-catalogue* forms (:class:`BladderVolume`, :class:`SpoolHysteresis`,
:class:`ReliefValve`, :class:`InletFlowForce`, :class:`LipSealLeak`) are effects no
catalogue effect expresses: their ``catalogue_name`` is None, meaning a discovery run
should name *no* catalogue effect for them (an open-form closure term may describe
them). They test the open-form stage blind.

Every form is a small frozen dataclass with SI units in its field names; it validates
its fields on construction (errors name the field) and :meth:`PlantForm.to_dict` gives
the record written to ``truth.json``. :func:`forms_from_names` builds realistic
defaults per rig, :func:`form_from_dict` reads a record back.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import ClassVar

from pneubayes.effects import CATALOGUE
from pneubayes.physics.cylinder import cylinder_preset
from pneubayes.physics.gas import GasConstants

#: Dynamic viscosity of air at 20 degC, Pa s (the catalogue's tube_delay uses the same).
AIR_VISCOSITY_PA_S = 1.81e-5


def _positive(obj, *names):
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                math.isfinite(v) and v > 0):
            raise ValueError(f"{type(obj).__name__}.{n} must be a finite number > 0, got {v!r}")


def _non_negative(obj, *names):
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                math.isfinite(v) and v >= 0):
            raise ValueError(f"{type(obj).__name__}.{n} must be a finite number >= 0, "
                             f"got {v!r}")


class PlantForm:
    """Base of the realistic forms: a frozen dataclass naming its catalogue effect."""

    #: The catalogue effect this form is a realistic version of; None for an effect
    #: outside the catalogue (discovery should name no catalogue effect for it).
    catalogue_name: ClassVar[str | None]

    def to_dict(self) -> dict:
        """``{"form": class name, "catalogue_name": ..., **fields}`` (JSON-ready)."""
        return {"form": type(self).__name__, "catalogue_name": self.catalogue_name,
                **asdict(self)}


@dataclass(frozen=True)
class AcousticTube(PlantForm):
    """The valve-chamber tube as a lumped transmission line (waves, friction, volume).

    ``segments`` cells of length ``dx = length_m / segments``, each a volume
    ``A dx`` (A = pi D^2 / 4) whose pressure obeys eq. 5 (isentropic, supply
    temperature) and, towards the next cell (the last one: the chamber), a mass-flow
    (momentum) state ``q``::

        dq/dt = A / l (p_i - p_{i+1}) - (f Re) mu q / (2 rho D^2)

    with the link ``l = dx`` between cells and ``l = dx / 2`` from the last cell's
    centre to the chamber (a staggered grid, second order in dx, as the model's line:
    :mod:`pneubayes.simulation.line`), rho the mean density of the two cells and the
    Darcy friction factor times the Reynolds number ``f Re`` from Churchill (1977) for a
    smooth tube: 64 (Poiseuille, ``32 mu / D^2`` per unit density) in laminar flow,
    Blasius-like in turbulent flow, smooth in between. Convective momentum is neglected
    (Mach < 0.2). Waves travel at ``c = sqrt(kappa Rs T)`` and reflect at the chamber.
    The valve's port flows enter the first cell; the tube's volume ``A L`` adds to the
    compressed volume.
    """

    catalogue_name: ClassVar[str] = "tube_delay"
    length_m: float
    diameter_m: float = 0.002
    segments: int = 8
    air_viscosity_Pa_s: float = AIR_VISCOSITY_PA_S

    def __post_init__(self):
        _positive(self, "length_m", "diameter_m", "air_viscosity_Pa_s")
        if isinstance(self.segments, bool) or not isinstance(self.segments, int) \
                or self.segments < 1:
            raise ValueError(f"AcousticTube.segments must be an integer >= 1, "
                             f"got {self.segments!r}")

    @property
    def area_m2(self) -> float:
        """Inner cross-section pi D^2 / 4, m^2."""
        return math.pi / 4.0 * self.diameter_m**2

    @property
    def volume_m3(self) -> float:
        """Inner volume A L, m^3."""
        return self.area_m2 * self.length_m

    def transit_time_s(self, gas: GasConstants) -> float:
        """One-way acoustic transit time L / c, s."""
        return self.length_m / gas.speed_of_sound_m_per_s


@dataclass(frozen=True)
class RoundedDeadzone(PlantForm):
    """Spool overlap with rounded (C1) corners, applied to the spool position s (V).

    ``u' = sign(s) phi(|s| - w)`` with half-width ``w = halfwidth_V``, rounding
    ``r = rounding_V`` and the quadratic corner

        phi(z) = 0 for z <= -r,  (z + r)^2 / (4 r) for |z| < r,  z for z >= r,

    which is C1 (value and slope continuous), exactly the hard dead band
    ``sign(s) max(|s| - w, 0)`` for ||s| - w| >= r and tends to it as r -> 0. The
    corners model the gradual opening of real spool edges (metering notches, edge
    radii, radial clearance). Needs ``r <= w`` so that u' = 0 around s = 0;
    ``rounding_V = 0`` is the hard dead band.
    """

    catalogue_name: ClassVar[str] = "valve_deadzone"
    halfwidth_V: float
    rounding_V: float

    def __post_init__(self):
        _non_negative(self, "halfwidth_V", "rounding_V")
        if self.rounding_V > self.halfwidth_V:
            raise ValueError(f"RoundedDeadzone.rounding_V ({self.rounding_V}) must not exceed "
                             f"halfwidth_V ({self.halfwidth_V})")


@dataclass(frozen=True)
class ClearanceLeak(PlantForm):
    """Compressible laminar flow through the annular piston-bore gap to atmosphere.

    ``mdot = pi D h^3 (p^2 - P_atm^2) / (24 mu L(x) Rs T)`` for gap ``h = gap_m``, seal
    diameter ``D`` (``seal_diameter_m``, None = the bore) and the leak path's length
    ``L(x) = seal_length_m + seal_length_slope * x`` at piston position x (m), gas at
    the supply temperature T. With ``seal_length_slope = 0`` this is the catalogue's
    laminar leak with conductance :meth:`conductance_kg_per_s_Pa2`; a slope (a tapered
    bore, a bushing whose engagement changes along the stroke) makes the leak depend on
    the position, which no catalogue form does.
    """

    catalogue_name: ClassVar[str] = "cylinder_leak"
    gap_m: float
    seal_length_m: float
    seal_diameter_m: float | None = None
    seal_length_slope: float = 0.0
    air_viscosity_Pa_s: float = AIR_VISCOSITY_PA_S

    def __post_init__(self):
        _positive(self, "gap_m", "seal_length_m", "air_viscosity_Pa_s")
        if self.seal_diameter_m is not None:
            _positive(self, "seal_diameter_m")
        if isinstance(self.seal_length_slope, bool) or not isinstance(
                self.seal_length_slope, (int, float)) or not math.isfinite(
                self.seal_length_slope):
            raise ValueError(f"ClearanceLeak.seal_length_slope must be a finite number, "
                             f"got {self.seal_length_slope!r}")

    def seal_length_at(self, position_m):
        """Leak-path length L(x) = seal_length_m + seal_length_slope x, m."""
        return self.seal_length_m + self.seal_length_slope * position_m

    def conductance_kg_per_s_Pa2(self, bore_m: float, gas: GasConstants,
                                 position_m: float = 0.0) -> float:
        """k in ``mdot = k (p^2 - P_atm^2)`` at ``position_m``, kg/(s Pa^2)."""
        d = bore_m if self.seal_diameter_m is None else self.seal_diameter_m
        length = self.seal_length_at(position_m)
        if not length > 0:
            raise ValueError(f"ClearanceLeak: seal length {length} m at position "
                             f"{position_m} m is not > 0")
        rs_t = gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
        return math.pi * d * self.gap_m**3 / (24.0 * self.air_viscosity_Pa_s * length * rs_t)


@dataclass(frozen=True)
class RegulatorDroop(PlantForm):
    """The supply at the valve inlet is a regulator's output that droops under load.

    A state ``D`` (Pa) with ``dD/dt = (droop_Pa_per_g_per_s * mdot_in - D) /
    time_constant_s``, ``mdot_in`` the inlet port's signed mass flow in g/s; the valve
    sees ``P_up - D`` where ``P_up`` is the upstream supply (the nominal, or the
    wandering supply of the catalogue's supply_fluctuation). The supply sensor sits at
    the valve inlet, so the recorded supply column shows the droop. ``D(0) = 0``.
    """

    catalogue_name: ClassVar[str] = "supply_fluctuation"
    droop_Pa_per_g_per_s: float
    time_constant_s: float

    def __post_init__(self):
        _non_negative(self, "droop_Pa_per_g_per_s")
        _positive(self, "time_constant_s")


@dataclass(frozen=True)
class SecondOrderSpool(PlantForm):
    """Second-order spool dynamics: ``s'' = w^2 (u - s) - 2 zeta w s'``, w = 2 pi f_n.

    The area maps (behind any dead band) see the spool position s (V); the spool starts
    at rest at the first command.
    """

    catalogue_name: ClassVar[str] = "spool_lag"
    natural_frequency_Hz: float
    damping: float

    def __post_init__(self):
        _positive(self, "natural_frequency_Hz", "damping")


@dataclass(frozen=True)
class WallHeatTransfer(PlantForm):
    """Energy equation of the chamber gas with convection to the wall.

    Chamber temperature T is a state. With net inflow enthalpy (inflow at the supply
    temperature T_s, outflow at T), heat ``Q = h A_w (T_w - T)`` and the chamber's wall
    area ``A_w = 2 A_bore + pi D V / A_bore`` (end caps and barrel of a cylinder of
    volume V, so it grows with the stroke)::

        dp/dt = kappa / V (Rs sum(T_src mdot) - p dV/dt) + (kappa - 1) Q / V
        dT/dt = T (dp/dt / p + dV/dt / V - Rs T mdot_net / (p V))

    Orifice flows leaving the chamber scale with sqrt(T_s / T) (eq. 1's upstream
    temperature). The wall is at ``wall_temperature_K`` (None = the supply temperature).
    At h = 0 the chamber is adiabatic; as h grows it tends to isothermal.
    """

    catalogue_name: ClassVar[str] = "heat_transfer"
    h_W_per_m2_K: float
    wall_temperature_K: float | None = None

    def __post_init__(self):
        _non_negative(self, "h_W_per_m2_K")
        if self.wall_temperature_K is not None:
            _positive(self, "wall_temperature_K")


# ------------------------------------------------------------ out-of-catalogue forms
@dataclass(frozen=True)
class BladderVolume(PlantForm):
    """A compliant chamber (bellows, muscle, soft hose) whose volume grows with gauge pressure.

    ``V = V_dead + A x + dV(p)`` with, for ``y = (p - P_atm) / p_scale``,
    ``dV = dV_max (1 - exp(-y))`` for y >= 0 and, below atmosphere, a stiffer collapse
    onto the seat ``dV = dV_max y / (1 - 4 y)`` (C1 at y = 0, never below
    -dV_max / 4). Eq. 5 then reads
    ``dp/dt (1 + kappa p dV'(p) / V) = kappa / V (Rs T mdot - p A dx/dt)``: the chamber
    is stiffer at high pressure. ``dV_max_m3 = 0`` is the rigid chamber.
    """

    catalogue_name: ClassVar[str | None] = None
    dV_max_m3: float
    pressure_scale_Pa: float = 150_000.0

    def __post_init__(self):
        _non_negative(self, "dV_max_m3")
        _positive(self, "pressure_scale_Pa")


@dataclass(frozen=True)
class SpoolHysteresis(PlantForm):
    """Backlash (play) between the command and the spool, with memory of direction.

    The effective spool s_h follows the spool s only once s leaves the band
    ``[s_h - b, s_h + b]``, ``b = half_band_V``; smoothed as a fast first-order play::

        ds_h/dt = (s - b - s_h) / tau  if s > s_h + b
                  (s + b - s_h) / tau  if s < s_h - b,  else 0

    with ``tau = time_constant_s`` (much faster than the spool). The area maps see s_h.
    ``half_band_V = 0`` is no play (the state is omitted). s_h starts at the first
    command.
    """

    catalogue_name: ClassVar[str | None] = None
    half_band_V: float
    time_constant_s: float = 2e-4

    def __post_init__(self):
        _non_negative(self, "half_band_V")
        _positive(self, "time_constant_s")


@dataclass(frozen=True)
class ReliefValve(PlantForm):
    """A spring-loaded relief valve on the chamber venting to atmosphere.

    ``mdot_out = k (p - p_crack)^1.5`` for ``p > p_crack`` (absolute), else 0: a poppet
    whose opening grows with the overpressure and whose flow grows with the opening
    and the root of the drop. ``k = flow_coefficient_kg_per_s_Pa1p5``; 0 is no valve.
    """

    catalogue_name: ClassVar[str | None] = None
    crack_pressure_Pa: float
    flow_coefficient_kg_per_s_Pa1p5: float

    def __post_init__(self):
        _positive(self, "crack_pressure_Pa")
        _non_negative(self, "flow_coefficient_kg_per_s_Pa1p5")


@dataclass(frozen=True)
class InletFlowForce(PlantForm):
    """Flow forces on the spool shrink the inlet's opening with the pressure drop.

    ``a_in_eff = a_in / (1 + k_ff max(p_s - p, 0) / P_atm)``, ``k_ff =
    flow_force_coefficient`` (per atmosphere of drop across the inlet, p_s the supply
    at the valve inlet, p the chamber). The exhaust is unaffected; 0 is no flow force.
    """

    catalogue_name: ClassVar[str | None] = None
    flow_force_coefficient: float

    def __post_init__(self):
        _non_negative(self, "flow_force_coefficient")


@dataclass(frozen=True)
class LipSealLeak(PlantForm):
    """A lip seal that lifts above a pressure and then leaks to atmosphere.

    ``mdot = k (p - p_seal)^2`` for ``p > p_seal`` (absolute), else 0: the lip is held
    shut by its preload up to ``p_seal = seal_pressure_Pa``, then the gap and the drop
    across it grow together. ``k = conductance_kg_per_s_Pa2``; 0 is a tight seal.
    Unlike the catalogue's leaks (orifice, laminar ``p^2 - P_atm^2``), nothing leaks
    below p_seal.
    """

    catalogue_name: ClassVar[str | None] = None
    seal_pressure_Pa: float
    conductance_kg_per_s_Pa2: float

    def __post_init__(self):
        _positive(self, "seal_pressure_Pa")
        _non_negative(self, "conductance_kg_per_s_Pa2")


FORMS: dict[str, type[PlantForm]] = {
    cls.__name__: cls for cls in (AcousticTube, RoundedDeadzone, ClearanceLeak, RegulatorDroop,
                                  SecondOrderSpool, WallHeatTransfer, BladderVolume,
                                  SpoolHysteresis, ReliefValve, InletFlowForce, LipSealLeak)
}
#: The out-of-catalogue forms (``catalogue_name`` None), by class name.
OUT_OF_CATALOGUE: tuple[str, ...] = tuple(n for n, c in FORMS.items()
                                          if c.catalogue_name is None)


def form_from_dict(record: Mapping) -> PlantForm:
    """Rebuild a form from :meth:`PlantForm.to_dict` output (e.g. truth.json's record)."""
    if not isinstance(record, Mapping) or "form" not in record:
        raise ValueError(f"form record must be an object with key 'form', got {record!r}")
    try:
        cls = FORMS[record["form"]]
    except (KeyError, TypeError):
        raise ValueError(f"form record: unknown form {record['form']!r}; known "
                         f"{sorted(FORMS)}") from None
    names = {f.name for f in fields(cls)}
    values = {k: v for k, v in record.items() if k not in ("form", "catalogue_name")}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ValueError(f"form record {record['form']}: unknown field(s) {unknown}")
    if record.get("catalogue_name", cls.catalogue_name) != cls.catalogue_name:
        raise ValueError(f"form record {record['form']}: catalogue_name "
                         f"{record['catalogue_name']!r} should be {cls.catalogue_name!r}")
    return cls(**values)


def check_forms(forms: Sequence[PlantForm], effect_names: Sequence[str] = ()) -> tuple:
    """Validate a forms tuple: PlantForm objects, each catalogue effect at most once
    among the forms and the catalogue ``effect_names`` planted beside them, each
    out-of-catalogue form at most once."""
    forms = tuple(forms)
    for f in forms:
        if not isinstance(f, PlantForm):
            raise TypeError(f"forms: {f!r} is not a plant form (one of {sorted(FORMS)})")
    seen = list(effect_names)
    kinds = [type(f).__name__ for f in forms]
    for k in set(kinds):
        if kinds.count(k) > 1:
            raise ValueError(f"forms: {k} planted {kinds.count(k)} times; plant each form once")
    for f in forms:
        if f.catalogue_name is None:
            continue
        if f.catalogue_name in seen:
            raise ValueError(f"forms: {type(f).__name__} is a form of {f.catalogue_name!r}, "
                             f"which is already planted (as an effect or another form); "
                             f"plant each catalogue effect once")
        seen.append(f.catalogue_name)
    return forms


#: Catalogue scale of the leak per cylinder (the bench's CYLINDER_TRUTH leak_scale).
_LEAK_SCALE = {"AIR37": 1.0, "AIR200": 1.0, "SMC": 0.05, "PRN": 0.05}
#: The catalogue's laminar bench conductance (CylinderLeak("laminar").bench_defaults()).
_LAMINAR_BENCH_K = 1.9e-16


def forms_from_names(names: Sequence[str], cylinder: str = "AIR37",
                     gas: GasConstants | None = None) -> tuple[PlantForm, ...]:
    """Realistic default forms for catalogue effect names, on ``cylinder``'s rig.

    - ``tube_delay``: a 1 m tube of 2 mm, 8 cells (L/c = 2.9 ms);
    - ``valve_deadzone``: 0.3 V half-width with 0.1 V rounding;
    - ``cylinder_leak``: a 4 mm seal lengthening to 6 mm over the stroke, with the gap
      that gives at position 0 the catalogue's laminar bench conductance (1.9e-16
      kg/(s Pa^2), the orifice default's flow at about 3 bar) times the rig's leak
      scale: about 10 um on the AIRPELs;
    - ``supply_fluctuation``: droop 40 kPa per g/s (20-35 kPa at the Table II valves'
      full inlet flow) with a 50 ms regulator time constant;
    - ``spool_lag``: 125 Hz natural frequency (the valve's bandwidth), damping 0.7;
    - ``heat_transfer``: wall convection h = 30 W/(m^2 K) (a wall time constant of
      about 0.1 s in a small chamber at 3 bar).
    """
    cyl = cylinder_preset(cylinder)
    gas = gas or GasConstants()
    out = []
    for n in names:
        if n == "tube_delay":
            out.append(AcousticTube(length_m=1.0, diameter_m=0.002, segments=8))
        elif n == "valve_deadzone":
            out.append(RoundedDeadzone(halfwidth_V=0.3, rounding_V=0.1))
        elif n == "cylinder_leak":
            k = _LAMINAR_BENCH_K * _LEAK_SCALE.get(cylinder, 1.0)
            seal = 0.004
            rs_t = gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
            gap = (k * 24.0 * AIR_VISCOSITY_PA_S * seal * rs_t / (math.pi * cyl.bore_m)) ** (1 / 3)
            out.append(ClearanceLeak(gap_m=float(gap), seal_length_m=seal,
                                     seal_length_slope=0.002 / cyl.stroke_m))
        elif n == "supply_fluctuation":
            out.append(RegulatorDroop(droop_Pa_per_g_per_s=40_000.0, time_constant_s=0.05))
        elif n == "spool_lag":
            out.append(SecondOrderSpool(natural_frequency_Hz=125.0, damping=0.7))
        elif n == "heat_transfer":
            out.append(WallHeatTransfer(h_W_per_m2_K=30.0))
        else:
            raise ValueError(f"forms_from_names: unknown effect {n!r}; the catalogue has "
                             f"{sorted(CATALOGUE)}")
    return check_forms(out)


def catalogue_names_of(forms: Sequence[PlantForm]) -> list[str]:
    """The catalogue effects the forms are versions of (out-of-catalogue forms: none),
    i.e. what a discovery run should name for them."""
    return [f.catalogue_name for f in forms if f.catalogue_name is not None]


def out_of_catalogue_defaults(name: str, cylinder: str = "AIR37",
                              atmospheric_pressure_Pa: float = 101_325.0) -> PlantForm:
    """Realistic default of out-of-catalogue form ``name`` (a class name) on ``cylinder``.

    - ``BladderVolume``: dV_max = 10 % of the swept volume (2.4e-7 m^3 on AIR37, 2.0e-6
      on SMC), pressure scale 150 kPa;
    - ``SpoolHysteresis``: half-band 0.15 V, smoothing 0.2 ms;
    - ``ReliefValve``: cracks at 3.5 bar gauge, k = 3.2e-11 kg/(s Pa^1.5) (1 g/s at
      1 bar overpressure, above the Table II valves' full inlet flow);
    - ``InletFlowForce``: k_ff = 0.1 per atm (the inlet 31 % smaller at the full 4.5 bar
      drop);
    - ``LipSealLeak``: lifts at 2 bar gauge, k = 4.8e-16 kg/(s Pa^2) (0.03 g/s at the
      5.5 bar supply, the AIRPEL's laminar leak at 3 bar).
    """
    cyl = cylinder_preset(cylinder)
    if name == "BladderVolume":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return BladderVolume(dV_max_m3=0.1 * swept, pressure_scale_Pa=150_000.0)
    if name == "SpoolHysteresis":
        return SpoolHysteresis(half_band_V=0.15, time_constant_s=2e-4)
    if name == "ReliefValve":
        return ReliefValve(crack_pressure_Pa=atmospheric_pressure_Pa + 350_000.0,
                           flow_coefficient_kg_per_s_Pa1p5=3.2e-11)
    if name == "InletFlowForce":
        return InletFlowForce(flow_force_coefficient=0.1)
    if name == "LipSealLeak":
        return LipSealLeak(seal_pressure_Pa=atmospheric_pressure_Pa + 200_000.0,
                           conductance_kg_per_s_Pa2=4.8e-16)
    raise ValueError(f"out_of_catalogue_defaults: unknown form {name!r}; known "
                     f"{list(OUT_OF_CATALOGUE)}")
