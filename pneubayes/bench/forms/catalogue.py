"""Realistic forms of the catalogue effects (each names the effect a discovery run
should report for it): the tube as a lumped line, a rounded dead band, a clearance
leak, a drooping regulator, a second-order spool, wall heat transfer."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from pneubayes.bench.forms.base import (
    AIR_VISCOSITY_PA_S,
    PlantForm,
    _non_negative,
    _positive,
)
from pneubayes.physics.gas import GasConstants


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

    ``unsteady_friction`` > 0 adds that share of Zielke's (1968) unsteady wall shear
    to each link, ``(4 mu / D) integral W(t - u) dV/du du`` (V the mean velocity), which
    damps a line's ringing faster than the quasi-steady shear alone: the laminar
    weighting function in Schohl's (2003) five exponentials, cut off in turbulent flow
    as Vardy and Brown (2003) give (:func:`pneubayes.bench.plant.unsteady_friction_rates`;
    five states per link). 0 (the default) is the quasi-steady tube above.
    """

    catalogue_name: ClassVar[str] = "tube_delay"
    length_m: float
    diameter_m: float = 0.002
    segments: int = 8
    air_viscosity_Pa_s: float = AIR_VISCOSITY_PA_S
    unsteady_friction: float = 0.0

    def __post_init__(self):
        _positive(self, "length_m", "diameter_m", "air_viscosity_Pa_s")
        if isinstance(self.unsteady_friction, bool) or not self.unsteady_friction >= 0:
            raise ValueError(f"AcousticTube.unsteady_friction must be a number >= 0, "
                             f"got {self.unsteady_friction!r}")
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

    ``jet_h_W_per_m2_K`` > 0 adds forced convection while the chamber fills: the inflow's
    jet stirs the gas against the wall, ``h = h_0 + h_jet (m_in / m_ref)^0.8`` (a
    Dittus-Boelter exponent on the jet's Reynolds number; ``m_ref`` is
    ``jet_flow_kg_per_s``), so the exchange is fast during a fill and slow in a hold or a
    vent, which no single coefficient or time constant gives.
    """

    catalogue_name: ClassVar[str] = "heat_transfer"
    h_W_per_m2_K: float
    wall_temperature_K: float | None = None
    jet_h_W_per_m2_K: float = 0.0
    jet_flow_kg_per_s: float = 1e-3

    def __post_init__(self):
        _non_negative(self, "h_W_per_m2_K", "jet_h_W_per_m2_K")
        _positive(self, "jet_flow_kg_per_s")
        if self.wall_temperature_K is not None:
            _positive(self, "wall_temperature_K")


# ------------------------------------------------------------ out-of-catalogue forms
