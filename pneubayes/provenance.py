"""Provenance recorded with every result: git revision (when in a checkout) and versions."""

from __future__ import annotations

import platform
import subprocess
from pathlib import Path


def provenance() -> dict:
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                             check=True, cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        rev = None
    dirty = None
    if rev is not None:  # tracked files differ from the revision: say so
        try:
            dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--"],
                                   capture_output=True, cwd=Path(__file__).resolve().parent
                                   ).returncode != 0
        except OSError:
            dirty = None
    import emcee
    import numba
    import numpy
    import scipy

    import pneubayes

    return {"git_revision": rev, "git_dirty": dirty, "python": platform.python_version(),
            "numpy": numpy.__version__, "scipy": scipy.__version__,
            "numba": numba.__version__, "emcee": emcee.__version__,
            "pneubayes": pneubayes.__version__}
