"""What a found port-flow term of the reading does, for the report's figure: the reading's
error the final model makes without it, against the term's own variable (the feature of
the port flows it reads; the term is a line of slope ``c`` there).

For each term ``k`` of a model's reading flow component, the training recordings are cut
into windows of the fit's horizon; the model with ``c_k = 0`` predicts them, the missing
reading is measured minus that prediction, and the variable is the term's first-order
effect per unit gain along it
(:meth:`~pneubayes.discovery.openform.reading_flow.FlowWindows.column`: the feature less
its value at the window's start along the start sensitivity). A term that is right
follows the binned means of the missing reading.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading_flow import flow_windows
from pneubayes.discovery.openform.reading_view import binned_reading_term
from pneubayes.effects.reading_flow import FLOW_FEATURE_UNITS, flow_gain_name
from pneubayes.inference.windows import WindowSet


def flow_views(model, params: dict, recordings, horizon_s: float, solver,
               n_bins: int = 12) -> list[dict]:
    """One view per term of ``model``'s reading flow component at ``params``.

    Parameters
    ----------
    model, params : Model, dict
        The final model (with a reading flow component) and its values.
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
        As :func:`~pneubayes.discovery.openform.reading_view.reading_views`' (``variable``
        the feature, ``unit`` its unit, ``x_scale`` 1: the variable is drawn in it).
    """
    if not model.has("reading_flow"):
        raise ValueError("flow_views: the model has no reading flow component")
    if n_bins < 2:
        raise ValueError(f"n_bins must be >= 2, got {n_bins}")
    ws = WindowSet(recordings, horizon_s, horizon_s)
    out = []
    for k, name in enumerate(model.effect("reading_flow").features):
        c = params[flow_gain_name(k)]
        blocks = flow_windows(ws, model, dict(params, **{flow_gain_name(k): 0.0}), solver)
        unit = FLOW_FEATURE_UNITS[name]
        out.append({"term": f"port flow term {k}", "formula": f"{c:+.3g} Pa per {unit} x {name}",
                    "variable": f"{name} (less its start)", "unit": unit, "x_scale": 1.0,
                    **binned_reading_term([b.column(name) for b in blocks],
                                          [b.windows.residual_Pa for b in blocks], c,
                                          n_bins)})
    return out
