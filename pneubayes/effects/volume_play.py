"""An open-form term on the chamber's volume with memory: a wall whose give is held by
friction.

The volume closure (:mod:`pneubayes.effects.volume_closure`) makes the chamber's volume a
function of its pressure. A wall that is held by friction (a braided sleeve on its
bladder, a rolling diaphragm, a bellows guided in a bore, a hose in its clamps) gives
only once the pressure has moved far enough to overcome the friction, and then follows
it; when the pressure turns back it holds again until the pressure has crossed the
friction band. Its volume over the pressure is a rate-independent loop, which no
function of the pressure is. This component adds ``K`` such walls (a Prandtl-Ishlinskii
sum of plays and stops)::

    V = V_0 + sum_k [C_k (w_k - P_atm) + H_k (p - w_k)],
    w_k = play of p with half-width r_k

(w_k holds while ``|p - w_k| < r_k``; beyond, it moves with p at ``r_k`` behind it).
``C_k`` (``volume_play_compliance_{k}``, m^3/Pa) is the wall's give per pascal once it
slides, ``H_k`` (``volume_play_held_compliance_{k}``, m^3/Pa) its give while friction
holds it, ``r_k`` (``volume_play_half_width_{k}``, Pa) the pressure change that frees it.
``H_k = 0`` is a play (a wall that gives only once freed); ``C_k = 0`` a stop (an elastic
give that saturates at ``H_k r_k`` and re-anchors where the pressure turns: a loop that
turns at the full rate and flattens near its memory, as a rubber sleeve with internal
friction); ``H_k = C_k`` a linear compliance whatever the half-width. Eq. 5 reads ``dp/dt
= n (Rs T mdot - p vdot) / (V + n p dV/dp)`` with ``dV/dp`` the sum of ``C_k`` over the
sliding walls and ``H_k`` over the held ones. Every compliance 0 is the chamber without
the component, whatever the half-widths; both non-negative keep the volume growing with
the pressure.

The simulator lays the plays onto its tabulated volume as it steps
(:mod:`pneubayes.simulation.volume_play`), so the component cannot be combined with a
volume closure, heat transfer, the tube's acoustic line (form ``"line"``; its
transmission line, ``"wave"``, carries it), a supply tank or a second compartment. A
window's walls start where the recorded reading's play leaves them. The discovery library
never searches for it: the open-form stage on the volume
(:class:`~pneubayes.discovery.stages.volume_form.VolumePlayForm`) proposes it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.path import VOLUME_PLAY_MAX_TERMS
from pneubayes.rig import Rig

#: A compliance's bounds, m^3/Pa (up to 100 cm^3 per bar: as the volume closure's).
COMPLIANCE_BOUNDS_M3_PER_PA = (0.0, 1e-9)
#: The play's kinds the search tries: a wall that gives once freed, a give that saturates.
KINDS = ("play", "stop")
#: A half-width's bounds and start, Pa.
HALF_WIDTH_BOUNDS_PA = (300.0, 3e5)
HALF_WIDTH_START_PA = 2e4


def compliance_name(k: int) -> str:
    """Play ``k``'s compliance parameter."""
    return f"volume_play_compliance_{k}"


def half_width_name(k: int) -> str:
    """Play ``k``'s half-width parameter."""
    return f"volume_play_half_width_{k}"


def held_compliance_name(k: int) -> str:
    """Play ``k``'s held compliance parameter (its give while friction holds it)."""
    return f"volume_play_held_compliance_{k}"


class VolumePlay(Effect):
    """``terms`` friction-held walls of the chamber, ``V = V_0 + sum_k [C_k (w_k - P_atm)
    + H_k (p - w_k)]`` with ``w_k`` the play of the pressure of half-width ``r_k``
    (``volume_play_compliance_{k}``, ``volume_play_held_compliance_{k}``,
    ``volume_play_half_width_{k}``)."""

    name = "volume_play"
    acts_on = tuple(f"volume_play_{what}_{k}" for what in ("compliance_m3_per_Pa",
                                                           "held_compliance_m3_per_Pa",
                                                           "half_width_Pa")
                    for k in range(VOLUME_PLAY_MAX_TERMS))
    library_searched = False
    cheap_forms = True
    beside_line = False

    def __init__(self, terms: int = 1):
        if isinstance(terms, bool) or not isinstance(terms, int) \
                or not 1 <= terms <= VOLUME_PLAY_MAX_TERMS:
            raise ValueError(f"volume_play: option 'terms' must be an integer in "
                             f"1..{VOLUME_PLAY_MAX_TERMS}, got {terms!r}")
        self.terms = terms

    def options(self):
        return {"terms": self.terms}

    def beside_tube(self, form: str) -> bool:
        """The transmission-line tube (``"wave"``) steps a compliant chamber; the
        acoustic line's cells (``"line"``) do not."""
        return form == "wave"

    def parameters(self):
        out = []
        for k in range(self.terms):
            out.append(Parameter(compliance_name(k), "m^3/Pa", *COMPLIANCE_BOUNDS_M3_PER_PA,
                                 "uniform", f"volume play {k}: the chamber's added volume "
                                 "per pascal while its wall slides", neutral=0.0))
            out.append(Parameter(half_width_name(k), "Pa", *HALF_WIDTH_BOUNDS_PA,
                                 "log-uniform", f"volume play {k}: the pressure change that "
                                 "frees the held wall (the term vanishes with its "
                                 "compliance whatever its half-width)",
                                 neutral=HALF_WIDTH_START_PA))
            out.append(Parameter(held_compliance_name(k), "m^3/Pa",
                                 *COMPLIANCE_BOUNDS_M3_PER_PA, "uniform",
                                 f"volume play {k}: the chamber's added volume per pascal "
                                 "while its wall is held (0: a play; with the compliance "
                                 "0: a stop)", neutral=0.0))
        return tuple(out)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        out = {}
        for k in range(self.terms):
            out[f"volume_play_compliance_m3_per_Pa_{k}"] = np.asarray(
                values[compliance_name(k)], np.float64)
            out[f"volume_play_half_width_Pa_{k}"] = np.asarray(values[half_width_name(k)],
                                                               np.float64)
            out[f"volume_play_held_compliance_m3_per_Pa_{k}"] = np.asarray(
                values[held_compliance_name(k)], np.float64)
        return out

    def bench_defaults(self):
        """A wall that gives 0.5 cm^3 per bar while held and 2 cm^3 per bar once 0.3 bar
        has freed it (a second, nearly a stop: 1 cm^3 per bar while held, 0.2 once freed
        1 bar past where it stuck)."""
        out = {compliance_name(0): 2e-11, half_width_name(0): 3e4,
               held_compliance_name(0): 5e-12}
        if self.terms > 1:
            out.update({compliance_name(1): 2e-12, half_width_name(1): 1e5,
                        held_compliance_name(1): 1e-11})
        return out
