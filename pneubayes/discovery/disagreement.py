"""Where the model and the recordings disagree: residuals binned by operating regime.

Two residuals are binned: the paper's 2-s open-loop prediction error (Pa) and the
one-step error (the dp/dt residual in integral form, reported in Pa/s). Every sample
gets a label in each regime family; per bin we report the count, the mean (bias), the
RMS, the RMS in excess of the noise floor, and a z score of the bias with a
cluster-robust standard error (clusters = 2-s windows or 1-s chunks), so that
autocorrelated residuals do not look significant. A bin is *flagged* when it stands out
from the rest of the residual, not merely from the noise (a model that misses
everywhere would otherwise flag every bin): its bias is significant (|z| > ``z_flag``)
and at least ``bias_share`` x the residual's overall RMS, or its RMS exceeds both
``excess_factor`` x the noise level and ``relative_factor`` x the overall RMS.

Regime families (issue 4): command band (inside/outside +-``band_V``); the dominant
port choked or subsonic; filling or exhausting; time since the last command step;
supply deviation from nominal; piston speed; pressure level.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pneubayes.effects.closure_histories import command_direction
from pneubayes.model import Model
from pneubayes.simulation.rates import rate_terms

FAMILIES = ("command band", "flow regime", "direction", "time since step",
            "supply deviation", "piston speed", "pressure level")


@dataclass(frozen=True)
class RegimeSettings:
    """Bin edges (SI units)."""

    band_V: float = 0.2
    step_edges_s: tuple[float, ...] = (0.005, 0.02, 0.1)
    supply_tolerance_Pa: float = 5_000.0
    speed_edges_m_per_s: tuple[float, ...] = (0.001, 0.02)
    z_flag: float = 3.0
    excess_factor: float = 1.5
    relative_factor: float = 1.2
    bias_share: float = 0.5


def regime_labels(model: Model, params: dict, recording, settings: RegimeSettings) -> dict:
    """Per-sample labels ``{family: array of str}`` for one recording."""
    t = np.asarray(recording.time_s, dtype=np.float64)
    u = np.asarray(recording.command_V, dtype=np.float64)
    p = np.asarray(recording.pressure_Pa, dtype=np.float64)
    x = recording.position_or_fixed()
    v = np.gradient(x, t)
    ps = recording.supply_or_nominal()
    rig = recording.rig()
    slots = model.lower(model.vector(params)[None], rig)[0]
    terms = rate_terms(slots, rig, np.maximum(p, 1.0), u, x, v, ps,
                       recording.exhaust_command(),
                       command_direction(u, recording.command_before_start), time_s=t)
    inlet_dominant = np.abs(terms.inlet) >= np.abs(terms.exhaust)
    choked = np.where(inlet_dominant, terms.inlet_choked, terms.exhaust_choked)
    net = terms.inlet + terms.exhaust + terms.leak
    switches = np.nonzero(np.diff(u) != 0)[0] + 1
    last = np.full(t.size, -np.inf)
    if switches.size:
        idx = np.searchsorted(switches, np.arange(t.size), side="right") - 1
        ok = idx >= 0
        last[ok] = t[switches[idx[ok]]]
    since = t - last
    e = settings.step_edges_s
    step_names = ([f"< {1e3 * e[0]:g} ms"]
                  + [f"{1e3 * a:g}-{1e3 * b:g} ms" for a, b in zip(e[:-1], e[1:])]
                  + [f"> {1e3 * e[-1]:g} ms"])
    dev = ps - rig.supply_pressure_Pa
    tol = settings.supply_tolerance_Pa
    se = settings.speed_edges_m_per_s
    speed_names = ["still", "slow", "fast"]
    frac = (p - rig.atmospheric_pressure_Pa) / rig.working_range_Pa
    card = recording.rig_card
    unit = "V" if card is None else card.command.unit
    if unit == "binary":
        band = np.where(u <= 0.5, "closed (u = 0)", "open (u = 1)")
    else:  # the band's width in the command's own unit
        band = np.where(np.abs(u) <= settings.band_V, f"|u| <= {settings.band_V:g} {unit}",
                        f"|u| > {settings.band_V:g} {unit}")
    return {
        "command band": band,
        "flow regime": np.where(choked, "choked", "subsonic"),
        "direction": np.where(net >= 0, "filling", "exhausting"),
        "time since step": np.array(step_names)[np.searchsorted(np.array(e), since)],
        "supply deviation": np.where(dev < -tol, "below nominal",
                                     np.where(dev > tol, "above nominal", "near nominal")),
        "piston speed": np.array(speed_names)[np.searchsorted(np.array(se), np.abs(v))],
        "pressure level": np.where(frac < 1 / 3, "low", np.where(frac < 2 / 3, "mid", "high")),
    }


def _bins(residual: np.ndarray, labels: dict, cluster: np.ndarray, noise: float,
          settings: RegimeSettings) -> dict:
    out = {}
    overall = float(np.sqrt(np.mean(residual * residual))) if residual.size else 0.0
    for fam in FAMILIES:
        lab = labels[fam]
        rows = []
        for name in dict.fromkeys(lab.tolist()):
            m = lab == name
            r = residual[m]
            n = int(m.sum())
            mean = float(r.mean())
            rms = float(np.sqrt(np.mean(r * r)))
            cl = cluster[m]
            uniq, inv = np.unique(cl, return_inverse=True)
            sums = np.bincount(inv, weights=r - mean)
            se = float(np.sqrt(np.sum(sums**2))) / n if uniq.size > 1 else float("inf")
            z = mean / se if se > 0 else 0.0
            excess = float(np.sqrt(max(rms**2 - noise**2, 0.0)))
            rows.append({"bin": name, "n": n, "mean": mean, "rms": rms, "excess_rms": excess,
                         "z_bias": z, "clusters": int(uniq.size),
                         "flagged": bool(
                             (abs(z) > settings.z_flag
                              and abs(mean) >= settings.bias_share * overall)
                             or (rms > settings.excess_factor * noise
                                 and rms > settings.relative_factor * overall))})
        out[fam] = sorted(rows, key=lambda d: _physical_order(d["bin"]))
    return out


#: Bins of the word-labelled families, in physical order.
_WORD_ORDER = {name: k for k, name in enumerate((
    "still", "slow", "fast", "low", "mid", "high", "below nominal", "near nominal",
    "above nominal", "choked", "subsonic", "filling", "exhausting", "closed (u = 0)",
    "open (u = 1)"))}


def _physical_order(name: str) -> tuple:
    """Sort key of a bin label: numeric ranges by their value ("< 5 ms", "5-20 ms",
    "> 100 ms"; "|u| <= 0.1 V" before "|u| > 0.1 V"), word bins in physical order."""
    if name in _WORD_ORDER:
        return (0, _WORD_ORDER[name], 0)
    m = re.match(r"\s*(<=|>=|<|>)?\s*([0-9.]+(?:[eE][+-]?[0-9]+)?)", name.replace("|u|", ""))
    if m is None:
        return (1, 0, name)
    side = {"<": -2, "<=": -1, None: 0, ">=": 1, ">": 2}[m.group(1)]
    return (0, float(m.group(2)), side)


def disagreement_map(model: Model, params: dict, recordings, prediction_residuals,
                     window_starts, horizon_samples: int, one_step_errors,
                     noise_floor_Pa: float, settings: RegimeSettings) -> dict:
    """Bin both residuals of ``recordings`` by regime.

    ``prediction_residuals[i]`` ``(W_i, L)`` are the window prediction errors of
    recording i for windows starting at ``window_starts[i]``; ``one_step_errors[i]``
    ``(N_i - 1,)`` its one-step errors (Pa). Returns ``{"prediction": {...}, "rate":
    {...}}`` (families -> bins) plus the noise levels used and ``horizon_s`` (the
    windows' length, s).
    """
    pr, pl, pc, rr, rl, rc = [], [], [], [], [], []
    dt_all = []
    cluster_base = 0
    for i, rec in enumerate(recordings):
        lab = regime_labels(model, params, rec, settings)
        res = np.asarray(prediction_residuals[i])
        idx = np.asarray(window_starts[i])[:, None] + np.arange(horizon_samples)[None, :]
        idx, res = idx[:, 1:], res[:, 1:]  # window starts are measured, not predicted
        pr.append(res.ravel())
        pl.append({f: lab[f][idx.ravel()] for f in FAMILIES})
        pc.append(cluster_base + np.repeat(np.arange(res.shape[0]), res.shape[1]))
        cluster_base += res.shape[0]
        t = np.asarray(rec.time_s)
        dt = float(np.median(np.diff(t)))
        dt_all.append(dt)
        e = np.asarray(one_step_errors[i]) / dt
        rr.append(e)
        rl.append({f: lab[f][1:] for f in FAMILIES})
        rc.append(cluster_base + (np.arange(e.size) * dt // 1.0).astype(np.int64))
        cluster_base += int(e.size * dt // 1.0) + 1

    def cat(parts):
        return {f: np.concatenate([p[f] for p in parts]) for f in FAMILIES}

    rate = np.concatenate(rr)
    dt = float(np.median(dt_all))
    rate_noise = float(np.sqrt(2.0) * noise_floor_Pa / dt)
    return {
        "noise_floor_Pa": noise_floor_Pa, "rate_noise_Pa_per_s": rate_noise,
        "horizon_s": (horizon_samples - 1) * dt,
        "prediction": _bins(np.concatenate(pr), cat(pl), np.concatenate(pc), noise_floor_Pa,
                            settings),
        "rate": _bins(rate, cat(rl), np.concatenate(rc), rate_noise, settings),
    }


def flagged_bins(dmap: dict, kind: str = "prediction") -> list[tuple[str, dict]]:
    """The flagged bins of one residual, strongest excess first."""
    out = [(fam, b) for fam, bins in dmap[kind].items() for b in bins if b["flagged"]]
    return sorted(out, key=lambda fb: fb[1]["excess_rms"], reverse=True)
