"""The gate a searched term passes to earn its trial through the simulator (the volume's
walls, a valve driver's clock).

A term is kept when it removes at least ``min_explained_fraction`` of the training
windows' residual sum of squares and the windows' reductions, each as a share of the
window's own sum of squares, are ``min_t`` standard errors above zero
(:func:`~pneubayes.discovery.openform.volume.window_reduction`), or when the windows'
mean reduction is above zero and it removes ``strong_explained_fraction`` of the residual
or other evidence says it is real: the held-out test that follows is the verdict, and a
term that removes most of the residual earns it however unevenly the windows share it.
"""

from __future__ import annotations


def check_gate(min_explained_fraction: float, min_t: float,
               strong_explained_fraction: float) -> None:
    """Raise ValueError unless ``min_explained_fraction`` is in (0, 1), ``min_t`` > 0
    and ``strong_explained_fraction`` in [``min_explained_fraction``, 1]."""
    if not 0.0 < min_explained_fraction < 1.0 or not min_t > 0.0 \
            or not min_explained_fraction <= strong_explained_fraction <= 1.0:
        raise ValueError("min_explained_fraction must be in (0, 1), min_t > 0 and "
                         "strong_explained_fraction in [min_explained_fraction, 1], got "
                         f"{min_explained_fraction!r}, {min_t!r}, "
                         f"{strong_explained_fraction!r}")


def earns_trial(explained: float, t: float, min_explained_fraction: float, min_t: float,
                strong_explained_fraction: float, evidence: bool = False) -> bool:
    """Whether a term that removes ``explained`` of the residual at relative ``t`` is kept
    (``evidence``: another test says it is real, as a strong share does)."""
    return explained >= min_explained_fraction and (
        t >= min_t or (t > 0.0 and (explained >= strong_explained_fraction or evidence)))


__all__ = ["check_gate", "earns_trial"]
