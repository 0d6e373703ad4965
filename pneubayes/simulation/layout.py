"""Layouts of the constant and solver vectors the compiled simulator reads.

Built by :mod:`pneubayes.simulation.simulator`; read by :mod:`kernel` and :mod:`line`.
"""

# Constant-vector layout (rig and gas).
C_BORE_AREA, C_P_ATM, C_P_NOM, C_T_SUPPLY, C_ALPHA, C_BETA, C_THETA, C_KAPPA, C_RS = range(9)
N_CONSTS = 9
# Solver-vector layout (SolverConfig.as_array); the kernel reads an optional seventh
# entry, S_DENSE > 0: steps may cross samples where the inputs hold (dense output;
# SolverConfig.dense_output).
S_RTOL, S_ATOL_P, S_ATOL_T, S_MAX_STEP, S_MIN_STEP, S_MAX_STEPS_PER_S, S_DENSE = range(7)
N_SOLVER = 6
