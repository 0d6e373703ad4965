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
