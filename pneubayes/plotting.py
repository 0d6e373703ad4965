"""Figures. The only module of pneubayes that imports matplotlib (lazily, Agg backend)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_predictions(time_s, measured_Pa, predictions: Mapping[str, np.ndarray], path,
                     title: str = "", command_V=None, position_m=None) -> Path:
    """Measured pressure against named predictions (kPa), with the command below."""
    plt = _pyplot()
    rows = 2 if command_V is not None else 1
    fig, axes = plt.subplots(rows, 1, figsize=(10, 3.2 * rows + 0.6), sharex=True,
                             squeeze=False, height_ratios=[3, 1][:rows])
    ax = axes[0, 0]
    ax.plot(time_s, np.asarray(measured_Pa) / 1e3, color="0.55", lw=0.8, label="measured")
    for name, p in predictions.items():
        ax.plot(time_s, np.asarray(p) / 1e3, lw=1.1, label=name)
    ax.set_ylabel("pressure (kPa abs)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title, fontsize=10)
    if command_V is not None:
        ax2 = axes[1, 0]
        ax2.step(time_s, command_V, where="post", lw=0.8, color="k")
        ax2.set_ylabel("command (V)")
        if position_m is not None:
            ax3 = ax2.twinx()
            ax3.plot(time_s, np.asarray(position_m) * 1e3, color="tab:cyan", lw=0.8)
            ax3.set_ylabel("position (mm)", color="tab:cyan")
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _save(fig, path) -> Path:
    plt = _pyplot()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_area_bands(model, samples, path, rig, n_draws: int = 300) -> Path:
    """Port area against command with 90 % posterior bands (the paper's Fig. 5a), over
    the command range a rig card declares (else -5..+5 V)."""
    from pneubayes.simulation.rates import port_areas

    plt = _pyplot()
    x = np.asarray(samples)[:: max(1, len(samples) // n_draws)]
    card = model.rig_card
    lo_u, hi_u, unit = ((-5.0, 5.0, "V") if card is None else
                        (card.command.lower, card.command.upper, card.command.unit))
    u = np.linspace(lo_u, hi_u, 201)
    slots = model.lower(x, rig)
    # a separate exhaust valve's area against its own command on the same axis
    areas = np.array([port_areas(row, u, u) for row in slots]) * 1e6  # (draws, 2, u)
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for k, (port, color) in enumerate((("inlet", "tab:blue"), ("exhaust", "tab:red"))):
        if not np.any(areas[:, k]):
            continue
        lo, med, hi = np.quantile(areas[:, k], [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(u, lo, hi, color=color, alpha=0.3, lw=0)
        ax.plot(u, med, color=color, label=f"{port} (median, 90 % band)")
    ax.set_xlabel(f"command ({unit})")
    ax.set_ylabel("port area (mm$^2$)")
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_volume_map(model, samples, bore_m: float, stroke_m: float, path) -> Path:
    """Chamber volume against position with its 90 % band (the paper's Fig. 5b)."""
    plt = _pyplot()
    v0 = np.asarray(samples)[:, list(model.parameter_names).index("dead_volume_m3")]
    x = np.linspace(0, stroke_m, 50)
    area = np.pi / 4 * bore_m**2
    vols = (v0[:, None] + area * x[None, :]) * 1e6
    lo, med, hi = np.quantile(vols, [0.05, 0.5, 0.95], axis=0)
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.fill_between(x * 1e3, lo, hi, alpha=0.3, lw=0)
    ax.plot(x * 1e3, med)
    ax.set_xlabel("piston position (mm)")
    ax.set_ylabel("chamber volume (cm$^3$)")
    ax.set_title(f"dead volume {np.median(v0) * 1e6:.3g} cm$^3$ "
                 f"[{np.quantile(v0, 0.05) * 1e6:.3g}, {np.quantile(v0, 0.95) * 1e6:.3g}]",
                 fontsize=9)
    return _save(fig, path)


def _display_scale(values) -> int:
    """The power of 1000 that brings the values' median magnitude to 0.1-1000."""
    m = float(np.nanmedian(np.abs(values)))
    if not np.isfinite(m) or m == 0.0:
        return 0
    return int(3 * np.floor(np.log10(m) / 3))


def plot_corner(names, samples, path, max_points: int = 2000, title: str = "",
                units=None, reference=None) -> Path:
    """Pairwise scatter and marginal histograms of posterior draws.

    Each parameter is shown in a power of 1000 of its unit (written in its label), few
    ticks per axis and rotated labels, so nothing overlaps; the posterior median is a
    dashed line in every panel, and ``reference`` values (e.g. a planted truth or a
    point estimate; NaN for none) a red line.

    Parameters
    ----------
    names : sequence of str
        Parameter names, one per column of ``samples``.
    samples : (S, D) array
        Posterior draws.
    path : path
        Where the PNG goes.
    max_points : int
        Draws thinned to at most this many.
    title : str
        Figure title.
    units : sequence of str or None
        Each parameter's unit (None: none written).
    reference : sequence of float or None
        Values to mark (NaN: none for that parameter).

    Returns
    -------
    Path
    """
    from matplotlib.ticker import MaxNLocator

    plt = _pyplot()
    x = np.asarray(samples, dtype=np.float64)
    x = x[:: max(1, len(x) // max_points)]
    d = len(names)
    exps = [_display_scale(x[:, i]) for i in range(d)]
    scale = np.array([10.0 ** -e for e in exps])
    x = x * scale
    med = np.median(x, axis=0)
    ref = (np.full(d, np.nan) if reference is None
           else np.asarray(reference, dtype=np.float64) * scale)
    units = [""] * d if units is None else list(units)
    labels = [f"{n}\n({'' if e == 0 else f'x 1e{e} '}{u})".replace("()", "")
              for n, e, u in zip(names, exps, units)]
    size = max(1.9 * d if d <= 6 else 1.25 * d + 4.0, 4.0)
    fig = plt.figure(figsize=(size, size))
    grid = fig.add_gridspec(d, d)
    for i in range(d):
        for j in range(i + 1):  # the lower triangle only: the upper one stays empty
            ax = fig.add_subplot(grid[i, j])
            ax.xaxis.set_major_locator(MaxNLocator(3))
            ax.yaxis.set_major_locator(MaxNLocator(3))
            if i == j:
                ax.hist(x[:, i], bins=30, color="0.4")
                ax.axvline(med[i], color="tab:blue", lw=0.8, ls="--")
                if np.isfinite(ref[i]):
                    ax.axvline(ref[i], color="tab:red", lw=0.8)
                ax.set_yticks([])
            else:
                ax.plot(x[:, j], x[:, i], ",", alpha=0.4, color="k")
                ax.axvline(med[j], color="tab:blue", lw=0.6, ls="--")
                ax.axhline(med[i], color="tab:blue", lw=0.6, ls="--")
                if np.isfinite(ref[j]) and np.isfinite(ref[i]):
                    ax.plot(ref[j], ref[i], "s", color="tab:red", ms=3)
            ax.tick_params(labelsize=5)
            ax.xaxis.get_offset_text().set_fontsize(5)
            ax.yaxis.get_offset_text().set_fontsize(5)
            if i == d - 1:
                ax.set_xlabel(labels[j], fontsize=6, rotation=20, ha="right")
                ax.xaxis.set_label_coords(0.5, -0.45)  # aligned along the bottom row
                ax.tick_params(axis="x", labelrotation=45)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(labels[i], fontsize=6, rotation=70, ha="right")
                ax.yaxis.set_label_coords(-0.45, 0.5)  # aligned along the first column
            elif i != j:
                ax.set_yticklabels([])
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)


#: A model with at most this many parameters has them all in its corner plot.
CORNER_ALL_MAX = 16


def corner_names(model) -> list[str]:
    """The parameters a fit's corner plot shows: all of them up to
    :data:`CORNER_ALL_MAX`, else the Gompertz scales and slopes, the dead volume and
    every effect's parameters (the fitted additions)."""
    if len(model.parameter_names) <= CORNER_ALL_MAX:
        return list(model.parameter_names)
    base = ("inlet_a_m2", "inlet_c_per_V", "exhaust_a_m2", "exhaust_c_per_V",
            "dead_volume_m3")
    if model.rig_card is not None:  # a rig card's unknowns are few: show them all
        base = tuple(p.name for c in model.base for p in c.parameters())
    effects = [p.name for e in model.effects for p in e.parameters()]
    return [n for n in model.parameter_names if n in base or n in effects]


def plot_fit_figures(model, samples, recordings, folder, idata=None) -> list[Path]:
    """The figures of a fit run: area bands, volume map, corner plot."""
    folder = Path(folder)
    rec = recordings[0]
    names = corner_names(model)
    cols = [list(model.parameter_names).index(n) for n in names]
    out = [plot_area_bands(model, samples, folder / "areas.png", rec.rig())]
    if "dead_volume_m3" in model.parameter_names and model.rig_card is None:
        out.append(plot_volume_map(model, samples, rec.metadata.bore_m,
                                   rec.metadata.stroke_m, folder / "volume.png"))
    base = ("the thin-port model" if model.rig_card is None
            else f"the rig card {model.rig_card.name!r}")
    out.append(plot_corner(names, np.asarray(samples)[:, cols], folder / "corner.png",
                           title="posterior of " + (" + ".join(model.effect_names) or base)
                           + " (dashed: medians)",
                           units=[model.parameter(n).unit for n in names]))
    return out


def plot_prediction_bands(bands, path, max_windows: int = 3, title: str = "") -> Path:
    """Measured pressure against the posterior-predictive mean and 90 % band (Figs. 7-10),
    and below each window the residual (measured - mean) with the band drawn around it,
    where a band narrower than the signal's scale can be seen."""
    plt = _pyplot()
    w = min(max_windows, bands.mean.shape[0])
    fig, axes = plt.subplots(2 * w, 1, figsize=(9, 3.6 * w), squeeze=False,
                             height_ratios=[2, 1] * w)
    for k in range(w):
        ax, res = axes[2 * k, 0], axes[2 * k + 1, 0]
        t = bands.time_s[k]
        mean = bands.mean[k]
        ax.fill_between(t, bands.q05[k] / 1e3, bands.q95[k] / 1e3, alpha=0.3, lw=0,
                        color="tab:blue", label="90 % predictive band")
        ax.plot(t, bands.measured[k] / 1e3, color="k", lw=0.7, label="measured")
        ax.plot(t, mean / 1e3, lw=1.0, ls="--", color="tab:orange", label="posterior mean")
        ax.set_ylabel("kPa abs", fontsize=8)
        ax.set_xticklabels([])
        res.fill_between(t, (bands.q05[k] - mean) / 1e3, (bands.q95[k] - mean) / 1e3,
                         alpha=0.3, lw=0, color="tab:blue")
        res.plot(t, (bands.measured[k] - mean) / 1e3, color="k", lw=0.6)
        res.axhline(0.0, color="tab:orange", lw=0.8, ls="--")
        res.set_ylabel("residual (kPa)", fontsize=8)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=9)
    return _save(fig, path)


def plot_disagreement(dmap: Mapping, path, title: str = "") -> Path:
    """Residual RMS per operating-regime bin (window prediction and dp/dt), flagged bins
    highlighted, the noise level as a line."""
    plt = _pyplot()
    fams = list(dmap["prediction"])
    horizon = dmap.get("horizon_s")
    window = "prediction" if horizon is None else f"{horizon:.3g}-s prediction"
    fig, axes = plt.subplots(2, len(fams), figsize=(2.1 * len(fams), 5.2), squeeze=False)
    for row, (kind, noise, unit, scale) in enumerate(
            (("prediction", dmap["noise_floor_Pa"], "kPa", 1e-3),
             ("rate", dmap["rate_noise_Pa_per_s"], "MPa/s", 1e-6))):
        for col, fam in enumerate(fams):
            ax = axes[row, col]
            bins = dmap[kind][fam]
            names = [b["bin"] for b in bins]
            rms = [b["rms"] * scale for b in bins]
            colors = ["tab:red" if b["flagged"] else "tab:gray" for b in bins]
            ax.bar(range(len(bins)), rms, color=colors)
            ax.axhline(noise * scale, color="k", lw=0.8, ls="--")
            ax.set_xticks(range(len(bins)))
            ax.set_xticklabels(names, rotation=60, ha="right", fontsize=6)
            ax.tick_params(axis="y", labelsize=6)
            if row == 0:
                ax.set_title(fam, fontsize=7)
            if col == 0:
                ax.set_ylabel(f"{window if kind == 'prediction' else 'dp/dt'} "
                              f"RMS ({unit})", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=8)
    return _save(fig, path)


def plot_evidence(searches, path) -> Path:
    """Bagged inclusion probability of every candidate group, one panel per round."""
    plt = _pyplot()
    n = len(searches)
    fig, axes = plt.subplots(1, max(n, 1), figsize=(3.2 * max(n, 1), 2.8), squeeze=False)
    for k, s in enumerate(searches):
        ax = axes[0, k]
        groups = s["ranking"]
        p = [s["evidence"][g]["inclusion_probability"] for g in groups]
        ax.barh(range(len(groups)), p, color="tab:blue")
        ax.set_yticks(range(len(groups)))
        ax.set_yticklabels(groups, fontsize=7)
        ax.invert_yaxis()
        ax.set_xlim(0, 1.05)
        ax.set_xlabel("inclusion probability", fontsize=7)
        ax.set_title(f"round {s['round']}: model + {', '.join(s['model']) or 'nothing'}",
                     fontsize=7)
    return _save(fig, path)


def plot_found_reading_terms(views, path) -> Path:
    """Each term of the reading (a relaxation against ``p - p_bar``, a port flow term
    against its feature) beside the reading the model misses without it (binned means
    with standard errors; :func:`pneubayes.discovery.openform.reading_view.reading_views`,
    :func:`pneubayes.discovery.openform.flow_view.flow_views`). A view's variable is
    drawn in kPa, or in its ``unit`` where it gives an ``x_scale``."""
    plt = _pyplot()
    n = len(views)
    fig, axes = plt.subplots(1, max(n, 1), figsize=(3.4 * max(n, 1), 3.0), squeeze=False)
    for k, v in enumerate(views):
        ax = axes[0, k]
        x = np.asarray(v["bin_centre"]) / v.get("x_scale", 1e3)
        ax.errorbar(x, np.asarray(v["missing_Pa"]) / 1e3,
                    yerr=np.asarray(v["missing_sem_Pa"]) / 1e3, fmt="o", ms=3,
                    color="tab:gray", label="missing without it")
        ax.plot(x, np.asarray(v["term_Pa"]) / 1e3, "-", color="tab:red", label="the term")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{v['variable']} ({v['unit'] if 'x_scale' in v else 'kPa'})",
                      fontsize=7)
        ax.set_ylabel("reading, measured - predicted (kPa)", fontsize=7)
        ax.set_title(f"{v['formula']}\nexplains {100 * v['explained_fraction']:.0f} % of "
                     "the missing reading's sum of squares", fontsize=7)
        ax.tick_params(labelsize=6)
        if k == 0:
            ax.legend(fontsize=6)
    return _save(fig, path)


def plot_found_volume_terms(views, path) -> Path:
    """Each found term on the chamber's volume: the volume it adds against the simulated
    pressure along the training recordings (a hinge's curve, a wall's loop;
    :func:`pneubayes.discovery.openform.volume_view.volume_views`)."""
    plt = _pyplot()
    n = len(views)
    fig, axes = plt.subplots(1, max(n, 1), figsize=(3.4 * max(n, 1), 3.0), squeeze=False)
    for k, v in enumerate(views):
        ax = axes[0, k]
        for p, vol in zip(v["pressure_Pa"], v["volume_m3"]):
            ax.plot(np.asarray(p) / 1e5, np.asarray(vol) * 1e6, "-", lw=0.6)
        ax.set_xlabel("chamber pressure (bar absolute)", fontsize=7)
        ax.set_ylabel("added volume (cm^3)", fontsize=7)
        ax.set_title(f"{v['term']}: {v['formula']}", fontsize=7)
        ax.tick_params(labelsize=6)
    return _save(fig, path)


def plot_found_terms(views, path) -> Path:
    """Each open-form term's mass flow against its main variable, beside the mass flow
    the model misses without it (binned means with standard errors;
    :func:`pneubayes.discovery.openform.term_view.term_views`)."""
    plt = _pyplot()
    n = len(views)
    fig, axes = plt.subplots(1, max(n, 1), figsize=(3.4 * max(n, 1), 3.0), squeeze=False)
    for k, v in enumerate(views):
        ax = axes[0, k]
        x = np.asarray(v["bin_centre"])
        scale = 1e6  # kg/s -> mg/s
        ax.errorbar(x, np.asarray(v["missing_kg_per_s"]) * scale,
                    yerr=np.asarray(v["missing_sem_kg_per_s"]) * scale, fmt="o", ms=3,
                    color="tab:gray", label="missing without the term")
        ax.plot(x, np.asarray(v["term_kg_per_s"]) * scale, "-", color="tab:red",
                label="the term")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{v['variable']} ({v['unit']})", fontsize=7)
        ax.set_ylabel("mass flow into the chamber (mg/s)", fontsize=7)
        ax.set_title(f"{v['formula']}\nexplains {100 * v['explained_fraction']:.0f} % of "
                     "the missing flow's sum of squares", fontsize=7)
        ax.tick_params(labelsize=6)
        if k == 0:
            ax.legend(fontsize=6)
    return _save(fig, path)
