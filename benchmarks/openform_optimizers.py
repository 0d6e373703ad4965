"""Which pysindy optimizer the open-form search should use: planted-term recovery.

For each optimizer and seed, the planted cases of ``tests/test_openform_search.py``
(synthetic signals, ``tests/openform_synthetic.py``; one planted term + white noise of
3e-5 kg/s per 1-ms interval; one case plants two), and a null control (noise only). A
case is recovered when the search returns exactly the planted families; the coefficient
error is relative (the largest of a case's terms).

Run: ``PYTHONPATH=.:tests python benchmarks/openform_optimizers.py [seeds] [optimizers]``.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from openform_synthetic import synthetic_signals

from pneubayes.discovery.openform import OpenFormSearch
from pneubayes.effects.closure_terms import Term

NOISE_KG_PER_S = 3e-5
#: Planted terms: [(term, threshold_a, threshold_b, coefficient)]; [] the null control.
CASES = {
    "constant": [(Term("one"), 0.0, 0.0, 2e-5)],
    "pressure_ratio": [(Term("pressure_ratio"), 0.0, 0.0, -4e-6)],
    "inlet_flow": [(Term("inlet_flow"), 0.0, 0.0, 0.1)],
    "pressure_hinge": [(Term("pressure_hinge"), 4.0, 0.0, 1.2e-5)],
    "spool_hinge_up": [(Term("spool_hinge_up"), 7.0, 0.0, 1e-5)],
    "inlet_flow*pressure_ratio": [(Term("inlet_flow", "pressure_ratio"), 0.0, 0.0, 0.03)],
    "constant + inlet_flow*pressure_ratio": [(Term("one"), 0.0, 0.0, 2e-5),
                                             (Term("inlet_flow", "pressure_ratio"), 0.0,
                                              0.0, 0.03)],
    "null": [],
}


def planted(seed: int, case: str, n_recordings: int = 2):
    """Signals and targets of ``n_recordings`` synthetic recordings."""
    sig, tgt = [], []
    for r in range(n_recordings):
        s = synthetic_signals(1000 * seed + r)
        rng = np.random.default_rng(10_000 + 1000 * seed + r)
        y = rng.normal(0.0, NOISE_KG_PER_S, s["pressure_Pa"].size)
        for term, ta, tb, c in CASES[case]:
            y = y + c * term.evaluate(s, ta, tb)
        sig.append(s)
        tgt.append(y)
    return sig, tgt


def score(found, case):
    """(recovered: exactly the planted families, the largest relative coefficient error
    or nan)."""
    plant = CASES[case]
    fams = sorted(frozenset((f.term.a, f.term.b)) for f in found)
    if sorted(frozenset((t.a, t.b)) for t, *_ in plant) != fams:
        return False, np.nan
    errs = [abs(f.coefficient / c - 1.0) for t, _, _, c in plant for f in found
            if {f.term.a, f.term.b} == {t.a, t.b}]
    return True, max(errs) if errs else np.nan


def main(seeds=(0, 1, 2), only=()):
    data = {(s, c): planted(s, c) for s in seeds for c in CASES}
    settings = {"frols": {}, "stlsq": {"threshold": 0.05}, "sr3": {"threshold": 0.05},
                "stlsq 0.2": {"optimizer": "stlsq", "threshold": 0.2}}
    try:
        import numpyro  # noqa: F401
        settings["sbr"] = {"threshold": 0.05}
    except ImportError:
        print("sbr: numpyro not installed, not measured")
    if only:
        settings = {k: v for k, v in settings.items() if k in only}
    print(f"{'optimizer':>10} {'recovered':>10} {'coef err med/max':>18} {'time/fit s':>11}")
    for name, kw in settings.items():
        ok, errs, t0, fails = 0, [], time.perf_counter(), []
        for (s, c), (sig, tgt) in data.items():
            found = OpenFormSearch(**{"optimizer": name, "seed": s, **kw}).fit(sig, tgt).terms_
            hit, err = score(found, c)
            ok += hit
            if hit and np.isfinite(err):
                errs.append(err)
            if not hit:
                fails.append(f"{c}/{s}: {[str(f.term) for f in found]}")
        dt = (time.perf_counter() - t0) / len(data)
        e = np.array(errs) if errs else np.array([np.nan])
        print(f"{name:>10} {ok:>5}/{len(data):<4} {np.median(e):>8.3f}/{e.max():<8.3f} "
              f"{dt:>11.2f}")
        for f in fails:
            print(f"{'':>12}missed {f}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(tuple(int(a) for a in args if a.isdigit()) or (0, 1, 2),
         tuple(a for a in args if not a.isdigit()))
