"""Population priors of the quantities that vary between runs, in log space.

:class:`LogNormalPrior` is what other runs teach (e.g. the log-normal of per-run point
fits, :meth:`LogNormalPrior.from_point_fits`, widened by a stated floor);
:class:`LogUniformPrior` is the model's bounds alone. Both work on the natural log of
the quantities (each needs a lower bound > 0), as :class:`~pneubayes.inference.online.
OnlineTracker` does.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from pneubayes.model import Model


def log_bounds(model: Model, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Log of the named parameters' bounds; each must have a lower bound > 0."""
    lo, hi = [], []
    for n in names:
        p = model.parameter(n)
        if not p.lower > 0:
            raise ValueError(f"vary: {n!r} has lower bound {p.lower:g}; the tracker works in "
                             "log space and needs quantities with a lower bound > 0")
        lo.append(np.log(p.lower))
        hi.append(np.log(p.upper))
    return np.array(lo), np.array(hi)


class LogUniformPrior:
    """Log-uniform over the model's bounds of the varying quantities (no population).

    Parameters
    ----------
    model : Model
    names : sequence of str
        The varying quantities (model parameter names, lower bounds > 0).
    """

    def __init__(self, model: Model, names: Sequence[str]):
        self.names = tuple(names)
        self.log_lower, self.log_upper = log_bounds(model, self.names)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, k)`` draws of the log values."""
        return rng.uniform(self.log_lower, self.log_upper, size=(n, len(self.names)))

    def logpdf(self, z) -> np.ndarray:
        """Log density of log values ``z`` ``(n, k)`` (up to a constant); -inf outside."""
        z = np.atleast_2d(z)
        inside = np.all((z >= self.log_lower) & (z <= self.log_upper), axis=1)
        return np.where(inside, 0.0, -np.inf)

    def describe(self) -> dict:
        return {"kind": "log-uniform", "names": list(self.names),
                "lower": np.exp(self.log_lower).tolist(),
                "upper": np.exp(self.log_upper).tolist()}


class LogNormalPrior(LogUniformPrior):
    """A log-normal population (independent quantities), cut at the model's bounds.

    Parameters
    ----------
    model : Model
    names : sequence of str
    median : mapping of str to float
        Each quantity's population median, in its unit.
    log_sd : mapping of str to float
        Each quantity's population spread, the standard deviation of its natural log.
    """

    def __init__(self, model: Model, names: Sequence[str], median: Mapping[str, float],
                 log_sd: Mapping[str, float]):
        super().__init__(model, names)
        for what, m in (("median", median), ("log_sd", log_sd)):
            missing = [n for n in self.names if n not in m]
            if missing:
                raise ValueError(f"LogNormalPrior: {what} has no value for {missing}")
        self.log_median = np.log([float(median[n]) for n in self.names])
        self.log_sd = np.array([float(log_sd[n]) for n in self.names])
        if not (np.all(np.isfinite(self.log_median)) and np.all(self.log_sd > 0)):
            raise ValueError(f"LogNormalPrior: medians must be > 0 and log_sd > 0, got "
                             f"{dict(median)}, {dict(log_sd)}")

    @classmethod
    def from_point_fits(cls, model: Model, names: Sequence[str],
                        fits: Sequence[Mapping[str, float]], floor_log_sd: float
                        ) -> "LogNormalPrior":
        """The population of per-run point fits: the median and standard deviation of
        each quantity's log over the fits, the spread widened to
        ``sqrt(sd^2 + floor_log_sd^2)`` (a few runs understate a population's spread)."""
        if len(fits) < 2:
            raise ValueError(f"from_point_fits: needs at least 2 fits, got {len(fits)}")
        if not floor_log_sd > 0:
            raise ValueError(f"floor_log_sd must be > 0, got {floor_log_sd!r}")
        logs = np.log([[float(f[n]) for n in names] for f in fits])
        sd = np.sqrt(np.var(logs, axis=0, ddof=1) + floor_log_sd**2)
        med = np.exp(np.median(logs, axis=0))
        return cls(model, names, dict(zip(names, med)), dict(zip(names, sd)))

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        out = rng.normal(self.log_median, self.log_sd, size=(n, len(self.names)))
        bad = np.any((out < self.log_lower) | (out > self.log_upper), axis=1)
        for _ in range(100):  # cut at the bounds: draw again where outside
            if not bad.any():
                break
            out[bad] = rng.normal(self.log_median, self.log_sd, size=(int(bad.sum()),
                                                                      len(self.names)))
            bad = np.any((out < self.log_lower) | (out > self.log_upper), axis=1)
        return np.clip(out, self.log_lower, self.log_upper)

    def logpdf(self, z) -> np.ndarray:
        z = np.atleast_2d(z)
        lp = -0.5 * np.sum(((z - self.log_median) / self.log_sd) ** 2, axis=1)
        return lp + super().logpdf(z)

    def describe(self) -> dict:
        return {"kind": "log-normal", "names": list(self.names),
                "median": np.exp(self.log_median).tolist(), "log_sd": self.log_sd.tolist()}
