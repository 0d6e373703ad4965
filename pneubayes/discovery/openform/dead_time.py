"""Whether the training recordings can tell a valve's dead time that depends on the
supply pressure (:class:`~pneubayes.effects.valve_dead_time.ValveDeadTime`) from a fixed
one: they can only where their nominal supplies differ.

A dead time's law in the supply is seen in how the command's delay changes from one
recording to the next; recordings at one supply see one delay, which a fixed delay of
the command or the tube's transit already carries. :class:`DeadTimeSearch` reads the
training blocks' nominal gauge supplies; where their spread reaches
``min_supply_spread`` it proposes the law from a generic start (a short dead time,
exponent 1/2: a moving part driven by a force proportional to the pressure) for the fit
through the simulator to move. It keeps no term of its own: the fit and the held-out
test decide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.inference.windows import WindowSet


@dataclass(frozen=True)
class DeadTimeTerm:
    """A proposed law: the dead time at the reference supply (s) and its exponent; the
    search explains nothing itself (``explained`` and ``t`` are 0)."""

    dead_time_s: float
    exponent: float
    explained: float = 0.0
    t: float = 0.0

    def __str__(self) -> str:
        return (f"dead time {1e3 * self.dead_time_s:.3g} ms x (p_ref / p_s)^"
                f"{self.exponent:.3g} (gauge supplies)")


class DeadTimeSearch:
    """Read the training recordings' nominal supplies (estimator contract: ``fit``
    returns self).

    Parameters
    ----------
    min_supply_spread : float
        The proposal needs the gauge supplies' range over their mean at least this.
    start_dead_time_s, start_exponent : float
        The generic start the proposal carries.

    Attributes
    ----------
    terms_, best_, explained_fraction_ : list, None, float
        Empty, None and 0 (after ``fit``, as every attribute here): the search keeps
        nothing of its own.
    supplies_gauge_Pa_ : ndarray
        The blocks' nominal gauge supplies, Pa.
    supply_spread_ : float
        Their range over their mean.
    proposal_ : DeadTimeTerm or None
        The generic start, or None where the spread is under ``min_supply_spread``.
    """

    def __init__(self, min_supply_spread: float = 0.05, start_dead_time_s: float = 0.002,
                 start_exponent: float = 0.5):
        self.min_supply_spread = min_supply_spread
        self.start_dead_time_s = start_dead_time_s
        self.start_exponent = start_exponent

    def get_params(self) -> dict:
        return {"min_supply_spread": self.min_supply_spread,
                "start_dead_time_s": self.start_dead_time_s,
                "start_exponent": self.start_exponent}

    def fit(self, windows: WindowSet) -> "DeadTimeSearch":
        """Read the nominal supplies of ``windows``' recordings."""
        if not self.min_supply_spread > 0:
            raise ValueError(f"DeadTimeSearch: min_supply_spread must be > 0, got "
                             f"{self.min_supply_spread!r}")
        gauge = np.array([b.rig.supply_pressure_Pa - b.rig.atmospheric_pressure_Pa
                          for b in windows.blocks])
        self.supplies_gauge_Pa_ = gauge
        self.supply_spread_ = float(np.ptp(gauge) / np.mean(gauge))  # (a Rig's is > 0)
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        self.proposal_ = (DeadTimeTerm(self.start_dead_time_s, self.start_exponent)
                          if self.supply_spread_ >= self.min_supply_spread else None)
        return self
