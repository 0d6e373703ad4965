"""What a found term on the chamber's volume does, for the report's figure: the volume it
adds along the final model's pressure on the training recordings, against that pressure
(a hinge's curve, a friction-held wall's loop, a loaded wall's ringing lag).

Each training recording is simulated by the final model in one window from its first
sample; a hinge adds ``C_k max(0, p - theta_k)``, a wall ``C_k (w_k - P_atm)`` with
``w_k`` the play of the simulated pressure of half-width ``r_k`` from rest at its first
sample (as the simulator starts a recording's walls), a loaded wall ``C x`` with ``x``
the simulated pressure's response through the wall, from rest at its first sample.
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.volume_closure import compliance_name, threshold_name
from pneubayes.effects.volume_play import compliance_name as wall_compliance_name
from pneubayes.effects.volume_play import half_width_name, held_compliance_name
from pneubayes.simulation import Inputs, simulate
from pneubayes.simulation.loaded_wall import wall_advance
from pneubayes.simulation.reading_play import play_series


def volume_views(model, params: dict, recordings, solver) -> list[dict]:
    """One view per found term of ``model``'s volume closure or volume play at
    ``params``: ``term``, ``formula``, and per training recording its simulated
    ``pressure_Pa`` and the term's added ``volume_m3`` along it (lists of arrays)."""
    terms = []
    if model.has("volume_closure"):
        for k in range(model.effect("volume_closure").terms):
            c, th = params[compliance_name(k)], params[threshold_name(k)]
            terms.append((f"hinge {k}", f"{c * 1e11:.3g} cm^3/bar above {th / 1e5:.4g} bar",
                          lambda p, p_atm, t, c=c, th=th: c * np.maximum(0.0, p - th)))
    if model.has("volume_play"):
        for k in range(model.effect("volume_play").terms):
            c, r = params[wall_compliance_name(k)], params[half_width_name(k)]
            h = params[held_compliance_name(k)]
            terms.append((f"wall {k}", f"{c * 1e11:.3g} cm^3/bar past a "
                          f"{2 * r / 1e5:.3g}-bar band, {h * 1e11:.3g} cm^3/bar inside it",
                          lambda p, p_atm, t, c=c, r=r, h=h: _wall_volume(p, p_atm, c, r,
                                                                          h)))
    if model.has("loaded_wall"):
        c, f, z = (params[n] for n in ("loaded_wall_compliance", "loaded_wall_frequency",
                                       "loaded_wall_damping"))
        terms.append(("loaded wall", f"{c * 1e11:.3g} cm^3/bar ringing at {f:.3g} Hz, "
                      f"damping ratio {z:.2g}",
                      lambda p, p_atm, t, c=c, f=f, z=z: c * _loaded_wall_x(p - p_atm, t, f,
                                                                             z)))
    if not terms:
        raise ValueError("volume_views: the model has no volume closure, volume play or "
                         "loaded wall")
    runs = [(simulate(model, params, Inputs.from_recording(rec), rec.rig(),
                      float(rec.pressure_Pa[0]), solver).pressure_Pa[0],
             rec.rig().atmospheric_pressure_Pa, np.asarray(rec.time_s, np.float64))
            for rec in recordings]
    return [{"term": name, "formula": formula, "pressure_Pa": [p for p, _, _ in runs],
             "volume_m3": [added(p, p_atm, t) for p, p_atm, t in runs]}
            for name, formula, added in terms]


def _wall_volume(p, p_atm, c, r, h):
    """A wall's added volume (m^3) along the pressure ``p`` (Pa): ``C (w - P_atm) + H (p -
    w)``, ``w`` its play from ``p[0]``."""
    w = play_series(p, r, p[0])
    return c * (w - p_atm) + h * (p - w)


def _loaded_wall_x(y, t, f, z):
    """A loaded wall's displacement (Pa) along the gauge pressure ``y`` (Pa) at times
    ``t`` (s), from rest under ``y[0]``, the pressure linear between samples."""
    w = 2.0 * np.pi * f
    x, v = float(y[0]), 0.0
    out = np.empty(y.size)
    out[0] = x
    for i in range(1, y.size):
        x, v = wall_advance(x, v, float(y[i - 1]), float(y[i]), float(t[i] - t[i - 1]), w, z)
        out[i] = x
    return out
