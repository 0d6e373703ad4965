"""Stage: the catalogue's untried groups, while the held-out error is above the noise
floor but not far above it and nothing (or little) passed."""

from __future__ import annotations

from pneubayes.discovery.stages.last_resort import LastResort
from pneubayes.discovery.state import RoundState


class CatalogueSweep(LastResort):
    """The last resort nearer the noise floor: below its zone (:meth:`RoundState.far`)
    and above ``min_noise_ratio`` x the noise floor, when no trial of the round passed or
    the best that passed closes under ``best_gap_closed`` of the gap, fit and verify the
    catalogue's groups the round has not tried, in the order of the search's evidence
    (ledger action ``catalogue sweep``).

    Beside a larger effect a small one (a clearance leak beside a spool lag or a tube)
    can fall under the search's inclusion threshold once the larger is added: its signal
    is a slow drift the one-step residual barely shows. Without this stage such a round
    supports nothing and the loop stops above the noise, or an open-form stage (which
    runs from 1.5 x) absorbs the effect in generic terms. The catalogue stays the first
    resort: the open form then competes with what passed here.

    Parameters
    ----------
    min_noise_ratio : float
        The stage runs while the held-out RMSE exceeds this x the noise floor (>= 1).
    min_gap_closed : float
        Share of the held-out RMSE's gap above the noise floor a group must close: a
        missing catalogue effect near the noise closes most of what is left, a stand-in
        a part of it.
    best_gap_closed : float
        The stage also runs when the best passing trial closes less than this share
        (0: only when none passed).
    """

    name = "catalogue_sweep"
    action = "catalogue sweep"

    def __init__(self, min_noise_ratio: float = 1.1, min_gap_closed: float = 0.5,
                 best_gap_closed: float = 0.25):
        if not min_noise_ratio >= 1.0:
            raise ValueError(f"CatalogueSweep: min_noise_ratio must be >= 1, got "
                             f"{min_noise_ratio}")
        super().__init__(min_gap_closed, best_gap_closed)  # (checks the two shares)
        self.min_noise_ratio = min_noise_ratio

    def options(self):
        return {"min_noise_ratio": self.min_noise_ratio, **super().options()}

    def _in_zone(self, state: RoundState) -> bool:
        """Above ``min_noise_ratio`` x the noise floor, not far above it."""
        return (state.current.heldout_rmse_Pa > self.min_noise_ratio * state.noise_Pa
                and not state.far())

    def opens_empty_round(self, state: RoundState) -> bool:
        return self._in_zone(state)
