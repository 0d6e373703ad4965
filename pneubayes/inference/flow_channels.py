"""Measured port flows in the likelihood: a recording's uncalibrated flow sensors.

A rig may log more than the chamber's pressure: a ventilator logs the differential
pressure across a venturi in its inhale and exhale limbs (flow proportional to its
square root), a lab a mass-flow meter in the supply line. Pressure alone confounds a
valve's area with the chamber's compliance (both scale dp/dt); a flow sensor measures
the valve's side alone. :class:`FlowChannel` names such a column and the valve port it
measures; :func:`flow_rows` turns it into residual rows a
:class:`~pneubayes.inference.refine.TrajectoryRefiner` (``extra_residuals``) or an
:class:`~pneubayes.inference.online_refit.OnlineRefit` (``channels``) adds to the
windows' pressure residuals.

The model's port flow at each sample is eqs. 1-3 at the *measured* pressure, ``q =
a(u) f(p_s, p)`` (the port's area from the command at that sample, the supply the valve
sees): an algebraic relation that needs no simulation, so the rows inform the valve's
map directly. The sensor is uncalibrated: its reading is ``offset + gain q^2``
(``law="square"``: a venturi or orifice meter) or ``offset + gain q`` (``"linear"``),
the offset and the gain (>= 0) refitted by least squares at every evaluation (they are
the sensor's, not the model's). A row is ``weight_Pa_per_unit x (reading - offset -
gain q^n)``: how many pascals of pressure error one unit of the channel's misfit is
worth. The port flows are taken at the command itself: a model with a command delay,
a spool lag or a sticking valve is refused (its spool is not the sampled command).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.physics.orifice import flow_function
from pneubayes.simulation.rates import inlet_supply, port_areas, port_laws

#: The laws that map a port's mass flow to the sensor's reading (before offset, gain).
LAWS = ("square", "linear")
#: Slots whose nonzero value means the valve's spool is not the sampled command.
_SPOOL_SLOTS = ("command_delay_s", "command_clock_period_s", "command_clock_latency_s",
                "spool_time_constant_s", "spool_fall_time_constant_s",
                "spool_natural_frequency_rad_per_s", "spool_rate_limit_V_per_s",
                "stiction_band_V")


@dataclass(frozen=True)
class FlowChannel:
    """A recording column measuring the flow through one valve port.

    Parameters
    ----------
    column : str
        The recording's extra column (e.g. ``"dp_inhale"``).
    port : {"inlet", "exhaust"}
        The port whose mass flow it measures.
    weight_Pa_per_unit : float
        Pascals of pressure error one unit of the column's misfit counts as (> 0).
    law : {"square", "linear"}
        Reading = offset + gain q^2 (a venturi) or offset + gain q.
    """

    column: str
    port: str
    weight_Pa_per_unit: float
    law: str = "square"

    def __post_init__(self):
        if self.port not in ("inlet", "exhaust"):
            raise ValueError(f"FlowChannel {self.column!r}: port must be 'inlet' or "
                             f"'exhaust', got {self.port!r}")
        if self.law not in LAWS:
            raise ValueError(f"FlowChannel {self.column!r}: law must be one of {LAWS}, got "
                             f"{self.law!r}")
        w = self.weight_Pa_per_unit
        if not (isinstance(w, (int, float)) and np.isfinite(w) and w > 0):
            raise ValueError(f"FlowChannel {self.column!r}: weight_Pa_per_unit must be > 0, "
                             f"got {w!r}")


def port_flows(model, theta, recording) -> tuple[np.ndarray, np.ndarray]:
    """``(inlet, exhaust)`` mass flows, kg/s, ``(B, N)``: eqs. 1-3 at the measured
    pressure and the sampled commands, for each parameter set of ``theta`` (B, P)."""
    rig = recording.rig()
    slots = model.lower(np.atleast_2d(theta), rig)
    for name in _SPOOL_SLOTS:
        if np.any(slots[:, S[name]] != 0):
            raise ValueError(f"port_flows: the model's {name} is not 0; a flow channel "
                             "takes the valve at the sampled command")
    p = np.asarray(recording.pressure_Pa, dtype=np.float64)
    u = np.asarray(recording.command_V, dtype=np.float64)
    ue = recording.exhaust_command()
    p_nom = rig.supply_pressure_Pa
    ps = np.asarray(recording.supply_or_nominal(), dtype=np.float64)
    inlet, exhaust = [], []
    for sl in slots:
        a_in, a_ex = port_areas(sl, u, ue)
        p_sup = p_nom + sl[S["supply_gain"]] * (ps - p_nom)
        b_in, b_ex, m_sub = port_laws(sl)
        inlet.append(a_in * flow_function(inlet_supply(sl, rig, p_sup, p, a_in), p,
                                          rig.gas, b_in, m_sub))
        exhaust.append(a_ex * flow_function(p, rig.atmospheric_pressure_Pa, rig.gas,
                                            b_ex, m_sub))
    return np.array(inlet), np.array(exhaust)


def flow_rows(model, theta, recording, channels) -> np.ndarray:
    """Residual rows ``(B, len(channels) x N)``, Pa-equivalent, of each channel against
    the model's port flows (the sensor's offset and gain refitted per parameter set);
    samples where the column is not finite, or the recording is marked invalid, give 0."""
    inlet, exhaust = port_flows(model, theta, recording)
    valid = np.asarray(recording.valid_mask(), dtype=bool)
    out = []
    for ch in channels:
        if ch.column not in recording.extra_columns:
            raise ValueError(f"{recording.source}: no column {ch.column!r} for the flow "
                             f"channel (it has {sorted(recording.extra_columns)})")
        y = np.asarray(recording.extra_columns[ch.column], dtype=np.float64)
        ok = valid & np.isfinite(y)
        q = inlet if ch.port == "inlet" else exhaust
        x = q * q if ch.law == "square" else q
        rows = np.zeros(x.shape)
        for b in range(x.shape[0]):
            offset, gain = _offset_and_gain(x[b, ok], y[ok])
            rows[b, ok] = ch.weight_Pa_per_unit * (y[ok] - offset - gain * x[b, ok])
        out.append(rows)
    return np.concatenate(out, axis=1)


def _offset_and_gain(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least squares ``y ~ offset + gain x`` with ``gain >= 0`` (else the mean alone)."""
    xc = x - x.mean()
    den = float(xc @ xc)
    gain = float(xc @ (y - y.mean())) / den if den > 0 else 0.0
    gain = max(gain, 0.0)
    return float(y.mean() - gain * x.mean()), gain
