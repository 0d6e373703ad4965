"""Chamber kind ``polynomial``: a volume given as a polynomial of a measured coordinate,
``V(s) = V_0 + c_1 s + c_2 s^2 + ...`` (a McKibben muscle's volume against its
contraction, a bellows against its extension).

Card keys: ``dead_volume_m3`` (V_0, the volume at s = 0 with the tube included; known
or a prior), ``coefficients_m3_per_m`` ([c_1, c_2, ...] in m^3/m^k, known) and
``coordinate_range_m`` ([lower, upper], m; V must grow with s over it). The recording's
``position_m`` column carries the coordinate s.

The chamber is lowered as the equivalent piston of area ``c_1`` (an area: m^3 per m)
at the equivalent position ``x = s + (c_2/c_1) s^2 + ...``, so ``V_0 + c_1 x = V(s)``
exactly and the compiled simulator's volume and dV/dt terms of eq. 5 carry it unchanged.

``compliance_m3_per_Pa`` (optional, default 0; known or a prior) adds a volume that
grows with the pressure, ``C (p - P_atm)``, as the ``compliant`` kind's: a muscle
whose tendon in series stretches under its force contracts by more than its joint
moves (fitted as ``chamber_compliance_m3_per_Pa``).
"""

from __future__ import annotations

import math

import numpy as np

from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import real


@register
class PolynomialChamber(RigComponent):
    role, kind = "chamber", "polynomial"
    quantities = (("dead_volume_m3", "m^3", "volume at coordinate 0, tube included",
                   "positive"),
                  ("compliance_m3_per_Pa", "m^3/Pa", "volume change per pascal above the "
                   "atmosphere (a tendon in series that stretches)", "nonnegative"))
    defaults = {"compliance_m3_per_Pa": 0.0}
    parameter_names_by_key = {"compliance_m3_per_Pa": "chamber_compliance_m3_per_Pa"}
    slots_written = ("volume_m3", "compliance_m3_per_Pa")
    maps_position = True

    @classmethod
    def option_keys(cls):
        return ("coefficients_m3_per_m", "coordinate_range_m")

    @classmethod
    def read_options(cls, table, where):
        c = table.get("coefficients_m3_per_m")
        at = f"{where} key 'coefficients_m3_per_m'"
        if not isinstance(c, list) or not c:
            raise RigCardError(f"{at}: must be a non-empty list [c_1, c_2, ...] (m^3/m^k), "
                               f"got {c!r}")
        coeffs = [real(v, f"{at} [{i}]") for i, v in enumerate(c)]
        if not coeffs[0] > 0:
            raise RigCardError(f"{at} [0]: c_1 must be > 0 (the volume grows with the "
                               f"coordinate), got {coeffs[0]!r}")
        r = table.get("coordinate_range_m")
        at = f"{where} key 'coordinate_range_m'"
        if not (isinstance(r, list) and len(r) == 2):
            raise RigCardError(f"{at}: must be [lower, upper] (m), got {r!r}")
        lo, hi = real(r[0], at), real(r[1], at)
        if not lo < hi:
            raise RigCardError(f"{at}: lower {lo!r} must be below upper {hi!r}")
        return {"coefficients_m3_per_m": coeffs, "coordinate_range_m": [lo, hi]}

    def check(self, where):
        lo, hi = self.extra["coordinate_range_m"]
        s = np.linspace(lo, hi, 201)
        slope = np.polyval(np.polyder(self._poly()), s)
        if np.any(slope <= 0):
            bad = float(s[np.argmax(slope <= 0)])
            raise RigCardError(f"{where} key 'coefficients_m3_per_m': the volume must grow "
                               f"with the coordinate over coordinate_range_m, but dV/ds <= 0 "
                               f"at s = {bad:g} m")

    def _poly(self) -> np.ndarray:
        """Coefficients of V(s) - V_0, highest power first (numpy.polyval order)."""
        return np.array(list(reversed(self.extra["coefficients_m3_per_m"])) + [0.0])

    @property
    def area_m2(self) -> float:
        return float(self.extra["coefficients_m3_per_m"][0])

    def equivalent_position_m(self, coordinate_m) -> np.ndarray:
        """The equivalent piston's position ``(V(s) - V_0) / c_1``, m."""
        return np.polyval(self._poly(), np.asarray(coordinate_m, dtype=np.float64)) \
            / self.area_m2

    def lower_all(self, values, rig):
        return {"volume_m3": values["dead_volume_m3"],
                "compliance_m3_per_Pa": values["compliance_m3_per_Pa"]}

    def coordinate_range(self) -> tuple[float, float]:
        """The coordinate's declared range ``(lower, upper)``, m."""
        lo, hi = self.extra["coordinate_range_m"]
        return lo, hi

    def metadata_defaults(self):
        lo, hi = self.coordinate_range()
        return {"bore_m": math.sqrt(4.0 * self.area_m2 / math.pi),
                "stroke_m": float(self.equivalent_position_m(hi))}

    def bind_columns(self, recording, where):
        s = recording.position_m
        if s is None:
            raise RigCardError(f"{where}: chamber kind {self.kind!r} needs the coordinate in "
                               f"the recording's position column; {recording.source} has none")
        lo, hi = self.coordinate_range()
        span = hi - lo
        out = np.nonzero((s < lo - 0.05 * span) | (s > hi + 0.05 * span))[0]
        if out.size:
            i = int(out[0])
            raise RigCardError(f"{recording.source} row {i + 1}: coordinate {s[i]:g} m is "
                               f"outside the rig card's coordinate range [{lo:g}, {hi:g}] "
                               f"(5 % margin)")
        return {"position_m": self.equivalent_position_m(s)}
