"""Compiled parts of the volume play (effect ``volume_play``): a chamber wall whose give
is held by friction.

Play k adds ``C_k (w_k - P_atm) + H_k (p - w_k)`` to the chamber's volume, its state
``w_k`` the play operator of the chamber pressure p with half-width ``r_k``: w_k holds
while ``|p - w_k| < r_k`` and moves with p, ``r_k`` behind it, once p pushes past. Given
w_k, the volume is a piecewise-linear function of p: growing with slope H_k (the held
wall's give) inside ``[w_k - r_k, w_k + r_k]`` and with slope C_k (the sliding wall's)
beyond either edge, which is exactly the play's volume for as long as p keeps moving one
way. The simulator lays that function onto its tabulated volume (slots
``volume_table_*``, read by :func:`pneubayes.simulation.chamber.compliant_volume`, whose
step and sensitivity already handle a table's kinks) on its own copy of the slots, with
w_k at its *anchor* (slot ``volume_play_anchor_Pa_k``). After each accepted step
:func:`play_accept` looks for a play that was sliding and whose pressure turned back: it
anchors it where the table's play stands at the step's end (so the volume is
continuous) and lays the table again. The turn is thus placed at the end of the step on
which it happened (the first step after a valve switch is short).

A window starts each play where the recorded reading's play puts it (from rest at the
recording's first sample) and then within its half-width of the window's start
pressure; without a recorded reading, at the start pressure (:func:`play_start`).
"""

from __future__ import annotations

import math

from numba import njit

from pneubayes.effects.path import SLOT_INDEX, VOLUME_PLAY_MAX_TERMS

_VT_N = SLOT_INDEX["volume_table_points"]
_VT_P = SLOT_INDEX["volume_table_pressure_Pa_0"]
_VT_V = SLOT_INDEX["volume_table_volume_m3_0"]
_C = SLOT_INDEX["volume_play_compliance_m3_per_Pa_0"]
_H = SLOT_INDEX["volume_play_held_compliance_m3_per_Pa_0"]
_R = SLOT_INDEX["volume_play_half_width_Pa_0"]
_A = SLOT_INDEX["volume_play_anchor_Pa_0"]
#: How far the table's outer points lie beyond its edges, Pa (the end segments extend).
PLAY_TABLE_MARGIN_PA = 1e4
#: Two edges this close (Pa) are moved apart to keep the table's points increasing.
PLAY_MIN_GAP_PA = 1e-3
#: A play counts as sliding where p is beyond its edge by more than this share of r_k.
SLIDING_TOLERANCE = 1e-9


@njit(cache=True, error_model="numpy")
def play_on(sl) -> bool:
    """Whether a parameter set carries a volume play (a compliance that is not 0)."""
    for k in range(VOLUME_PLAY_MAX_TERMS):
        if _term_on(sl, k):
            return True
    return False


@njit(cache=True, error_model="numpy")
def _term_on(sl, k) -> bool:
    """Whether play ``k`` gives at all (its sliding or its held compliance not 0)."""
    return sl[_C + k] != 0.0 or sl[_H + k] != 0.0


@njit(cache=True, error_model="numpy")
def _play_volume(sl, q, p_atm):
    """The plays' volume (m^3) at pressure ``q`` (Pa) with every play at its anchor."""
    v = 0.0
    for k in range(VOLUME_PLAY_MAX_TERMS):
        if _term_on(sl, k):
            a, r = sl[_A + k], sl[_R + k]
            w = min(max(a, q - r), q + r)
            v += sl[_C + k] * (w - p_atm) + sl[_H + k] * (q - w)
    return v


@njit(cache=True, error_model="numpy")
def play_table(sl, p_atm) -> None:
    """Lay the plays' volume at their anchors onto the slots' volume table: every edge
    ``a_k -+ r_k`` a point (sorted), one point beyond each end."""
    n = 0
    for k in range(VOLUME_PLAY_MAX_TERMS):
        if _term_on(sl, k):
            for side in (-1.0, 1.0):
                q = sl[_A + k] + side * sl[_R + k]
                i = n + 1  # insertion sort into points 1..n
                while i > 1 and sl[_VT_P + i - 1] > q:
                    sl[_VT_P + i] = sl[_VT_P + i - 1]
                    i -= 1
                sl[_VT_P + i] = q
                n += 1
    for i in range(2, n + 1):
        if sl[_VT_P + i] < sl[_VT_P + i - 1] + PLAY_MIN_GAP_PA:
            sl[_VT_P + i] = sl[_VT_P + i - 1] + PLAY_MIN_GAP_PA
    sl[_VT_P] = sl[_VT_P + 1] - PLAY_TABLE_MARGIN_PA
    sl[_VT_P + n + 1] = sl[_VT_P + n] + PLAY_TABLE_MARGIN_PA
    sl[_VT_N] = n + 2
    for i in range(n + 2):
        sl[_VT_V + i] = _play_volume(sl, sl[_VT_P + i], p_atm)


@njit(cache=True, error_model="numpy")
def play_start(sl, pm, k0, p, p_atm) -> None:
    """Anchor every play at the window's start, sample ``k0`` at pressure ``p`` (Pa): the
    play of the recorded reading ``pm`` (NaN: unknown) over samples ``0..k0``, from rest
    at its first known one (none known: at ``p``), then moved to within its half-width
    of ``p``; and lay the table."""
    for k in range(VOLUME_PLAY_MAX_TERMS):
        if not _term_on(sl, k):
            continue
        r = sl[_R + k]
        w = math.nan
        for i in range(k0 + 1):
            if math.isfinite(pm[i]):
                w = pm[i] if math.isnan(w) else min(max(w, pm[i] - r), pm[i] + r)
        if math.isnan(w):
            w = p
        sl[_A + k] = min(max(w, p - r), p + r)
    play_table(sl, p_atm)


@njit(cache=True, error_model="numpy")
def play_accept(sl, p_prev, p, p_atm) -> bool:
    """After a step from ``p_prev`` to ``p`` (Pa): anchor each play that was sliding at
    ``p_prev`` and turned back where its table's play stands at ``p``; True where the
    table was laid again (rates computed before it are stale)."""
    relaid = False
    for k in range(VOLUME_PLAY_MAX_TERMS):
        if not _term_on(sl, k):
            continue
        a, r = sl[_A + k], sl[_R + k]
        tol = SLIDING_TOLERANCE * r
        if (p_prev > a + r + tol and p < p_prev) or (p_prev < a - r - tol and p > p_prev):
            sl[_A + k] = min(max(a, p - r), p + r)
            relaid = True
    if relaid:
        play_table(sl, p_atm)
    return relaid
