"""What a found relaxation of the reading does, for the report's figure: the reading's
error the final model makes without it, against the relaxation's own variable
``p - p_bar`` (the term is a line of slope ``g`` there).

For each relaxation ``k`` of a model's reading closure, the training recordings are cut
into windows of the fit's horizon; the model with ``g_k = 0`` predicts them, the
missing reading is measured minus that prediction, and the variable is the relaxation's
first-order effect per unit gain along it
(:meth:`~pneubayes.discovery.openform.reading.ReadingWindows.column`). A relaxation
that is right follows the binned means of the missing reading.
"""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.openform.reading import reading_windows
from pneubayes.discovery.openform.term_view import binned
from pneubayes.effects.reading_closure import gain_name, time_constant_name
from pneubayes.inference.windows import WindowSet


def reading_views(model, params: dict, recordings, horizon_s: float, solver,
                  n_bins: int = 12) -> list[dict]:
    """One view per relaxation of ``model``'s reading closure at ``params``.

    Parameters
    ----------
    model, params : Model, dict
        The final model (with a reading closure) and its values.
    recordings : sequence of Recording
        The training recordings.
    horizon_s : float
        The windows' length, s (the fit's horizon).
    solver : SolverConfig
    n_bins : int
        Bins along the variable (equal counts of samples).

    Returns
    -------
    list of dict
        ``term``, ``formula``, ``variable`` and ``unit`` (``p - p_bar_k``, Pa),
        ``bin_centre`` (the bins' median variable), ``term_Pa`` (the relaxation, ``g_k``
        times it), ``missing_Pa`` and ``missing_sem_Pa`` (the bins' mean reading missed
        without it, and its standard error), ``explained_fraction`` (1 - the sum of
        squares of missing minus term over that of missing, every sample).
    """
    if not model.has("reading_closure"):
        raise ValueError("reading_views: the model has no reading closure")
    if n_bins < 2:
        raise ValueError(f"n_bins must be >= 2, got {n_bins}")
    ws = WindowSet(recordings, horizon_s, horizon_s)
    out = []
    for k in range(model.effect("reading_closure").terms):
        g, tau = params[gain_name(k)], params[time_constant_name(k)]
        without = dict(params, **{gain_name(k): 0.0})
        blocks = reading_windows(ws, model, without, solver)
        out.append({"term": f"relaxation {k}",
                    "formula": f"{g:+.3g} (p - p_bar), tau = {tau:.3g} s",
                    "variable": f"p - p_bar_{k}", "unit": "Pa",
                    **binned_reading_term([b.column(tau) for b in blocks],
                                          [b.residual_Pa for b in blocks], g, n_bins)})
    return out


def binned_reading_term(columns, missing, gain: float, n_bins: int) -> dict:
    """A reading term ``gain x`` against the reading missed without it, binned along
    ``x``: the per-window variables ``columns`` and missed readings ``missing`` (Pa, any
    shape, the same samples) joined, non-finite samples left out, and :func:`binned`'s
    results as ``bin_centre``, ``term_Pa``, ``missing_Pa``, ``missing_sem_Pa`` and
    ``explained_fraction``."""
    x = np.concatenate([np.asarray(c, dtype=np.float64).reshape(-1) for c in columns])
    m = np.concatenate([np.asarray(v, dtype=np.float64).reshape(-1) for v in missing])
    ok = np.isfinite(x) & np.isfinite(m)
    x, m = x[ok], m[ok]
    centre, term, miss, sem, explained = binned(x, gain * x, m, n_bins)
    return {"bin_centre": centre, "term_Pa": term, "missing_Pa": miss,
            "missing_sem_Pa": sem, "explained_fraction": explained}
