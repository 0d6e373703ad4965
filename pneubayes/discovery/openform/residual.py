"""What the open-form search regresses: the current model's residual on the training data,
as the mass flow into the chamber it lacks.

Two sources (:class:`~pneubayes.discovery.stages.open_form.OpenForm` runs both):
:func:`one_step_residual`, per sample interval of each recording (the search sums them
in blocks), and :func:`window_residual`, the prediction windows' residual, each
candidate entering as its first-order effect on the predicted pressure
(:mod:`~pneubayes.discovery.openform.trajectory`).
"""

from __future__ import annotations

from pneubayes.discovery.one_step import one_step_data
from pneubayes.discovery.openform.signals import (
    missing_mass_flow,
    parameter_flows,
    path_signals,
)
from pneubayes.discovery.openform.trajectory import WindowResponse


def one_step_residual(model, params, recordings, solver, with_nuisance: bool):
    """``(signals, targets, None, nuisance)``: per recording, ``model``'s signals along
    its path at ``params``, the mass flow into the chamber it misses (kg/s, per
    interval; the search sums its block of them per row) and, ``with_nuisance``, its
    parameter sensitivities as mass flows (else None); one-step errors by ``solver``."""
    signals, targets, nuisance = [], [], []
    for rec in recordings:
        d = one_step_data(rec, 1)  # (per interval: the search makes the rows)
        e = d.errors(model, params, solver)[0]
        sig = path_signals(model, params, rec, d)
        signals.append(sig)  # (its "valid" leaves out intervals touching a bad sample)
        targets.append(missing_mass_flow(sig, e, d.rig))
        if with_nuisance:
            nuisance.append(parameter_flows(model, params, d, solver, sig))
    return signals, targets, None, (nuisance if with_nuisance else None)


def window_residual(model, params, recordings, window_set, solver, path, window_rows: int,
                    path_nuisance=None):
    """``(signals, targets, row maps, nuisance)`` of the prediction windows
    ``window_set`` (of ``recordings``): per recording with windows, ``model``'s signals
    along its path (``path``: per recording, in order), the windows' residual (measured
    minus predicted at ``params`` by ``solver``, Pa) at about ``window_rows`` points per
    window, the map from a per-interval mass flow to its first-order effect there
    (:mod:`~pneubayes.discovery.openform.trajectory`), and ``path_nuisance``'s arrays
    (per recording, in order; or None) matched to them."""
    ws = window_set
    theta = model.vector(params)[None]
    missing = -ws.residuals(model, theta, solver)[0]
    extra = [None] * len(path) if path_nuisance is None else list(path_nuisance)
    if len(ws.blocks) == len(path):  # (the window set keeps the recordings' order)
        paths, nuisance = list(path), extra
    else:  # a recording without a window is left out of the window set
        by_source = {str(rec.source): (sig, z)
                     for rec, sig, z in zip(recordings, path, extra)}
        if len(by_source) != len(path):
            raise ValueError("the training recordings' sources repeat, so their "
                             "windows cannot be matched to them")
        paths = [by_source[b.source][0] for b in ws.blocks]
        nuisance = [by_source[b.source][1] for b in ws.blocks]
    every = max(1, (ws.length - 1) // window_rows)
    signals, targets, maps = [], [], []
    n0 = 0
    for b, sig in zip(ws.blocks, paths):
        w = b.starts.size
        response = WindowResponse(sig, b.starts, ws.length, b.rig, every)
        signals.append(sig)
        maps.append(response)
        targets.append(response.sample(missing[n0:n0 + w]))
        n0 += w
    return signals, targets, maps, (None if path_nuisance is None else nuisance)
