"""Layouts of the constant and solver vectors the compiled simulator reads.

Built here (:func:`rig_constants`) and by :mod:`pneubayes.simulation.simulator`; read by
:mod:`kernel` and :mod:`line`.
"""

import numpy as np

# Constant-vector layout (rig and gas).
C_BORE_AREA, C_P_ATM, C_P_NOM, C_T_SUPPLY, C_ALPHA, C_BETA, C_THETA, C_KAPPA, C_RS = range(9)
N_CONSTS = 9
# Solver-vector layout (SolverConfig.as_array); the kernel reads an optional seventh
# entry, S_DENSE > 0: steps may cross samples where the inputs hold (dense output;
# SolverConfig.dense_output).
S_RTOL, S_ATOL_P, S_ATOL_T, S_MAX_STEP, S_MIN_STEP, S_MAX_STEPS_PER_S, S_DENSE = range(7)
N_SOLVER = 6


def rig_constants(rig) -> np.ndarray:
    """A :class:`~pneubayes.rig.Rig`'s and its gas's constants in the kernel's layout."""
    g = rig.gas
    c = np.empty(N_CONSTS)
    c[C_BORE_AREA] = rig.bore_area_m2
    c[C_P_ATM] = rig.atmospheric_pressure_Pa
    c[C_P_NOM] = rig.supply_pressure_Pa
    c[C_T_SUPPLY] = g.temperature_K
    c[C_ALPHA] = g.alpha_s_per_m
    c[C_BETA] = g.beta_s_per_m
    c[C_THETA] = g.theta
    c[C_KAPPA] = g.heat_capacity_ratio
    c[C_RS] = g.specific_gas_constant_J_per_kg_K
    return c
