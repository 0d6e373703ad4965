"""Which parameters the data pin down, which only move together, and what would
separate them (issue: identifiability report)."""

from __future__ import annotations

import numpy as np

from pneubayes.model import Model

#: Known structural confounding, with the experiment that separates the group.
_STRUCTURAL = (
    (("inlet_b", "inlet_d_V"), "eq. 11 depends on b and d only through ln b - c d",
     "none needed: only the combination matters; report or fix d"),
    (("exhaust_b", "exhaust_d_V"), "eq. 11 depends on b and d only through ln b - c d",
     "none needed: only the combination matters; report or fix d"),
    (("exhaust_offset_m2", "leak_area_m2"),
     "an orifice leak has the exhaust port's law (eq. 9): only their sum is seen",
     "characterise the valve alone (flow meter as in Fig. 4, or a recording with the "
     "cylinder port blocked), or fit the laminar clearance leak law"),
)


def identifiability_report(model: Model, names, samples: np.ndarray,
                           threshold: float = 0.9) -> dict:
    """Correlations and flagged groups from posterior ``samples`` ``(S, D)``.

    Flags: structural groups present in the model; other pairs with
    |correlation| > ``threshold`` (e.g. dead volume against the area scales in
    fixed-volume data); parameters whose 90 % interval spans over half their prior range
    (the data hardly inform them).
    """
    names = list(names)
    x = np.asarray(samples, dtype=np.float64)
    sd = x.std(axis=0)
    keep = sd > 0
    corr = np.full((len(names), len(names)), np.nan)
    sub = np.corrcoef(x[:, keep].T) if keep.sum() > 1 else np.ones((1, 1))
    idx = np.nonzero(keep)[0]
    corr[np.ix_(idx, idx)] = sub
    groups = []
    structural_pairs = set()
    for pair, why, experiment in _STRUCTURAL:
        if all(n in names for n in pair):
            groups.append({"parameters": list(pair), "kind": "structural", "reason": why,
                           "separating_experiment": experiment})
            structural_pairs.add(frozenset(pair))
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            c = corr[i, j]
            if np.isfinite(c) and abs(c) > threshold and \
                    frozenset((names[i], names[j])) not in structural_pairs:
                pair = [names[i], names[j]]
                exp = ("record at two or more fixed positions (volumes) or with the piston "
                       "moving" if "dead_volume_m3" in pair else
                       "excite the regimes where their effects differ")
                groups.append({"parameters": pair, "kind": "correlated",
                               "correlation": float(c), "separating_experiment": exp})
    weak = []
    for j, n in enumerate(names):
        if n in model.parameter_names:
            p = model.parameter(n)
            lo, hi = np.quantile(x[:, j], [0.05, 0.95])
            if p.prior == "log-uniform":
                frac = (np.log(max(hi, 1e-300)) - np.log(max(lo, 1e-300))) / \
                    (np.log(p.upper) - np.log(p.lower))
            else:
                frac = (hi - lo) / (p.upper - p.lower)
            if frac > 0.5:
                weak.append(n)
    return {"correlation": {"names": names, "matrix": corr.tolist()}, "groups": groups,
            "prior_dominated": weak}
