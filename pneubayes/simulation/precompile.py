"""Compile the simulator's kernels ahead of their first use (``pneubayes compile``).

numba compiles the simulation kernel the first time it runs and keeps the machine code
in its on-disk cache beside the package (:mod:`pneubayes.compile_cache`). On a fresh
install the first simulation therefore waits for the compiler: about a minute and a half
on one core for all four variants below. Compiling them once after installing, the
variants in separate processes at once, moves that wait out of the first fit and lets
several later processes (test workers, ablation workers) load the same cache instead of
each compiling its own copy.

The kernel has two compiled variants: the chamber's pressure alone, or the *general*
kernel with a second state (heat transfer, an acoustic or wave line, a supply tank, a
second compartment), an open-form closure or one of the rarer forms
(:func:`pneubayes.simulation.kernel.needs_general`); the same compiled loop runs on one
thread or on several (:func:`pneubayes.simulation.kernel._run_tasks`). Per state there
is also the carried chain (:func:`pneubayes.simulation.simulate_carried`, the
online tracker's carried mode; on the calling thread). The virtual test bench's plant
(:mod:`pneubayes.bench.plant`, ``pneubayes bench``) is compiled too, as a third entry.

:func:`compile_variant` builds one state's two loops (or the bench's plant) by running a
tiny simulation of it; :func:`compile_kernels` runs them in parallel processes, the
general kernel's largest callees (:mod:`pneubayes.simulation.general_callees`) in the
second process while the first compiles that kernel, which then loads them from the
cache: the general kernel's compile, the longest, is shared by both.
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from multiprocessing import get_context

import numpy as np

from pneubayes.compile_cache import assume_first_calls, hold_first_calls, kernel_first_call
from pneubayes.simulation.general_callees import compile_general_callees

#: What :func:`compile_variant` compiles: the kernel's states (which model compiles
#: each: its effects) and the bench's plant.
STATES = ("pressure", "general", "bench")
#: :func:`compile_kernels`' job compiling the general kernel's largest callees beside it.
CALLEES_JOB = "general callees"


def first_call_names(state: str) -> tuple[str, ...]:
    """The first-call locks (:func:`pneubayes.compile_cache.first_call`) of what
    :func:`compile_variant` compiles for ``state``."""
    if state == "bench":  # its first call is a whole recording: not worth a wait
        return ()
    general = state == "general"
    return kernel_first_call("simulate", general), kernel_first_call("carried", general)


def compile_variant(state: str, locks_held_by_caller: bool = False) -> float:
    """Compile (or load from the cache) the kernel stepping ``state`` (one of
    :data:`STATES`) and its carried chain, or (``"bench"``) the bench's plant; returns
    the seconds it took. ``locks_held_by_caller``: the process that started this one
    holds the variant's first-call locks (:func:`compile_kernels`), so this one must
    not wait on them."""
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.rig import Rig
    from pneubayes.simulation import (
        Inputs,
        SolverConfig,
        fresh_carry,
        simulate,
        simulate_carried,
    )

    if state not in STATES:
        raise ValueError(f"state must be one of {STATES}, got {state!r}")
    if locks_held_by_caller:
        assume_first_calls(first_call_names(state))
    start = time.perf_counter()
    supply_Pa, atmosphere_Pa = 551325.0, 101325.0
    rig = Rig(0.009, atmosphere_Pa, supply_Pa, stroke_m=0.03)
    t = np.arange(21) * 1e-3
    inputs = Inputs(t, np.where(t < 0.01, 3.0, -3.0), np.zeros_like(t),
                    np.full_like(t, supply_Pa))
    values = dict(valve_preset("valve1").parameters(), dead_volume_m3=2.4e-6,
                  heat_transfer_rate_per_s=20.0, heat_transfer_coupling=1.0)
    if state == "bench":
        from pneubayes.bench.plant import PlantConfig, simulate_plant

        base = {k: v for k, v in values.items() if not k.startswith("heat_transfer")}
        simulate_plant(base, (), inputs, rig, 2e5, PlantConfig.reference())
        # an implicit method calls the plant's Jacobian, which LSODA's stiff switch does
        # on a small chamber: compiled here, not in the first such recording
        stiff = replace(PlantConfig.reference(), method="Radau")
        simulate_plant(base, (), inputs, rig, 2e5, stiff)
        return time.perf_counter() - start
    model = Model(["heat_transfer"] if state == "general" else [])
    row = [values[name] for name in model.parameter_names]
    simulate(model, np.array([row]), inputs, rig, 2e5, SolverConfig.standard())
    simulate_carried(model, np.array([row]), inputs, rig, [0, 10, 20], 2e5, fresh_carry(1, rig),
                     np.full(t.shape, 2e5), 1.0, SolverConfig.standard())
    return time.perf_counter() - start


def compile_kernels(jobs: int = 2) -> dict[str, float]:
    """Compile every variant of the kernel and the bench's plant, in up to ``jobs``
    processes at once; returns the seconds each took (its process's own wall time), with
    more than one job also those of the general kernel's callees (:data:`CALLEES_JOB`).

    It holds each variant's first-call lock until that variant is in the cache
    (:mod:`pneubayes.compile_cache`): a process starting cold beside it waits for the
    variant it needs instead of compiling its own copy."""
    if not isinstance(jobs, int) or isinstance(jobs, bool) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    names = {state: first_call_names(state) for state in STATES}
    # no wait for a lock another process holds (another compile: both then compile; a
    # child re-running a script's unguarded call must reach multiprocessing's error)
    with hold_first_calls([n for state in STATES for n in names[state]],
                          wait_s=0.0) as release:
        if jobs == 1:
            seconds = {}
            for state in STATES:
                seconds[state] = compile_variant(state)
                for name in names[state]:
                    release(name)
            return seconds
        # fresh interpreters: a forked child would inherit this process's numba state.
        # The second process first compiles the general kernel's largest callees, which
        # the first loads from the cache when its compile reaches them
        # (:mod:`pneubayes.simulation.general_callees`); the shorter jobs follow.
        with ProcessPoolExecutor(max_workers=min(jobs, len(STATES) + 1),
                                 mp_context=get_context("spawn")) as pool:
            futures = {pool.submit(compile_variant, "general", True): "general",
                       pool.submit(compile_general_callees): CALLEES_JOB}
            futures.update({pool.submit(compile_variant, state, True): state
                            for state in STATES if state != "general"})
            seconds = {}
            for done in as_completed(futures):
                seconds[futures[done]] = done.result()
                for name in names.get(futures[done], ()):
                    release(name)
            return {job: seconds[job] for job in (*STATES, CALLEES_JOB)}
