"""A modal tube (issue 68's "few states" candidate) against the finely lumped tube.

    python benchmarks/tube_modal.py [--modes 8 16 32] [--friction uniform distributed]
        [--tubes 0 1 2] [--dt 1e-4] [--json OUT.json]

A study of a form the library does not have, written here so that its numbers can be
re-run. The valve-chamber tube as ``N`` Galerkin modes of the linear line (mass flow q,
pressure p, section A, sound speed c at the supply's temperature, friction rate
lambda): with ``phi_j = cos(k_j x)``, ``psi_j = sin(k_j x)``, ``k_j = (2j - 1) pi / 2L``,
``s_j = (-1)^(j+1)``::

    da_j/dt = (2 c^2 / (A L G)) q_a - (c^2 / A) k_j b_j
    db_j/dt = A k_j a_j - lambda b_j - (2 A / (L G)) s_j p_c
    p_v = sum_j a_j,  q_c = sum_j s_j b_j

the valve's flow ``q_a`` entering at x = 0 and the chamber's pressure ``p_c`` closing
x = L (both natural conditions of the weak form). ``G = (2 / L) sum_j s_j / k_j`` (-> 1)
rescales the two couplings so that the truncated line passes steady flow and pressure
exactly, and lambda is scaled by ``G / F`` (``F = (8 / pi^2) sum_j (2j - 1)^-2``) so that
its steady drop is ``lambda L q / A``. The chamber (eq. 5, fixed or moving piston) is a
state of the same linear system. Per sample the system is stepped exactly for a flow
linear over the step (its matrix exponential, scipy), lambda (Churchill's ``f Re`` at the
ends' mean flow and density) and the volume held over the step, and the valve's end
solved implicitly (a scalar monotone equation in ``p_v``). ``--friction distributed``
adds the difference between the local friction (at 2N points along the tube) and the
uniform rate as a forcing held over the step.

The reference and the inputs are :mod:`tube_forms`' (64 cells, random 5-V steps, 1 s,
``--dt`` 0.1 ms; its fixed piston); the library's 8-element wave tube beside it. The
matrix exponential per step makes this slow (seconds per case): it measures accuracy,
not cost. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy.linalg import expm
from scipy.optimize import brentq

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tube_forms as tf  # noqa: E402  (the sibling benchmark's cases)

from pneubayes.atomic import write_json_atomic  # noqa: E402
from pneubayes.bench.forms import AcousticTube  # noqa: E402
from pneubayes.bench.forms.catalogue import AIR_VISCOSITY_PA_S  # noqa: E402
from pneubayes.bench.plant import PlantConfig, simulate_plant  # noqa: E402
from pneubayes.effects import make_effect  # noqa: E402
from pneubayes.model import Model  # noqa: E402
from pneubayes.physics.orifice import flow_function  # noqa: E402
from pneubayes.physics.tube import churchill_fre  # noqa: E402
from pneubayes.physics.valve import valve_preset  # noqa: E402
from pneubayes.provenance import provenance  # noqa: E402
from pneubayes.rig import Rig  # noqa: E402
from pneubayes.simulation import SolverConfig, simulate  # noqa: E402


def modal_pressure(inputs, rig: Rig, dead_volume_m3: float, length_m: float,
                   diameter_m: float, modes: int, distributed: bool,
                   viscosity_Pa_s: float = AIR_VISCOSITY_PA_S) -> np.ndarray:
    """Chamber pressure (Pa) at the samples of ``inputs`` with the modal tube; the valve
    is Table II's valve 1, the supply ``tf.P_SUP``, the start at rest at atmosphere."""
    gas = rig.gas
    kap, rs_t = gas.heat_capacity_ratio, gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
    c, area, length = math.sqrt(kap * rs_t), math.pi * diameter_m ** 2 / 4.0, length_m
    n_m = modes
    j = np.arange(1, n_m + 1)
    k = (2 * j - 1) * math.pi / (2 * length)
    s = (-1.0) ** (j + 1)
    g_sum = 2.0 / length * np.sum(s / k)
    f_sum = 8.0 / math.pi ** 2 * np.sum(1.0 / (2 * j - 1) ** 2)
    valve = valve_preset("valve1")
    a_in, a_ex = valve.inlet.area(inputs.command_V), valve.exhaust.area(inputs.command_V)
    t, x = inputs.time_s, inputs.position_m
    n = 2 * n_m + 1
    z = np.zeros(n)
    z[:n_m] = 2.0 * s * tf.P_ATM / (length * k * g_sum)  # at rest: p_v = p_c = P_atm
    z[-1] = tf.P_ATM
    out = np.empty(t.size)
    out[0] = tf.P_ATM
    x_q = (np.arange(2 * n_m) + 0.5) * length / (2 * n_m)
    cos_q, sin_q = np.cos(np.outer(x_q, k)), np.sin(np.outer(x_q, k))
    m = np.zeros((n, n))
    m[:n_m, n_m:2 * n_m] = np.diag(-(c * c / area) * k)
    m[n_m:2 * n_m, :n_m] = np.diag(area * k)
    m[n_m:2 * n_m, -1] = -(2.0 * area / (length * g_sum)) * s
    b = np.zeros(n)
    b[:n_m] = 2.0 * c * c / (area * length * g_sum)

    def valve_flow(p_v, i):
        return float(a_in[i] * flow_function(tf.P_SUP, p_v, gas)
                     - a_ex[i] * flow_function(p_v, tf.P_ATM, gas))

    for i in range(t.size - 1):
        h = t[i + 1] - t[i]
        vol = rig.bore_area_m2 * 0.5 * (x[i] + x[i + 1]) + dead_volume_m3
        vdot = rig.bore_area_m2 * (x[i + 1] - x[i]) / h
        p_v, q_c = float(np.sum(z[:n_m])), float(s @ z[n_m:2 * n_m])
        q_a0 = valve_flow(p_v, i)
        rho = 0.5 * (p_v + z[-1]) / rs_t
        re = 0.5 * (abs(q_a0) + abs(q_c)) * diameter_m / (area * viscosity_Pa_s)
        lam = churchill_fre(re) * viscosity_Pa_s / (2.0 * rho * diameter_m ** 2)
        m[n_m:2 * n_m, n_m:2 * n_m] = np.diag(np.full(n_m, -lam * g_sum / f_sum))
        m[-1, n_m:2 * n_m] = kap * rs_t / vol * s
        m[-1, -1] = -kap * vdot / vol
        force = np.zeros(n)
        if distributed:  # the local friction's departure from the uniform rate
            p_q, q_q = np.maximum(cos_q @ z[:n_m], 1e4), sin_q @ z[n_m:2 * n_m]
            lam_q = np.array([churchill_fre(r) for r in
                              np.abs(q_q) * diameter_m / (area * viscosity_Pa_s)])
            lam_q *= viscosity_Pa_s * rs_t / (2.0 * p_q * diameter_m ** 2)
            force[n_m:2 * n_m] = -(sin_q.T @ ((lam_q - lam) * q_q)) / n_m
        aug = np.zeros((n + 3, n + 3))  # [z, q_a0, dq_a, constant force]
        aug[:n, :n], aug[:n, n], aug[:n, n + 2] = m * h, b * h, force * h
        aug[n, n + 1] = 1.0
        e = expm(aug)
        z_free = e[:n, :n] @ z + (e[:n, n] - e[:n, n + 1]) * q_a0 + e[:n, n + 2]
        gain = e[:n, n + 1]  # the end state's slope in the step's end flow
        c0, c1 = float(np.sum(z_free[:n_m])), float(np.sum(gain[:n_m]))
        p_end = brentq(lambda p, c0=c0, c1=c1, i=i: p - c0 - c1 * valve_flow(p, i), 1e3, 3e6,
                       xtol=1e-6)
        z = z_free + gain * valve_flow(p_end, i)
        out[i + 1] = z[-1]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--modes", type=int, nargs="+", default=[8, 16, 32])
    ap.add_argument("--friction", nargs="+", default=["uniform", "distributed"],
                    choices=["uniform", "distributed"])
    ap.add_argument("--tubes", type=int, nargs="+", default=[0, 1, 2],
                    help="indices into tube_forms.TUBES")
    ap.add_argument("--dt", type=float, default=tf.DT_S, help="sample interval (s)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", default=None, help="results (JSON, written atomically)")
    args = ap.parse_args(argv)
    rig = Rig(tf.BORE, tf.P_ATM, tf.P_SUP)
    base = dict(valve_preset("valve1").parameters(), dead_volume_m3=1.5e-7)
    rows = []
    for ti in args.tubes:
        length, dia = tf.TUBES[ti]
        inputs = tf._inputs(args.seed, False, dt_s=args.dt)
        ref = simulate_plant(base, (AcousticTube(length, dia, segments=64),), inputs, rig,
                             tf.P_ATM, PlantConfig.reference()).pressure_Pa
        params, _ = tf._tube_params(rig, base, length, dia)
        wave = simulate(Model([make_effect("tube_delay", form="wave", segments=8)]), params,
                        inputs, rig, tf.P_ATM, SolverConfig.standard()).pressure_Pa[0]
        cases = [("wave, 8 elements", wave)] + [
            (f"modal, {nm} modes, {fr} friction",
             modal_pressure(inputs, rig, base["dead_volume_m3"], length, dia, nm,
                            fr == "distributed"))
            for fr in args.friction for nm in args.modes]
        for label, y in cases:
            rmse = float(np.sqrt(np.mean((y - ref) ** 2)))
            row = {"length_m": length, "diameter_m": dia, "form": label, "rmse_Pa": rmse,
                   "max_error_Pa": float(np.max(np.abs(y - ref))),
                   "rmse_percent_of_range": 100.0 * rmse / float(np.ptp(ref))}
            rows.append(row)
            print(f"{length:4.2f} m x {dia * 1e3:4.2f} mm {label:36s} RMSE {rmse:6.0f} Pa "
                  f"({row['rmse_percent_of_range']:.3f} % of range), max "
                  f"{row['max_error_Pa']:6.0f} Pa", flush=True)
    if args.json:
        write_json_atomic(Path(args.json), {"seed": args.seed, "dt_s": args.dt, "rows": rows,
                                            "provenance": provenance()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
