"""Solver settings. There are no hidden defaults: every call takes a SolverConfig, and
results store the one they used. :meth:`SolverConfig.standard` is the documented preset
that meets the accuracy floor (0.1 % of the working range against Radau at rtol 1e-10)
for volumes 1e-7 to 2e-5 m^3; :meth:`SolverConfig.sampling` the same with dense output,
the posterior's preset; :meth:`SolverConfig.refinement` is the fits' least-squares
preset and :meth:`SolverConfig.reference` a tight one for the bench. Each preset is
declared here once.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np


@dataclass(frozen=True)
class SolverConfig:
    """Adaptive-step settings of the exponential integrator.

    Parameters
    ----------
    rtol : float
        Relative tolerance on the local error.
    atol_Pa : float
        Absolute tolerance on pressure, Pa.
    atol_K : float
        Absolute tolerance on temperature (heat-transfer models), K.
    max_step_s : float
        Largest step, s. Steps also stop on every sample and delay break point.
    min_step_s : float
        Smallest step before the integrator gives up, s.
    max_steps_per_s : float
        Step budget per simulated second of a window, beyond the one step every sample
        interval takes at least (a window of duration D s with N samples may take
        N - 1 + max_steps_per_s * D steps). Legitimate 2-s windows take 1-10 steps per
        1-ms sample; a budget that scales with the window lets a fit fail a degenerate
        trial in a second instead of minutes.
    dense_output : bool
        Let a step cross the samples over which the command and the supply the model
        reads hold, and read those samples from the step's interpolant
        (:func:`pneubayes.simulation.simulate_windows`); over a moving piston the step
        reads the position's chord and corrects the samples it crosses and its end for
        the difference (checked against the tolerance); models with a second state or a
        sensor lag step as without it. Fewer steps where commands hold for many samples
        (a controller's candidates, recordings of a model without
        ``supply_fluctuation``), results within the solver's tolerance of the default's.
        Default False; recorded by :meth:`to_dict` only when True, so the identities of
        settings saved before it existed are unchanged.
    """

    rtol: float
    atol_Pa: float
    atol_K: float
    max_step_s: float
    min_step_s: float
    max_steps_per_s: float
    dense_output: bool = False

    def __post_init__(self):
        for name in ("rtol", "atol_Pa", "atol_K", "max_step_s", "min_step_s",
                     "max_steps_per_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"SolverConfig.{name} must be finite and > 0, got {v!r}")
        if self.min_step_s >= self.max_step_s:
            raise ValueError("SolverConfig.min_step_s must be < max_step_s")
        if not isinstance(self.dense_output, (bool, np.bool_)):
            raise TypeError(f"SolverConfig.dense_output must be True or False, got "
                            f"{self.dense_output!r}")

    @classmethod
    def standard(cls) -> "SolverConfig":
        """Preset for fitting and prediction.

        Measured against Radau (rtol 1e-10) by ``benchmarks/solver_accuracy.py`` (1-s
        random-step trajectories, valve2, fixed and moving chambers of 1e-7, 2.4e-6 and
        2e-5 m^3, the paper's model and each of the eight effects alone; seeds 0 and 1):
        at most 33.7 Pa (0.007 % of a 450 kPa range), a thirteenfold margin on the 0.1 %
        floor (:meth:`sampling`: the same cases, at most 43.3 Pa). With wall
        heat exchange (rate 5 and 50 /s, h = 300 W/(m^2 K), 2.4e-7 and 2.4e-6 m^3, moving,
        two seeds): 22-42 Pa; the (p, T) state is stepped with its full Jacobian, so
        tightening converges as fast as for pressure alone.
        """
        return cls(rtol=3e-5, atol_Pa=10.0, atol_K=0.01, max_step_s=0.02, min_step_s=1e-12,
                   max_steps_per_s=2.5e6)

    @classmethod
    def sampling(cls) -> "SolverConfig":
        """Preset for the posterior's likelihood (``FitSettings.sample_solver``): the
        standard tolerances with ``dense_output``.

        On ``benchmarks/mcmc.py``'s data (the paper's model, 4 x 20-s fixed recordings at
        1 kHz, 32 walkers; a quiet machine, one run each): the fit 68 s (114 CPU s) against
        116 s (209 CPU s) with :meth:`standard` (the solver-roughness check tightened it
        once, 0.08 nat, against 0.29 nat untightened), the same 400 steps, R-hat 1.004 /
        1.003, ESS 1441 / 1404, the same interval coverage (12 of 12) and held-out error
        (541 Pa); medians within 0.06 emcee SDs of each other (a loaded run).
        """
        return cls.standard().with_dense_output()

    @classmethod
    def refinement(cls) -> "SolverConfig":
        """Preset for least squares and multiple shooting (``FitSettings.refine_solver``):
        tight tolerances, so the windows are smooth in the parameters for finite
        differences, and a step budget of 1e5 per simulated second, about ten times what
        the costliest legitimate window measured needs (a 0.3-ms acoustic line: 9,000
        steps per second), so a degenerate trial of a fit fails in about a second
        instead of a minute."""
        return cls(rtol=1e-6, atol_Pa=1.0, atol_K=0.01, max_step_s=0.02, min_step_s=1e-12,
                   max_steps_per_s=1e5)

    @classmethod
    def reference(cls) -> "SolverConfig":
        """Tight preset for the virtual bench's ground truth."""
        return cls(rtol=1e-8, atol_Pa=0.01, atol_K=1e-5, max_step_s=0.005, min_step_s=1e-14,
                   max_steps_per_s=2.5e7)

    def tightened(self, factor: float) -> "SolverConfig":
        """The same settings with ``rtol`` and both absolute tolerances divided by
        ``factor`` (> 1)."""
        if not (math.isfinite(factor) and factor > 1.0):
            raise ValueError(f"SolverConfig.tightened: factor must be > 1, got {factor!r}")
        return replace(self, rtol=self.rtol / factor, atol_Pa=self.atol_Pa / factor,
                       atol_K=self.atol_K / factor)

    def with_dense_output(self, dense_output: bool = True) -> "SolverConfig":
        """The same settings with ``dense_output`` set."""
        return replace(self, dense_output=dense_output)

    def to_dict(self) -> dict:
        doc = asdict(self)
        if not self.dense_output:  # as saved before the option existed
            del doc["dense_output"]
        else:
            doc["dense_output"] = True
        return doc

    def as_array(self) -> np.ndarray:
        """The kernel's solver vector (:mod:`pneubayes.simulation.layout`): six entries,
        a seventh (1.0) with dense output."""
        sv = [self.rtol, self.atol_Pa, self.atol_K, self.max_step_s, self.min_step_s,
              self.max_steps_per_s]
        return np.array(sv + [1.0] if self.dense_output else sv)
