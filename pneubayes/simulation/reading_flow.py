"""The reading's terms in the ports' mass flows (effect ``reading_flow``), added to
simulated windows.

A model with :class:`~pneubayes.effects.reading_flow.ReadingFlow` reads each window's
pressure ``p`` as ``r = p + sum_k c_k F_k``, each ``F_k`` a feature of the ports' mass
flows at the sample (:func:`feature_values`)::

    q_in = A_in(s) f(p_s, p),    q_ex = A_ex(s) f(p, P_atm)       (eqs. 1-3, kg/s)

``A`` the ports' areas at the spool position ``s`` (the dead band, the Gompertz maps of
eq. 11 and a switching valve's opening: :func:`~pneubayes.simulation.rates.port_areas`),
``s`` the command as the valve's stiction, delay and lag leave it
(:func:`~pneubayes.simulation.spool_path.spool_at`), ``p_s = P_nom + g (p_meas - P_nom)``
the supply the valve sees (``g`` the model's supply gain), all at the sample instants
along each parameter set's own predicted pressure. They are the valve's port flows, so
a tube's pressure drop, a restriction's node at the port (the flows here are at the
chamber's pressure), a heat-transfer model's temperature scaling and a closure's extra
flow are not in them; beside a sensor lag or a declared filter they are evaluated
along the lagged (filtered) pressure the kernel returns, and the terms are not lagged.

The chamber starts at the pressure that reads the window's first reading: ``p0 = r0 -
sum_k c_k F_k(p0)``, solved by :data:`START_ITERATIONS` fixed-point iterations from
``r0`` (each gains the factor ``sum_k c_k dF_k/dp``, far below 1 for the gains'
bounds).
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.path import SLOT_INDEX as S
from pneubayes.effects.reading_flow import FLOW_FEATURES
from pneubayes.physics.orifice import flow_function
from pneubayes.simulation.rates import inlet_supply, port_areas, port_laws
from pneubayes.simulation.spool_path import spool_at

#: The flows' unit in the features, kg/s (the features are in g/s).
FLOW_UNIT_KG_PER_S = 1e-3
#: Fixed-point iterations of a window's chamber start (see the module's docstring).
START_ITERATIONS = 3
#: Relative pressure step of the central difference of the features' slope in p.
SLOPE_STEP = 1e-5
#: The slots the spool's path reads (:func:`~pneubayes.simulation.spool_path.spool_at`):
#: parameter sets equal in them share it.
SPOOL_SLOTS = np.array([S[n] for n in (
    "command_delay_s", "command_clock_latency_s", "spool_time_constant_s",
    "spool_rate_limit_V_per_s", "spool_fall_time_constant_s",
    "spool_natural_frequency_rad_per_s", "spool_damping", "stiction_band_V",
    "stiction_slip_fraction")])


def feature_values(name: str, inlet_kg_per_s, exhaust_kg_per_s) -> np.ndarray:
    """Feature ``name`` (one of :data:`~pneubayes.effects.reading_flow.FLOW_FEATURES`) of
    the ports' mass flows (kg/s): a flow in g/s or its signed square ``q |q|`` in
    (g/s)^2."""
    if name not in FLOW_FEATURES:
        raise ValueError(f"reading_flow: unknown feature {name!r}; one of {FLOW_FEATURES}")
    q = np.asarray(inlet_kg_per_s if name.startswith("inlet") else exhaust_kg_per_s,
                   dtype=np.float64) / FLOW_UNIT_KG_PER_S
    return q * np.abs(q) if name.endswith("_square") else q


class PortFlows:
    """The valve's port flows along windows of one recording, for any pressures.

    Parameters
    ----------
    inputs : Inputs
        The recording's drive signals.
    rig : Rig
    starts : (W,) int array
        The windows' first samples.
    length : int
        Samples per window.
    """

    def __init__(self, inputs, rig, starts, length: int):
        self.inputs, self.rig = inputs, rig
        self.idx = np.asarray(starts, dtype=np.int64)[:, None] + np.arange(int(length))
        self.samples = np.unique(self.idx)
        self.where = np.searchsorted(self.samples, self.idx)
        self._spools: dict[bytes, np.ndarray] = {}
        self._ports: dict[bytes, tuple] = {}

    def _spool(self, slots_row: np.ndarray) -> np.ndarray:
        key = slots_row[SPOOL_SLOTS].tobytes()
        if key not in self._spools:
            t = np.asarray(self.inputs.time_s, dtype=np.float64)[self.samples]
            self._spools[key] = spool_at(t, self.inputs, slots_row)[self.where]
        return self._spools[key]

    def ports(self, slots_row: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(inlet area, exhaust area, supply)`` at the windows' samples (m^2, m^2, Pa; each
        ``(W, L)``) for one parameter set, computed once per set."""
        key = slots_row.tobytes()
        if key not in self._ports:
            ue = self.inputs.exhaust_command
            a_in, a_ex = port_areas(slots_row, self._spool(slots_row),
                                    None if ue is None else np.asarray(ue, np.float64)[self.idx])
            p_nom = self.rig.supply_pressure_Pa
            ps = np.asarray(self.inputs.supply_pressure_Pa, dtype=np.float64)[self.idx]
            self._ports[key] = (a_in, a_ex, p_nom + slots_row[S["supply_gain"]] * (ps - p_nom))
        return self._ports[key]

    def flows(self, slots_row: np.ndarray, pressure_Pa) -> tuple[np.ndarray, np.ndarray]:
        """``(q_in, q_ex)`` (kg/s) at the chamber pressures ``pressure_Pa`` (``(W, L)``,
        or ``(W,)`` at the windows' first samples)."""
        a_in, a_ex, p_sup = self.ports(slots_row)
        p = np.asarray(pressure_Pa, dtype=np.float64)
        if p.ndim == 1:
            a_in, a_ex, p_sup = a_in[:, 0], a_ex[:, 0], p_sup[:, 0]
        g = self.rig.gas
        b_in, b_ex, m_sub = port_laws(slots_row)
        return (a_in * flow_function(inlet_supply(slots_row, self.rig, p_sup, p, a_in), p,
                                     g, b_in, m_sub),
                a_ex * flow_function(p, self.rig.atmospheric_pressure_Pa, g, b_ex, m_sub))


def flow_reading(port_flows: PortFlows, slots, pressure_Pa, gains, features
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(sum_k c_k F_k, its slope in p)`` at each parameter set's pressures
    ``pressure_Pa`` ``(B, W, L)`` (or ``(B, W)``): Pa and -, for ``gains`` ``(B, K)`` (Pa
    per feature unit) of the ``features`` (K names); zeros without a term."""
    p = np.asarray(pressure_Pa, dtype=np.float64)
    g = np.asarray(gains, dtype=np.float64)
    out, slope = np.zeros(p.shape), np.zeros(p.shape)
    if not len(features):
        return out, slope
    for b in range(p.shape[0]):
        if not np.any(g[b] != 0.0):
            continue
        row = slots[b]
        ok = np.isfinite(p[b]) & (p[b] > 0.0)  # (a failed simulation's NaN stays NaN)
        pb = np.where(ok, p[b], 1.0e5)
        dp = SLOPE_STEP * pb
        at = [port_flows.flows(row, pb + s * dp) for s in (0.0, 1.0, -1.0)]
        out[b][~ok], slope[b][~ok] = np.nan, np.nan
        for c, name in zip(g[b], features):
            if c == 0.0:
                continue
            f = [feature_values(name, *q) for q in at]
            out[b] += c * f[0]
            slope[b] += c * (f[1] - f[2]) / (2.0 * dp)
    return out, slope


def flow_start(port_flows: PortFlows, slots, reading0_Pa, gains, features) -> np.ndarray:
    """Each parameter set's chamber start ``(B, W)`` (Pa) that reads ``reading0_Pa``
    (``(W,)`` or ``(B, W)``) through the flow terms (:data:`START_ITERATIONS`
    fixed-point iterations of ``p0 = r0 - sum_k c_k F_k(p0)``, each kept above half the
    reading: a start whose terms would read more than the reading is none)."""
    g = np.asarray(gains, dtype=np.float64)
    r0 = np.broadcast_to(np.asarray(reading0_Pa, dtype=np.float64),
                         (g.shape[0], np.shape(reading0_Pa)[-1]))
    p0 = r0.copy()
    for _ in range(START_ITERATIONS):
        shift, _ = flow_reading(port_flows, slots, p0, g, features)
        p0 = np.maximum(r0 - shift, 0.5 * r0)
    return p0
