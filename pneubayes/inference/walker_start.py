"""Where an emcee run starts: the walker ball and its centre.

The refined (least-squares) point and its Fisher information are in natural parameters;
the sampler works in sampling coordinates (:meth:`WindowLikelihood.to_sampling`). The
information is carried over exactly (``D^T H D``, ``D = dx/dz``) and inverted on the
identified coordinates only, given the nuisance ones: a covariance carried by the delta
method would bring the near-null direction of each Gompertz ``(b, d)`` pair with it, and
the finite-difference Jacobian never aligns that direction exactly with the nuisance
coordinate, so its huge variance leaked into ``ln b - c d`` (walker balls measured 20
nats below the centre instead of the 5 of an 11-dimensional Gaussian). The coordinates
only the prior informs (:meth:`WindowLikelihood.nuisance`) start spread over their
range, where the posterior is flat; and the centre moves from the least-squares point
(which is not the posterior's centre: least squares on predictions is not the AR(1)
window likelihood) to the log-posterior's own, by Newton steps.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pneubayes.inference.likelihood import WindowLikelihood

#: Factors of the Newton step tried at once (one batched call) by :func:`posterior_centre`.
LINE_SEARCH = np.array([0.25, 0.5, 1.0, 1.5])


def sampling_jacobian(like: WindowLikelihood, x: np.ndarray) -> np.ndarray:
    """``dz/dx`` of :meth:`WindowLikelihood.to_sampling` at natural parameters ``x``
    (central differences; the map is elementary, so steps of 1e-6 of each value, or of
    1e-2 of the prior range where a linear parameter is near 0, are exact to about
    1e-10 relative)."""
    d = x.size
    lo, hi = like.bounds
    log = np.array([p.prior == "log-uniform" for p in like.parameters])
    h = 1e-6 * np.where(log, np.abs(x), np.maximum(np.abs(x), 1e-2 * (hi - lo)))
    rows = np.concatenate([x + np.diag(h), x - np.diag(h)])
    z = like.to_sampling(rows)
    return ((z[:d] - z[d:]) / (2.0 * h)[:, None]).T


def correlation_form(m: np.ndarray):
    """``(sd, s, m / outer(s, s))`` of the symmetric ``m``: its diagonal's square roots,
    and the same with 1 for a zero diagonal (so the division is safe). The coordinates
    differ by many orders of magnitude (areas ~1e-8 m^2, slopes ~1 /V), and an unscaled
    inverse or eigen-decomposition loses the small ones' correlations."""
    m = 0.5 * (m + m.T)
    sd = np.sqrt(np.maximum(np.diag(m), 0.0))
    s = np.where(sd > 0, sd, 1.0)
    return sd, s, m / np.outer(s, s)


def standardised_inverse(m: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of the symmetric ``m`` taken on its correlation form
    (:func:`correlation_form`). A coordinate with a zero diagonal gets zero variance."""
    sd, s, r = correlation_form(m)
    inv = np.linalg.pinv(r, rcond=1e-12, hermitian=True) / np.outer(s, s)
    inv[sd == 0, :] = 0.0
    inv[:, sd == 0] = 0.0
    return inv


def laplace_in_sampling(like: WindowLikelihood, start: np.ndarray, information):
    """The Laplace approximation in sampling coordinates, given the nuisance ones.

    ``information`` is the Fisher information of the natural parameters at ``start``
    (e.g. :attr:`TrajectoryRefiner.information_ <pneubayes.inference.refine.TrajectoryRefiner>`).
    Returns ``(x0, z0, ident, cz)``: ``start`` clipped just inside the bounds, its
    sampling coordinates, the identified (non-nuisance) columns, and the inverse of
    ``(D^T H D)`` on those columns (``D = dx/dz``): their covariance given the nuisance
    coordinates, on which the likelihood does not depend.
    """
    lo, hi = like.bounds
    d = start.size
    h = np.asarray(information, dtype=np.float64)
    if h.shape != (d, d):
        raise ValueError(f"laplace_in_sampling: information must be ({d}, {d}) for the "
                         f"model's {d} parameters, got {h.shape}")
    eps = 1e-9 * (hi - lo)
    x0 = np.clip(start, lo + eps, hi - eps)
    dxdz = np.linalg.inv(sampling_jacobian(like, x0))
    hz = dxdz.T @ (0.5 * (h + h.T)) @ dxdz
    nuis = sorted(like.nuisance())
    ident = np.array([j for j in range(d) if j not in nuis], dtype=np.int64)
    cz = standardised_inverse(hz[np.ix_(ident, ident)])
    return x0, like.to_sampling(x0)[0], ident, cz


def gaussian_draws(mean: np.ndarray, cov: np.ndarray, rng: np.random.Generator,
                   n: int) -> np.ndarray:
    """``n`` draws of N(mean, cov), taken on the correlation form
    (:func:`correlation_form`: numpy's own draw decomposes ``cov`` unscaled)."""
    sd, _, r = correlation_form(cov)
    y = rng.multivariate_normal(np.zeros(sd.size), r, size=n, method="eigh")
    return mean + y * sd


def spread_nuisance(like: WindowLikelihood, z: np.ndarray, rng: np.random.Generator):
    """Draw each nuisance coordinate of the rows ``z`` (sampling coordinates, changed in
    place) uniformly over the range the other coordinates allow
    (:meth:`WindowLikelihood.nuisance_ranges`): the posterior is flat there."""
    nuis = sorted(like.nuisance())
    if nuis:
        rlo, rhi = like.nuisance_ranges(z)
        u = rng.random(size=rlo.shape)
        z[:, nuis] = np.where(rhi > rlo, rlo + (rhi - rlo) * u, z[:, nuis])


def walker_ball(like: WindowLikelihood, start: np.ndarray, information,
                rng: np.random.Generator, n: int, init_scale: float) -> np.ndarray:
    """``n`` starting walkers in sampling coordinates.

    With ``information`` (the Fisher information of the model parameters at ``start``),
    the identified coordinates are drawn from :func:`laplace_in_sampling` (SDs times
    ``init_scale``) and each nuisance coordinate uniformly over the range the others
    allow. Without it, a ball of 1e-3 relative width. Walkers without a finite density
    are replaced by copies of ones with.
    """
    lo, hi = like.bounds
    d = start.size
    eps = 1e-9 * (hi - lo)
    if information is None:
        x0 = np.clip(start, lo + eps, hi - eps)
        std = 1e-3 * np.maximum(np.abs(x0), 1e-2 * (hi - lo))
        draws = np.clip(x0 + rng.normal(size=(n, d)) * std, lo + eps, hi - eps)
        z = like.to_sampling(draws)
    else:
        _, z0, ident, cz = laplace_in_sampling(like, start, information)
        z = np.tile(z0, (n, 1))
        z[:, ident] = gaussian_draws(z0[ident], cz * init_scale**2, rng, n)
        # the nuisance coordinates first (their ranges depend on the identified ones
        # only), then the bounds: clipping first would pull an orifice leak's area into
        # its bounds by moving the identified offset + leak sum (~1,000 nats a walker)
        spread_nuisance(like, z, rng)
        z = like.to_sampling(np.clip(like.from_sampling(z), lo + eps, hi - eps))
    return with_density(like, z, rng)


def with_density(like: WindowLikelihood, z: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray:
    """The walkers ``z`` (sampling coordinates, changed in place), each without a finite
    posterior density replaced by a copy of one with; FloatingPointError if none has."""
    lp = like.log_prob_sampling(z)
    bad = ~np.isfinite(lp)
    if bad.all():
        raise FloatingPointError("no walker has a finite posterior density at the start")
    good = z[~bad]
    z[bad] = good[rng.integers(0, good.shape[0], bad.sum())]
    return z


def whitened_basis(cz: np.ndarray):
    """``basis`` with ``z_ident = z0_ident + basis @ y`` and ``y ~ N(0, I)`` under the
    covariance ``cz`` (its near-null directions dropped), or None when a variance is not
    positive."""
    sd = np.sqrt(np.maximum(np.diag(cz), 0.0))
    if not np.all(sd > 0):
        return None
    w, v = np.linalg.eigh(cz / np.outer(sd, sd))
    keep = w > 1e-10 * w.max()
    return sd[:, None] * (v[:, keep] * np.sqrt(w[keep]))


def curvature_stencil(k: int, h: float) -> np.ndarray:
    """The points of :func:`whitened_curvature` in whitened coordinates: ``+-h`` along
    every one of ``k`` axes, then ``+h`` along every pair (``(2 k + k (k - 1) / 2, k)``)."""
    eye = np.eye(k)
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)]
    return np.concatenate([h * eye, -h * eye]
                          + [h * (eye[[a for a, _ in pairs]] + eye[[b for _, b in pairs]])])


def whitened_curvature(like: WindowLikelihood, z: np.ndarray, ident: np.ndarray,
                       basis: np.ndarray, f0: float, h: float = 2.0):
    """Slope and Hessian of the log-posterior at ``z`` (sampling coordinates, log-density
    ``f0``) in the whitened coordinates ``y`` (``z[ident] += basis @ y``), in one batched
    call: the points at +-h along every axis and at +h along every pair of axes (2 k +
    k (k - 1) / 2 evaluations for k axes). Returns ``(grad, hess)``, or None when a
    point has no finite density."""
    k = basis.shape[1]
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)]
    y = curvature_stencil(k, h)
    rows = np.tile(z, (y.shape[0], 1))
    rows[:, ident] += y @ basis.T
    f = like.log_prob_sampling(rows)
    if not np.all(np.isfinite(f)):
        return None
    fp, fm, fpair = f[:k], f[k:2 * k], f[2 * k:]
    grad = (fp - fm) / (2.0 * h)
    hess = np.diag((fp - 2.0 * f0 + fm) / h**2)
    for (a, b), fab in zip(pairs, fpair):
        hess[a, b] = hess[b, a] = (fab - fp[a] - fp[b] + f0) / h**2
    return grad, hess


class Centre(NamedTuple):
    """Where :func:`posterior_centre` stopped: natural parameters ``x`` and sampling
    coordinates ``z``, the whitening ``basis`` of its
    steps (``z[ident] += basis @ y``), the predicted rise of each Newton step taken or
    declined (nats, ``rises``), and ``curvature``: the (slope, Hessian) in ``y`` taken at
    ``z`` itself, or None (the centring moved after taking it)."""
    x: np.ndarray
    z: np.ndarray
    basis: np.ndarray | None
    curvature: tuple | None
    rises: tuple


def whitened_slope(like: WindowLikelihood, z: np.ndarray, ident: np.ndarray,
                   basis: np.ndarray, h: float = 2.0):
    """The slope of :func:`whitened_curvature` alone (the points at +-h along every
    axis: 2 k evaluations in one batched call), or None when a point has no finite
    density."""
    k = basis.shape[1]
    rows = np.tile(z, (2 * k, 1))
    rows[:, ident] += curvature_stencil(k, h)[:2 * k] @ basis.T
    f = like.log_prob_sampling(rows)
    if not np.all(np.isfinite(f)):
        return None
    return (f[:k] - f[k:]) / (2.0 * h)


def posterior_centre(like: WindowLikelihood, start: np.ndarray, information,
                     iterations: int, tolerance_nats: float = 0.0) -> Centre:
    """Newton steps on the log-posterior from ``start`` in the identified sampling
    coordinates, whitened by the Laplace covariance (``information`` as for
    :func:`laplace_in_sampling`); returns the :class:`Centre` (``.x``: natural
    parameters).

    The first iteration evaluates, in one batched call, the points at +-2 (whitened)
    along every axis and at +2 along every pair of axes: central slopes, and the Hessian
    by second differences (2 Laplace SDs keep the solver's log-density roughness small
    against the differences; :func:`whitened_curvature`); later ones take the slopes
    alone (2 k points, :func:`whitened_slope`) with that Hessian: the simplified Newton
    method, on a posterior near a Gaussian nearly Newton's at a fraction of the cost
    (k (k - 1) / 2 + 2 k points a Hessian; 152 for 16 identified coordinates beside a
    wave tube, 37 s on two cores). The Newton step uses the
    absolute values of the Hessian's eigenvalues (an ascent direction even where it is
    not negative definite) and at most 5 SDs an axis; it is scaled by the best of
    :data:`LINE_SEARCH` (a second batched call) and kept only if the log-posterior
    rises. A point outside the prior stops the centring there, and so does a Newton
    step whose predicted rise, ``g' |H|^-1 g / 2`` (half the squared Newton decrement),
    is under ``tolerance_nats`` (0: every iteration steps): the point is then within
    about ``sqrt(2 tolerance_nats)`` SDs of the mode. Where the centring ends at the
    point of its Hessian (it did not move from there), that is the centre's
    (``Centre.curvature``).
    """
    if not tolerance_nats >= 0.0:
        raise ValueError(f"tolerance_nats must be >= 0, got {tolerance_nats!r}")
    x0, z, ident, cz = laplace_in_sampling(like, start, information)
    basis = whitened_basis(cz)
    if basis is None:
        return Centre(x0, z, None, None, ())
    f0 = float(like.log_prob_sampling(z[None])[0])
    if not np.isfinite(f0):
        return Centre(x0, z, basis, None, ())
    here, rises, hess = None, [], None
    for _ in range(iterations):
        if hess is None:
            curv = whitened_curvature(like, z, ident, basis, f0)
            if curv is None:
                break
            (grad, hess), here = curv, curv
        else:
            grad = whitened_slope(like, z, ident, basis)
            if grad is None:
                break
        lam, q = np.linalg.eigh(hess)
        newton = q @ ((q.T @ grad) / np.maximum(np.abs(lam), 1e-3))
        rises.append(0.5 * float(grad @ newton))
        if rises[-1] < tolerance_nats:
            break
        step = np.clip(newton, -5.0, 5.0)
        cand = np.tile(z, (LINE_SEARCH.size, 1))
        cand[:, ident] += np.outer(LINE_SEARCH, basis @ step)
        fc = like.log_prob_sampling(cand)
        best = int(np.argmax(np.where(np.isfinite(fc), fc, -np.inf)))
        if not fc[best] > f0:
            break
        z, f0, here = cand[best], float(fc[best]), None
    return Centre(like.from_sampling(z[None])[0], z, basis, here, tuple(rises))
