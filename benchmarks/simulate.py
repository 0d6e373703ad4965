"""Speed and accuracy benchmark of the pneubayes simulator against scipy's solve_ivp.

    .venv/bin/python benchmarks/simulate.py --json results/bench_simulate.json [--quick]

One run measures, on seeded 2-s trajectories (1 kHz, random step commands) for three
chamber volumes (fixed 2.4e-6 m^3, fixed 1e-7 m^3, moving piston on 2e-7 m^3):

1. pneubayes wall time per trajectory (warm, single thread, batch of one), its maximum
   error against a tight Radau reference (rtol 1e-10), and the scipy LSODA and RK45
   baselines (rtol 1e-6) with their own errors against the same reference;
2. batched throughput (1, 64 and 1024 perturbed parameter sets on 1 and 2 threads) for
   the fixed 2.4e-6 m^3 case, plus batch-64 single-thread throughput for every case.

It prints a table and writes every number to the JSON file (atomically). It never fails
on slow times: the floors of the issue are reported as booleans. See benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import gc
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic

SCHEMA = "pneubayes-bench-simulate/1"

# ----------------------------------------------------------------------------- setup
SAMPLE_RATE_HZ = 1000.0
DURATION_S = 2.0
P_ATM = 101325.0
P_SUPPLY = 551325.0
BORE_M = 0.009            # AIR37
STROKE_M = 0.0375
STROKE_MARGIN_M = 0.00125  # keep the moving piston this far from both ends
MAX_PISTON_SPEED = 0.5     # m/s, the moving case is scaled to reach (at most) this
MOTION_FREQS_HZ = (1.0, 2.0, 3.5, 5.5, 8.0)
LEAK_AREA_M2 = 3.04e-8
HOLD_MS = (30, 300)        # command holds, uniform (inclusive), ms
LEVEL_V = (-5.0, 5.0)      # command levels, uniform, V
PERTURB = 0.10             # +-10 % multiplicative parameter perturbation
BATCH_SIZES = (1, 64, 1024)
THREAD_COUNTS = (1, 2)

SCIPY_RTOL, SCIPY_ATOL_PA = 1e-6, 1e-3
RADAU_RTOL, RADAU_ATOL_PA = 1e-10, 1e-6
SCIPY_CHUNK_S = 0.25       # scipy runs proceed in chunks so a slow one can be cut short

FLOOR_SIM_S_PER_S_PER_CORE = 3000.0
FLOOR_SIM_S_PER_S_BATCH1 = 5000.0    # issue 23: batch 1, one thread, via simulate()
FLOOR_BATCH64_RATIO = 1.2            # issue 23: batch-64 cost per trajectory / batch-1's
FLOOR_FIRST_CALL_S = 20.0            # issue 23: first simulate on a fresh install
FLOOR_SPEEDUP_LSODA_FIXED = 100.0
FLOOR_SPEEDUP_LSODA_MOVING = 1000.0
LOAD_WARN = 0.5            # 1-min load average above which the run notes contention
ACCURACY_FLOOR_PERCENT = 0.1  # SolverConfig.standard()'s documented accuracy, % of range
FLOOR_TUBE_RELATIVE = 0.25  # issue 68: the tube form discovery tries, x the paper's model
TUBE_DISCOVERY_FORM = "tube wave, 8 elements"  # (discovery's forms.tube_line_form "wave")

CASES = (
    # name, dead volume m^3, moving?
    ("fixed_2.4e-6", 2.4e-6, False),
    ("fixed_1e-7", 1e-7, False),
    ("moving_2e-7", 2e-7, True),
)
FIXED_CASE = "fixed_2.4e-6"
MOVING_CASE = "moving_2e-7"
#: Section 4: each effect form beside the paper's model, at its bench defaults.
EFFECT_FORMS = (
    # label, catalogue name (None: the paper's model alone), options
    ("paper's model", None, {}),
    ("spool_lag", "spool_lag", {}),
    ("spool_lag 2nd order", "spool_lag", {"form": "second_order"}),
    ("spool_lag asymmetric", "spool_lag", {"form": "asymmetric"}),
    ("sensor_lag", "sensor_lag", {}),
    ("sensor_lag 2nd order", "sensor_lag", {"form": "second_order"}),
    ("sensor_lag pressure-dependent", "sensor_lag", {"form": "pressure_dependent"}),
    ("tube_delay", "tube_delay", {}),
    ("tube line, 3 cells", "tube_delay", {"form": "line", "segments": 3}),
    ("tube line, 8 cells", "tube_delay", {"form": "line", "segments": 8}),
    ("tube wave, 8 elements", "tube_delay", {"form": "wave"}),
    ("valve_deadzone", "valve_deadzone", {}),
    ("valve_stiction", "valve_stiction", {}),
    ("heat_transfer", "heat_transfer", {}),
    ("reading_closure", "reading_closure", {}),
    ("reading_play", "reading_play", {}),
    ("loaded_wall", "loaded_wall", {}),
    ("port_restriction", "port_restriction", {}),
    ("critical_ratio iso6358", "critical_ratio", {"form": "iso6358"}),
)


def _parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", required=True, metavar="OUT.json",
                    help="where to write all measurements (written atomically)")
    ap.add_argument("--seed", type=int, default=0,
                    help="seed of the command, motion and parameter perturbations (default 0)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: ~0.2 s of repetitions per timing and 0.5-s scipy "
                         "baselines (compared per simulated second)")
    ap.add_argument("--scipy-budget", type=float, default=60.0, metavar="SECONDS",
                    help="wall-time budget of one scipy run; a run that exceeds it stops at "
                         "the next 0.25-s chunk and is normalised per simulated second "
                         "(default 60)")
    return ap.parse_args(argv)


# ----------------------------------------------------------------------------- signals
def make_command(rng, n):
    """Random step command on n samples: holds uniform in HOLD_MS, levels in LEVEL_V."""
    u = np.empty(n)
    i = 0
    while i < n:
        hold = int(rng.integers(HOLD_MS[0], HOLD_MS[1] + 1))  # samples at 1 kHz
        u[i:i + hold] = rng.uniform(*LEVEL_V)
        i += hold
    return u


def make_motion(rng, t):
    """Aggressive piston motion: sum of sinusoids (1-8 Hz, random phases) within the stroke.

    Amplitudes fall as f^-0.2; the sum is scaled so the largest sample-to-sample speed is
    MAX_PISTON_SPEED unless that would leave the stroke (then it fills the stroke).
    """
    f = np.asarray(MOTION_FREQS_HZ)
    phase = rng.uniform(0.0, 2.0 * np.pi, f.size)
    x = (f[:, None] ** -0.2 * np.sin(2 * np.pi * f[:, None] * t[None, :]
                                     + phase[:, None])).sum(axis=0)
    speed = np.abs(np.diff(x) / np.diff(t)).max()
    usable = STROKE_M - 2 * STROKE_MARGIN_M
    scale = min(MAX_PISTON_SPEED / speed, usable / np.ptp(x))
    x = (x - 0.5 * (x.max() + x.min())) * scale + 0.5 * STROKE_M
    return x


# ----------------------------------------------------------------------------- helpers
def _git_revision():
    here = Path(__file__).resolve().parent
    out = {"revision": None, "dirty": None}
    try:
        out["revision"] = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here,
                                         capture_output=True, text=True, timeout=10,
                                         check=True).stdout.strip() or None
        st = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                            cwd=here, capture_output=True, text=True, timeout=10, check=True)
        out["dirty"] = bool(st.stdout.strip())
    except Exception as exc:  # noqa: BLE001 - no git, not a repo, ...: tolerated
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def _loadavg():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def machine_reference_ns(repeats=5, iterations=2_000_000):
    """The machine's speed on the kernel's kind of arithmetic: ns per iteration (median
    of ``repeats``) of one compiled dependent chain of a power (exp of a log), a square
    root and a division, as a step's orifice flows have. The simulator's absolute
    numbers move with the machine (the same code read 10-20 % apart on one day's
    runs); dividing two runs' sim-s/s by the inverse ratio of this number compares them
    across machines and days. Not a floor: a diagnostic beside the timings."""
    import numba

    @numba.njit(cache=False)
    def chain(n):
        x = 0.7
        for _ in range(n):
            x = math.exp(math.log(x) / 1.4) * 0.5 + math.sqrt(x) / (1.0 + x) * 0.25 + 0.1
        return x

    chain(10)
    out = []
    for _ in range(repeats):
        a = time.perf_counter()
        chain(iterations)
        out.append((time.perf_counter() - a) / iterations * 1e9)
    return float(np.median(out))


def time_calls(fn, min_total_s, min_reps):
    """Warm call, then repeat fn until min_total_s and min_reps are both reached."""
    t0 = time.perf_counter()
    fn()
    warm = time.perf_counter() - t0
    times = []
    gc_was = gc.isenabled()
    gc.disable()
    try:
        start = time.perf_counter()
        while len(times) < min_reps or time.perf_counter() - start < min_total_s:
            a = time.perf_counter()
            fn()
            times.append(time.perf_counter() - a)
    finally:
        if gc_was:
            gc.enable()
    arr = np.asarray(times)
    return {"median_s": float(np.median(arr)), "mean_s": float(arr.mean()),
            "min_s": float(arr.min()), "max_s": float(arr.max()), "repetitions": int(arr.size),
            "warm_call_s": warm}


def _pct(err_pa, working_range):
    return None if err_pa is None else 100.0 * err_pa / working_range


# ----------------------------------------------------------------------------- cold start
_COLD_SNIPPET = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
import numba
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate
out = {"import_s": time.perf_counter() - t0}
n = 2001
t = np.arange(n) / 1000.0
rig = Rig(0.009, 101325.0, 551325.0)
inputs = Inputs(t, np.where(t < 1.0, 3.0, -3.0), np.zeros(n), np.full(n, 551325.0))
p = valve_preset("valve1").parameters()
p.update(dead_volume_m3=2.4e-6, leak_area_m2=3.04e-8)
model = Model(["cylinder_leak"])
a = time.perf_counter()
simulate(model, model.vector(p), inputs, rig, 101325.0, SolverConfig.standard())
out["first_simulate_s"] = time.perf_counter() - a
out["first_call_total_s"] = time.perf_counter() - t0
if numba.config.NUMBA_NUM_THREADS > 1:
    numba.set_num_threads(2)
    a = time.perf_counter()
    simulate(model, np.tile(model.vector(p), (8, 1)), inputs, rig, 101325.0,
             SolverConfig.standard())
    out["first_batched_two_threads_s"] = time.perf_counter() - a
if "--general" in sys.argv:
    hot = Model(["cylinder_leak", "heat_transfer"])
    q = {**hot.neutral_values(), **p, "heat_transfer_rate_per_s": 20.0,
         "heat_transfer_coupling": 1.0}
    a = time.perf_counter()
    simulate(hot, hot.vector(q), inputs, rig, 101325.0, SolverConfig.standard())
    out["first_general_form_s"] = time.perf_counter() - a
print(json.dumps(out))
"""


def cold_start(general):
    """The first calls of a fresh install: a new process with an empty numba cache
    (``NUMBA_CACHE_DIR`` a new temporary folder), timing the import, the first
    ``simulate`` of the paper's model (which compiles it), the first batched call on 2
    threads and, with ``general``, the first model with a second state (heat transfer)."""
    import json
    import tempfile

    with tempfile.TemporaryDirectory(prefix="pneubayes-cold-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        a = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", _COLD_SNIPPET]
                              + (["--general"] if general else []),
                              capture_output=True, text=True, env=env, timeout=900)
        wall = time.perf_counter() - a
    if proc.returncode != 0:
        return {"error": proc.stderr[-800:], "process_wall_s": wall}
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["process_wall_s"] = wall
    return out


# ----------------------------------------------------------------------------- user's scipy
def make_user_rhs(params, volume_m3, gas, inputs):
    """The chamber ODE as a user would write it for scipy: plain Python floats, eqs. 1-5
    and 11 with the orifice leak, command held between samples, piston linear between
    samples. Returns ``rhs(t, y)``; it calls nothing from pneubayes."""
    k = gas.heat_capacity_ratio
    rs_t = gas.specific_gas_constant_J_per_kg_K * gas.temperature_K
    alpha, beta, theta = gas.alpha_s_per_m, gas.beta_s_per_m, gas.theta
    t0, dt = float(inputs.time_s[0]), float(inputs.time_s[1] - inputs.time_s[0])
    u, x = inputs.command_V.tolist(), inputs.position_m.tolist()
    n = len(u)
    area = np.pi * BORE_M ** 2 / 4.0
    pin = [params[f"inlet_{q}"] for q in ("offset_m2", "a_m2", "b", "c_per_V", "d_V")]
    pex = [params[f"exhaust_{q}"] for q in ("offset_m2", "a_m2", "b", "c_per_V", "d_V")]
    leak = params["leak_area_m2"]

    def gompertz(c, off, a, b, cc, d):
        return off + a * np.exp(-b * np.exp(-cc * (c + d)))

    def z(pu, pd):  # eq. 3, pu >= pd
        if pu > theta * pd:
            return beta * pu
        r = pd / pu
        return alpha * pu * np.sqrt(max(r ** (2.0 / k) - r ** ((k + 1.0) / k), 0.0))

    def f(pu, pd):  # eq. 2, signed
        return z(pu, pd) if pu >= pd else -z(pd, pu)

    def rhs(t, y):
        p = y[0]
        i = min(int((t - t0) / dt), n - 2)
        c = u[i]
        fr = (t - t0) / dt - i
        vol = volume_m3 + area * (x[i] + fr * (x[i + 1] - x[i]))
        vdot = area * (x[i + 1] - x[i]) / dt
        mdot = (gompertz(c, *pin) * f(P_SUPPLY, p)
                - (gompertz(c, *pex) + leak) * f(p, P_ATM))
        return [k / vol * (rs_t * mdot - p * vdot)]

    return rhs


def run_user_scipy(rhs, inputs, method, rtol, atol, p0, max_horizon_s):
    """solve_ivp on the user's right-hand side, one call per sample interval (the held
    command is discontinuous at samples; so is the piston speed), up to max_horizon_s."""
    from scipy.integrate import solve_ivp

    t = inputs.time_s
    n_max = min(round(max_horizon_s * SAMPLE_RATE_HZ), t.size - 1)
    y = np.empty(n_max + 1)
    y[0] = p0
    a = time.perf_counter()
    for i in range(n_max):
        sol = solve_ivp(rhs, (t[i], t[i + 1]), [y[i]], method=method, rtol=rtol, atol=atol)
        if not sol.success:
            return {"failed": True, "error": sol.message}, None
        y[i + 1] = sol.y[0, -1]
    wall = time.perf_counter() - a
    horizon = float(t[n_max] - t[0])
    return {"failed": False, "horizon_s": horizon, "wall_s": wall,
            "wall_per_simulated_second_s": wall / horizon}, y


# ----------------------------------------------------------------------------- scipy runs
def run_scipy(ctx, inputs, params, method, rtol, atol, max_horizon_s, budget_s):
    """reference_simulate in SCIPY_CHUNK_S chunks up to max_horizon_s or the wall budget.

    Each chunk restarts from the previous chunk's last pressure. reference_simulate already
    integrates every sample interval separately, and this model (cylinder_leak, no delay,
    spool lag or heat transfer) has pressure as its only state, so chunking does not
    change the result.
    """
    Inputs, reference_simulate = ctx["Inputs"], ctx["reference_simulate"]
    t = inputs.time_s
    dt = t[1] - t[0]
    n_max = round(max_horizon_s / dt)  # intervals
    n_max = min(n_max, t.size - 1)
    chunk = max(1, round(SCIPY_CHUNK_S / dt))
    out = [np.array([ctx["p0"]])]
    p = ctx["p0"]
    k = 0
    nfev = 0
    wall = 0.0
    error = None
    stopped_by_budget = False
    while k < n_max:
        b = min(k + chunk, n_max)
        sub = Inputs(t[k:b + 1], inputs.command_V[k:b + 1], inputs.position_m[k:b + 1],
                     inputs.supply_pressure_Pa[k:b + 1])
        a0 = time.perf_counter()
        try:
            y, nf = reference_simulate(ctx["model"], params, sub, ctx["rig"], p, method=method,
                                       rtol=rtol, atol=atol, return_stats=True)
        except Exception as exc:  # noqa: BLE001 - any solver failure: record, stop
            wall += time.perf_counter() - a0
            error = f"{type(exc).__name__}: {exc}".strip()[:500]
            break
        wall += time.perf_counter() - a0
        nfev += nf
        out.append(y[1:])
        p = float(y[-1])
        k = b
        if not np.all(np.isfinite(y)):
            break
        if wall > budget_s and k < n_max:
            stopped_by_budget = True
            break
    traj = np.concatenate(out)
    horizon = (traj.size - 1) * dt
    returned_nan = bool(not np.all(np.isfinite(traj)))
    ok = error is None and not returned_nan and traj.size - 1 == n_max
    return {
        "method": method, "rtol": rtol, "atol_Pa": atol,
        "requested_horizon_s": n_max * dt, "horizon_s": horizon,
        "wall_s": wall, "wall_per_simulated_second_s": wall / horizon if horizon > 0 else None,
        "rhs_evaluations": nfev, "failed": error is not None, "error": error,
        "returned_nan": returned_nan, "completed": ok,
        "shortened_by_budget": stopped_by_budget, "budget_s": budget_s,
    }, traj


def max_abs_diff(a, b):
    n = min(a.size, b.size)
    if n < 2:
        return None, 0
    d = np.abs(a[:n] - b[:n])
    if not np.all(np.isfinite(d)):
        return None, n
    return float(d.max()), n


# ----------------------------------------------------------------------------- main
def main(argv=None):
    args = _parse(argv)
    run_start = time.perf_counter()
    started = _dt.datetime.now(_dt.UTC)
    load_start = _loadavg()
    reference_start = machine_reference_ns()

    import numba
    import scipy

    from pneubayes.effects import make_effect
    from pneubayes.errors import SimulationError
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.rig import Rig
    from pneubayes.simulation import Inputs, SolverConfig, simulate
    from pneubayes.simulation.reference import reference_simulate

    quick = args.quick
    min_total = 0.2 if quick else 1.0
    min_reps = 1 if quick else 3
    scipy_horizon = 0.5 if quick else DURATION_S
    notes = []
    if quick:
        notes.append("--quick: timings repeat for ~0.2 s; scipy baselines and the Radau "
                     "reference cover the first 0.5 s of each trajectory, so scipy is "
                     "compared per simulated second and errors are over 0.5 s.")

    ss = np.random.SeedSequence(args.seed)
    rng_cmd, rng_motion, rng_params = (np.random.default_rng(s) for s in ss.spawn(3))

    n = round(DURATION_S * SAMPLE_RATE_HZ) + 1
    t = np.arange(n) / SAMPLE_RATE_HZ
    sim_s = float(t[-1] - t[0])
    command = make_command(rng_cmd, n)
    motion = make_motion(rng_motion, t)
    supply = np.full(n, P_SUPPLY)

    model = Model(["cylinder_leak"])
    rig = Rig(BORE_M, P_ATM, P_SUPPLY)
    working_range = rig.working_range_Pa
    solver = SolverConfig.standard()
    lo, hi = model.bounds
    threads_available = int(numba.config.NUMBA_NUM_THREADS)

    # One perturbation matrix, reused (rescaled per case) so batches are comparable.
    perturb = rng_params.uniform(1.0 - PERTURB, 1.0 + PERTURB,
                                 size=(max(BATCH_SIZES), model.n_parameters))
    perturb[0] = 1.0  # row 0 is the base vector: batch 1 is the section-1 trajectory

    cases = {}
    for name, volume, moving in CASES:
        params = valve_preset("valve1").parameters()
        params.update(dead_volume_m3=volume, leak_area_m2=LEAK_AREA_M2)
        base = model.vector(params)
        batch = np.clip(base[None, :] * perturb, lo, hi)
        pos = motion if moving else np.zeros(n)
        inputs = Inputs(t, command, pos, supply)
        cases[name] = {"volume": volume, "moving": moving, "params": params, "base": base,
                       "batch": batch, "inputs": inputs}

    ctx = {"model": model, "rig": rig, "p0": P_ATM, "Inputs": Inputs,
           "reference_simulate": reference_simulate}

    def sim(theta, inputs, dense_output=False):
        return simulate(model, theta, inputs, rig, P_ATM,
                        solver.with_dense_output(dense_output))

    # Diagnostic: the compiled kernel alone (no Python wrapper); internal API, optional.
    try:
        from pneubayes.simulation import kernel as _kernel
        from pneubayes.simulation import rig_constants as _rig_constants

        def kernel_only(theta, inputs):
            slots = np.ascontiguousarray(model.lower(model.as_matrix(theta), rig))
            return _kernel.simulate_windows(
                slots, _rig_constants(rig), solver.as_array(), inputs.time_s,
                inputs.command_V, np.zeros(inputs.n_samples), inputs.position_m,
                inputs.supply_pressure_Pa,
                np.array([0], dtype=np.int64), inputs.n_samples, np.array([P_ATM]))
    except Exception as exc:  # noqa: BLE001 - internal API moved: skip the diagnostic
        kernel_only = None
        notes.append(f"kernel-only diagnostic unavailable: {type(exc).__name__}: {exc}")

    # ---------------------------------------------------------------- 1. per trajectory
    numba.set_num_threads(1)
    per_case = {}
    first_call_s = None
    for name, c in cases.items():
        res = {"dead_volume_m3": c["volume"], "moving": c["moving"]}
        if c["moving"]:
            x = c["inputs"].position_m
            res["position_min_m"] = float(x.min())
            res["position_max_m"] = float(x.max())
            res["max_piston_speed_m_per_s"] = float(np.abs(np.diff(x) / np.diff(t)).max())
        print(f"[{name}] pneubayes ...", file=sys.stderr, flush=True)
        pb = {"threads": 1, "batch": 1}
        try:
            if first_call_s is None:
                a = time.perf_counter()
                sim(c["base"], c["inputs"])
                first_call_s = time.perf_counter() - a
            timing = time_calls(lambda c=c: sim(c["base"], c["inputs"]), min_total,
                                min_reps)
            pb.update(timing)
            pb["wall_per_trajectory_s"] = timing["median_s"]
            pb["wall_per_simulated_second_s"] = timing["median_s"] / sim_s
            pb["sim_seconds_per_second"] = sim_s / timing["median_s"]
            traj = sim(c["base"], c["inputs"]).pressure_Pa[0]
            pb["returned_nan"] = bool(not np.all(np.isfinite(traj)))
        except SimulationError as exc:
            pb["error"] = str(exc)[:500]
            traj = None
        if kernel_only is not None:
            try:
                kt = time_calls(lambda c=c: kernel_only(c["base"], c["inputs"]), min_total,
                                min_reps)
                pb["kernel_only_median_s"] = kt["median_s"]
                pb["kernel_only_sim_seconds_per_second"] = sim_s / kt["median_s"]
            except Exception as exc:  # noqa: BLE001 - diagnostic only
                pb["kernel_only_error"] = f"{type(exc).__name__}: {exc}"[:300]
        res["pneubayes"] = pb

        # the same with dense output (steps cross the samples where the command holds;
        # over the moving piston on the position's chord)
        pbd = {"threads": 1, "batch": 1, "dense_output": True}
        traj_dense = None
        try:
            timing = time_calls(lambda c=c: sim(c["base"], c["inputs"], True), min_total,
                                min_reps)
            pbd.update(timing)
            pbd["sim_seconds_per_second"] = sim_s / timing["median_s"]
            traj_dense = sim(c["base"], c["inputs"], True).pressure_Pa[0]
        except SimulationError as exc:
            pbd["error"] = str(exc)[:500]
        res["pneubayes_dense"] = pbd

        # batch 64, one thread, for the batched headline
        b64 = {"threads": 1, "batch": 64}
        try:
            timing = time_calls(lambda c=c: sim(c["batch"][:64], c["inputs"]), min_total,
                                min_reps)
            b64.update(timing)
            b64["sim_seconds_per_second"] = 64 * sim_s / timing["median_s"]
            b64["sim_seconds_per_second_per_core"] = b64["sim_seconds_per_second"]
        except SimulationError as exc:
            b64["error"] = str(exc)[:500]
        res["pneubayes_batch64"] = b64

        # batch 64 of the identical parameter vector: the cost per trajectory against
        # batch 1's (a trajectory should cost the same alone or in a batch)
        same = {"threads": 1, "batch": 64, "parameters": "base vector tiled"}
        try:
            tiled = np.tile(c["base"], (64, 1))
            timing = time_calls(lambda tiled=tiled, c=c: sim(tiled, c["inputs"]),
                                min_total, min_reps)
            same.update(timing)
            same["wall_per_trajectory_s"] = timing["median_s"] / 64
            if pb.get("wall_per_trajectory_s"):
                same["ratio_to_batch1"] = (same["wall_per_trajectory_s"]
                                           / pb["wall_per_trajectory_s"])
        except SimulationError as exc:
            same["error"] = str(exc)[:500]
        res["pneubayes_batch64_identical"] = same

        # Radau reference and scipy baselines
        print(f"[{name}] scipy Radau reference ...", file=sys.stderr, flush=True)
        radau, radau_traj = run_scipy(ctx, c["inputs"], c["base"], "Radau", RADAU_RTOL,
                                      RADAU_ATOL_PA, scipy_horizon, args.scipy_budget)
        res["reference_radau"] = radau
        ref_ok = not radau["failed"] and not radau["returned_nan"]
        if traj is not None and ref_ok:
            err, nn = max_abs_diff(traj, radau_traj)
            pb["max_abs_error_vs_radau_Pa"] = err
            pb["max_abs_error_vs_radau_percent_of_range"] = _pct(err, working_range)
            pb["error_horizon_s"] = (nn - 1) / SAMPLE_RATE_HZ
        if traj_dense is not None and ref_ok:
            err, _ = max_abs_diff(traj_dense, radau_traj)
            pbd["max_abs_error_vs_radau_Pa"] = err
            pbd["max_abs_error_vs_radau_percent_of_range"] = _pct(err, working_range)
        res["scipy"] = {}
        for method in ("LSODA", "RK45"):
            print(f"[{name}] scipy {method} ...", file=sys.stderr, flush=True)
            r, y = run_scipy(ctx, c["inputs"], c["base"], method, SCIPY_RTOL, SCIPY_ATOL_PA,
                             scipy_horizon, args.scipy_budget)
            if ref_ok and not r["failed"] and not r["returned_nan"]:
                err, nn = max_abs_diff(y, radau_traj)
                r["max_abs_diff_vs_radau_Pa"] = err
                r["max_abs_diff_vs_radau_percent_of_range"] = _pct(err, working_range)
                r["diff_horizon_s"] = (nn - 1) / SAMPLE_RATE_HZ
            else:
                r["max_abs_diff_vs_radau_Pa"] = None
                r["max_abs_diff_vs_radau_percent_of_range"] = None
            if (not r["failed"] and not r["returned_nan"] and r["horizon_s"] > 0
                    and "wall_per_simulated_second_s" in pb):
                r["speedup_of_pneubayes"] = (r["wall_per_simulated_second_s"]
                                             / pb["wall_per_simulated_second_s"])
            else:
                r["speedup_of_pneubayes"] = None
            res["scipy"][method] = r
            if r["shortened_by_budget"]:
                notes.append(f"{name}: {method} exceeded the {args.scipy_budget:g}-s budget and "
                             f"was measured over {r['horizon_s']:g} s; its speed is per "
                             "simulated second.")
            if r["failed"] or r["returned_nan"]:
                notes.append(f"{name}: scipy {method} failed ({r['error'] or 'NaN output'}); "
                             "no speedup or error recorded for it.")
        # the same solvers on a lean NumPy right-hand side written as a user would
        res["scipy_user_rhs"] = {}
        user_rhs = make_user_rhs({**c["params"]}, c["volume"], rig.gas, c["inputs"])
        for method in ("LSODA", "RK45"):
            print(f"[{name}] scipy {method} on a user's NumPy right-hand side ...",
                  file=sys.stderr, flush=True)
            r, y = run_user_scipy(user_rhs, c["inputs"], method, SCIPY_RTOL, SCIPY_ATOL_PA,
                                  P_ATM, scipy_horizon)
            if not r["failed"]:
                if ref_ok:
                    err, nn = max_abs_diff(y, radau_traj)
                    r["max_abs_diff_vs_radau_Pa"] = err
                    r["max_abs_diff_vs_radau_percent_of_range"] = _pct(err, working_range)
                if "wall_per_simulated_second_s" in pb:
                    r["speedup_of_pneubayes"] = (r["wall_per_simulated_second_s"]
                                                 / pb["wall_per_simulated_second_s"])
            res["scipy_user_rhs"][method] = r
        if radau["shortened_by_budget"]:
            notes.append(f"{name}: the Radau reference exceeded the budget; errors are over "
                         f"the first {radau['horizon_s']:g} s.")
        if not ref_ok:
            notes.append(f"{name}: the Radau reference failed ({radau['error']}); no errors.")
        per_case[name] = res

    # ---------------------------------------------------------------- 2. throughput
    throughput = []
    c = cases[FIXED_CASE]
    for nt in THREAD_COUNTS:
        for bsz in BATCH_SIZES:
            row = {"case": FIXED_CASE, "threads": nt, "batch": bsz}
            if nt > threads_available:
                row["skipped"] = (f"numba.config.NUMBA_NUM_THREADS={threads_available} < {nt}")
                throughput.append(row)
                continue
            numba.set_num_threads(nt)
            print(f"[throughput] batch {bsz}, {nt} thread(s) ...", file=sys.stderr, flush=True)
            theta = c["batch"][:bsz]
            try:
                timing = time_calls(lambda theta=theta: sim(theta, c["inputs"]), min_total,
                                    min_reps)
                row.update(timing)
                row["wall_per_call_s"] = timing["median_s"]
                row["sim_seconds_per_second"] = bsz * sim_s / timing["median_s"]
                row["sim_seconds_per_second_per_core"] = row["sim_seconds_per_second"] / nt
            except SimulationError as exc:
                row["error"] = str(exc)[:500]
            throughput.append(row)
    numba.set_num_threads(1)

    # ---------------------------------------------------------------- 4. effect forms
    # (run before the cold start of section 3, which starts a new process)
    # batch 1, one thread, the fixed case: each form's cost against the paper's model
    # in the same run (a regression in one form's stepping shows here)
    effect_costs = []
    c = cases[FIXED_CASE]
    for label, name, options in EFFECT_FORMS:
        print(f"[effects] {label} ...", file=sys.stderr, flush=True)
        row = {"form": label, "effect": name, "options": options}
        m = model if name is None else Model([*model.effects, make_effect(name, **options)])
        theta = dict(c["params"], **({} if name is None else m.effects[-1].bench_defaults()))
        row["parameters"] = {k: theta[k] for k in m.parameter_names if k not in c["params"]}
        try:
            m.vector(theta)
            simulate(m, theta, c["inputs"], rig, P_ATM, solver)  # compiles a new form
            timing = time_calls(lambda m=m, theta=theta: simulate(
                m, theta, c["inputs"], rig, P_ATM, solver), min_total, min_reps)
            row.update(timing)
            row["sim_seconds_per_second"] = sim_s / timing["median_s"]
            if name == "tube_delay" and options.get("form") in ("line", "wave"):
                # the tube forms' solver error: against the same model at the tight
                # preset (SolverConfig.reference(); tests/test_simulator.py holds the
                # 3-cell line against scipy's Radau, too slow to run here: 1-14 min
                # per 0.7 s)
                got = simulate(m, theta, c["inputs"], rig, P_ATM, solver).pressure_Pa[0]
                fine = simulate(m, theta, c["inputs"], rig, P_ATM,
                                SolverConfig.reference()).pressure_Pa[0]
                err = float(np.max(np.abs(got - fine)))
                row["max_abs_error_vs_reference_preset_Pa"] = err
                row["max_abs_error_vs_reference_preset_percent_of_range"] = _pct(
                    err, working_range)
        except SimulationError as exc:
            row["error"] = str(exc)[:500]
        effect_costs.append(row)
    base_speed = effect_costs[0].get("sim_seconds_per_second")
    for row in effect_costs:
        if base_speed and row.get("sim_seconds_per_second"):
            row["relative_to_paper_model"] = row["sim_seconds_per_second"] / base_speed

    # ---------------------------------------------------------------- 3. cold start
    print("[cold start] a fresh process with an empty numba cache ...", file=sys.stderr,
          flush=True)
    cold = cold_start(general=not quick)

    # ---------------------------------------------------------------- headline + floors
    def _get(d, *keys):
        for k in keys:
            if not isinstance(d, dict) or d.get(k) is None:
                return None
            d = d[k]
        return d

    by_case = {k: _get(v, "pneubayes", "sim_seconds_per_second") for k, v in per_case.items()}
    by_case_b64 = {k: _get(v, "pneubayes_batch64", "sim_seconds_per_second_per_core")
                   for k, v in per_case.items()}
    headline = (min(by_case.values()) if all(v is not None for v in by_case.values())
                else None)
    headline_b64 = (min(by_case_b64.values())
                    if all(v is not None for v in by_case_b64.values()) else None)
    ratios = {k: _get(v, "pneubayes_batch64_identical", "ratio_to_batch1")
              for k, v in per_case.items()}
    worst_ratio = (max(ratios.values()) if all(v is not None for v in ratios.values())
                   else None)
    sp_fixed = _get(per_case, FIXED_CASE, "scipy", "LSODA", "speedup_of_pneubayes")
    sp_moving = _get(per_case, MOVING_CASE, "scipy", "LSODA", "speedup_of_pneubayes")

    def _met(v, floor):
        return None if v is None else bool(v >= floor)

    tube_row = next((row for row in effect_costs if row["form"] == TUBE_DISCOVERY_FORM), {})
    tube_ratio = tube_row.get("relative_to_paper_model")
    tube_err_pct = tube_row.get("max_abs_error_vs_reference_preset_percent_of_range")
    floors = {
        "sim_seconds_per_second_per_core": {
            "floor": FLOOR_SIM_S_PER_S_PER_CORE, "value": headline,
            "met": _met(headline, FLOOR_SIM_S_PER_S_PER_CORE),
            "per_case": {k: {"value": v, "met": _met(v, FLOOR_SIM_S_PER_S_PER_CORE)}
                         for k, v in by_case.items()},
            "definition": "single thread, batch of 1, via pneubayes.simulation.simulate; "
                          "minimum over the three volume cases",
        },
        "batch1_sim_seconds_per_second_issue23": {
            "floor": FLOOR_SIM_S_PER_S_BATCH1, "value": headline,
            "met": _met(headline, FLOOR_SIM_S_PER_S_BATCH1),
            "per_case": {k: {"value": v, "met": _met(v, FLOOR_SIM_S_PER_S_BATCH1)}
                         for k, v in by_case.items()},
            "definition": "as sim_seconds_per_second_per_core, against issue 23's floor",
            "with_dense_output": {
                k: _get(v, "pneubayes_dense", "sim_seconds_per_second")
                for k, v in per_case.items()},
        },
        "batch64_over_batch1_per_trajectory": {
            "ceiling": FLOOR_BATCH64_RATIO, "value": worst_ratio,
            "met": None if worst_ratio is None else bool(worst_ratio <= FLOOR_BATCH64_RATIO),
            "per_case": ratios,
            "definition": "wall per trajectory of 64 copies of the base vector in one call "
                          "over that of one, single thread, via simulate; maximum over cases",
        },
        "first_call_s": {
            "ceiling": FLOOR_FIRST_CALL_S, "value": cold.get("first_call_total_s"),
            "met": (None if cold.get("first_call_total_s") is None
                    else bool(cold["first_call_total_s"] <= FLOOR_FIRST_CALL_S)),
            "definition": "import plus the first simulate of the paper's model in a new "
                          "process with an empty numba cache",
        },
        "tube_form_issue68": {
            "floor": FLOOR_TUBE_RELATIVE, "value": tube_ratio,
            "met": _met(tube_ratio, FLOOR_TUBE_RELATIVE),
            "form": TUBE_DISCOVERY_FORM,
            "accuracy_ceiling_percent_of_range": ACCURACY_FLOOR_PERCENT,
            "accuracy_percent_of_range": tube_err_pct,
            "definition": "sim-s/s of the tube form discovery tries (DiscoverySettings' "
                          "forms.tube_line_form) over the paper model's, section 4, the "
                          "same run; its error against the tight preset",
        },
        "speedup_vs_lsoda_fixed": {
            "floor": FLOOR_SPEEDUP_LSODA_FIXED, "value": sp_fixed,
            "met": _met(sp_fixed, FLOOR_SPEEDUP_LSODA_FIXED), "case": FIXED_CASE},
        "speedup_vs_lsoda_moving": {
            "floor": FLOOR_SPEEDUP_LSODA_MOVING, "value": sp_moving,
            "met": _met(sp_moving, FLOOR_SPEEDUP_LSODA_MOVING), "case": MOVING_CASE},
    }
    acc = {k: _get(v, "pneubayes", "max_abs_error_vs_radau_percent_of_range")
           for k, v in per_case.items()}
    accuracy_check = {
        "floor_percent_of_range": ACCURACY_FLOOR_PERCENT,
        "per_case_percent_of_range": acc,
        "met": (None if any(v is None for v in acc.values())
                else all(v <= ACCURACY_FLOOR_PERCENT for v in acc.values())),
        "note": "informational; SolverConfig.standard()'s documented accuracy against Radau "
                "rtol 1e-10, not one of the issue's speed floors",
    }

    try:
        threading_layer = numba.threading_layer()
    except Exception:  # noqa: BLE001
        threading_layer = None
    try:
        affinity = len(os.sched_getaffinity(0))
    except Exception:  # noqa: BLE001
        affinity = None
    total_s = time.perf_counter() - run_start
    load_end = _loadavg()
    reference_end = machine_reference_ns()
    if load_start is not None and load_start[0] > LOAD_WARN:
        notes.append(f"the 1-min load average was {load_start[0]:.2f} when the run started: "
                     "other processes were using the CPUs, so timings (especially the "
                     "2-thread ones) may be pessimistic and noisy.")
    report = {
        "schema": SCHEMA,
        "sim_seconds_per_second_per_core": headline,
        "sim_seconds_per_second_per_core_by_case": by_case,
        "sim_seconds_per_second_per_core_batched": headline_b64,
        "sim_seconds_per_second_per_core_batched_by_case": by_case_b64,
        "speedup_vs_lsoda_fixed": sp_fixed,
        "speedup_vs_lsoda_moving": sp_moving,
        "floors": floors,
        "all_floors_met": (None if any(f["met"] is None for f in floors.values())
                           else all(f["met"] for f in floors.values())),
        "cold_start": cold,
        "accuracy_check": accuracy_check,
        "cases": per_case,
        "throughput": throughput,
        "effect_forms": effect_costs,
        "setup": {
            "duration_s": sim_s, "sample_rate_Hz": SAMPLE_RATE_HZ, "samples": n,
            "initial_pressure_Pa": P_ATM, "supply_pressure_Pa": P_SUPPLY,
            "atmospheric_pressure_Pa": P_ATM, "working_range_Pa": working_range,
            "bore_m": BORE_M, "stroke_m": STROKE_M,
            "command": {"kind": "random steps, zero-order hold", "hold_ms": list(HOLD_MS),
                        "level_V": list(LEVEL_V), "min_V": float(command.min()),
                        "max_V": float(command.max()),
                        "steps": int(np.count_nonzero(np.diff(command)))},
            "motion": {"kind": "sum of sinusoids, amplitude ~ f^-0.2, random phases",
                       "frequencies_Hz": list(MOTION_FREQS_HZ),
                       "max_speed_target_m_per_s": MAX_PISTON_SPEED,
                       "stroke_margin_m": STROKE_MARGIN_M},
            "model_effects": list(model.effect_names), "valve": "valve1",
            "leak_area_m2": LEAK_AREA_M2,
            "base_parameters": {k: cases[k]["params"] for k in cases},
            "parameter_perturbation": f"uniform multiplicative 1 +- {PERTURB:g}, clipped to "
                                      "bounds; row 0 is the base vector; batch B uses "
                                      "the first B rows",
            "solver": solver.to_dict(),
            "scipy": {"baseline_rtol": SCIPY_RTOL, "baseline_atol_Pa": SCIPY_ATOL_PA,
                      "reference": "Radau", "reference_rtol": RADAU_RTOL,
                      "reference_atol_Pa": RADAU_ATOL_PA,
                      "horizon_s": scipy_horizon, "chunk_s": SCIPY_CHUNK_S,
                      "budget_s_per_run": args.scipy_budget,
                      "speed_compared": "per simulated second"},
            "timing": {"statistic": "median", "min_total_s": min_total, "min_reps": min_reps,
                       "warm": "one untimed call before timing; gc disabled while timing"},
        },
        "metadata": {
            "seed": args.seed, "quick": quick, "argv": sys.argv if argv is None else list(argv),
            "git": _git_revision(),
            "python": sys.version.split()[0], "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__,
            "platform": platform.platform(), "machine": platform.machine(),
            "processor": platform.processor() or None,
            "cpu_count": os.cpu_count(), "cpu_affinity": affinity,
            "numba_num_threads": threads_available, "numba_threading_layer": threading_layer,
            "first_call_s": first_call_s,
            "timestamp_utc": started.isoformat(timespec="seconds"),
            "loadavg_at_start": load_start, "loadavg_at_end": load_end,
            "reference_loop_ns": [reference_start, reference_end],
            "total_runtime_s": total_s,
        },
        "notes": notes,
    }
    write_json_atomic(args.json, report)
    print(format_table(report))
    print(f"\nwrote {args.json} ({total_s:.1f} s)")
    return 0


# ----------------------------------------------------------------------------- table
def _f(v, fmt, width):
    return f"{'-':>{width}}" if v is None else f"{v:{width}{fmt}}"


def format_table(r):
    s = r["setup"]
    m = r["metadata"]
    L = []
    L.append(f"pneubayes simulate benchmark  seed={m['seed']}  quick={m['quick']}  "
             f"git={(m['git'].get('revision') or '?')[:12]}"
             f"{' (dirty)' if m['git'].get('dirty') else ''}")
    L.append(f"python {m['python']}  numpy {m['numpy']}  scipy {m['scipy']}  numba "
             f"{m['numba']}  cpus {m['cpu_count']}  numba threads {m['numba_num_threads']}"
             f" ({m['numba_threading_layer']})  load at start "
             f"{(m['loadavg_at_start'] or ['?'])[0]}"
             + (f"  reference loop {m['reference_loop_ns'][0]:.1f} / "
                f"{m['reference_loop_ns'][1]:.1f} ns (start / end)"
                if m.get("reference_loop_ns") else ""))
    L.append(f"{s['duration_s']:g}-s trajectories at {s['sample_rate_Hz']:g} Hz, random steps; "
             f"error = max |p - Radau(rtol 1e-10)| over {s['scipy']['horizon_s']:g} s; "
             f"range {s['working_range_Pa']:g} Pa")
    L.append("")
    L.append("1) pneubayes, 1 thread (median wall per trajectory)")
    L.append(f"{'case':<14}{'V0 m^3':>9}{'ms/traj':>10}{'sim-s/s':>10}{'kernel':>10}"
             f"{'b64 sim-s/s':>13}{'err Pa':>10}{'% range':>10}")
    for name, c in r["cases"].items():
        pb, b = c["pneubayes"], c["pneubayes_batch64"]
        ms = None if pb.get("median_s") is None else 1e3 * pb["median_s"]
        L.append(f"{name:<14}{c['dead_volume_m3']:>9.1e}{_f(ms, '.3f', 10)}"
                 f"{_f(pb.get('sim_seconds_per_second'), '.0f', 10)}"
                 f"{_f(pb.get('kernel_only_sim_seconds_per_second'), '.0f', 10)}"
                 f"{_f(b.get('sim_seconds_per_second'), '.0f', 13)}"
                 f"{_f(pb.get('max_abs_error_vs_radau_Pa'), '.2f', 10)}"
                 f"{_f(pb.get('max_abs_error_vs_radau_percent_of_range'), '.4f', 10)}")
        if c.get("moving"):
            L.append(f"{'':<14}piston {c['position_min_m'] * 1e3:.2f}-"
                     f"{c['position_max_m'] * 1e3:.2f} mm, max speed "
                     f"{c['max_piston_speed_m_per_s']:.3f} m/s")
    L.append("  (kernel = compiled kernel alone, without the Python wrapper: diagnostic)")
    for name, c in r["cases"].items():
        d = c.get("pneubayes_dense", {})
        if d.get("sim_seconds_per_second") is not None:
            L.append(f"  {name}: with dense output "
                     f"{_f(d.get('sim_seconds_per_second'), '.0f', 0).strip()} sim-s/s, "
                     f"error {_f(d.get('max_abs_error_vs_radau_Pa'), '.2f', 0).strip()} Pa")
    for name, c in r["cases"].items():
        same = c.get("pneubayes_batch64_identical", {})
        if same.get("ratio_to_batch1") is not None:
            L.append(f"  {name}: 64 copies of the base vector in one call: "
                     f"{1e3 * same['wall_per_trajectory_s']:.3f} ms per trajectory = "
                     f"{same['ratio_to_batch1']:.2f} x batch 1")
    L.append("")
    L.append("   scipy solve_ivp (rtol 1e-6, atol 1e-3 Pa) and Radau reference")
    L.append(f"{'case':<14}{'solver':<7}{'horizon s':>10}{'wall s':>9}{'s/sim-s':>9}"
             f"{'speedup':>10}{'err Pa':>10}{'% range':>9}  status")
    for name, c in r["cases"].items():
        rows = [("Radau", c["reference_radau"])] + list(c["scipy"].items())
        for meth, x in rows:
            status = ("FAILED: " + (x["error"] or "")[:40] if x["failed"]
                      else "NaN" if x["returned_nan"]
                      else "shortened (budget)" if x["shortened_by_budget"] else "ok")
            L.append(f"{name:<14}{meth:<7}{x['horizon_s']:>10.3f}{x['wall_s']:>9.2f}"
                     f"{_f(x.get('wall_per_simulated_second_s'), '.2f', 9)}"
                     f"{_f(x.get('speedup_of_pneubayes'), '.0f', 10)}"
                     f"{_f(x.get('max_abs_diff_vs_radau_Pa'), '.2f', 10)}"
                     f"{_f(x.get('max_abs_diff_vs_radau_percent_of_range'), '.4f', 9)}  "
                     f"{status}")
    for name, c in r["cases"].items():
        for meth, x in c.get("scipy_user_rhs", {}).items():
            if x.get("failed"):
                L.append(f"{name:<14}{meth + '*':<7}  FAILED: {(x.get('error') or '')[:50]}")
                continue
            L.append(f"{name:<14}{meth + '*':<7}{x['horizon_s']:>10.3f}{x['wall_s']:>9.2f}"
                     f"{_f(x.get('wall_per_simulated_second_s'), '.2f', 9)}"
                     f"{_f(x.get('speedup_of_pneubayes'), '.0f', 10)}"
                     f"{_f(x.get('max_abs_diff_vs_radau_Pa'), '.2f', 10)}"
                     f"{_f(x.get('max_abs_diff_vs_radau_percent_of_range'), '.4f', 9)}  ok")
    L.append("  (* = solve_ivp on a lean NumPy right-hand side written as a user would, "
             "not the toolkit's reference one)")
    L.append("  (speedup = scipy wall per simulated second / pneubayes wall per simulated "
             "second)")
    L.append("")
    L.append(f"2) throughput, {r['throughput'][0]['case']}, perturbed parameter sets")
    L.append(f"{'batch':>6}{'threads':>8}{'wall/call s':>13}{'reps':>6}{'sim-s/s':>12}"
             f"{'per core':>11}")
    for row in r["throughput"]:
        if "skipped" in row:
            L.append(f"{row['batch']:>6}{row['threads']:>8}  skipped: {row['skipped']}")
            continue
        L.append(f"{row['batch']:>6}{row['threads']:>8}"
                 f"{_f(row.get('wall_per_call_s'), '.5f', 13)}"
                 f"{row.get('repetitions', 0):>6}"
                 f"{_f(row.get('sim_seconds_per_second'), '.0f', 12)}"
                 f"{_f(row.get('sim_seconds_per_second_per_core'), '.0f', 11)}")
    cold = r.get("cold_start", {})
    L.append("")
    L.append("3) cold start (new process, empty numba cache)")
    if "error" in cold:
        L.append(f"  FAILED: {cold['error'][:200]}")
    for key, label in (("import_s", "import"),
                       ("first_simulate_s", "first simulate, paper's model (compiles)"),
                       ("first_call_total_s", "import + first simulate"),
                       ("first_batched_two_threads_s", "then first batched call, 2 threads"),
                       ("first_general_form_s", "then first heat-transfer model")):
        if cold.get(key) is not None:
            L.append(f"  {label:<50}{cold[key]:>8.1f} s")
    L.append("")
    L.append(f"4) each effect form beside the paper's model, {FIXED_CASE}, batch 1, "
             "1 thread, bench defaults")
    L.append(f"{'form':<24}{'sim-s/s':>10}{'x paper model':>15}{'err vs tight Pa':>17}")
    for row in r.get("effect_forms", []):
        if "error" in row:
            L.append(f"{row['form']:<24}  FAILED: {row['error'][:60]}")
            continue
        err = row.get("max_abs_error_vs_reference_preset_Pa")
        L.append(f"{row['form']:<24}{_f(row.get('sim_seconds_per_second'), '.0f', 10)}"
                 f"{_f(row.get('relative_to_paper_model'), '.4f', 15)}"
                 + ("" if err is None else _f(err, '.1f', 17)))
    L.append("")
    L.append("headline")

    def met(x):
        return "n/a" if x is None else ("MET" if x else "NOT MET")

    fl = r["floors"]
    rows = [
        ("sim_seconds_per_second_per_core (min over volumes, batch 1, 1 thread)",
         r["sim_seconds_per_second_per_core"], fl["sim_seconds_per_second_per_core"]),
        ("sim_seconds_per_second_per_core_batched (min over volumes, batch 64)",
         r["sim_seconds_per_second_per_core_batched"], None),
        ("batch 1 sim-s/s, issue 23's floor (min over volumes)",
         r["sim_seconds_per_second_per_core"], fl["batch1_sim_seconds_per_second_issue23"]),
        (f"speedup_vs_lsoda_fixed  ({fl['speedup_vs_lsoda_fixed']['case']})",
         r["speedup_vs_lsoda_fixed"], fl["speedup_vs_lsoda_fixed"]),
        (f"speedup_vs_lsoda_moving ({fl['speedup_vs_lsoda_moving']['case']})",
         r["speedup_vs_lsoda_moving"], fl["speedup_vs_lsoda_moving"]),
    ]
    for label, value, floor in rows:
        tail = "" if floor is None else f"  floor {floor['floor']:>6.0f}  {met(floor['met'])}"
        L.append(f"  {label:<72}{_f(value, '.0f', 8)}{tail}")
    for key, label, fmt in (("batch64_over_batch1_per_trajectory",
                             "batch-64 / batch-1 cost per trajectory (max over volumes)", ".2f"),
                            ("first_call_s", "first call on a fresh install, s", ".1f")):
        f = fl[key]
        L.append(f"  {label:<72}{_f(f['value'], fmt, 8)}  ceiling {f['ceiling']:>4g}  "
                 f"{met(f['met'])}")
    tube = fl.get("tube_form_issue68")
    if tube is not None:
        label = f"issue 68: {tube['form']} x the paper model's sim-s/s"
        L.append(f"  {label:<72}{_f(tube['value'], '.4f', 8)}  floor {tube['floor']:>4g}  "
                 f"{met(tube['met'])}")
    a = r["accuracy_check"]
    label = f"accuracy: max error <= {a['floor_percent_of_range']:g} % of range in every case"
    L.append(f"  {label:<72}{'':>8}  {met(a['met'])}")
    if r["notes"]:
        L.append("")
        L.append("notes")
        L.extend(f"  - {x}" for x in r["notes"])
    return "\n".join(L)


if __name__ == "__main__":
    sys.exit(main())
