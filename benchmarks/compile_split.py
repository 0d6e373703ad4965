"""`pneubayes compile --jobs 2` from an empty cache: the shared general compile against
the variants side by side.

Each round starts two fresh processes per scheme, each with its own empty numba cache
(``NUMBA_CACHE_DIR`` a new temporary folder), and times the whole compile:

- ``shared``: :func:`pneubayes.simulation.precompile.compile_kernels` (the second
  process compiles the general kernel's largest callees first, which the first process
  loads when its compile of the general kernel reaches them);
- ``side by side``: the same variants in two processes without the callees' job (the
  general kernel in one, the pressure kernel then the bench's plant in the other).

    python benchmarks/compile_split.py [--rounds 2] [--json results/compile_split.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

_SHARED = """
from pneubayes.simulation.precompile import compile_kernels
if __name__ == "__main__":
    print(compile_kernels(2))
"""
_SIDE_BY_SIDE = """
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pneubayes.simulation.precompile import compile_variant
if __name__ == "__main__":
    with ProcessPoolExecutor(2, mp_context=get_context("spawn")) as pool:
        jobs = {s: pool.submit(compile_variant, s) for s in ("general", "pressure", "bench")}
        print({s: f.result() for s, f in jobs.items()})
"""


def timed(snippet: str) -> float:
    """Wall seconds of ``snippet`` in a new process with an empty numba cache."""
    with tempfile.TemporaryDirectory(prefix="pneubayes-compile-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        start = time.perf_counter()
        with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
            f.write(snippet)  # a file, so that spawned workers can re-import __main__
        try:
            subprocess.run([sys.executable, f.name], env=env, check=True,
                           capture_output=True, text=True)
        finally:
            os.unlink(f.name)
        return time.perf_counter() - start


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    runs = {"shared": [], "side by side": []}
    for r in range(args.rounds):
        for name, snippet in (("shared", _SHARED), ("side by side", _SIDE_BY_SIDE)):
            runs[name].append(timed(snippet))
            print(f"round {r}: {name} {runs[name][-1]:.1f} s", file=sys.stderr, flush=True)
    doc = {"cores": os.cpu_count(), "rounds": args.rounds, "wall_s": runs}
    print(json.dumps(doc))
    if args.json:
        from pneubayes.atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
