"""Shared by the real-recording experiments: which recordings train and which are held
out (``--data``, ``--held-out``), the plain model's refit and the figure of measured
pressure against the plain model and the discovered model's posterior band."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pneubayes.inference.pipeline import load_posterior
from pneubayes.inference.predictive import PosteriorPredictive
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import SolverConfig, simulate_windows
from pneubayes.simulation.drive import Inputs


def add_split_arguments(ap, data: Path, held_out: tuple, what: str) -> None:
    """``--data`` (default ``data``) and ``--held-out NAME`` (repeatable; default
    ``held_out``) on the parser ``ap``; ``what`` names a held-out unit in the help (a
    trial, a run). Every recording not held out trains."""
    ap.add_argument("--data", default=str(data),
                    help=f"the imported recordings (default {data})")
    ap.add_argument("--held-out", action="append", default=None, metavar="NAME",
                    help=f"a {what} held out whole (repeatable; default "
                         f"{', '.join(held_out)}); every other {what} trains")


def split_held_out(items, names, key, where: str, prefix: bool = False) -> tuple:
    """``(train, held)``: ``items`` whose ``key(item)`` is one of ``names`` (or, with
    ``prefix``, starts with one: a trial folder named with its date) are held out, the
    rest train. A name that matches nothing, or a split that leaves nothing to train on
    or nothing held out, stops with an error naming ``where`` and the names there."""
    names = tuple(names)
    keys = [key(i) for i in items]

    def held(k):
        return k.startswith(names) if prefix else k in names

    unmatched = [n for n in names
                 if not any((k.startswith(n) if prefix else k == n) for k in keys)]
    if unmatched:
        raise SystemExit(f"{where}: --held-out {', '.join(unmatched)} matches no recording "
                         f"there (they are: {', '.join(sorted(set(keys)))})")
    train = [i for i, k in zip(items, keys) if not held(k)]
    out = [i for i, k in zip(items, keys) if held(k)]
    if not train or not out:
        raise SystemExit(f"{where}: holding out {', '.join(names)} leaves "
                         + ("nothing to train on" if not train else "nothing held out"))
    return train, out


def added_names(doc: dict) -> list[str]:
    """What a discovery document added to the model: the named effects, the stand-ins
    kept at a bound (marked), and the open-form terms' components."""
    out = [e["name"] for e in doc["effects"]]
    out += [f"{e['name']} (stand-in)" for e in doc.get("stand_ins", [])]
    if doc.get("found_terms"):
        out.append("closure")
    if doc.get("found_reading_terms"):
        out.append("reading relaxation")
    for t in doc.get("found_volume_terms", []):
        out.append(f"volume {t['term']}")
    if doc.get("found_command_terms"):
        out.append("driver clock")
    if doc.get("found_port_terms"):
        out.append("port restriction")
    return out


def plain_fit(train, horizon_s: float, solver: SolverConfig, max_nfev: int = 60) -> dict:
    """The rig card's plain model refined on the training windows from the card's start
    (the discovery loop's base fit, repeated here to draw it)."""
    model = Model(rig_card=train[0].rig_card)
    ws = WindowSet(train, horizon_s, horizon_s)
    return TrajectoryRefiner(model, solver, max_nfev=max_nfev).fit(
        ws, model.base_start_values()).params_


def prediction_figure(recs, plain_params: dict, run_dir: Path, horizon_s: float,
                      path: Path, title: str, seed: int, n_draws: int = 200):
    """Per held-out recording: measured pressure (gauge kPa), the plain model's windowed
    prediction, and the discovered model's posterior-predictive mean and 90 % band.

    Returns ``(path, metrics)``: the posterior predictive's held-out RMSE (of its mean),
    its 90 % coverage and band width against sensor noise, pooled over the windows."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(seed)
    model, draws, noise = load_posterior(run_dir, n_draws, rng)
    pred = PosteriorPredictive(model, draws, noise, SolverConfig.standard())
    plain = Model(rig_card=recs[0].rig_card)
    fig, axes = plt.subplots(len(recs), 1, figsize=(9, 2.2 * len(recs)), squeeze=False)
    sq, inside, n, widths, floors = 0.0, 0, 0, [], []
    for ax, rec in zip(axes[:, 0], recs):
        b = pred.bands(rec, horizon_s, horizon_s, rng)
        y = b.measured[:, 1:]
        sq += float(np.sum((b.mean[:, 1:] - y) ** 2))
        inside += int(np.sum((y >= b.q05[:, 1:]) & (y <= b.q95[:, 1:])))
        n += y.size
        widths.append(float(np.median(b.q95[:, 1:] - b.q05[:, 1:])))
        floors.append(b.noise_floor_Pa)
        atm = rec.metadata.atmospheric_pressure_Pa
        base = simulate_windows(plain, plain_params, Inputs.from_recording(rec), rec.rig(),
                                b.starts, b.mean.shape[1],
                                rec.pressure_Pa[b.starts], SolverConfig.standard())[0]
        for w in range(b.starts.size):
            t = b.time_s[w]
            ax.fill_between(t, (b.q05[w] - atm) / 1e3, (b.q95[w] - atm) / 1e3,
                            color="tab:blue", alpha=0.3, lw=0,
                            label="after discovery: 90 % band" if w == 0 else None)
            ax.plot(t, (b.mean[w] - atm) / 1e3, color="tab:blue", lw=1.0,
                    label="after discovery: mean" if w == 0 else None)
            ax.plot(t, (base[w] - atm) / 1e3, color="tab:orange", lw=1.0, ls="--",
                    label="plain model" if w == 0 else None)
        ax.plot(rec.time_s, (rec.pressure_Pa - atm) / 1e3, color="k", lw=0.7,
                label="measured")
        ax.set_ylabel("kPa gauge", fontsize=8)
        ax.set_title(Path(str(rec.source)).parent.name + "/" + Path(str(rec.source)).stem,
                     fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="upper left")
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    width = float(np.median(widths))
    metrics = {"posterior_mean_rmse_Pa": float(np.sqrt(sq / n)),
               "coverage_90": inside / n, "band_90_width_Pa": width,
               "band_90_width_over_sensor_noise":
                   width / (2 * 1.645 * float(np.median(floors))),
               "n_draws": int(draws.shape[0])}
    return path, metrics
