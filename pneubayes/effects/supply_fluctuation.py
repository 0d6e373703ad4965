"""Supply-pressure fluctuation (paper IV-F): the inlet sees the measured supply.

In a model: ``P_c = P_nom + g (P_meas - P_nom)`` with ``supply_gain`` g (1 = the measured
supply column, 0 = the nominal value of the recording's JSON). Recordings without a
supply column carry the nominal value, so the effect is then inert.

On the bench: the supply header wanders around the nominal as the other ~40 cylinders
of the hand draw air (an Ornstein-Uhlenbeck process plus occasional load steps that
recover through the regulator); the valve's inlet sees the header through its supply
hose, a first-order pneumatic lag of ``line_time_constant_s`` (the hose's volume filled
through its own resistance), and the plant sees that with gain 1.
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.base import DirectEffect, Parameter
from pneubayes.effects.discovery import TrialTerm
from pneubayes.rig import Rig


class SupplyFluctuation(DirectEffect):
    """Measured rather than nominal supply pressure at the inlet port."""

    name = "supply_fluctuation"
    slot = "supply_gain"
    parameter = Parameter("supply_gain", "-", 0.0, 1.5, "uniform",
                          "weight of the measured supply deviation at the inlet", neutral=0.0)
    bench_value = 1.0

    def __init__(self, fluctuation_std_Pa: float = 12_000.0, correlation_time_s: float = 0.4,
                 load_step_rate_per_s: float = 0.5, load_step_Pa: float = 25_000.0,
                 recovery_time_s: float = 0.25, line_time_constant_s: float = 0.005):
        if not (np.isfinite(line_time_constant_s) and line_time_constant_s >= 0.0):
            raise ValueError("supply_fluctuation: line_time_constant_s must be finite and "
                             f">= 0, got {line_time_constant_s!r}")
        self.fluctuation_std_Pa = fluctuation_std_Pa
        self.correlation_time_s = correlation_time_s
        self.load_step_rate_per_s = load_step_rate_per_s
        self.load_step_Pa = load_step_Pa
        self.recovery_time_s = recovery_time_s
        self.line_time_constant_s = line_time_constant_s

    def options(self):
        return {"fluctuation_std_Pa": self.fluctuation_std_Pa,
                "correlation_time_s": self.correlation_time_s,
                "load_step_rate_per_s": self.load_step_rate_per_s,
                "load_step_Pa": self.load_step_Pa,
                "recovery_time_s": self.recovery_time_s,
                "line_time_constant_s": self.line_time_constant_s}

    library_strengths = (1.0,)
    discovery_fallback = {"supply_gain": 1.0}

    def library_terms(self, strengths):
        """The inlet at the measured instead of the nominal supply, weighted by each
        trial gain: the supply deviation times the inlet flow's sensitivity, to all
        orders."""
        return tuple(TrialTerm(f"measured supply x {v:g}", {"supply_gain": v},
                               values={"supply_gain": v}) for v in strengths)

    def candidate_start(self, term_start):
        """Gain 1 whatever the term: the inlet sees the measured supply, as the
        physics says; the fit moves the gain from there."""
        return dict(self.discovery_fallback)

    def perturb_inputs(self, time_s, supply_pressure_Pa, rig: Rig, rng: np.random.Generator):
        """True supply at the valve inlet (Pa): nominal + OU wander + decaying load dips,
        through the supply hose's first-order lag (none if ``line_time_constant_s`` is 0;
        the lag draws no random numbers, so a seed gives the same header either way)."""
        t = np.asarray(time_s, dtype=np.float64)
        dt = np.diff(t, prepend=t[0])
        tau, sd = self.correlation_time_s, self.fluctuation_std_Pa
        ou = np.empty_like(t)
        ou[0] = rng.normal(0.0, sd)
        decay = np.exp(-dt / tau)
        kicks = rng.normal(0.0, 1.0, t.size) * sd * np.sqrt(1.0 - decay**2)
        dip = np.zeros_like(t)
        steps = rng.random(t.size) < self.load_step_rate_per_s * dt
        depth = rng.uniform(0.5, 1.0, t.size) * self.load_step_Pa
        rec = np.exp(-dt / self.recovery_time_s)
        for i in range(1, t.size):
            ou[i] = ou[i - 1] * decay[i] + kicks[i]
            dip[i] = dip[i - 1] * rec[i] + (depth[i] if steps[i] else 0.0)
        dev = ou - dip
        if self.line_time_constant_s > 0.0:
            # exact for a deviation held over each step; starts settled
            keep = np.exp(-dt / self.line_time_constant_s)
            for i in range(1, t.size):
                dev[i] = dev[i - 1] * keep[i] + (1.0 - keep[i]) * dev[i]
        return np.asarray(supply_pressure_Pa, dtype=np.float64) + dev
