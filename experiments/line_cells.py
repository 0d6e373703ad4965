"""How many cells the acoustic line needs: the lumped line of n cells fitted to a finer
one (issue 22, item 1).

    python experiments/line_cells.py --out results/line_cells [--seed 3] [--quick]

The bench plant's AcousticTube of 8 cells (an independent implementation, LSODA) feeds
a chamber through a tube of 1 m (AIR200 and SMC) and 2.5 m (SMC), 2 mm bore, under a
seeded random-step command (holds of 30-300 ms, +-5 V) and a 2-Hz piston motion; its
pressure, noise-free and sampled at 1 kHz, is the data. For each n the model's line
form (``tube_delay``, form ``line``) is scored on 2-s windows from each window's measured
start: at the true transit time, bore and dead volume, and after a least-squares fit
of those three from the truth (the valve and the rest known). Reported: the RMSE (Pa)
at the truth and fitted, and the fitted transit time / true (a tube's length is this
ratio times the true length), per rig, tube length and cell count.

A lumped line identifies its transit time short when it has fewer cells than the tube
it stands for (its waves travel with the wrong dispersion, which a shorter line
offsets), so a length or an interval read from a coarse line is biased: on the
staggered grid (seed 3) by 3-4 % with 3 cells and under 1 % with 6; lumped at each
cell's upstream end, as before commit a177704, by 11 % with 3 cells. Seed recorded
in OUT/line_cells.json (written atomically).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.forms import AcousticTube
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.effects import make_effect
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.provenance import provenance
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate_windows

P_ATM, P_SUP = 101325.0, 551325.0
FINE_S, SAMPLE_S, WINDOW = 1e-4, 1e-3, 2001
#: (rig, bore m, stroke m, plant dead volume m^3, tube length m)
CASES = (("AIR200", 0.009, 0.2, 1.5e-7, 1.0), ("SMC", 0.016, 0.1, 2e-6, 1.0),
         ("SMC", 0.016, 0.1, 2e-6, 2.5))
CELLS = (3, 4, 5, 6, 8)


def case_data(bore, stroke, volume, length, duration_s, seed):
    """(rig, inputs at 1 kHz, measured pressure, plant parameters, the tube)."""
    rig = Rig(bore, P_ATM, P_SUP, stroke_m=stroke)
    t = np.arange(int(round(duration_s / FINE_S)) + 1) * FINE_S
    rng = np.random.default_rng(seed)
    holds = rng.integers(30, 300, 400) * int(round(SAMPLE_S / FINE_S))
    u = np.repeat(rng.uniform(-5.0, 5.0, 400), holds)[:t.size]
    x = 0.5 * stroke + 0.3 * stroke * np.sin(2 * np.pi * 2.0 * t)
    base = dict(valve_preset("valve2").parameters(), dead_volume_m3=volume)
    tube = AcousticTube(length, 0.002, 8)
    plant = simulate_plant(base, (tube,), Inputs(t, u, x, np.full(t.size, P_SUP)), rig,
                           P_ATM, PlantConfig.reference()).pressure_Pa
    k = slice(None, None, int(round(SAMPLE_S / FINE_S)))
    inputs = Inputs(t[k], u[k], x[k], np.full(t[k].size, P_SUP))
    return rig, inputs, plant[k], base, tube


def score(cells, rig, inputs, measured, base, tube):
    """RMSE at the truth and fitted, and the fitted (transit, bore, volume) / true."""
    model = Model([make_effect("tube_delay", form="line", segments=cells)])
    starts = np.arange(0, inputs.n_samples - WINDOW + 1, WINDOW - 1)
    want = np.stack([measured[s:s + WINDOW] for s in starts])
    transit = tube.transit_time_s(rig.gas)
    volume = base["dead_volume_m3"] + tube.volume_m3

    def residual(scale):
        params = dict(base, tube_delay_s=scale[0] * transit,
                      tube_diameter_m=scale[1] * tube.diameter_m,
                      dead_volume_m3=scale[2] * volume)
        sim = simulate_windows(model, params, inputs, rig, starts, WINDOW, measured[starts],
                               SolverConfig.standard())[0]
        return (sim - want).ravel()

    at_truth = residual(np.ones(3))
    fit = least_squares(residual, np.ones(3), bounds=([0.3] * 3, [3.0] * 3), diff_step=1e-4,
                        max_nfev=60)
    return {"cells": cells, "rmse_true_parameters_Pa": float(np.sqrt(np.mean(at_truth**2))),
            "rmse_fitted_Pa": float(np.sqrt(np.mean(fit.fun**2))),
            "fitted_over_true": {"transit_time": float(fit.x[0]), "bore": float(fit.x[1]),
                                 "dead_volume": float(fit.x[2])}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="results folder")
    ap.add_argument("--seed", type=int, default=3, help="command seed (default 3)")
    ap.add_argument("--quick", action="store_true", help="4 s of data, 3 and 8 cells")
    args = ap.parse_args(argv)
    duration = 4.0 if args.quick else 6.0
    cells = (3, 8) if args.quick else CELLS
    rows = []
    for rig_name, bore, stroke, volume, length in CASES:
        data = case_data(bore, stroke, volume, length, duration, args.seed)
        for n in cells:
            row = {"rig": rig_name, "tube_length_m": length, **score(n, *data)}
            rows.append(row)
            print(f"{rig_name} {length:g} m, {n} cells: RMSE {row['rmse_true_parameters_Pa']:.0f}"
                  f" Pa at the truth, {row['rmse_fitted_Pa']:.0f} Pa fitted; transit time "
                  f"fitted / true {row['fitted_over_true']['transit_time']:.3f}", flush=True)
    write_json_atomic(Path(args.out) / "line_cells.json",
                      {"seed": args.seed, "duration_s": duration, "plant_cells": 8,
                       "rows": rows, "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
