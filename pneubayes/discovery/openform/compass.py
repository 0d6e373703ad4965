"""A compass (pattern) search over a few multiplicative values and the dead volume's
scale, refining a grid search's best through the windows' simulations."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import product

import numpy as np


def compass_refine(problem, centre, sse, factors: Sequence[float],
                   bounds: Sequence[tuple[float, float]], scale_step: float, passes: int):
    """Refine ``centre`` = (values, dead-volume scale) of a search on ``problem`` (its
    ``window_sse`` takes one term per set, the values in order, and the scales).

    Each pass simulates the neighbours of the centre: every value times ``1 / f``, 1 or
    ``f`` (its entry of ``factors``; a value of 0, or a factor of 1, is held) within its
    ``bounds``, and the scale by ``-scale_step``, 0 or ``+scale_step`` relative (0:
    held), all combined (a valley may run across the axes). It moves to the best where
    that is better than ``sse`` (the centre's windows' sums of squares), and else takes
    the factors' square roots and halves the scale's step. Returns ``(centre, sse)``."""
    factors = [float(f) for f in factors]
    for _ in range(passes):
        values, scale = centre
        axes = [[float(np.clip(v * m, *b)) for m in (1.0 / f, 1.0, f)]
                if v > 0.0 and f > 1.0 else [v]
                for v, f, b in zip(values, factors, bounds)]
        steps = (-scale_step, 0.0, scale_step) if scale_step else (0.0,)
        cand = [(tuple(vs), scale * (1.0 + d)) for vs in product(*axes) for d in steps]
        got = problem.window_sse([[c] for c, _ in cand], [s for _, s in cand])
        j = int(np.argmin(np.sum(got, axis=1)))
        if np.isfinite(got[j]).all() and np.sum(got[j]) < np.sum(sse) and cand[j] != centre:
            centre, sse = cand[j], got[j]  # moved: the same steps again
        else:
            factors = [float(np.sqrt(f)) for f in factors]
            scale_step *= 0.5
    return centre, sse


__all__ = ["compass_refine"]
