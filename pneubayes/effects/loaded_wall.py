"""An open-form term on the chamber's volume with inertia: a wall that carries a load.

A flexible part of the chamber (a soft finger's skin with its payload, a bellows
pushing a sprung mass, a pneumatic muscle pulling a limb through a tendon) gives as a
mass on a spring driven by the gauge pressure, so the volume lags the pressure and
rings::

    V = V_0 + C x,    x'' + 2 z w x' + w^2 x = w^2 (p - P_atm),

``x`` (Pa) the gauge pressure the wall would be at rest under. ``C``
(``loaded_wall_compliance``, m^3/Pa) is the wall's static give per pascal, ``w / 2 pi``
(``loaded_wall_frequency``, Hz) its natural frequency with the load and ``z``
(``loaded_wall_damping``) its damping ratio; an overdamped wall (``z`` well above 1) is a
creep of the volume after the pressure with time constant ``2 z / w``. Eq. 5 reads the
wall's ``C dx/dt`` as a moving piston's ``dV/dt``. Compliance 0 is the chamber without
it, whatever the frequency and the damping.

The simulator steps the wall beside the pressure (:mod:`pneubayes.simulation.loaded_wall`)
on a rigid chamber, with or without the tube's transmission line (form ``"wave"``) or
heat transfer; not beside a compliant chamber, a volume closure or play, the acoustic
line, a supply tank or a second compartment. A window's wall starts where the recorded
reading's history leaves it. The discovery library never searches for it: the open-form
stage on the volume (:class:`~pneubayes.discovery.stages.loaded_wall_form.LoadedWallForm`)
proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig

#: The compliance's bounds, m^3/Pa (up to 100 cm^3 per bar: as the volume closure's).
COMPLIANCE_BOUNDS_M3_PER_PA = (0.0, 1e-9)
#: The natural frequency's bounds and start, Hz.
FREQUENCY_BOUNDS_HZ = (0.3, 300.0)
FREQUENCY_START_HZ = 10.0
#: The damping ratio's bounds and start.
DAMPING_BOUNDS = (0.03, 10.0)
DAMPING_START = 0.3

COMPLIANCE = "loaded_wall_compliance"
FREQUENCY = "loaded_wall_frequency"
DAMPING = "loaded_wall_damping"


class LoadedWall(Effect):
    """A chamber wall carrying a load: ``V = V_0 + C x``, ``x'' + 2 z w x' + w^2 x = w^2
    (p - P_atm)`` (``loaded_wall_compliance`` C m^3/Pa, ``loaded_wall_frequency`` w / 2 pi
    Hz, ``loaded_wall_damping`` z)."""

    name = "loaded_wall"
    acts_on = ("loaded_wall_compliance_m3_per_Pa", "loaded_wall_frequency_Hz",
               "loaded_wall_damping_ratio")
    library_searched = False
    cheap_forms = True
    beside_line = False

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) or terms != 1:
            raise ValueError(f"loaded_wall: option 'terms' must be 1 (one wall), got "
                             f"{terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def beside_tube(self, form: str) -> bool:
        """The transmission-line tube (``"wave"``) steps the wall's moving volume; the
        acoustic line's cells (``"line"``) do not."""
        return form == "wave"

    def parameters(self):
        return (
            Parameter(COMPLIANCE, "m^3/Pa", *COMPLIANCE_BOUNDS_M3_PER_PA, "uniform",
                      "loaded wall: the chamber's added volume per pascal of gauge "
                      "pressure once the wall has settled", neutral=0.0),
            Parameter(FREQUENCY, "Hz", *FREQUENCY_BOUNDS_HZ, "log-uniform",
                      "loaded wall: its natural frequency with its load (the term "
                      "vanishes with its compliance whatever its frequency)",
                      neutral=FREQUENCY_START_HZ),
            Parameter(DAMPING, "-", *DAMPING_BOUNDS, "log-uniform",
                      "loaded wall: its damping ratio (above 1: a creep without a ring)",
                      neutral=DAMPING_START),
        )

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        return {"loaded_wall_compliance_m3_per_Pa": np.asarray(values[COMPLIANCE], np.float64),
                "loaded_wall_frequency_Hz": np.asarray(values[FREQUENCY], np.float64),
                "loaded_wall_damping_ratio": np.asarray(values[DAMPING], np.float64)}

    def bench_defaults(self):
        """A wall giving 1 cm^3 per bar that rings at 12 Hz, damping ratio 0.25."""
        return {COMPLIANCE: 1e-11, FREQUENCY: 12.0, DAMPING: 0.25}
