"""An exactly Gaussian log-density with the sampling interface of
:class:`~pneubayes.inference.likelihood.WindowLikelihood` (tests of the walkers' start,
the posterior's centre and the Laplace approximation)."""

import numpy as np

from pneubayes.effects.base import Parameter


class GaussianTarget:
    """A log-density exactly Gaussian in identity sampling coordinates, with coordinate 2
    a flat nuisance over [-100, 100]; no density outside ``bounds`` (+-100 unless
    replaced). ``calls`` counts the batched evaluations."""

    def __init__(self, mean, precision):
        self.mean, self.precision = mean, precision
        self.bounds = (np.full(mean.size, -100.0), np.full(mean.size, 100.0))
        self.parameters = [Parameter(f"p{j}", "-", -100.0, 100.0, "uniform", "test")
                           for j in range(mean.size)]
        self.calls = 0

    def nuisance(self):
        return {2: (-100.0, 100.0)}

    def nuisance_ranges(self, z):
        n = np.atleast_2d(z).shape[0]
        return np.full((n, 1), -100.0), np.full((n, 1), 100.0)

    def to_sampling(self, x):
        return np.array(np.atleast_2d(x), dtype=np.float64)

    from_sampling = to_sampling

    def log_prob_sampling(self, z):
        self.calls += 1
        z = np.atleast_2d(z)
        lo, hi = self.bounds
        r = np.delete(z - self.mean, 2, axis=1)
        lp = -0.5 * np.einsum("bi,ij,bj->b", r, self.precision, r)
        return np.where(np.all((z >= lo) & (z <= hi), axis=1), lp, -np.inf)

    def emcee_target(self, z):
        z = np.atleast_2d(z)
        return np.column_stack([self.log_prob_sampling(z), np.zeros((z.shape[0], 5))])


#: The identified coordinates of a 5-D :class:`GaussianTarget` (2 is the nuisance one).
IDENT = [0, 1, 3, 4]


def random_covariance(rng: np.random.Generator, ridge: float) -> np.ndarray:
    """A random 4 x 4 covariance ``a a^T + ridge I`` (one draw of ``rng``)."""
    a = rng.normal(size=(4, 4))
    return a @ a.T + ridge * np.eye(4)


def information_of(cov: np.ndarray) -> np.ndarray:
    """The 5 x 5 Fisher information whose identified block (:data:`IDENT`) is ``cov``'s
    inverse, and 1 on the nuisance coordinate."""
    info = np.zeros((5, 5))
    info[np.ix_(IDENT, IDENT)] = np.linalg.inv(cov)
    info[2, 2] = 1.0
    return info
