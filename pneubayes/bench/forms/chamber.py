"""Out-of-catalogue forms of the chamber: volumes that follow the pressure, leaks and
vents out of it, a cushion at the stroke's end."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from pneubayes.bench.forms.base import (
    PlantForm,
    _non_negative,
    _positive,
    _smoothstep,
)


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


# ------------------------------------------ out-of-catalogue forms, the ninth blind set


@dataclass(frozen=True)
class SealSpeedLeak(PlantForm):
    """A piston seal whose lubricating film thickens with the piston's speed and leaks
    through it: hydrodynamic lift gives a film ``h ~ sqrt(|v|)``, and the compressible
    laminar flow through it ``~ h^3 (p^2 - P_atm^2)``::

        mdot_out = k (|dx/dt| / v_ref)^1.5 (p^2 - P_atm^2),

    ``k = conductance_kg_per_s_Pa2`` at ``v_ref = reference_speed_m_per_s``; nothing
    while the piston rests. ``conductance_kg_per_s_Pa2 = 0`` is a dry seal.
    """

    catalogue_name: ClassVar[str | None] = None
    conductance_kg_per_s_Pa2: float
    reference_speed_m_per_s: float = 0.1

    def __post_init__(self):
        _non_negative(self, "conductance_kg_per_s_Pa2")
        _positive(self, "reference_speed_m_per_s")


# ------------------------------------------ out-of-catalogue forms, the tenth blind set


@dataclass(frozen=True)
class BraidFriction(PlantForm):
    """A flexible part of the chamber's wall (a rolling diaphragm, a bellows, a braided
    sleeve) whose give is held by Coulomb friction: its volume follows the gauge
    pressure only once the pressure has moved the friction band past where the wall
    stuck, so the volume's loop over the pressure is rate-independent::

        V = V_0 + C y,   y follows p - P_atm where |p - P_atm - y| reaches w, in the
                         direction the pressure moves; otherwise y holds,

    ``C = compliance_m3_per_Pa``, ``w = friction_band_Pa`` (the stuck wall starts at the
    initial gauge pressure; the band's edge is smoothed over 10 % of it).
    ``compliance_m3_per_Pa = 0`` is a rigid wall.
    """

    catalogue_name: ClassVar[str | None] = None
    compliance_m3_per_Pa: float
    friction_band_Pa: float = 30e3

    def __post_init__(self):
        _non_negative(self, "compliance_m3_per_Pa")
        _positive(self, "friction_band_Pa")


@dataclass(frozen=True)
class BoucWenWall(PlantForm):
    """A wall whose give has a smooth, saturating hysteresis (a rubber sleeve with
    internal friction, a fabric bellows whose fibres slip and bind): an elastic part that
    follows the gauge pressure and a hysteretic part ``z`` (Bouc-Wen, beta = gamma) that
    moves with the pressure at a rate that falls as it nears its memory ``z_max`` while
    the pressure keeps pushing it there, and at the full rate once the pressure turns::

        V = V_0 + C_e y + V_h z / z_max,   y = p - P_atm,
        dz/dt = (1 - (|z| / z_max)^n) dy/dt   where z dy/dt > 0, else dy/dt,

    ``C_e = elastic_compliance_m3_per_Pa``, ``V_h = loop_volume_m3`` (half the loop's
    height at saturation), ``z_max = memory_Pa``, ``n = exponent`` (a sharper knee as it
    grows). ``z`` starts at 0 (the wall relaxed at the initial pressure).
    ``elastic_compliance_m3_per_Pa = loop_volume_m3 = 0`` is a rigid wall.
    """

    catalogue_name: ClassVar[str | None] = None
    elastic_compliance_m3_per_Pa: float
    loop_volume_m3: float
    memory_Pa: float = 50e3
    exponent: float = 1.0

    def __post_init__(self):
        _non_negative(self, "elastic_compliance_m3_per_Pa", "loop_volume_m3")
        _positive(self, "memory_Pa")
        if not (isinstance(self.exponent, (int, float)) and 1.0 <= self.exponent <= 8.0):
            raise ValueError(f"BoucWenWall.exponent must be in [1, 8], got "
                             f"{self.exponent!r}")


@dataclass(frozen=True)
class LoadedWall(PlantForm):
    """A flexible part of the chamber's wall that carries a load (a soft finger's skin
    with its payload, a bellows pushing a sprung mass): its give ``dV`` is a mass on a
    spring, driven by the gauge pressure, so the volume lags the pressure and rings::

        dV'' + 2 z w dV' + w^2 dV = w^2 C (p - P_atm),   V = V_0 + dV,

    ``C = compliance_m3_per_Pa`` (the static give per pascal), ``w = 2 pi
    natural_frequency_Hz``, ``z = damping_ratio``; the wall starts at rest at its static
    give under the initial pressure. ``compliance_m3_per_Pa = 0`` is a rigid wall.
    """

    catalogue_name: ClassVar[str | None] = None
    compliance_m3_per_Pa: float
    natural_frequency_Hz: float = 15.0
    damping_ratio: float = 0.2

    def __post_init__(self):
        _non_negative(self, "compliance_m3_per_Pa")
        _positive(self, "natural_frequency_Hz", "damping_ratio")
