"""Realistic alternative forms of the catalogue effects, for the high-fidelity plant.

The catalogue effects (:mod:`pneubayes.effects`) are the forms the models fit. A
discovery loop tuned on data planted with exactly those forms may not recognise an
effect built differently, as it is in outside recordings. Each class here is a
physically different, more detailed form of one catalogue effect, simulated by the
independent plant of :mod:`pneubayes.bench.plant`; ``catalogue_name`` names the effect
a discovery run should report for it.

The *out-of-catalogue* forms are effects no catalogue effect expresses: their
``catalogue_name`` is None, meaning a discovery run should name *no* catalogue effect
for them (an open-form closure term may describe them). They test the open-form stage
blind, in two sets drawn once each: the first (:class:`BladderVolume`,
:class:`SpoolHysteresis`, :class:`ReliefValve`, :class:`InletFlowForce`,
:class:`LipSealLeak`) and, built after the open-form stage had been developed against
the first, the second (:class:`ExhaustSilencer`, :class:`ScoredBarrelLeak`,
:class:`CreepingWall`, :class:`PilotInletValve`), and, built after the stage had been
developed against the second, the third (:class:`Iso6358Ports`, :class:`SpoolSlewLimit`,
:class:`SpoolUnderlap`, :class:`MeterOutThrottle`), and, built after the stage had been
developed against the third, the fourth (:class:`SupplyHose`, :class:`LowReynoldsPorts`,
:class:`SpoolStiction`, :class:`SensorBow`); the later sets' forms are listed in
:data:`FORMS` in the order they were written (the eighth: :class:`QuickExhaustValve`,
:class:`GasAccumulator`, :class:`SpoolLandLeak`, :class:`SensorThermalShock`).

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

import numpy as np

from pneubayes.effects import CATALOGUE
from pneubayes.effects.closure_histories import first_order_low_pass
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


def _finite(obj, *names):
    for n in names:
        v = getattr(obj, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{type(obj).__name__}.{n} must be a finite number, got {v!r}")


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


# ------------------------------------------- out-of-catalogue forms, the second blind set
def _smoothstep(z: float) -> float:
    """C1 ramp: 0 for z <= 0, 3 z^2 - 2 z^3 on (0, 1), 1 for z >= 1 (the plant's own
    copy is compiled in :mod:`pneubayes.bench.plant`)."""
    z = min(max(z, 0.0), 1.0)
    return z * z * (3.0 - 2.0 * z)


@dataclass(frozen=True)
class ExhaustSilencer(PlantForm):
    """A porous (sintered) silencer on the valve's exhaust port, with its own volume.

    The valve's exhaust port discharges into the silencer body (pressure ``p_m``, volume
    ``V_m = volume_m3``) instead of the atmosphere; the body vents through the porous
    element with a Forchheimer law (Darcy's viscous drop plus an inertial drop)::

        p_m - P_atm = R_l m_out + R_t m_out |m_out|
        dp_m/dt = kappa Rs T_s / V_m (m_ex - m_out),   m_ex = a_ex f(p, p_m)

    with ``R_l = laminar_fraction dp_ref / m_ref`` and ``R_t = (1 - laminar_fraction)
    dp_ref / m_ref^2`` for the back-pressure ``dp_ref = back_pressure_Pa`` the element
    makes at a steady ``m_ref = 1 g/s``. The chamber's exhaust then sees a back-pressure
    that grows with its own flow (a clogged silencer slows the exhaust most when it is
    fastest) and the gas in the body blows back for a moment when the valve switches.
    The leaks still vent to the atmosphere. ``back_pressure_Pa = 0`` is no silencer (the
    state is omitted). ``p_m`` starts at the atmosphere.
    """

    catalogue_name: ClassVar[str | None] = None
    back_pressure_Pa: float
    laminar_fraction: float = 0.5
    volume_m3: float = 2e-6

    #: The reference flow at which ``back_pressure_Pa`` is stated, kg/s (1 g/s).
    REFERENCE_FLOW_KG_PER_S: ClassVar[float] = 1e-3

    def __post_init__(self):
        _non_negative(self, "back_pressure_Pa")
        _positive(self, "volume_m3")
        f = self.laminar_fraction
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0.0 <= f <= 1.0:
            raise ValueError(f"ExhaustSilencer.laminar_fraction must be a number in [0, 1], "
                             f"got {f!r}")

    @property
    def resistances(self) -> tuple[float, float]:
        """``(R_l Pa/(kg/s), R_t Pa/(kg/s)^2)`` of the Forchheimer law."""
        m = self.REFERENCE_FLOW_KG_PER_S
        return (self.laminar_fraction * self.back_pressure_Pa / m,
                (1.0 - self.laminar_fraction) * self.back_pressure_Pa / (m * m))


@dataclass(frozen=True)
class ScoredBarrelLeak(PlantForm):
    """A scored (scratched) section of the barrel: the piston seal leaks only over it.

    Where the seal rides over the score the chamber leaks to the vented side of the
    piston (the atmosphere) through an orifice of area ``a(x) = area_m2 w(x)`` with the
    thin-port law of eqs. 1-3, ``mdot = a(x) f(p, P_atm)``; the window::

        w(x) = S((x - start_m) / edge_m + 1/2) S((end_m - x) / edge_m + 1/2)

    with S the C1 smoothstep (0 below 0, ``3 z^2 - 2 z^3``, 1 above 1) is 1 on the score
    and 0 more than ``edge_m / 2`` outside it. x is the piston position (m, 0 = fully
    retracted). Unlike the catalogue's leaks (uniform, or graded linearly along the
    stroke) nothing leaks off the score. ``area_m2 = 0`` is a sound barrel.
    """

    catalogue_name: ClassVar[str | None] = None
    start_m: float
    end_m: float
    area_m2: float
    edge_m: float = 0.001

    def __post_init__(self):
        _non_negative(self, "start_m", "area_m2")
        _positive(self, "end_m", "edge_m")
        if self.end_m - self.start_m < self.edge_m:
            raise ValueError(f"ScoredBarrelLeak.end_m ({self.end_m}) must exceed start_m "
                             f"({self.start_m}) by at least edge_m ({self.edge_m})")

    def window(self, position_m: float) -> float:
        """w(x): 1 on the score, 0 off it, C1 edges."""
        return (_smoothstep((position_m - self.start_m) / self.edge_m + 0.5)
                * _smoothstep((self.end_m - position_m) / self.edge_m + 0.5))


@dataclass(frozen=True)
class CreepingWall(PlantForm):
    """A viscoelastic wall (an elastomer liner, a soft hose, a porous wall) that creeps.

    The chamber's volume has a part ``v_c`` that creeps towards ``C (p - P_atm)`` with a
    slow time constant (a standard linear solid's creep, at constant pressure)::

        V = V_dead + A x + v_c,    dv_c/dt = (C (p - P_atm) - v_c) / tau

    ``C = compliance_m3_per_Pa``, ``tau = time_constant_s``. Eq. 5 sees
    ``dV/dt = A dx/dt + dv_c/dt``: after a fill the pressure sags as the wall gives, after
    a vent it recovers. Unlike :class:`BladderVolume` (an instantaneous law) the volume
    lags the pressure. ``C = 0`` is a rigid wall (the state is omitted); v_c starts in
    equilibrium with the initial pressure.
    """

    catalogue_name: ClassVar[str | None] = None
    compliance_m3_per_Pa: float
    time_constant_s: float = 0.2

    def __post_init__(self):
        _non_negative(self, "compliance_m3_per_Pa")
        _positive(self, "time_constant_s")


@dataclass(frozen=True)
class PilotInletValve(PlantForm):
    """A pilot-operated inlet stage that needs a minimum pressure difference to stay open.

    The inlet's main stage (a diaphragm or poppet) is held open by the pressure
    difference across it against its spring; it closes when the difference
    ``|p_s - p|`` (supply at the valve inlet against the chamber) falls below
    ``dp_min = min_pressure_difference_Pa``. The inlet area is scaled by

        phi = S((|p_s - p| - dp_min) / w + 1/2),   w = transition_fraction dp_min,

    S the C1 smoothstep: fully open above ``dp_min + w / 2``, shut below
    ``dp_min - w / 2`` (so shut at no difference, as ``transition_fraction <= 2``). A
    full fill stalls about ``dp_min`` below the supply; a chamber the piston compresses
    above the supply blows back through the inlet once the difference lifts the
    diaphragm. The exhaust is unaffected; ``min_pressure_difference_Pa = 0`` is a
    direct-acting valve (no pilot stage).
    """

    catalogue_name: ClassVar[str | None] = None
    min_pressure_difference_Pa: float
    transition_fraction: float = 0.5

    def __post_init__(self):
        _non_negative(self, "min_pressure_difference_Pa")
        _positive(self, "transition_fraction")
        if self.transition_fraction > 2.0:
            raise ValueError(f"PilotInletValve.transition_fraction must be in (0, 2], got "
                             f"{self.transition_fraction!r}")

    def opening(self, drop_Pa: float) -> float:
        """phi at a drop ``p_s - p`` across the inlet (1 without a pilot stage)."""
        if self.min_pressure_difference_Pa == 0.0:
            return 1.0
        w = self.transition_fraction * self.min_pressure_difference_Pa
        return _smoothstep((abs(drop_Pa) - self.min_pressure_difference_Pa) / w + 0.5)


@dataclass(frozen=True)
class Iso6358Ports(PlantForm):
    """Both ports follow the ISO 6358 flow law instead of eqs. 1-3's isentropic shape.

    Real valves are rated by a sonic conductance C, a critical pressure ratio ``b`` and a
    subsonic index ``m`` (ISO 6358-1): at a ratio ``r = p_down / p_up``

        f = beta p_up                                   r <= b (choked),
        f = beta p_up (1 - ((r - b) / (1 - b))^2)^m     r > b,

    and reversed flow swaps the ends. The choked flow is the thin port's ``beta p_up``
    (the Gompertz area is the sonic conductance), so only the subsonic shape differs:
    with ``b`` 0.2-0.4, as catalogued valves have, the flow starts to fall at a lower
    ratio than the isentropic 0.528 and falls more gradually. ``b = 0.528``, ``m = 0.5``
    is close to eqs. 1-3.
    """

    catalogue_name: ClassVar[str | None] = None
    critical_pressure_ratio: float
    subsonic_index: float = 0.5

    def __post_init__(self):
        if not 0.0 < self.critical_pressure_ratio < 1.0:
            raise ValueError("Iso6358Ports.critical_pressure_ratio must be in (0, 1), got "
                             f"{self.critical_pressure_ratio!r}")
        _positive(self, "subsonic_index")


@dataclass(frozen=True)
class SpoolSlewLimit(PlantForm):
    """A spool whose speed saturates: a proportional valve's current-limited driver.

    The spool position s (V of command) follows the command u with a smooth rate limit::

        ds/dt = r tanh((u - s) / (tau r)),   r = slew_rate_V_per_s, tau = time_constant_s

    A small step is a first-order lag of ``tau``; a large one is a ramp at ``r`` (a full
    10-V swing takes ``10 / r`` s). Unlike the catalogue's linear spool lags, the delay
    grows with the step. ``slew_rate_V_per_s = 0`` is no limit (the state is omitted);
    it replaces the catalogue's spool stages and cannot be planted beside them.
    """

    catalogue_name: ClassVar[str | None] = None
    slew_rate_V_per_s: float
    time_constant_s: float = 5e-4

    def __post_init__(self):
        _non_negative(self, "slew_rate_V_per_s")
        _positive(self, "time_constant_s")


@dataclass(frozen=True)
class SpoolUnderlap(PlantForm):
    """An underlapped spool: both ports stay a little open around the null.

    Where the lands are narrower than the ports, supply and exhaust both connect to the
    chamber near the null (a crossport leak through the valve). Each port's area gains::

        a_u(s) = area_m2 (1 - S(|s| / width_V)),   S the C1 smoothstep,

    at the spool position s (V): ``area_m2`` at the null, nothing beyond ``width_V``. A
    chamber held at the null settles between the supply and the atmosphere instead of
    holding its pressure. Unlike the Gompertz maps' constant offsets the extra opening is
    confined to the null. ``area_m2 = 0`` is a critically lapped spool.
    """

    catalogue_name: ClassVar[str | None] = None
    area_m2: float
    width_V: float = 0.5

    def __post_init__(self):
        _non_negative(self, "area_m2")
        _positive(self, "width_V")

    def opening(self, spool_V: float) -> float:
        """a_u(s), m^2."""
        return self.area_m2 * (1.0 - _smoothstep(abs(spool_V) / self.width_V))


@dataclass(frozen=True)
class MeterOutThrottle(PlantForm):
    """A one-way flow control (a meter-out speed controller) at the cylinder's port.

    Between the valve and the chamber sits a fitting of volume ``volume_m3`` (pressure
    p_f, which the valve's ports see). From the fitting into the chamber the gas passes
    a needle of area ``needle_area_m2`` and, in parallel, a check valve of area
    ``check_area_m2`` that opens with the forward drop ``p_f - p``::

        mdot_fc = (A_n + A_c S((p_f - p - dp_c) / dp_c + 1/2)) f(p_f, p),

    S the C1 smoothstep, ``dp_c = crack_pressure_Pa``, f the thin-port flow of eqs. 1-3
    (signed; below a 1-kPa drop linear in the drop, as laminar flow is, which keeps the
    two restrictions in series well posed). A fill passes the open check; a vent leaves
    through the needle alone, so the exhaust is throttled and the fitting's pressure lags
    the chamber's. Eq. 5 holds in the fitting at the supply temperature.
    ``needle_area_m2 = 0`` is no throttle (the state is omitted); it cannot be planted
    beside an AcousticTube.
    """

    catalogue_name: ClassVar[str | None] = None
    needle_area_m2: float
    check_area_m2: float = 1e-6
    crack_pressure_Pa: float = 10e3
    volume_m3: float = 5e-7

    def __post_init__(self):
        _non_negative(self, "needle_area_m2")
        _positive(self, "check_area_m2", "crack_pressure_Pa", "volume_m3")

    def check_opening(self, forward_drop_Pa: float) -> float:
        """The check valve's fraction open at a drop ``p_f - p`` (Pa)."""
        c = self.crack_pressure_Pa
        return _smoothstep((forward_drop_Pa - c) / c + 0.5)


@dataclass(frozen=True)
class SupplyHose(PlantForm):
    """A supply line that starves the valve: a hose of volume ``volume_m3`` fed from the
    regulator through a restriction (a fitting, a quick coupling, the regulator's own
    port) of sonic area ``restriction_area_m2``.

    The valve's inlet sees the hose's pressure p_h, not the regulator's p_r::

        dp_h/dt = kappa Rs T / V_h (A_r f(p_r, p_h) - mdot_in),

    f the thin-port flow of eqs. 1-3. A fill draws the hose down and it recovers
    through the restriction; the supply sensor sits at the regulator (the recording's
    supply column is p_r), so the drop is not measured. ``restriction_area_m2 = 0`` is no
    hose (the state is omitted).
    """

    catalogue_name: ClassVar[str | None] = None
    restriction_area_m2: float
    volume_m3: float = 5e-5

    def __post_init__(self):
        _non_negative(self, "restriction_area_m2")
        _positive(self, "volume_m3")


@dataclass(frozen=True)
class LowReynoldsPorts(PlantForm):
    """Valve ports whose discharge falls at low Reynolds numbers (viscous losses in a
    small or barely open port, at a small pressure difference).

    Each port's thin-port flow m_0 = a f (eqs. 1-3) is scaled by a discharge factor that
    rises with the port's Reynolds number Re = 4 |m_0| / (pi mu d), d = sqrt(4 a / pi)
    the port's equivalent diameter::

        mdot = m_0 Re / (Re + Re_c),   Re_c = ``critical_reynolds``,

    so the flow falls off where it is small: near a port's pressure balance (the last
    part of a fill or a vent) and through the ports' leakage at the null.
    ``critical_reynolds = 0`` is the thin-port law.
    """

    catalogue_name: ClassVar[str | None] = None
    critical_reynolds: float
    air_viscosity_Pa_s: float = AIR_VISCOSITY_PA_S

    def __post_init__(self):
        _non_negative(self, "critical_reynolds")
        _positive(self, "air_viscosity_Pa_s")


@dataclass(frozen=True)
class SpoolStiction(PlantForm):
    """A sticking spool (static friction without dither): it stays put until the
    command moves ``breakaway_V`` away from where it stuck, then slides and stops short
    of the command by ``stop_V``.

    At each change of the (delayed) command u_k the spool's target s_k becomes::

        s_k = s_(k-1)                          if |u_k - s_(k-1)| < breakaway_V,
        s_k = u_k - sign(u_k - s_(k-1)) stop_V  otherwise,

    from s_0 = u_0, and the valve sees s_k for as long as u_k is held. Small command
    steps are ignored entirely; a large one is followed but for ``stop_V`` on the side
    it came from. ``breakaway_V = 0`` (with ``stop_V = 0``) is a free spool.
    """

    catalogue_name: ClassVar[str | None] = None
    breakaway_V: float
    stop_V: float = 0.0

    def __post_init__(self):
        _non_negative(self, "breakaway_V", "stop_V")
        if self.stop_V > self.breakaway_V:
            raise ValueError(f"SpoolStiction.stop_V must be <= breakaway_V "
                             f"({self.breakaway_V}), got {self.stop_V}")

    def targets(self, command_V):
        """The spool's held positions for a held command series (V)."""
        u = [float(v) for v in command_V]
        out = list(u)
        s = u[0] if u else 0.0
        for k, v in enumerate(u):
            if k and abs(v - s) >= self.breakaway_V and v != s:
                s = v - math.copysign(self.stop_V, v - s)
            out[k] = s
        return out


@dataclass(frozen=True)
class SensorBow(PlantForm):
    """A pressure sensor whose reading bows away from its straight line (the bridge's
    nonlinearity, a data sheet's "BFSL" error): zero at both ends of its range, largest
    at mid-range::

        r = p + bow_Pa 4 x (1 - x),   x = clip((p - P_atm) / span_Pa, 0, 1),

    ``span_Pa`` its gauge full scale, ``bow_Pa`` the error at mid-range (either sign). A
    straight-line recalibration (offset and gain) removes at most a third of it.
    ``bow_Pa = 0`` is a linear sensor.
    """

    catalogue_name: ClassVar[str | None] = None
    bow_Pa: float
    span_Pa: float = 1.0e6

    def __post_init__(self):
        _finite(self, "bow_Pa")
        _positive(self, "span_Pa")

    def read(self, pressure_Pa, atmospheric_pressure_Pa: float):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa``."""
        p = np.asarray(pressure_Pa, dtype=np.float64)
        x = np.clip((p - atmospheric_pressure_Pa) / self.span_Pa, 0.0, 1.0)
        return p + self.bow_Pa * 4.0 * x * (1.0 - x)


@dataclass(frozen=True)
class SpringReturnSpool(PlantForm):
    """A single-solenoid spool returned by its spring: it moves up (towards a larger
    command, the solenoid pulling) with one time constant and down (the spring
    returning it against the spool's friction) with another::

        ds/dt = (u - s) / tau_up    if u > s,
        ds/dt = (u - s) / tau_down  otherwise,

    s the spool position (V of command). Unlike the catalogue's linear spool lags the
    response depends on the direction of travel: a square wave's mean position shifts
    towards the faster side. ``rise_time_constant_s = 0`` (with the fall 0 too) is a
    free spool (the state is omitted); it replaces the catalogue's spool stages and
    cannot be planted beside them.
    """

    catalogue_name: ClassVar[str | None] = None
    rise_time_constant_s: float
    fall_time_constant_s: float = 0.0

    def __post_init__(self):
        _non_negative(self, "rise_time_constant_s", "fall_time_constant_s")
        if (self.rise_time_constant_s > 0) != (self.fall_time_constant_s > 0):
            raise ValueError("SpringReturnSpool.fall_time_constant_s must be > 0 exactly "
                             "when rise_time_constant_s is (both 0: a free spool), got "
                             f"{self.fall_time_constant_s!r}")


@dataclass(frozen=True)
class WarmingCoil(PlantForm):
    """A voltage-driven proportional solenoid whose coil warms as it works: its
    resistance rises with its temperature (copper: +0.39 %/K), so the same command
    drives less current and the spool sits nearer its zero-current end.

    The command u (V) drives the coil from ``command_min_V`` (no current) over
    ``command_span_V``; with the coil's heat theta (1: the steady heat of the full
    command on a cold coil) the valve acts on::

        u_eff = u_min + (u - u_min) / (1 + k theta),
        dtheta/dt = (((u - u_min) / span)^2 / (1 + k theta) - theta) / tau_th,

    ``k = resistance_rise`` (the resistance's fractional rise at theta = 1) and
    ``tau_th = time_constant_s`` the coil's thermal time constant. A recording starts
    with a cold coil; a held command drifts the spool's position over seconds (at the
    null the coil still carries half its current). ``resistance_rise = 0`` is a coil at
    constant resistance (the state is omitted).
    """

    catalogue_name: ClassVar[str | None] = None
    resistance_rise: float
    time_constant_s: float = 5.0
    command_min_V: float = -5.0
    command_span_V: float = 10.0

    def __post_init__(self):
        _non_negative(self, "resistance_rise")
        _positive(self, "time_constant_s", "command_span_V")
        _finite(self, "command_min_V")


@dataclass(frozen=True)
class CapillarySensorPort(PlantForm):
    """A pressure sensor that reads the chamber through a capillary (a snubber, a thin
    sensing line into a small cavity in front of the membrane).

    Isothermal laminar (Poiseuille) flow of a gas through the capillary is
    proportional to the difference of the squared pressures, so the cavity's
    pressure r, which the sensor reads, follows the chamber's p as::

        dr/dt = c (p^2 - r^2),   c = 1 / (2 p_ref tau_ref),

    (c = pi d^4 / (256 mu L V) for a capillary of bore d and length L into a cavity
    V): a lag of ``tau_ref = time_constant_s`` near ``p_ref = reference_pressure_Pa``
    (the supply), ``tau_ref p_ref / p`` near a pressure p (about 5 x slower at the
    atmosphere), and faster filling than emptying. ``time_constant_s = 0`` reads the
    chamber directly.
    """

    catalogue_name: ClassVar[str | None] = None
    time_constant_s: float
    reference_pressure_Pa: float = 551_325.0

    def __post_init__(self):
        _non_negative(self, "time_constant_s")
        _positive(self, "reference_pressure_Pa")

    def read(self, time_s, pressure_Pa):
        """The cavity's pressure (Pa) on a uniform grid ``time_s`` (s), starting at rest
        at the chamber's first pressure: exact for the pressure held at each step's mean
        (the Riccati equation's closed form)."""
        t = np.asarray(time_s, dtype=np.float64)
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if self.time_constant_s == 0.0 or p.size < 2:
            return p.copy()
        if not np.all(p > 0):
            raise ValueError("CapillarySensorPort.read: pressures must be > 0 (absolute)")
        c = 1.0 / (2.0 * self.reference_pressure_Pa * self.time_constant_s)
        mid = 0.5 * (p[1:] + p[:-1])
        decay = np.exp(-2.0 * c * mid * np.diff(t))
        out = np.empty_like(p)
        r = out[0] = p[0]
        for i in range(mid.size):
            m = mid[i]
            z = (r - m) / (r + m) * decay[i]
            r = out[i + 1] = m * (1.0 + z) / (1.0 - z)
        return out


@dataclass(frozen=True)
class LaggingPositionSensor(PlantForm):
    """A length sensor whose reading lags the piston: an analog position transducer
    behind an RC filter (or a draw-wire sensor's drum), a first-order lag::

        dx_r/dt = (x - x_r) / tau,

    recorded instead of the piston's position x. The chamber's volume the recording
    implies then trails the true one by about ``A tau dx/dt``. ``time_constant_s = 0``
    reads the piston directly.
    """

    catalogue_name: ClassVar[str | None] = None
    time_constant_s: float

    def __post_init__(self):
        _non_negative(self, "time_constant_s")

    def read(self, time_s, position_m):
        """The lagged reading (m) at the sample times ``time_s`` (s), at rest at the first
        position (exact for a position linear between the samples)."""
        x = np.asarray(position_m, dtype=np.float64)
        if self.time_constant_s == 0.0:
            return x.copy()
        return first_order_low_pass(time_s, x, self.time_constant_s)


# -------------------------------------------- out-of-catalogue forms, the sixth blind set
@dataclass(frozen=True)
class ExhaustCheckValve(PlantForm):
    """A check valve in the exhaust line (a non-return on a shared exhaust manifold, a
    quick-exhaust valve's lip): the exhaust port discharges against its cracking
    pressure, so the chamber vents only down to it::

        mdot_ex = a_ex f(p, P_atm + p_c)  for p > P_atm + p_c, else 0,

    f the orifice law of eqs. 1-3 and ``p_c = crack_pressure_Pa`` (gauge). Nothing
    enters through the exhaust. ``crack_pressure_Pa = 0`` is the plain exhaust.
    """

    catalogue_name: ClassVar[str | None] = None
    crack_pressure_Pa: float

    def __post_init__(self):
        _non_negative(self, "crack_pressure_Pa")


@dataclass(frozen=True)
class SeatLeak(PlantForm):
    """A worn inlet seat that passes supply air into the chamber whatever the spool
    does, through a crack short enough that its flow follows the incompressible
    orifice law with the upstream density::

        mdot = C A sign(d) sqrt(2 rho_up |d|),   d = p_s - p,   rho_up = p_up / (R T_s),

    linear in d below ``laminar_drop_Pa`` (a smooth crossing). ``area_m2`` is C A;
    0 is a tight seat. Unlike eqs. 1-3 it never chokes.
    """

    catalogue_name: ClassVar[str | None] = None
    area_m2: float
    laminar_drop_Pa: float = 500.0

    def __post_init__(self):
        _non_negative(self, "area_m2")
        _positive(self, "laminar_drop_Pa")


@dataclass(frozen=True)
class InletFlowLimiter(PlantForm):
    """A flow limiter at the valve's inlet (a pressure-compensated flow-control valve,
    a flow fuse): the inlet's mass flow saturates at ``max_flow_kg_per_s``::

        mdot_in = m_max tanh(a_in f(p_s, p) / m_max),

    so a large opening fills at a fixed rate while a small one is as the valve's map.
    ``max_flow_kg_per_s = 0`` is no limiter.
    """

    catalogue_name: ClassVar[str | None] = None
    max_flow_kg_per_s: float

    def __post_init__(self):
        _non_negative(self, "max_flow_kg_per_s")


@dataclass(frozen=True)
class ReleaseDelay(PlantForm):
    """A solenoid that releases late: the valve acts on a falling command
    ``delay_s`` later than on a rising one (the armature's residual magnetism, the
    driver's flyback), on top of any delay both share. A rise that comes before a
    pending fall has acted cancels it. ``delay_s = 0`` acts on both alike.
    """

    catalogue_name: ClassVar[str | None] = None
    delay_s: float

    def __post_init__(self):
        _non_negative(self, "delay_s")

    def switches(self, time_s, command, shared_delay_s: float = 0.0):
        """``(times, values)``: when (s) the valve takes each held value of
        ``command`` (sampled at ``time_s``), ``times[0] = -inf`` holding the first; a
        change acts ``shared_delay_s`` after its sample, a fall ``delay_s`` later
        still, and a change superseded before it acts is dropped."""
        t = np.asarray(time_s, dtype=np.float64)
        u = np.asarray(command, dtype=np.float64)
        times, values = [-math.inf], [float(u[0])]
        for k in np.nonzero(np.diff(u) != 0)[0] + 1:
            at = t[k] + shared_delay_s + (self.delay_s if u[k] < u[k - 1] else 0.0)
            while len(times) > 1 and times[-1] >= at:  # pending changes it overtakes
                times.pop()
                values.pop()
            times.append(at)
            values.append(float(u[k]))
        return np.array(times), np.array(values)


# ------------------------------------------ out-of-catalogue forms, the seventh blind set
@dataclass(frozen=True)
class PistonSealBypass(PlantForm):
    """A worn piston seal that passes air to the cylinder's other chamber, which
    breathes to the atmosphere through a small vent (a sintered breather)::

        mdot_s = k (p^2 - p_b^2)                      (laminar, as a clearance leak)
        dp_b/dt = kappa (Rs T_s (mdot_s - a_v f(p_b, P_atm)) + p_b A dx/dt) / V_b,
        V_b = opposite_volume_m3 - A x,

    f the orifice law of eqs. 1-3 (either direction), A the bore's area, x the piston
    position (the other chamber shrinks as the measured one grows); p_b starts at the
    atmosphere. The measured chamber loses ``mdot_s`` (gains it when p_b > p).
    ``conductance_kg_per_s_Pa2 = 0`` is a tight seal.
    """

    catalogue_name: ClassVar[str | None] = None
    conductance_kg_per_s_Pa2: float
    vent_area_m2: float
    opposite_volume_m3: float

    def __post_init__(self):
        _non_negative(self, "conductance_kg_per_s_Pa2", "vent_area_m2")
        _positive(self, "opposite_volume_m3")


@dataclass(frozen=True)
class EnergisedSealLeak(PlantForm):
    """A pressure-energised seal (an O-ring squeezed tighter by the pressure it holds)
    whose laminar gap closes as the gauge pressure g rises, the flow going with the
    gap's cube::

        mdot = k (p^2 - P_atm^2) / (1 + g / p_e)^3,   g = max(p - P_atm, -p_e / 2),

    so the leak grows at low pressure, peaks, and falls again as the seal energises;
    ``p_e = energising_pressure_Pa`` is the gauge pressure that halves the gap.
    ``conductance_kg_per_s_Pa2 = 0`` is a tight seal.
    """

    catalogue_name: ClassVar[str | None] = None
    conductance_kg_per_s_Pa2: float
    energising_pressure_Pa: float

    def __post_init__(self):
        _non_negative(self, "conductance_kg_per_s_Pa2")
        _positive(self, "energising_pressure_Pa")


@dataclass(frozen=True)
class SensorZeroDrift(PlantForm):
    """A pressure sensor whose zero drifts as it warms up after each recording starts
    (the bridge's temperature coefficient)::

        r = p + drift_Pa (1 - exp(-(t - t_0) / tau)),

    t_0 the recording's first sample. ``drift_Pa = 0`` is a stable sensor. The
    catalogue's ``sensor_drift`` (form ``warm_up``, on the recording's clock, which the
    bench starts at t_0 = 0) has since expressed it exactly; it keeps ``catalogue_name``
    None as blind set 7 drew and scored it.
    """

    catalogue_name: ClassVar[str | None] = None
    drift_Pa: float
    time_constant_s: float

    def __post_init__(self):
        _finite(self, "drift_Pa")
        _positive(self, "time_constant_s")

    def read(self, time_s, pressure_Pa):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa`` at the
        times ``time_s`` (s)."""
        t = np.asarray(time_s, dtype=np.float64)
        p = np.asarray(pressure_Pa, dtype=np.float64)
        return p + self.drift_Pa * -np.expm1(-(t - t[0]) / self.time_constant_s)


@dataclass(frozen=True)
class EndCushion(PlantForm):
    """An end-of-stroke cushion at the measured chamber's end cap: over the last
    ``length_m`` of the stroke (x -> 0) a spear closes the port's bore, so air leaving
    the chamber passes a needle in series with the valve's port (two orifices in
    series, the incompressible rule)::

        a_eff = a a_n / sqrt(a^2 + a_n^2),   blended in by w = smoothstep((L - x) / e + 1/2),

    a the port's area (the exhaust's when venting; the inlet's when the chamber blows
    back into the supply), ``a_n = needle_area_m2``, ``e = edge_m``. Inflow passes the
    cushion's check valve unthrottled. ``needle_area_m2 = 0`` is no cushion.
    """

    catalogue_name: ClassVar[str | None] = None
    length_m: float
    needle_area_m2: float
    edge_m: float

    def __post_init__(self):
        _non_negative(self, "needle_area_m2")
        _positive(self, "length_m", "edge_m")


@dataclass(frozen=True)
class QuickExhaustValve(PlantForm):
    """A quick-exhaust valve (QEV) at the chamber's port, fed by the valve through a
    line of volume ``line_volume_m3``. Its diaphragm passes air from the line into the
    chamber; when the chamber is above the line it seals the line and opens its own
    exhaust straight to the atmosphere::

        w = smoothstep((p - p_l) / switch_band_Pa),
        m_chamber = a_p (1 - w) f(p_l, p) - a_q w f(p, P_atm),
        dp_l/dt = kappa Rs T_s / V_l (m_in(p_l) - m_ex(p_l) - a_p (1 - w) f(p_l, p)),

    p_l the line's pressure (the valve's ports see it), ``a_q = exhaust_area_m2``,
    ``a_p = passage_area_m2``, f eqs. 1-3 (signed; through the passage linear in the
    drop below 1 kPa, laminar). ``exhaust_area_m2 = 0`` is no QEV (the port as without
    it).
    """

    catalogue_name: ClassVar[str | None] = None
    exhaust_area_m2: float
    passage_area_m2: float = 1.5e-6
    switch_band_Pa: float = 1e4
    line_volume_m3: float = 5e-7

    def __post_init__(self):
        _non_negative(self, "exhaust_area_m2")
        _positive(self, "passage_area_m2", "switch_band_Pa", "line_volume_m3")


@dataclass(frozen=True)
class GasAccumulator(PlantForm):
    """A gas-charged accumulator (a bladder pulsation damper) on the chamber: its gas,
    ``volume_m3`` at the precharge pressure ``precharge_Pa`` (absolute), is compressed
    polytropically once the chamber is above the precharge, and the chamber's air takes
    the room it gives up::

        V = V_dead + A x + V_a (1 - (p_0 / p)^(1 / n))   (p > p_0; else no change),

    n = ``polytropic_index`` (1: slow, isothermal; 1.4: fast, adiabatic). Below the
    precharge the bladder rests on its poppet. ``volume_m3 = 0`` is no accumulator.
    """

    catalogue_name: ClassVar[str | None] = None
    volume_m3: float
    precharge_Pa: float = 2.5e5
    polytropic_index: float = 1.2

    def __post_init__(self):
        _non_negative(self, "volume_m3")
        _positive(self, "precharge_Pa", "polytropic_index")
        if not 1.0 <= self.polytropic_index <= 1.4:
            raise ValueError(f"GasAccumulator.polytropic_index must be in [1, 1.4], got "
                             f"{self.polytropic_index!r}")


@dataclass(frozen=True)
class SpoolLandLeak(PlantForm):
    """Internal leakage across the spool's lands (the radial clearance of a spool in
    its sleeve): laminar, compressible, from the supply into the chamber across the
    inlet land and from the chamber to the exhaust across the exhaust land, each through
    a sealing length that grows as the spool moves to close its port::

        m_in += k (p_s^2 - p_v^2) / (1 + max(0, -s) / s_L),
        m_ex += k (p_v^2 - P_atm^2) / (1 + max(0, s) / s_L),

    s the spool position (V, after the dead band's input), p_v the port's pressure,
    ``k = conductance_kg_per_s_Pa2`` (the leak at the null), ``s_L =
    overlap_scale_V``. ``conductance_kg_per_s_Pa2 = 0`` is a tight spool.
    """

    catalogue_name: ClassVar[str | None] = None
    conductance_kg_per_s_Pa2: float
    overlap_scale_V: float = 0.5

    def __post_init__(self):
        _non_negative(self, "conductance_kg_per_s_Pa2")
        _positive(self, "overlap_scale_V")


@dataclass(frozen=True)
class SensorThermalShock(PlantForm):
    """A pressure sensor whose diaphragm warms and cools with the gas it sees: after a
    pressure change its reading overshoots (``gain > 0``) or undershoots and settles as
    the diaphragm's temperature relaxes::

        r = p + gain (p - p_bar),   tau dp_bar/dt = p - p_bar  (p_bar = p at the start),

    ``tau = time_constant_s``. ``gain = 0`` is a sensor without the transient.
    """

    catalogue_name: ClassVar[str | None] = None
    gain: float
    time_constant_s: float = 0.3

    def __post_init__(self):
        _finite(self, "gain")
        _positive(self, "time_constant_s")

    def read(self, time_s, pressure_Pa):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa`` at the
        times ``time_s`` (s)."""
        t = np.asarray(time_s, dtype=np.float64)
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if self.gain == 0.0:
            return p.copy()
        return p + self.gain * (p - first_order_low_pass(t, p, self.time_constant_s))


FORMS: dict[str, type[PlantForm]] = {
    cls.__name__: cls for cls in (AcousticTube, RoundedDeadzone, ClearanceLeak, RegulatorDroop,
                                  SecondOrderSpool, WallHeatTransfer, BladderVolume,
                                  SpoolHysteresis, ReliefValve, InletFlowForce, LipSealLeak,
                                  ExhaustSilencer, ScoredBarrelLeak, CreepingWall,
                                  PilotInletValve, Iso6358Ports, SpoolSlewLimit,
                                  SpoolUnderlap, MeterOutThrottle, SupplyHose,
                                  LowReynoldsPorts, SpoolStiction, SensorBow,
                                  SpringReturnSpool, WarmingCoil, CapillarySensorPort,
                                  LaggingPositionSensor, ExhaustCheckValve, SeatLeak,
                                  InletFlowLimiter, ReleaseDelay, PistonSealBypass,
                                  EnergisedSealLeak, SensorZeroDrift, EndCushion,
                                  QuickExhaustValve, GasAccumulator, SpoolLandLeak,
                                  SensorThermalShock)
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

    - ``BladderVolume``: 10 % of the swept volume (2.4e-7 m^3 on AIR37), scale 150 kPa;
    - ``SpoolHysteresis``: half-band 0.15 V, smoothing 0.2 ms;
    - ``ReliefValve``: cracks at 3.5 bar gauge, 1 g/s at 1 bar overpressure;
    - ``InletFlowForce``: 0.1 per atm (the inlet 31 % smaller at the full drop);
    - ``LipSealLeak``: lifts at 2 bar gauge, 0.03 g/s at the 5.5 bar supply;
    - ``ExhaustSilencer``: 100 kPa at 1 g/s, half of it viscous, a 2 cm^3 body;
    - ``ScoredBarrelLeak``: 30-55 % of the stroke, edges 5 % of it, 8e-8 m^2;
    - ``CreepingWall``: 8 % of the swept volume at 4.5 bar gauge, 0.2 s;
    - ``PilotInletValve``: needs 40 kPa across the inlet, the transition half of it;
    - ``Iso6358Ports``: critical pressure ratio 0.3, subsonic index 0.5;
    - ``SpoolSlewLimit``: 300 V/s, 0.5 ms small-step lag;
    - ``SpoolUnderlap``: 5e-8 m^2 per port at the null, gone beyond 0.5 V;
    - ``MeterOutThrottle``: needle 2e-7 m^2, check 1e-6 m^2 at 10 kPa, fitting 0.5 cm^3;
    - ``SupplyHose``: a 1e-6 m^2 restriction into 50 cm^3 (2.5 m of 5 mm);
    - ``LowReynoldsPorts``: critical Reynolds number 500;
    - ``SpoolStiction``: breaks away at 0.15 V, stops 0.05 V short;
    - ``SensorBow``: +3 kPa at mid-range of a 10-bar (gauge) sensor;
    - ``SpringReturnSpool``: 0.6 ms up, 2.4 ms down;
    - ``WarmingCoil``: 8 % more resistance at the full command's heat, 5 s;
    - ``CapillarySensorPort``: 2 ms at the supply (about 11 ms at the atmosphere);
    - ``LaggingPositionSensor``: 5 ms;
    - ``ExhaustCheckValve``: cracks at 30 kPa;
    - ``SeatLeak``: C A = 3e-8 m^2 (about 0.07 g/s at 4.5 bar across it);
    - ``InletFlowLimiter``: 0.5 g/s (about two thirds of valve 1's full inlet);
    - ``ReleaseDelay``: falls act 4 ms late;
    - ``PistonSealBypass``: 2e-16 kg/(s Pa^2) (0.05 g/s at 4 bar gauge), a 3e-8 m^2
      vent, the other chamber 1.2 x the swept volume;
    - ``EnergisedSealLeak``: 8e-15 kg/(s Pa^2), the gap halved at 1.5 bar gauge (the
      leak largest near there, about 0.05 g/s);
    - ``SensorZeroDrift``: 5 kPa, 10 s;
    - ``EndCushion``: the last 10 % of the stroke, a 5e-8 m^2 needle, 2 % edges;
    - ``QuickExhaustValve``: a 1.5e-6 m^2 exhaust, a 1.5e-6 m^2 passage, switching over
      10 kPa, a 0.5 cm^3 line;
    - ``GasAccumulator``: half the swept volume, precharged at 2 bar gauge, n = 1.2;
    - ``SpoolLandLeak``: 1e-16 kg/(s Pa^2) (0.02 g/s at the null into 3 bar), the
      sealing length doubled 0.5 V from the null;
    - ``SensorThermalShock``: 3 % overshoot, settling in 0.3 s.
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
    if name == "ExhaustSilencer":
        return ExhaustSilencer(back_pressure_Pa=100_000.0, laminar_fraction=0.5,
                               volume_m3=2e-6)
    if name == "ScoredBarrelLeak":
        return ScoredBarrelLeak(start_m=0.30 * cyl.stroke_m, end_m=0.55 * cyl.stroke_m,
                                area_m2=8e-8, edge_m=0.05 * cyl.stroke_m)
    if name == "CreepingWall":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return CreepingWall(compliance_m3_per_Pa=0.08 * swept / 450_000.0,
                            time_constant_s=0.2)
    if name == "PilotInletValve":
        return PilotInletValve(min_pressure_difference_Pa=40_000.0, transition_fraction=0.5)
    if name == "Iso6358Ports":
        return Iso6358Ports(critical_pressure_ratio=0.3, subsonic_index=0.5)
    if name == "SpoolSlewLimit":
        return SpoolSlewLimit(slew_rate_V_per_s=300.0, time_constant_s=5e-4)
    if name == "SpoolUnderlap":
        return SpoolUnderlap(area_m2=5e-8, width_V=0.5)
    if name == "MeterOutThrottle":
        return MeterOutThrottle(needle_area_m2=2e-7, check_area_m2=1e-6,
                                crack_pressure_Pa=10e3, volume_m3=5e-7)
    if name == "SupplyHose":
        return SupplyHose(restriction_area_m2=1e-6, volume_m3=5e-5)
    if name == "LowReynoldsPorts":
        return LowReynoldsPorts(critical_reynolds=500.0)
    if name == "SpoolStiction":
        return SpoolStiction(breakaway_V=0.15, stop_V=0.05)
    if name == "SensorBow":
        return SensorBow(bow_Pa=3000.0, span_Pa=1.0e6)
    if name == "SpringReturnSpool":
        return SpringReturnSpool(rise_time_constant_s=6e-4, fall_time_constant_s=2.4e-3)
    if name == "WarmingCoil":
        return WarmingCoil(resistance_rise=0.08, time_constant_s=5.0)
    if name == "CapillarySensorPort":
        return CapillarySensorPort(time_constant_s=2e-3)
    if name == "LaggingPositionSensor":
        return LaggingPositionSensor(time_constant_s=5e-3)
    if name == "ExhaustCheckValve":
        return ExhaustCheckValve(crack_pressure_Pa=30e3)
    if name == "SeatLeak":
        return SeatLeak(area_m2=3e-8)
    if name == "InletFlowLimiter":
        return InletFlowLimiter(max_flow_kg_per_s=5e-4)
    if name == "ReleaseDelay":
        return ReleaseDelay(delay_s=4e-3)
    if name == "PistonSealBypass":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return PistonSealBypass(conductance_kg_per_s_Pa2=2e-16, vent_area_m2=3e-8,
                                opposite_volume_m3=1.2 * swept)
    if name == "EnergisedSealLeak":
        return EnergisedSealLeak(conductance_kg_per_s_Pa2=8e-15, energising_pressure_Pa=1.5e5)
    if name == "SensorZeroDrift":
        return SensorZeroDrift(drift_Pa=5e3, time_constant_s=10.0)
    if name == "EndCushion":
        return EndCushion(length_m=0.1 * cyl.stroke_m, needle_area_m2=5e-8,
                          edge_m=0.02 * cyl.stroke_m)
    if name == "QuickExhaustValve":
        return QuickExhaustValve(exhaust_area_m2=1.5e-6)
    if name == "GasAccumulator":
        swept = math.pi / 4.0 * cyl.bore_m**2 * cyl.stroke_m
        return GasAccumulator(volume_m3=0.5 * swept,
                              precharge_Pa=atmospheric_pressure_Pa + 200_000.0)
    if name == "SpoolLandLeak":
        return SpoolLandLeak(conductance_kg_per_s_Pa2=1e-16)
    if name == "SensorThermalShock":
        return SensorThermalShock(gain=0.03)
    raise ValueError(f"out_of_catalogue_defaults: unknown form {name!r}; known "
                     f"{list(OUT_OF_CATALOGUE)}")
