"""A valve whose ports choke at their own critical pressure ratio (ISO 6358's ``b``).

Eq. 3 is the isentropic nozzle: a port chokes where the pressure ratio ``r = p_d / p_u``
falls to ``1 / theta`` (0.528 for air). Real valves do not: their passages lose
pressure before the throat, and a datasheet rates each flow path by a sonic conductance
and a critical pressure ratio ``b`` of 0.2-0.45 (ISO 6358-1). The flow stays choked
(``beta p_u`` per unit area, eq. 3's) down to ``r = b`` and falls more gradually above
it. This effect lays eq. 3's subsonic curve over ``[b, 1]``: the ratio is mapped
linearly, ``r' = 1/theta + (r - b) (1 - 1/theta) / (1 - b)``, and eq. 3 read at ``r'``
(:func:`pneubayes.physics.orifice.z_terms`). The shape is within 0.3 % of ISO 6358's
ellipse ``sqrt(1 - ((r - b) / (1 - b))^2)`` (subsonic index 1/2) at every ratio; at
``b = 1/theta`` it is eq. 3 to rounding, so a trial of it contains the model without it.
The Gompertz areas stay the ports' choked areas (their sonic conductances).

ISO 6358 also rates a subsonic index ``m`` (1/2 for most valves): form ``iso6358`` raises
the subsonic flow's share of the choked one to ``2 m`` (``subsonic_index``, 1/2 neutral),
which bends the curve's tail as a port nears pressure balance.

Form ``shared`` (the first): one ratio ``critical_ratio`` for both ports; form ``ports``:
``inlet_critical_ratio`` and ``exhaust_critical_ratio``; form ``iso6358``: those and
``subsonic_index`` (one for both ports). The leak keeps eq. 3. The simulator steps it
beside every form but a supply tank and the restrictions at the port or upstream of the
inlet.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import TrialTerm
from pneubayes.rig import Rig

#: Eq. 3's critical ratio for air (heat capacity ratio 1.4): the neutral value.
ISENTROPIC_RATIO = (2.0 / 2.4) ** 3.5
#: The ratio's bounds (-).
RATIO_BOUNDS = (0.05, 0.9)
#: The subsonic index's bounds (-; ISO 6358-1 rates valves at 0.3-0.8).
INDEX_BOUNDS = (0.2, 1.0)

_SLOTS = ("inlet_critical_ratio", "exhaust_critical_ratio")


class CriticalRatio(Effect):
    """The valve's ports choked at their own critical pressure ratio (ISO 6358's
    ``b``), eq. 3's subsonic curve laid over the rest."""

    name = "critical_ratio"
    acts_on = (*_SLOTS, "port_subsonic_index")
    forms = ("shared", "ports", "iso6358")
    cheap_forms = True
    library_strengths = (0.3,)
    discovery_fallback = {"critical_ratio": 0.35}

    def __init__(self, form: str = "shared"):
        self.form = form
        self._check()

    def options(self):
        return {} if self.form == "shared" else {"form": self.form}

    def parameters(self):
        def ratio(name, what):
            return Parameter(name, "-", *RATIO_BOUNDS, "uniform",
                             f"{what} critical pressure ratio p_d / p_u (ISO 6358's b; "
                             "eq. 3's 0.528 for air)", neutral=ISENTROPIC_RATIO)
        if self.form == "shared":
            return (ratio("critical_ratio", "the valve's ports'"),)
        ports = (ratio("inlet_critical_ratio", "the inlet's"),
                 ratio("exhaust_critical_ratio", "the exhaust's"))
        if self.form == "ports":
            return ports
        return ports + (Parameter("subsonic_index", "-", *INDEX_BOUNDS, "uniform",
                                  "the ports' subsonic index m (ISO 6358; 1/2 eq. 3's "
                                  "shape)", neutral=0.5),)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        if self.form == "shared":
            b = np.asarray(values["critical_ratio"], np.float64)
            return {"inlet_critical_ratio": b, "exhaust_critical_ratio": b}
        out = {s: np.asarray(values[s], np.float64) for s in _SLOTS}
        if self.form == "iso6358":
            out["port_subsonic_index"] = np.asarray(values["subsonic_index"], np.float64)
        return out

    def bench_defaults(self):
        """A valve rated at b = 0.3 (the middle of catalogued valves' 0.2-0.45) and m =
        0.5."""
        return {n: 0.5 if n == "subsonic_index" else 0.3 for n in self.parameter_names()}

    def library_terms(self, strengths):
        """The model with both ports choked at each trial ratio (the regression's signed
        coefficient reads a ratio on either side of eq. 3's)."""
        return tuple(TrialTerm(f"critical ratio {b:g}", {"critical_ratio": b},
                               values={n: b for n in self.parameter_names()
                                       if n != "subsonic_index"})
                     for b in strengths)

    def candidate_forms(self, ctx):
        """One ratio for both ports, then each port's own, then with the subsonic index
        (each from the last one's fit: :meth:`form_after_fit`)."""
        if self.form != "shared":
            return [(self, {})]
        return [(self, self.candidate_start(ctx.term_start))]

    def form_after_fit(self, params, ctx):
        """Form ``ports`` from the shared ratio's fit; ``iso6358`` from the ports'."""
        if self.form == "shared" and "critical_ratio" in params:
            b = float(params["critical_ratio"])
            return CriticalRatio(form="ports"), {s: b for s in _SLOTS}
        if self.form == "ports":
            return CriticalRatio(form="iso6358"), {**{s: float(params[s]) for s in _SLOTS},
                                                   "subsonic_index": 0.5}
        return None
