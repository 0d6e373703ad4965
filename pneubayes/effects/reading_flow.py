"""An open-form term at the reading: a reading that moves with the valve's port flows.

A sensor does not always read the chamber. One on the valve's outlet, on a manifold or
at a tee before a fitting reads the chamber's pressure plus the drop across what lies
between (a hose, a fitting, a check valve: linear in the flow where it is laminar,
quadratic where it is turbulent); one whose port faces the inlet's jet reads a share of
the jet's dynamic pressure (the square of the inflow), or less where the jet entrains
the gas beside it. Such a term follows the flows the valve passes, not the pressure
alone, and no relaxation, play or lag of the command expresses it. This component adds,
to the reading of the chamber pressure ``p``, ``K`` terms of the ports' mass flows::

    r = p + sum_k c_k F_k,

each ``F_k`` one of :data:`FLOW_FEATURES` (``reading_flow_features``, an option): the
inlet's or the exhaust's mass flow in g/s (``inlet_flow``, ``exhaust_flow``; eqs. 1-3
at the sample, the spool as the valve's stiction, delay and lag leave it) or its signed
square (``inlet_flow_square``, ``exhaust_flow_square``: ``q |q|`` in (g/s)^2), and
``c_k`` its gain (``reading_flow_gain_{k}``, Pa per feature unit). Every gain 0 is the
reading without the component.

The chamber's physics is unchanged: the simulator adds the terms to each simulated
window's reading after the kernel (:mod:`pneubayes.simulation.reading_flow`), the
flows evaluated at the samples along each parameter set's own predicted pressure, and
starts the chamber at the pressure that reads the window's first reading. The discovery
library never searches for it: the open-form stage at the reading
(:class:`~pneubayes.discovery.stages.reading_flow_form.ReadingFlowForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig

#: The features a term reads, in the order the search tries them.
FLOW_FEATURES = ("inlet_flow", "exhaust_flow", "inlet_flow_square", "exhaust_flow_square")
#: Each feature's unit (its gain is in Pa per this unit).
FLOW_FEATURE_UNITS = {"inlet_flow": "g/s", "exhaust_flow": "g/s",
                      "inlet_flow_square": "(g/s)^2", "exhaust_flow_square": "(g/s)^2"}
#: The most terms one component carries.
FLOW_MAX_TERMS = 2
#: A gain's bounds, Pa per feature unit. A jet's dynamic pressure at a port is large
#: for the flows of small valves (0.5 g/s through 1 mm^2 is sonic: hundreds of kPa at the
#: jet's core), so a sensor facing it may read tens of kPa per (g/s)^2.
FLOW_GAIN_BOUNDS_PA = (-1.0e6, 1.0e6)


def flow_gain_name(k: int) -> str:
    """Term ``k``'s gain parameter."""
    return f"reading_flow_gain_{k}"


class ReadingFlow(Effect):
    """``features`` (one or two of :data:`FLOW_FEATURES`) of the ports' mass flows in the
    reading, ``r = p + sum_k c_k F_k`` (``reading_flow_gain_{k}``)."""

    name = "reading_flow"
    acts_on = ()  # (the simulator adds it after the kernel, to the windows' reading)
    library_searched = False
    cheap_forms = True
    relaxes_reading = True

    def __init__(self, features=("inlet_flow_square",)):
        feats = (features,) if isinstance(features, str) else tuple(features)
        if not 1 <= len(feats) <= FLOW_MAX_TERMS or len(set(feats)) != len(feats) \
                or any(f not in FLOW_FEATURES for f in feats):
            raise ValueError(f"reading_flow: option 'features' must be 1..{FLOW_MAX_TERMS} "
                             f"distinct names of {FLOW_FEATURES}, got {features!r}")
        self.features = feats

    @property
    def terms(self) -> int:
        """How many terms the component carries."""
        return len(self.features)

    def options(self):
        return {"features": list(self.features)}

    def parameters(self):
        return tuple(
            Parameter(flow_gain_name(k), f"Pa/({FLOW_FEATURE_UNITS[f]})",
                      *FLOW_GAIN_BOUNDS_PA, "uniform",
                      f"reading flow term {k}: the reading's shift per unit of the {f} "
                      f"({FLOW_FEATURE_UNITS[f]})", neutral=0.0)
            for k, f in enumerate(self.features))

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {}  # (no slot of the kernel: see the module's docstring)

    def reading_flows(self, values: Mapping[str, np.ndarray]) \
            -> tuple[np.ndarray, tuple[str, ...]]:
        """``(gains (B, K) in Pa per feature unit, the K feature names)``."""
        return self.flows_named(values, [flow_gain_name(k) for k in range(self.terms)],
                                self.features)

    @staticmethod
    def flows_named(values: Mapping[str, np.ndarray], gains: list[str], features
                    ) -> tuple[np.ndarray, tuple[str, ...]]:
        """``(gains (B, K), features)``: the gains read from ``values`` under the parameter
        names ``gains``, one per feature of ``features``."""
        g = np.stack([np.atleast_1d(np.asarray(values[n], np.float64)) for n in gains],
                     axis=-1)
        return g, tuple(features)

    def bench_defaults(self):
        """2 kPa per (g/s)^2 on the first feature (a jet's share at a few g/s), -500 Pa
        per unit on a second."""
        out = {flow_gain_name(0): 2000.0}
        if self.terms > 1:
            out[flow_gain_name(1)] = -500.0
        return out
