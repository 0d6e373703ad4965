"""Numba's on-disk cache, kept in step with the sources compiled into it.

Numba stamps a cached function with its *own* file's modification time and size. Code it
calls from other files is compiled into it but not checked: "cache invalidation fails
to recognize changes in functions defined in a different file" (numba's notes on
caching), and module constants are frozen into it too. The simulation kernel calls into
``line.py``, ``physics/`` and reads ``effects/path.py``'s slot layout, so after an edit
there (or a ``git pull`` that changes only those files) a cached kernel would silently
run the old code.

:func:`clear_if_stale` hashes the sources of the packages whose numba code ends up in a
cached function and, when the digest differs from the one stamped beside the cache (or
there is no stamp), removes those packages' numba cache files (``*.nbi``, ``*.nbc``)
before anything loads them (``pneubayes/__init__.py`` calls it first; this module
imports nothing compiled). A fresh clone has no cache and nothing to remove.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from pneubayes.atomic import write_text_atomic

#: Packages (folders of pneubayes) whose numba functions are cached or compiled into a
#: cached function.
NUMBA_PACKAGES = ("simulation", "physics", "effects", "bench")
STAMP_NAME = "pneubayes-numba-sources.sha256"


def sources_digest(folders) -> str:
    """SHA-256 over the names and contents of every ``*.py`` file in ``folders``."""
    h = hashlib.sha256()
    for folder in folders:
        for f in sorted(Path(folder).glob("*.py")):
            h.update(f.name.encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def clear_if_stale(folders, stamp: Path) -> int:
    """Remove the numba cache files in ``folders``' ``__pycache__`` if their sources
    changed since ``stamp`` was written (or it is missing); then write the stamp.

    Returns the number of files removed. A folder whose cache cannot be written is left
    alone (numba then caches elsewhere, where pip's fresh files reset its stamps).
    """
    stamp = Path(stamp)
    digest = sources_digest(folders)
    try:
        if stamp.read_text().strip() == digest:
            return 0
    except OSError:
        pass
    removed = 0
    for folder in folders:
        cache = Path(folder) / "__pycache__"
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            try:
                f.unlink()
                removed += 1
            except FileNotFoundError:  # another process cleared it first
                pass
            except OSError:
                return removed
    try:
        write_text_atomic(stamp, digest + "\n")
    except OSError:
        pass
    return removed


def clear_stale_package_cache() -> int:
    """:func:`clear_if_stale` for pneubayes' own numba packages."""
    root = Path(__file__).resolve().parent
    return clear_if_stale([root / p for p in NUMBA_PACKAGES],
                          root / "simulation" / "__pycache__" / STAMP_NAME)
