"""The general kernel's largest callees, compiled on their own (``pneubayes compile``).

numba compiles the functions a compiled function calls before the function itself and
caches each of them on its own; a process that compiles the caller later loads them
from the cache. :func:`compile_general_callees` compiles the general kernel's largest
callees (the wave tube's window end, the acoustic line's step, the chamber's right-hand
side with and without its Jacobian, the heat-transfer, tank and second-compartment
steps), so that ``pneubayes compile``'s second process shares the general kernel's
compile with the first (:func:`pneubayes.simulation.precompile.compile_kernels`).

The argument types below must be the ones the kernel passes (a different signature is a
second compiled copy, shared with nothing): every float a float64, the counts int64,
the arrays C-contiguous float64, the kernel's ``general`` flag a (non-literal) bool,
the Jacobian switch a literal. ``tests/test_precompile.py`` checks it.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from pneubayes.simulation.chamber import chamber_rhs
from pneubayes.simulation.line import line_step, line_workspace
from pneubayes.simulation.lung import lung_step
from pneubayes.simulation.tank import tank_step
from pneubayes.simulation.thermal import thermal_step
from pneubayes.simulation.wave import wave_constants, wave_window_end, wave_workspace

#: The callees :func:`compile_general_callees` compiles, in the order it compiles them
#: (the order the kernel's compile reaches them in).
CALLEES = (wave_window_end, line_step, chamber_rhs, thermal_step, tank_step, lung_step)


@njit
def _typed_calls(n, flag, x):
    """Calls each of :data:`CALLEES` with the kernel's argument types (``n < 0``: never
    runs them; compiling this compiles them)."""
    if n >= 0:
        return
    f = x[0]
    sl, cs, carry = np.empty(n), np.empty(n), np.empty(n)
    hist, ring, w_rd, w_row = wave_workspace(flag)
    w_work = (hist, ring, np.zeros(n), w_rd, w_row)
    tube = wave_constants(sl, cs)  # (typed as the kernel's, whatever its length)
    wave_window_end(w_work, tube, (f, f, f, f, f), carry, f, f, f, f, f, f, f, cs)
    y, y_new, prop = np.empty(n), np.empty(n), np.empty((n, n))
    line_step(y, n, f, f, f, f, f, f, f, f, f, f, f, f, f, sl, cs, f, f, f, y_new, prop,
              line_workspace(n))
    chamber_rhs(f, f, f, f, f, f, f, sl, cs, f, True, f, f, f, f, f, f, flag)
    chamber_rhs(f, f, f, f, f, f, f, sl, cs, f, False, f, f, f, f, f, f, flag)
    thermal_step(f, f, f, f, f, f, f, f, f, f, f, f, f, f, f, sl, cs, f, f, f, f, f, f, f,
                 flag)
    tank_step(f, f, f, f, f, f, f, f, f, f, f, f, sl, cs, f, f, f, f, f, f, f, flag)
    lung_step(f, f, f, f, f, f, f, f, f, f, f, f, f, f, f, sl, cs, f, f, f, f, f, f, flag)


def compile_general_callees() -> float:
    """Compile (or load from the cache) :data:`CALLEES` with the general kernel's
    argument types; returns the seconds it took."""
    start = time.perf_counter()
    _typed_calls(0, True, np.zeros(1))
    return time.perf_counter() - start
