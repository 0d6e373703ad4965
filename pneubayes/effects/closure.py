"""An open-form closure: an extra mass flow into the chamber built from typed features.

Each term is ``c_k F_a F_b`` (kg/s) of the features of
:mod:`pneubayes.effects.closure_features` (``F_b = one`` for a single feature); its
coefficient ``closure_coefficient_{k}`` carries ``kg/s`` over the features' units and each
hinge feature's threshold (a relaxation's time constant, s) is a parameter
``closure_threshold_{k}_{a|b}``. The terms are
the ``terms`` option, e.g. ``"inlet_flow*pressure_hinge; one"``, so a model card stores
them (they cannot be read off the parameter names).

The flow enters eq. 5 as a port flow does (mass is conserved): at the supply's
temperature when positive, leaving at the chamber's when negative (with a temperature
state). A term that reads a port's flow modulates that port, its factor clipped where
the port's flow would reverse
(:data:`~pneubayes.effects.closure_terms.PORT_FACTOR_LIMITS`). The compiled
simulator evaluates it in
:func:`pneubayes.simulation.chamber.chamber_rhs`; :func:`pneubayes.simulation.rates.rate_terms`
gives its dp/dt at a given state and :mod:`pneubayes.simulation.reference` integrates it
independently. It cannot be combined with the tube's acoustic line; beside the wave tube
its terms may read every feature but the valve's ports
(:data:`~pneubayes.effects.closure_features.PORT_FEATURES`), which the tube puts at its
far end.

Every coefficient 0 lowers to ``closure_terms`` 0 (the simulator's closure-free path), so
the neutral closure reproduces the model without it bit for bit. The discovery library
never searches for it (no library terms): the open-form search proposes its terms.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.closure_features import feature
from pneubayes.effects.closure_terms import (
    Term,
    parse_terms,
    reads_ports,
)
from pneubayes.effects.path import CLOSURE_MAX_TERMS
from pneubayes.rig import Rig

#: The largest magnitude each feature typically takes on a rig (its unit): pressure
#: ratios up to 10, commands within +-10 (a hinge's reach up to 20; the null hinge's up
#: to 2), port areas up to 5 mm^2 (an area beyond a cap's threshold 0.5 mm^2, so that a
#: port's flux times it may take the coefficient +-1 that caps the port; a late valve's
#: area change likewise), port flows up to 1e-3 kg/s (and per mm^2 of area), volumes up
#: to 100 cm^3, relative volume rates up to 100 1/s, swept-volume speeds up to 100
#: cm^3/s, a command's lag 2 units (a lagged port's area then changes by up to 0.5 mm^2
#: per command unit within the bound). A coefficient's bound is
#: :data:`FLOW_BOUND_KG_PER_S` over the product of its features' magnitudes.
TYPICAL_MAGNITUDE: dict[str, float] = {
    "one": 1.0, "pressure_ratio": 10.0, "supply_ratio": 10.0, "spool": 10.0,
    "inlet_area": 5.0, "exhaust_area": 5.0, "inlet_flow": 1e-3, "exhaust_flow": 1e-3,
    "volume": 100.0, "volume_rate": 100.0, "pressure_hinge": 10.0, "spool_hinge_up": 20.0,
    "spool_hinge_down": 20.0, "net_flow": 1e-3, "pressure_hinge_down": 10.0,
    "command_direction": 1.0, "pressure_relaxation": 1.0, "volume_hinge_up": 100.0,
    "volume_hinge_down": 100.0, "net_flow_lag": 1e-3, "inlet_drop": 10.0,
    "inlet_drop_hinge": 3.0, "inlet_flux": 1e-3, "exhaust_flux": 1e-3,
    "spool_null_hinge": 2.0, "net_flux": 1e-3, "inlet_area_hinge": 0.5,
    "exhaust_area_hinge": 0.5, "command_lag": 2.0, "command_lag_fall": 2.0,
    "command_lag_rise": 2.0, "inlet_area_late_fall": 0.5, "exhaust_area_late_fall": 0.5,
    "inlet_area_late_rise": 0.5, "exhaust_area_late_rise": 0.5, "volume_speed": 100.0,
}
#: The largest closure flow a coefficient's bound allows at typical feature magnitudes,
#: kg/s (ten times a port's typical 1e-4 kg/s).
FLOW_BOUND_KG_PER_S = 1e-3
#: The bench's coefficient as a fraction of its bound (1e-5 kg/s for ``one``).
BENCH_FRACTION = 0.01
#: A hinge threshold's bounds, neutral (start) and bench value, by feature (its unit;
#: a relaxation's time constant in s, log-uniform between its bounds).
THRESHOLDS: dict[str, tuple[float, float, float, float]] = {
    "pressure_hinge": (1.0, 10.0, 5.5, 3.0),
    "spool_hinge_up": (-10.0, 10.0, 0.0, 2.0),
    "spool_hinge_down": (-10.0, 10.0, 0.0, -2.0),
    "pressure_hinge_down": (1.0, 10.0, 5.5, 3.0),
    "pressure_relaxation": (1e-3, 10.0, 0.1, 0.2),
    "volume_hinge_up": (0.0, 1000.0, 10.0, 3.0),
    "volume_hinge_down": (0.0, 1000.0, 10.0, 30.0),
    "net_flow_lag": (1e-3, 10.0, 0.1, 0.05),
    "inlet_drop_hinge": (0.0, 10.0, 0.5, 0.3),
    "spool_null_hinge": (0.0, 10.0, 1.0, 0.5),
    "inlet_area_hinge": (0.0, 100.0, 1.0, 0.3),
    "exhaust_area_hinge": (0.0, 100.0, 1.0, 0.3),
    "command_lag": (1e-4, 10.0, 0.01, 0.005),
    "command_lag_fall": (1e-4, 10.0, 0.01, 0.005),
    "command_lag_rise": (1e-4, 10.0, 0.01, 0.005),
    "inlet_area_late_fall": (1e-4, 1.0, 0.01, 0.005),
    "exhaust_area_late_fall": (1e-4, 1.0, 0.01, 0.005),
    "inlet_area_late_rise": (1e-4, 1.0, 0.01, 0.005),
    "exhaust_area_late_rise": (1e-4, 1.0, 0.01, 0.005),
}


class Closure(Effect):
    """An open-form extra mass flow into the chamber, ``sum_k c_k F_a F_b`` (kg/s).

    ``terms``: one to :data:`~pneubayes.effects.closure_terms.CLOSURE_MAX_TERMS`
    terms joined by ``"; "``, each a feature or two joined by ``"*"``
    (:func:`~pneubayes.effects.closure_terms.parse_terms`)."""

    name = "closure"
    acts_on: ClassVar[tuple[str, ...]] = (
        ("closure_terms",)
        + tuple(f"closure_{kind}_{k}" for kind in ("feature_a", "feature_b", "threshold_a",
                                                   "threshold_b", "coefficient")
                for k in range(CLOSURE_MAX_TERMS)))
    library_searched = False
    #: the simulator refuses a closure beside a tube's acoustic line (and the loop then
    #: proposes the tube's plain delay beside it)
    beside_line = False

    def beside_tube(self, form: str) -> bool:
        """Beside the wave tube when no term reads the valve's ports (which the tube puts
        at its far end); never beside the acoustic line."""
        return form == "wave" and not reads_ports(self.term_list())

    def __init__(self, terms: str = "one"):
        if not isinstance(terms, str):
            raise ValueError(f"closure: option 'terms' must be a string such as "
                             f"'inlet_flow*pressure_hinge; one', got {terms!r}")
        try:
            self._terms = parse_terms(terms)
        except ValueError as exc:
            raise ValueError(f"closure: option 'terms': {exc}") from None
        self.terms = "; ".join(str(t) for t in self._terms)

    def options(self):
        return {"terms": self.terms}

    def term_list(self) -> tuple[Term, ...]:
        """The parsed terms, in order (term k has ``closure_coefficient_{k}``)."""
        return self._terms

    def parameters(self):
        out = []
        for k, t in enumerate(self._terms):
            bound = FLOW_BOUND_KG_PER_S / (TYPICAL_MAGNITUDE[t.a] * TYPICAL_MAGNITUDE[t.b])
            out.append(Parameter(f"closure_coefficient_{k}", t.unit, -bound, bound, "uniform",
                                 f"closure term {k} ({t}): its coefficient c, the term's "
                                 "mass flow into the chamber being c F_a F_b", neutral=0.0))
            for side in t.hinges():
                f = feature(getattr(t, side))
                lo, hi, mid, _ = THRESHOLDS[f.name]
                what = ("time constant" if f.time_constant else "dead time" if f.dead_time
                        else "threshold")
                timed = f.time_constant or f.dead_time
                out.append(Parameter(f"closure_threshold_{k}_{side}", f.parameter_unit, lo,
                                     hi, "log-uniform" if timed else "uniform",
                                     f"closure term {k} ({t}): the {what} of its {f.name} "
                                     "feature (the term vanishes with its coefficient "
                                     f"whatever the {what})", neutral=mid))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        coefs = [np.asarray(values[f"closure_coefficient_{k}"], dtype=np.float64)
                 for k in range(len(self._terms))]
        # every coefficient 0: no closure at all (the simulator's closure-free path)
        active = np.any(np.stack(np.broadcast_arrays(*coefs)) != 0.0, axis=0)
        out = {"closure_terms": np.where(active, float(len(self._terms)), 0.0)}
        for k, t in enumerate(self._terms):
            out[f"closure_feature_a_{k}"] = float(feature(t.a).code)
            out[f"closure_feature_b_{k}"] = float(feature(t.b).code)
            out[f"closure_coefficient_{k}"] = coefs[k]
            for side in t.hinges():
                out[f"closure_threshold_{side}_{k}"] = np.asarray(
                    values[f"closure_threshold_{k}_{side}"], dtype=np.float64)
        return out

    def bench_defaults(self):
        """Each coefficient at :data:`BENCH_FRACTION` of its bound (1e-5 kg/s for a
        constant), each threshold at its bench value (e.g. 3 for a pressure hinge)."""
        out = {}
        for p in self.parameters():
            if p.name.startswith("closure_coefficient_"):
                out[p.name] = BENCH_FRACTION * p.upper
            else:
                side = p.name[-1]
                k = int(p.name.split("_")[2])
                out[p.name] = THRESHOLDS[getattr(self._terms[k], side)][3]
        return out
