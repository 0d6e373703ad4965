"""Out-of-catalogue forms of the sensors: readings that bow, lag, drift or overshoot
(the bench applies them to the plant's output)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pneubayes.bench.forms.base import (
    PlantForm,
    _finite,
    _non_negative,
    _positive,
)
from pneubayes.effects.closure_histories import first_order_low_pass


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


# ------------------------------------------ out-of-catalogue forms, the ninth blind set


@dataclass(frozen=True)
class SensorHysteresis(PlantForm):
    """A pressure sensor whose diaphragm has mechanical hysteresis (friction in its
    linkage, a gauge's play): the reading is the mean of ``plays`` play operators
    (Prandtl-Ishlinskii) of half-widths ``b (i + 1) / plays``, i = 0 .. plays - 1,
    ``b = half_width_Pa``::

        y_i = min(max(y_i, p - b_i), p + b_i)   (each sample, y_i = p at the start),

    so after a rise the reading trails the pressure by up to about ``b (plays + 1) /
    (2 plays)`` and after a fall leads it back by as much: a loop, independent of the
    rate. ``half_width_Pa = 0`` reads true.
    """

    catalogue_name: ClassVar[str | None] = None
    half_width_Pa: float
    plays: int = 4

    def __post_init__(self):
        _non_negative(self, "half_width_Pa")
        if isinstance(self.plays, bool) or not isinstance(self.plays, int) \
                or not 1 <= self.plays <= 16:
            raise ValueError(f"SensorHysteresis.plays must be an integer in 1..16, got "
                             f"{self.plays!r}")

    def read(self, pressure_Pa):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa``
        (sampled in order)."""
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if self.half_width_Pa == 0.0 or p.size == 0:
            return p.copy()
        widths = self.half_width_Pa * np.arange(1, self.plays + 1) / self.plays
        return np.mean([_play(p, b) for b in widths], axis=0)


def _play(p: np.ndarray, half_width: float) -> np.ndarray:
    """The play operator of ``half_width`` on the samples ``p``, starting at ``p[0]``."""
    out = np.empty_like(p)
    y = float(p[0])
    for i, v in enumerate(p.tolist()):
        if v - half_width > y:
            y = v - half_width
        elif v + half_width < y:
            y = v + half_width
        out[i] = y
    return out


# ------------------------------------------ out-of-catalogue forms, the tenth blind set


@dataclass(frozen=True)
class SolenoidGroundShift(PlantForm):
    """A pressure sensor that shares its ground return with the valve's solenoid driver:
    the coil's current through the common wire shifts the sensor's zero, so the reading
    moves with the command, not with the pressure::

        r = p + shift_Pa i,   tau di/dt = min(|u| / full_command_V, 1) - i,

    ``i`` the coil's current as a fraction of full (the coil's L / R is ``tau =
    time_constant_s``; i starts at its steady value for the first command), u the
    command (V) the driver receives. ``shift_Pa`` (either sign) is the shift at full
    current. ``shift_Pa = 0`` is a sensor with its own ground.
    """

    catalogue_name: ClassVar[str | None] = None
    shift_Pa: float
    time_constant_s: float = 5e-3
    full_command_V: float = 5.0

    def __post_init__(self):
        _finite(self, "shift_Pa")
        _positive(self, "time_constant_s", "full_command_V")

    def current(self, time_s, command_V):
        """The coil's current (fraction of full) at the times ``time_s`` (s) for the
        command ``command_V`` (V, held between samples as the driver holds it)."""
        t = np.asarray(time_s, dtype=np.float64)
        drive = np.minimum(np.abs(np.asarray(command_V, dtype=np.float64))
                           / self.full_command_V, 1.0)
        if t.size == 0:
            return drive.copy()
        # a held command: the exact lag of a piecewise-constant drive
        out = np.empty_like(drive)
        i = float(drive[0])
        out[0] = i
        decay = np.exp(-np.diff(t) / self.time_constant_s)
        for k in range(1, t.size):
            i = drive[k - 1] + (i - drive[k - 1]) * decay[k - 1]
            out[k] = i
        return out

    def read(self, time_s, command_V, pressure_Pa):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa`` at the
        times ``time_s`` (s) under the command ``command_V`` (V)."""
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if self.shift_Pa == 0.0:
            return p.copy()
        return p + self.shift_Pa * self.current(time_s, command_V)


@dataclass(frozen=True)
class InletJetAtSensor(PlantForm):
    """A pressure sensor whose port faces the jet from the valve's inlet: it reads the
    chamber's pressure plus a share of the jet's dynamic pressure, which grows with the
    square of the inflow (a port beside the jet, where the jet entrains the gas, reads
    low instead)::

        r = p + shift_Pa (max(mdot_in, 0) / reference_flow_kg_per_s)^2,

    ``mdot_in`` the mass flow through the valve's inlet port (kg/s; the plant's), the
    exhaust drawing from the whole chamber without a jet. ``shift_Pa`` (either sign) is
    the shift at the reference flow. ``shift_Pa = 0`` is a sensor away from the jet.
    """

    catalogue_name: ClassVar[str | None] = None
    shift_Pa: float
    reference_flow_kg_per_s: float = 5e-4

    def __post_init__(self):
        _finite(self, "shift_Pa")
        _positive(self, "reference_flow_kg_per_s")

    def read(self, inlet_flow_kg_per_s, pressure_Pa):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa`` with the
        inlet's mass flows ``inlet_flow_kg_per_s`` (kg/s) at the same samples."""
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if self.shift_Pa == 0.0:
            return p.copy()
        q = np.maximum(np.asarray(inlet_flow_kg_per_s, dtype=np.float64), 0.0)
        return p + self.shift_Pa * (q / self.reference_flow_kg_per_s) ** 2


@dataclass(frozen=True)
class SaturatingSensor(PlantForm):
    """A pressure sensor (or the amplifier or ADC behind it) whose output saturates at the
    top of its range: the rig's supply is above the sensor's full scale, so the top of a
    fill is read flat. The output bends into its rail over a knee (an amplifier's soft
    saturation)::

        r = P_atm + F - w ln(1 + exp((F - y) / w)),   y = p - P_atm,

    ``F = full_scale_Pa`` (gauge) the rail, ``w = knee_Pa`` the knee's width. Well below
    the rail ``r = p`` to within ``w exp(-(F - y) / w)``; well above it ``r = P_atm + F``.
    ``full_scale_Pa = inf`` is a sensor that never saturates.
    """

    catalogue_name: ClassVar[str | None] = None
    full_scale_Pa: float
    knee_Pa: float = 5e3

    def __post_init__(self):
        if not (self.full_scale_Pa > 0.0):  # inf allowed: no rail
            raise ValueError(f"SaturatingSensor.full_scale_Pa must be > 0 (inf: no rail), "
                             f"got {self.full_scale_Pa!r}")
        _positive(self, "knee_Pa")

    def read(self, pressure_Pa, atmospheric_pressure_Pa: float):
        """The reading (Pa, absolute) of the absolute pressures ``pressure_Pa``."""
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if not np.isfinite(self.full_scale_Pa):
            return p.copy()
        y = p - atmospheric_pressure_Pa
        w = self.knee_Pa
        return (atmospheric_pressure_Pa + self.full_scale_Pa
                - w * np.logaddexp(0.0, (self.full_scale_Pa - y) / w))


@dataclass(frozen=True)
class SkewedPressureChannel(PlantForm):
    """A pressure channel logged late against the command and the position (a digital
    transmitter's processing and bus delay, a data logger whose pressure channel is
    buffered or read after a multiplexer settles): the recording's pressure at t is the
    sensor's at ``t - d``::

        r(t) = p(t - d),

    with the chamber at rest (its first value) before the record. ``delay_s = d``;
    ``delay_s = 0`` is a channel in step with the others.
    """

    catalogue_name: ClassVar[str | None] = None
    delay_s: float

    def __post_init__(self):
        _non_negative(self, "delay_s")

    def read(self, time_s, pressure_Pa):
        """The logged pressures (Pa) at ``time_s`` (s, increasing) of the sensor's
        ``pressure_Pa`` at the same times, linear between them."""
        t = np.asarray(time_s, dtype=np.float64)
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if self.delay_s == 0.0 or p.size == 0:
            return p.copy()
        return np.interp(t - self.delay_s, t, p)
