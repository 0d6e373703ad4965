"""Repeated wall-clock timing of one call, shared by the benchmarks."""

from __future__ import annotations

import time

import numpy as np


def time_calls(fn, seconds: float, min_calls: int = 3, per: int = 1) -> dict:
    """Call ``fn()`` until ``seconds`` have passed and at least ``min_calls`` times;
    returns the seconds per call divided by ``per`` (e.g. the trajectories a call
    simulates): ``{"median_s", "min_s", "calls"}``. Compile or warm up before."""
    times = []
    start = time.perf_counter()
    while time.perf_counter() - start < seconds or len(times) < min_calls:
        a = time.perf_counter()
        fn()
        times.append((time.perf_counter() - a) / per)
    return {"median_s": float(np.median(times)), "min_s": float(min(times)),
            "calls": len(times)}
