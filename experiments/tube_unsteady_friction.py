"""A line's unsteady friction: the wave tube's shear against the plant's, and its size.

    python experiments/tube_unsteady_friction.py --out results/tube_unsteady_friction

Two cases, each simulated by the bench's plant (a 48-cell ``AcousticTube``, LSODA) with
the quasi-steady shear alone and with Zielke's unsteady wall shear
(``unsteady_friction`` 0 and 1), and by the model's wave tube (8 elements, reference
solver) with the weight ``tube_unsteady_friction`` at 0, 0.5, 1 and 1.5:

- ``on/off fill``: a 1.88-m x 4-mm line (GTDynamics' documented tube) into 4.24e-5 m^3
  from 80 psi gauge through a 3e-6 m^2 on/off valve open for 60 ms, 0.15 s at 10 kHz;
- ``random steps``: valve 1 of Table II under random commands in +-5 V held 40-200 ms
  (seed 1), a 2.4-m x 4-mm line into 5e-5 m^3 at half stroke, 2 s at 1 kHz.

For each: the RMS difference between the two plant lines (what the shear changes), each
wave weight's RMS error against either line (Pa), and the weight fitted alone (bounded
scalar search over 0-3) on either line. Deterministic. Writes
OUT/tube_unsteady_friction.json (atomically).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.forms import AcousticTube
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.bench.protocols import step_commands
from pneubayes.effects import make_effect
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.provenance import provenance
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate

P_ATM = 101_325.0
BORE_M = 0.009
WEIGHTS = (0.0, 0.5, 1.0, 1.5)
CELLS = 48
#: An on/off valve: both Gompertz terms shut within +-1.5 V, the inlet wide open at 5 V.
ON_OFF = {"inlet_offset_m2": 0.0, "inlet_a_m2": 3e-6, "inlet_b": 3.5, "inlet_c_per_V": 20.0,
          "inlet_d_V": -3.0, "exhaust_offset_m2": 0.0, "exhaust_a_m2": 6e-7,
          "exhaust_b": 3.5, "exhaust_c_per_V": -20.0, "exhaust_d_V": 3.0}


def on_off_fill():
    """``(rig, inputs, base parameters, p0, length, bore)`` of the on/off fill."""
    p_sup = P_ATM + 80 * 6894.757
    t = np.arange(1501) * 1e-4
    inputs = Inputs(t, np.where(t < 0.06, 5.0, 0.0), np.full(t.size, 0.01),
                    np.full(t.size, p_sup))
    return (Rig(BORE_M, P_ATM, p_sup), inputs, dict(ON_OFF, dead_volume_m3=4.24e-5),
            P_ATM + 2e4, 1.88, 0.004)


def random_steps():
    """The same for valve 1's random steps."""
    p_sup = 551_325.0
    t = np.arange(2001) * 1e-3
    u = step_commands(t, np.random.default_rng(1), 5.0, hold_s=(0.04, 0.2), clock_s=1e-3)
    inputs = Inputs(t, u, np.full(t.size, 0.01875), np.full(t.size, p_sup))
    return (Rig(BORE_M, P_ATM, p_sup), inputs,
            dict(valve_preset("valve1").parameters(), dead_volume_m3=5e-5), P_ATM, 2.4, 0.004)


def run_case(name, case) -> dict:
    rig, inputs, base, p0, length, bore = case
    plant = {w: simulate_plant(base, (AcousticTube(length, bore, segments=CELLS,
                                                   unsteady_friction=w),),
                               inputs, rig, p0, PlantConfig.reference()).pressure_Pa
             for w in (0.0, 1.0)}
    tube = AcousticTube(length, bore)
    params = dict(base, tube_delay_s=tube.transit_time_s(rig.gas), tube_diameter_m=bore,
                  dead_volume_m3=base["dead_volume_m3"] + tube.volume_m3)
    model = Model([make_effect("tube_delay", form="wave", segments=8,
                               unsteady_friction=True)])

    def wave(weight):
        return simulate(model, dict(params, tube_unsteady_friction=weight), inputs, rig, p0,
                        SolverConfig.reference()).pressure_Pa[0]

    def rms(x):
        return float(np.sqrt(np.mean(x ** 2)))

    rows = [{"weight": w, **{f"rmse_vs_plant_{int(v)}_Pa": rms(wave(w) - plant[v])
                             for v in plant}} for w in WEIGHTS]
    fitted = {}
    for v in plant:
        fit = minimize_scalar(lambda w, v=v: rms(wave(w) - plant[v]), bounds=(0.0, 3.0),
                              method="bounded", options={"xatol": 1e-3})
        fitted[f"plant_{int(v)}"] = {"weight": float(fit.x), "rmse_Pa": float(fit.fun)}
    span = float(np.ptp(plant[0.0]))
    print(f"{name}: the plant's lines apart {rms(plant[1.0] - plant[0.0]):.0f} Pa RMS "
          f"(span {span:.0f} Pa)", flush=True)
    for r in rows:
        print(f"  wave w = {r['weight']}: {r['rmse_vs_plant_0_Pa']:6.0f} Pa vs the "
              f"quasi-steady line, {r['rmse_vs_plant_1_Pa']:6.0f} Pa vs the unsteady one",
              flush=True)
    print(f"  weight fitted: {fitted}", flush=True)
    return {"case": name, "length_m": length, "diameter_m": bore, "cells": CELLS,
            "span_Pa": span, "plants_apart_rms_Pa": rms(plant[1.0] - plant[0.0]),
            "wave": rows, "fitted_weight": fitted}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    cases = [run_case("on/off fill", on_off_fill()), run_case("random steps", random_steps())]
    write_json_atomic(Path(args.out) / "tube_unsteady_friction.json",
                      {"cases": cases, "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
