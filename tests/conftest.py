"""Shared fixtures of the numerical test-suite.

Everything "independent" in here (gas constants, flow function, Gompertz map, chamber
right-hand side) is written with plain ``math`` from the paper's formulas (section III
and the appendix) and deliberately does not call into :mod:`pneubayes.physics`, so a
mistake there cannot cancel out in a comparison.
"""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pneubayes.io.recording import Recording, RecordingMetadata
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig

P_ATM = 101325.0
P_SUP = 551325.0
WORKING_RANGE = P_SUP - P_ATM  # 450 kPa, the denominator of Table III's percentages
BORE = 0.009
STROKE = 0.03  # m: moving_position's default sine stays inside it

# Table IV (appendix) and NOTES.md temperature.
C_DIS, Z_CMP, M_AIR, R_GAS, KAPPA, T_GAS = 0.72, 0.99, 0.029, 8.31, 1.4, 293.15


# ---------------------------------------------------------------- independent physics
def hand_gas():
    """alpha, beta, theta, Rs from the appendix formulas with plain math."""
    k = KAPPA
    alpha = C_DIS * math.sqrt(2.0 * M_AIR / (Z_CMP * R_GAS * T_GAS) * k / (k - 1.0))
    beta = C_DIS * math.sqrt(k * M_AIR / (Z_CMP * R_GAS * T_GAS)
                             * (2.0 / (k + 1.0)) ** ((k + 1.0) / (k - 1.0)))
    theta = ((k + 1.0) / 2.0) ** (k / (k - 1.0))
    rs = R_GAS / M_AIR
    return SimpleNamespace(alpha=alpha, beta=beta, theta=theta, rs=rs, kappa=k, T=T_GAS)


def hand_z(pu, pd):
    """Eq. 3 for pu >= pd, plain math."""
    g = hand_gas()
    if pu / pd > g.theta:
        return g.beta * pu
    r = pd / pu
    val = r ** (2.0 / g.kappa) - r ** ((g.kappa + 1.0) / g.kappa)
    return g.alpha * pu * math.sqrt(max(val, 0.0))


def hand_flow(pu, pd):
    """Signed eq. 2 with the roles swapped for reverse flow (NOTES.md)."""
    return hand_z(pu, pd) if pu >= pd else -hand_z(pd, pu)


def hand_gompertz(u, offset, a, b, c, d):
    """Eq. 11, plain math."""
    return offset + a * math.exp(-b * math.exp(-c * (u + d)))


def hand_equilibrium(params, supply=P_SUP, atm=P_ATM, u=5.0):
    """Pressure at which the net mass flow of eqs. 4/9 vanishes at a held command (brentq)."""
    from scipy.optimize import brentq

    a_in = hand_gompertz(u, params["inlet_offset_m2"], params["inlet_a_m2"], params["inlet_b"],
                         params["inlet_c_per_V"], params["inlet_d_V"])
    a_ex = hand_gompertz(u, params["exhaust_offset_m2"], params["exhaust_a_m2"],
                         params["exhaust_b"], params["exhaust_c_per_V"], params["exhaust_d_V"])
    a_l = params.get("leak_area_m2", 0.0)

    def net(p):
        return a_in * hand_flow(supply, p) - (a_ex + a_l) * hand_flow(p, atm)

    return brentq(net, atm * (1 + 1e-12), supply * (1 - 1e-12), xtol=1e-6, rtol=1e-14)


def hand_reference(params, t, u, x, supply, p0, bore=BORE, rtol=1e-10, atol=1e-6):
    """Independent Radau solution of eqs. 1-5, 9 and 11 (thin port + orifice leak).

    Command zero-order held, position and supply linear between samples, solved per
    sample interval. Plain-math right-hand side; no pneubayes code is used.
    """
    g = hand_gas()
    area = math.pi / 4.0 * bore * bore
    ins = [params[f"inlet_{n}"] for n in ("offset_m2", "a_m2", "b", "c_per_V", "d_V")]
    exs = [params[f"exhaust_{n}"] for n in ("offset_m2", "a_m2", "b", "c_per_V", "d_V")]
    v0 = params["dead_volume_m3"]
    a_l = params.get("leak_area_m2", 0.0)
    out = np.empty(len(t))
    out[0] = p = float(p0)
    for k in range(len(t) - 1):
        ta, tb = float(t[k]), float(t[k + 1])
        a_in = hand_gompertz(u[k], *ins)
        a_ex = hand_gompertz(u[k], *exs)
        vdot = area * (x[k + 1] - x[k]) / (tb - ta)
        sa, sb, xa = float(supply[k]), float(supply[k + 1]), float(x[k])

        def rhs(tt, y, a_in=a_in, a_ex=a_ex, vdot=vdot, ta=ta, tb=tb, sa=sa, sb=sb, xa=xa):
            pp = y[0]
            fr = (tt - ta) / (tb - ta)
            vol = v0 + area * xa + vdot * (tt - ta)
            ps = sa + fr * (sb - sa)
            mdot = a_in * hand_flow(ps, pp) - (a_ex + a_l) * hand_flow(pp, P_ATM)
            return [g.kappa / vol * (g.rs * g.T * mdot - pp * vdot)]

        sol = solve_ivp(rhs, (ta, tb), [p], method="Radau", rtol=rtol, atol=atol)
        assert sol.success, sol.message
        p = float(sol.y[0, -1])
        out[k + 1] = p
    return out


# ---------------------------------------------------------------- input generators
def random_steps(rng, n, dt, hold_s=(0.03, 0.3), levels=(-5.0, 5.0)):
    """Random step command: holds uniform in ``hold_s`` seconds, levels uniform."""
    u = np.empty(n)
    i = 0
    while i < n:
        hold = max(1, int(round(rng.uniform(*hold_s) / dt)))
        u[i:i + hold] = rng.uniform(*levels)
        i += hold
    return u


def moving_position(t, mean=0.015, amp=0.01, freq=2.0):
    """A sinusoidal piston position, m (moves the volume by ~ +-6.4e-7 m^3 at 9 mm bore)."""
    return mean + amp * np.sin(2.0 * np.pi * freq * np.asarray(t))


def fluctuating_supply(t, nominal=P_SUP, amp=15_000.0):
    """A supply column that wanders around the nominal (two sines), Pa."""
    t = np.asarray(t)
    return nominal + amp * (0.7 * np.sin(2 * np.pi * 1.3 * t) + 0.3 * np.sin(2 * np.pi * 7.1 * t))


def moving_step_inputs(seed, n, dt, **kw):
    """``n`` samples every ``dt`` s: random steps (``random_steps``'s options) on a piston
    moving at 3 Hz with a fluctuating supply."""
    t = np.arange(n) * dt
    u = random_steps(np.random.default_rng(seed), n, dt, **kw)
    return Inputs(t, u, moving_position(t, freq=3.0), fluctuating_supply(t))


def valve1_params(volume=2.4e-6, **extra):
    """Valve 1 of Table II with a dead volume of ``volume`` m^3 and ``extra`` values."""
    return {**valve_preset("valve1").parameters(), "dead_volume_m3": volume, **extra}


def valve1_recordings(model, params, name, seed0, count=3, n=6001, read=None):
    """``count`` recordings of ``n`` samples at 1 kHz from the atmosphere (AIR37, valve
    1, fixed piston at 15 mm; random command steps held 0.1-0.6 s): ``model`` at
    ``params`` simulated, each reading passed through ``read`` (None: as it is) with
    200 Pa of noise; recording ``i`` seeded ``seed0 + i`` and named ``{name}_{i}.csv``."""
    from pneubayes.simulation import simulate

    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    recs = []
    for i in range(count):
        rng = np.random.default_rng(seed0 + i)
        t = np.arange(n) * 1e-3
        u = random_steps(rng, n, 1e-3, hold_s=(0.1, 0.6))
        blank = Recording(md, t, u, np.full(n, P_ATM))
        p = simulate(model, params, Inputs.from_recording(blank), blank.rig(), P_ATM,
                     SolverConfig.standard()).pressure_Pa[0]
        p = p if read is None else read(p)
        recs.append(Recording(md, t, u, p + rng.normal(0.0, 200.0, n),
                              source=f"{name}_{i}.csv"))
    return recs


def tight_solver(rtol: float = 1e-8) -> SolverConfig:
    """A solver far tighter than the standard preset, for checks against a reference
    solver: ``rtol`` and an absolute pressure tolerance of ``rtol`` x 1e5 Pa."""
    return SolverConfig(rtol=rtol, atol_Pa=rtol * 1e5, atol_K=1e-6, max_step_s=0.02,
                        min_step_s=1e-14, max_steps_per_s=2.5e7)


def heat_beside_line(heat, params, steps, rig, switched_off: dict) -> tuple[float, float]:
    """The heat form ``heat`` behind a 3-cell acoustic line (2 ms, 1.5-mm bore) over the
    first 111 samples of ``steps``, from 2e5 Pa: ``(largest |Radau - the compiled
    simulator with switched_off's values|, largest |compiled - Radau|)``, Pa: how far the
    part switched off moves the pressure, and how closely the compiled simulator follows
    the reference (tolerance 1e-9, Radau at 1e-10)."""
    from pneubayes.effects import TubeDelay
    from pneubayes.model import Model
    from pneubayes.simulation import Inputs, simulate
    from pneubayes.simulation.reference import reference_simulate

    steps = Inputs(steps.time_s[:111], steps.command_V[:111], steps.position_m[:111],
                   steps.supply_pressure_Pa[:111])
    model = Model([heat, TubeDelay(form="line", segments=3)])
    params = dict(params, tube_delay_s=0.002, tube_diameter_m=0.0015)
    params = {k: v for k, v in params.items() if k in model.parameter_names}
    ref = reference_simulate(model, params, steps, rig, 2e5, rtol=1e-10)
    got = simulate(model, params, steps, rig, 2e5, tight_solver(1e-9)).pressure_Pa[0]
    off = simulate(model, dict(params, **switched_off), steps, rig, 2e5,
                   tight_solver(1e-9)).pressure_Pa[0]
    return float(np.max(np.abs(ref - off))), float(np.max(np.abs(got - ref)))


def reference_errors(model, params, inputs, rig, p0: float, rtols=(1e-6, 1e-9),
                     ref_rtol: float = 1e-10):
    """``(ref, errs)``: scipy Radau's trajectory at ``ref_rtol`` and the compiled
    simulator's largest error against it (Pa) at each of ``rtols``
    (:func:`tight_solver`), from ``p0``."""
    from pneubayes.simulation import simulate
    from pneubayes.simulation.reference import reference_simulate

    ref = reference_simulate(model, params, inputs, rig, p0, rtol=ref_rtol)
    errs = [float(np.max(np.abs(simulate(model, params, inputs, rig, p0, tight_solver(r))
                                .pressure_Pa[0] - ref))) for r in rtols]
    return ref, errs


def filling_rhs(sl, cs, p_sup: float, a_in: float = 5e-7):
    """``rhs(p, temp, tt)``: :func:`~pneubayes.simulation.chamber.chamber_rhs` of a
    2.4e-6-m^3 chamber filling through ``a_in`` m^2 (exhaust 1e-8 m^2) from ``p_sup``,
    ``tt`` s from the point with the inlet opening at 4e-5 m^2/s, the supply rising at 3
    MPa/s and the volume growing at 1e-6 m^3/s (the inputs the slopes' ``v`` terms
    follow)."""
    from pneubayes.simulation.chamber import chamber_rhs

    da_in, dsup, vdot = 4e-5, 3e6, 1e-6

    def rhs(p, temp, tt=0.0):
        return chamber_rhs(p, temp, a_in + tt * da_in, 1e-8, 2.4e-6 + tt * vdot, vdot,
                           p_sup + tt * dsup, sl, cs, 1e-5, True, dsup, da_in, 0.0, 0.0,
                           0.0, 0.0, True)
    return rhs


def assert_chamber_slopes(rhs, p: float, temp: float) -> None:
    """The chamber right-hand side's slopes (:func:`~pneubayes.simulation.chamber.
    chamber_rhs`'s ``J_pp``, ``J_Tp``, ``J_pT``, ``J_TT``, ``v_p``, ``v_T``) against
    central differences of ``rhs(p, temp, tt)`` (``tt`` the time from the point, the
    inputs moving with it) at ``(p, temp)``."""
    out = rhs(p, temp)
    d, dt, h = 1.0, 1e-3, 1e-7
    for k, a, b, w, rel in ((1, (p + d, temp), (p - d, temp), d, 1e-5),
                            (6, (p + d, temp), (p - d, temp), d, 1e-5),
                            (5, (p, temp + dt), (p, temp - dt), dt, 1e-5),
                            (3, (p, temp + dt), (p, temp - dt), dt, 1e-5),
                            (4, (p, temp, h), (p, temp, -h), h, 1e-4),
                            (7, (p, temp, h), (p, temp, -h), h, 1e-4)):
        row = 0 if k in (1, 5, 4) else 2  # dp/dt's slopes, then dT/dt's
        assert out[k] == pytest.approx((rhs(*a)[row] - rhs(*b)[row]) / (2 * w), rel=rel), k


def refit_planted(model, truth: dict, name: str, start: float, seed: int) -> float:
    """A planted value of parameter ``name`` refitted alone: 2 s of noise-free fills and
    vents (valve steps of 50 ms at 0.015 m, from 2e5 Pa) simulated at ``truth``, the
    trajectory refinement started with ``name`` at ``start``; returns its estimate."""
    from pneubayes.inference.refine import TrajectoryRefiner
    from pneubayes.simulation import simulate

    t = np.arange(2001) * 1e-3
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-4.0, -0.5, 0.3, 1.0, 4.0], 41), 50)[:t.size]
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    blank = Recording(md, t, u, np.full(t.size, P_ATM))
    p = simulate(model, truth, Inputs.from_recording(blank), blank.rig(), 2e5,
                 tight_solver(1e-9)).pressure_Pa[0]
    fit = TrajectoryRefiner(model, tight_solver(1e-7), 0.5, 0.5, free=[name], max_nfev=40,
                            uncertainty=False).fit([Recording(md, t, u, p)],
                                                   dict(truth, **{name: start}))
    return fit.params_[name]


# ---------------------------------------------------------------- fixtures
@pytest.fixture
def sagging_steps():
    """Steps between full inlet, closed, full exhaust and a half opening, a piston at
    2 Hz and a supply that sags and recovers: 0.15 s."""
    t = np.arange(151) * 1e-3
    u = np.select([t < 0.04, t < 0.06, t < 0.1, t < 0.125], [3.0, 0.0, -3.0, 0.6], -0.6)
    x = 0.05 + 0.01 * np.sin(2 * np.pi * 2 * t)
    return Inputs(t, u, x, P_SUP - 3e4 * np.sin(np.pi * t / 0.15))


@pytest.fixture
def valve_params():
    """Valve 1 of Table II and a 2.4e-6 m^3 dead volume."""
    return {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}


@pytest.fixture(scope="session")
def rig():
    return Rig(BORE, P_ATM, P_SUP, stroke_m=STROKE)


@pytest.fixture(scope="session")
def leak_model():
    return Model(["cylinder_leak"])


@pytest.fixture
def base_params():
    """Valve 1 of Table II, 2.4e-6 m^3 dead volume, AIRPEL leak (orifice form)."""
    v = valve_preset("valve1").parameters()
    v.update(dead_volume_m3=2.4e-6, leak_area_m2=3.04e-8)
    return v


@pytest.fixture(scope="session")
def prn_leak_bench(tmp_path_factory):
    """Two 6-s fixed-volume PRN/valve1 bench recordings with the catalogue's orifice leak
    (seed 3): ``(recordings, model, truth)``."""
    from pneubayes.bench.bench import BenchConfig, run_bench
    from pneubayes.effects import effects_from_names
    from pneubayes.io import read_recording

    out = tmp_path_factory.mktemp("prn_leak_bench")
    cfg = BenchConfig("PRN", "valve1", effects_from_names(["cylinder_leak"]), protocol="fixed",
                      duration_s=6.0, seed=3, positions=(0.5, 0.9), ranges_V=(5.0,))
    res = run_bench(cfg, out)
    model, truth = Model.load_card(res.truth_path)
    return [read_recording(p) for p in res.recordings], model, truth


@pytest.fixture(scope="session")
def standard():
    return SolverConfig.standard()


@pytest.fixture
def step_command():
    """``step_command(seed, n, dt, **kw)``: seeded random step command."""
    def make(seed, n, dt, **kw):
        return random_steps(np.random.default_rng(seed), n, dt, **kw)
    return make


@pytest.fixture
def make_inputs():
    """``make_inputs(t, u, position=0.0 | array, supply=P_SUP | array)``."""
    def make(t, u, position=0.0, supply=P_SUP):
        t = np.asarray(t, dtype=np.float64)
        x = np.broadcast_to(np.asarray(position, np.float64), t.shape).copy()
        s = np.broadcast_to(np.asarray(supply, np.float64), t.shape).copy()
        return Inputs(t, np.asarray(u, np.float64), x, s)
    return make


@pytest.fixture
def closable_params():
    """Base parameters whose valve shuts completely at command 0 (inside the bounds).

    Offsets 0; the inlet opens only for u > ~3 V and the exhaust only for u < ~-3 V
    (d = -3 / +3 V, steep c): at u = 0 both Gompertz terms underflow to exactly 0.
    """
    return {"inlet_offset_m2": 0.0, "inlet_a_m2": 5.5e-7, "inlet_b": 3.5, "inlet_c_per_V": 20.0,
            "inlet_d_V": -3.0, "exhaust_offset_m2": 0.0, "exhaust_a_m2": 6e-7,
            "exhaust_b": 3.5, "exhaust_c_per_V": -20.0, "exhaust_d_V": 3.0,
            "dead_volume_m3": 2.4e-6}


@pytest.fixture(scope="session")
def hand():
    """The independent plain-math physics of this file."""
    return SimpleNamespace(gas=hand_gas, z=hand_z, flow=hand_flow, gompertz=hand_gompertz,
                           equilibrium=hand_equilibrium, reference=hand_reference,
                           random_steps=random_steps, moving_position=moving_position,
                           fluctuating_supply=fluctuating_supply, P_ATM=P_ATM, P_SUP=P_SUP,
                           RANGE=WORKING_RANGE)


def load_experiment(name: str):
    """Import ``experiments/<name>.py`` (scripts, not a package) as a module."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "experiments" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ---------------------------------------------------------------- plausibility recordings
ATM = 101325.0
SUPPLY = 601325.0


def chamber_recording(rate_Hz=1000.0, duration_s=3.0, seed=0, atm=ATM, supply=SUPPLY,
                      tau_s=0.02, noise_Pa=300.0, position=True) -> Recording:
    """A first-order chamber following random full-scale command steps (SI, absolute)."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * rate_Hz) + 1
    t = np.arange(n) / rate_Hz
    hold = int(0.25 * rate_Hz)
    u = np.repeat(rng.choice([-5.0, 5.0], size=n // hold + 1), hold)[:n]
    target = np.where(u > 0, supply, atm)
    p = np.empty(n)
    p[0] = atm
    a = np.exp(-1.0 / (rate_Hz * tau_s))
    for i in range(1, n):
        p[i] = target[i] + (p[i - 1] - target[i]) * a
    md = RecordingMetadata("AIR37", "valve1", 0.009, 0.0375, atm, supply, 293.15)
    pos = 0.0375 * (0.5 + 0.3 * np.sin(2 * np.pi * t)) if position else None
    return Recording(md, t, u, p + rng.normal(0, noise_Pa, n), position_m=pos)


def ventilator_like(seed=0) -> Recording:
    """100 Hz, a few kPa gauge over a 5-kPa blower: unusual but real."""
    rec = chamber_recording(rate_Hz=100.0, duration_s=20.0, seed=seed, supply=ATM + 5e3,
                            tau_s=0.15, noise_Pa=20.0, position=False)
    return replace(rec, pressure_Pa=ATM + 0.7 * (rec.pressure_Pa - ATM))


def discovery_settings(*tables, **groups):
    """A DiscoverySettings with nested tables applied in turn
    (:func:`pneubayes.settings_tree.override`), e.g.
    ``discovery_settings({"rounds": {"max_effects": 1}}, posterior={"method": "none"})``."""
    from pneubayes.discovery.settings import DiscoverySettings
    from pneubayes.settings_tree import override

    s = DiscoverySettings()
    for table in (*tables, groups):
        s = override(s, table)
    return s
