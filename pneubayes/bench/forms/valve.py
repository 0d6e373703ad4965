"""Out-of-catalogue forms of the valve: its spool's motion and memory, its ports' flow
laws and leaks, its solenoid."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pneubayes.bench.forms.base import (
    AIR_VISCOSITY_PA_S,
    PlantForm,
    _finite,
    _non_negative,
    _positive,
    _smoothstep,
)


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
    is close to eqs. 1-3. A realistic form of the catalogue's ``critical_ratio`` (whose
    subsonic curve is eq. 3's stretched over ``[b, 1]``, at a subsonic index of 1/2
    only).
    """

    catalogue_name: ClassVar[str | None] = "critical_ratio"
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
class PressureHeldSolenoid(PlantForm):
    """A solenoid whose armature is held against its seat by the pressure across the
    inlet: opening (the command above the spool) starts slower the larger the drop,
    closing (the spring and the pressure together) is fast::

        ds/dt = (u - s) / (tau (1 + k max(p_s - p_v, 0) / P_atm))   if u > s,
        ds/dt = (u - s) / tau                                       otherwise,

    s the spool position (V of command), ``tau = time_constant_s``, ``k =
    slowing_per_atm``, p_s the supply at the valve and p_v the pressure at its work
    port. Unlike the catalogue's spool lags its time constant depends on the pressures,
    so a valve that opens into an empty chamber lags more than into a full one.
    ``time_constant_s = 0`` is a free spool (the state is omitted); it replaces the
    catalogue's spool stages and cannot be planted beside them.
    """

    catalogue_name: ClassVar[str | None] = None
    time_constant_s: float
    slowing_per_atm: float = 1.0

    def __post_init__(self):
        _non_negative(self, "time_constant_s", "slowing_per_atm")


@dataclass(frozen=True)
class PilotFedSpool(PlantForm):
    """A proportional spool pushed back by the delivered pressure: a pilot passage feeds
    the work port's pressure onto an unbalanced end of the spool, against the solenoid,
    and a preloaded spring holds the pilot's piston until the pressure lifts it::

        s_eff = s - k max(q - q_0, 0) / (1 bar),   dq/dt = ((p - P_atm) - q) / tau_q,

    s the spool position (V of command, after any spool stage), q the pilot chamber's
    gauge pressure (a first-order lag of the work port's through the pilot orifice),
    ``k = feedback_V_per_bar``, ``q_0 = preload_Pa`` and ``tau_q =
    pilot_time_constant_s``. The valve delivers less than its command asks at high
    pressure (a fill slows, then stalls where the shifted spool closes the inlet) and
    vents harder there: part of a pressure regulator's loop inside a directional valve.
    ``feedback_V_per_bar = 0`` is a plain spool (the state is omitted).
    """

    catalogue_name: ClassVar[str | None] = None
    feedback_V_per_bar: float
    preload_Pa: float = 1.0e5
    pilot_time_constant_s: float = 5e-3

    def __post_init__(self):
        _non_negative(self, "feedback_V_per_bar", "preload_Pa")
        _positive(self, "pilot_time_constant_s")


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

    @property
    def acts(self) -> bool:
        """Whether it changes when the valve takes the command (not at zero strength)."""
        return self.delay_s > 0

    def switches(self, time_s, command, shared_delay_s: float = 0.0):
        """``(times, values)``: when (s) the valve takes each held value of
        ``command`` (sampled at ``time_s``), ``times[0] = -inf`` holding the first; a
        change acts ``shared_delay_s`` after its sample, a fall ``delay_s`` later
        still, and a change superseded before it acts is dropped."""
        t = np.asarray(time_s, dtype=np.float64)
        u = np.asarray(command, dtype=np.float64)
        return _changes_acting(u, lambda k: t[k] + shared_delay_s
                               + (self.delay_s if u[k] < u[k - 1] else 0.0))


def _changes_acting(u: np.ndarray, act_time) -> tuple[np.ndarray, np.ndarray]:
    """``(times, values)``: each change of the held command ``u`` (at sample k) acting at
    ``act_time(k)`` (s), ``times[0] = -inf`` holding the first value; a change that a
    later one overtakes (acts at or before it) is dropped."""
    times, values = [-math.inf], [float(u[0])]
    for k in np.nonzero(np.diff(u) != 0)[0] + 1:
        at = act_time(k)
        while len(times) > 1 and times[-1] >= at:  # pending changes it overtakes
            times.pop()
            values.pop()
        times.append(at)
        values.append(float(u[k]))
    return np.array(times), np.array(values)


@dataclass(frozen=True)
class ArmatureDeadTime(PlantForm):
    """A solenoid valve whose moving part the supply drives: each command change acts
    after the coil's own delay and the part's travel, a part moved from rest over a fixed
    stroke by a force proportional to the gauge supply (a pilot-operated valve's main
    stage)::

        d = coil_s + travel_s sqrt(reference_gauge_Pa / (p_s - P_atm)),

    p_s the supply at the moment the change reaches the valve (not the recording's
    nominal). A change overtaken by a later one that acts first is dropped. Both 0 is a
    valve that follows the command at once. (The catalogue's ``valve_dead_time`` is a
    power law of the nominal supply, without the coil's offset.)
    """

    catalogue_name: ClassVar[str | None] = "valve_dead_time"
    travel_s: float
    coil_s: float = 0.002
    reference_gauge_Pa: float = 5e5
    reads_supply: ClassVar[bool] = True

    def __post_init__(self):
        _non_negative(self, "travel_s", "coil_s")
        _positive(self, "reference_gauge_Pa")

    @property
    def acts(self) -> bool:
        """Whether it changes when the valve takes the command (not at zero strength)."""
        return self.travel_s > 0 or self.coil_s > 0

    def switches(self, time_s, command, shared_delay_s: float = 0.0, supply_gauge_at=None):
        """``(times, values)``: when (s) the valve takes each held value of ``command``
        (``times[0] = -inf``), ``supply_gauge_at(t)`` the gauge supply (Pa) at time t."""
        t = np.asarray(time_s, dtype=np.float64)
        u = np.asarray(command, dtype=np.float64)

        def act_time(k):
            reach = t[k] + shared_delay_s
            gauge = float(supply_gauge_at(reach))
            if not gauge > 0:
                raise ValueError(f"ArmatureDeadTime: the gauge supply at {reach:g} s is "
                                 f"{gauge:g} Pa; the travel needs a positive one")
            return reach + self.coil_s + self.travel_s * self.travel_factor(gauge)

        return _changes_acting(u, act_time)

    def travel_factor(self, gauge_Pa: float) -> float:
        """The travel time at gauge supply ``gauge_Pa`` over that at the reference: the
        inverse square root of the driving force's ratio."""
        return math.sqrt(self.reference_gauge_Pa / gauge_Pa)


@dataclass(frozen=True)
class HeldArmatureDeadTime(ArmatureDeadTime):
    """A direct-acting solenoid valve whose poppet the supply holds shut: the coil's
    force less the supply's on the seat drives the armature, ``F = A (p_lim - g)`` for
    gauge supply g, so the travel lengthens as the supply rises and the valve cannot open
    at ``limit_gauge_Pa`` (p_lim)::

        d = coil_s + travel_s sqrt((p_lim - p_ref) / (p_lim - g)),

    at each command change, as :class:`ArmatureDeadTime` (a realistic form of
    ``valve_dead_time`` whose dead time rises with the supply).
    """

    limit_gauge_Pa: float = 1e6

    def __post_init__(self):
        super().__post_init__()
        _positive(self, "limit_gauge_Pa")  # (the forms' shared message for a bad number)
        if not self.limit_gauge_Pa > self.reference_gauge_Pa:
            raise ValueError(f"HeldArmatureDeadTime.limit_gauge_Pa must exceed "
                             f"reference_gauge_Pa ({self.reference_gauge_Pa:g}), got "
                             f"{self.limit_gauge_Pa!r}")

    def travel_factor(self, gauge_Pa: float) -> float:
        if not gauge_Pa < self.limit_gauge_Pa:
            raise ValueError(f"HeldArmatureDeadTime: a gauge supply of {gauge_Pa:g} Pa holds "
                             f"the valve shut (its limit {self.limit_gauge_Pa:g} Pa)")
        return math.sqrt((self.limit_gauge_Pa - self.reference_gauge_Pa)
                         / (self.limit_gauge_Pa - gauge_Pa))


# ------------------------------------------ out-of-catalogue forms, the seventh blind set


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


# ------------------------------------------ out-of-catalogue forms, the ninth blind set


def _held_at(time_s: np.ndarray, command: np.ndarray, at: np.ndarray,
             shared_delay_s: float) -> np.ndarray:
    """The held command (sampled at ``time_s``) that a driver reading it at the times
    ``at`` sees, the command reaching it ``shared_delay_s`` late (the first value before
    the first sample)."""
    k = np.searchsorted(time_s + shared_delay_s, at, side="right") - 1
    return command[np.clip(k, 0, command.size - 1)]


@dataclass(frozen=True)
class PwmValve(PlantForm):
    """On/off valves driven by pulse-width modulation of the command, in place of a
    proportional valve.

    The driver runs at ``frequency_Hz`` from the recording's first sample; at each
    period's start it reads the command u and opens the inlet (u > 0) or the exhaust
    (u < 0) fully, as the proportional valve at ``+-full_command_V``, for the duty
    ``min(|u| / full_command_V, 1)`` of the period; between pulses both are shut (the
    valve at 0 V). A solenoid opens ``opening_delay_s`` after its pulse starts and closes
    ``closing_delay_s`` after it ends, so a pulse shorter than the difference never
    opens the valve and pulses that overlap merge. ``alignment`` places each pulse in its
    period: it starts that share of the period's shut time after the period's start (0:
    from the start, a timer's edge-aligned PWM; 0.5: centred, a phase-correct one).
    ``frequency_Hz = 0`` is the proportional valve (no modulation).
    """

    catalogue_name: ClassVar[str | None] = None
    frequency_Hz: float
    opening_delay_s: float = 3e-3
    closing_delay_s: float = 2e-3
    full_command_V: float = 5.0
    alignment: float = 0.0

    def __post_init__(self):
        _non_negative(self, "frequency_Hz", "opening_delay_s", "closing_delay_s")
        _positive(self, "full_command_V")
        _finite(self, "alignment")
        if not 0.0 <= self.alignment <= 1.0:
            raise ValueError(f"PwmValve.alignment must be in [0, 1], got {self.alignment!r}")

    @property
    def acts(self) -> bool:
        """Whether it changes when the valve takes the command (not at zero strength)."""
        return self.frequency_Hz > 0

    def switches(self, time_s, command, shared_delay_s: float = 0.0):
        """``(times, values)``: when (s) the valve takes each command value (V), as
        :meth:`ReleaseDelay.switches` (``times[0] = -inf``)."""
        t = np.asarray(time_s, dtype=np.float64)
        u = np.asarray(command, dtype=np.float64)
        if self.frequency_Hz == 0.0:
            return ReleaseDelay(0.0).switches(t, u, shared_delay_s)
        period = 1.0 / self.frequency_Hz
        starts = t[0] + period * np.arange(int(math.ceil((t[-1] - t[0]) / period)) + 1)
        held = _held_at(t, u, starts, shared_delay_s)
        duty = np.minimum(np.abs(held) / self.full_command_V, 1.0)
        # the driver's signal: a pulse in each period (from its start at alignment 0),
        # adjacent pulses of one sign one (at full duty the signal never falls)
        signal = []
        for s, d, v in zip(starts, duty, held):
            if d == 0.0:
                continue
            s = s + self.alignment * (1.0 - d) * period
            value = math.copysign(self.full_command_V, v)
            if signal and signal[-1][1] >= s and signal[-1][2] == value:
                signal[-1] = (signal[-1][0], s + d * period, value)
            else:
                signal.append((s, s + d * period, value))
        # the solenoid: open after the opening delay, shut after the closing delay; a
        # pulse too short never opens it, one that reopens it before it shut merges,
        # and a pulse of the other sign cuts the last short where it opens its port
        pulses = []
        for a, b, value in signal:
            on, off = a + self.opening_delay_s, b + self.closing_delay_s
            if off <= on:
                continue
            if pulses and pulses[-1][1] >= on:
                last = pulses[-1]
                if last[2] == value:
                    pulses[-1] = (last[0], max(last[1], off), value)
                    continue
                pulses[-1] = (last[0], on, last[2])
            pulses.append((on, off, value))
        times, values = [-math.inf], [0.0]
        for on, off, value in pulses:
            if times[-1] == on:
                values[-1] = value
            else:
                times.append(on)
                values.append(value)
            times.append(off)
            values.append(0.0)
        return np.array(times), np.array(values)


@dataclass(frozen=True)
class ZohDriver(PlantForm):
    """A networked valve driver (a fieldbus, a USB DAQ): it takes the command only every
    ``update_period_s``, at ``phase`` of a period after the recording's first sample,
    holds it, and applies it ``latency_s`` later. A command change waits between 0 and
    one period for the next update. ``update_period_s = 0`` is a driver that follows
    the command at once.
    """

    catalogue_name: ClassVar[str | None] = None
    update_period_s: float
    latency_s: float = 0.0
    phase: float = 0.0

    def __post_init__(self):
        _non_negative(self, "update_period_s", "latency_s")
        _finite(self, "phase")
        if not 0.0 <= self.phase < 1.0:
            raise ValueError(f"ZohDriver.phase must be in [0, 1), got {self.phase!r}")

    @property
    def acts(self) -> bool:
        """Whether it changes when the valve takes the command (not at zero strength)."""
        return self.update_period_s > 0 or self.latency_s > 0

    def switches(self, time_s, command, shared_delay_s: float = 0.0):
        """``(times, values)``: when (s) the valve takes each command value (V), as
        :meth:`ReleaseDelay.switches` (``times[0] = -inf``)."""
        t = np.asarray(time_s, dtype=np.float64)
        u = np.asarray(command, dtype=np.float64)
        if self.update_period_s == 0.0:
            return ReleaseDelay(0.0).switches(t, u, shared_delay_s + self.latency_s)
        period = self.update_period_s
        ticks = t[0] + period * (self.phase + np.arange(
            int(math.ceil((t[-1] - t[0]) / period)) + 1))
        held = _held_at(t, u, ticks, shared_delay_s)
        times, values = [-math.inf], [float(_held_at(t, u, t[:1], shared_delay_s)[0])]
        for at, v in zip(ticks + self.latency_s, held):
            if v != values[-1]:
                times.append(float(at))
                values.append(float(v))
        return np.array(times), np.array(values)
