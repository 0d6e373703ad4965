"""What a found knee of the reading does, for the report's figure: the reading's error
the final model makes without it, against the knee's own variable ``max(0, p -
theta)`` (less its start; the term is a line of slope ``c`` there).

For each knee ``k`` of a model's reading hinge, the training recordings are cut into
windows of the fit's horizon; the model with ``c_k = 0`` predicts them, the missing
reading is measured minus that prediction, and the variable is the knee's first-order
effect per unit gain along it
(:meth:`~pneubayes.discovery.openform.reading.ReadingWindows.hinge_column`). A knee that
is right follows the binned means of the missing reading.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading import reading_windows
from pneubayes.discovery.openform.reading_view import binned_reading_term
from pneubayes.effects.reading_hinge import hinge_gain_name, hinge_threshold_name
from pneubayes.inference.windows import WindowSet


def hinge_views(model, params: dict, recordings, horizon_s: float, solver,
                n_bins: int = 12) -> list[dict]:
    """One view per knee of ``model``'s reading hinge at ``params``; arguments and
    return as :func:`~pneubayes.discovery.openform.reading_view.reading_views`'
    (``variable`` ``max(0, p - theta_k)`` less its start, Pa)."""
    if not model.has("reading_hinge"):
        raise ValueError("hinge_views: the model has no reading hinge")
    if n_bins < 2:
        raise ValueError(f"n_bins must be >= 2, got {n_bins}")
    ws = WindowSet(recordings, horizon_s, horizon_s)
    out, below = [], model.effect("reading_hinge").below
    side = "min" if below else "max"
    for k in range(model.effect("reading_hinge").terms):
        c, theta = params[hinge_gain_name(k)], params[hinge_threshold_name(k)]
        blocks = reading_windows(ws, model, dict(params, **{hinge_gain_name(k): 0.0}),
                                 solver)
        out.append({"term": f"knee {k}",
                    "formula": f"{c:+.3g} {side}(0, p - theta), theta = {theta / 1e3:.4g} kPa",
                    "variable": f"{side}(0, p - theta_{k}) less its start", "unit": "Pa",
                    **binned_reading_term([b.hinge_column(theta, below) for b in blocks],
                                          [b.residual_Pa for b in blocks], c, n_bins)})
    return out
