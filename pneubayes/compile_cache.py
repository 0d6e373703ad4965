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

:func:`first_call` makes processes that start cold at once (test workers, ablation
workers, a ``pneubayes compile`` running beside them) compile each kernel variant once:
the first call of a variant in a process holds a file lock beside the cache, so a second
process reaching the same variant waits, then loads what the first one compiled instead
of compiling its own copy. ``pneubayes compile`` takes every variant's lock before it
starts compiling (:func:`hold_first_calls`). Where file locks are unavailable (Windows,
a cache folder that cannot be written) each process compiles on its own, as numba does.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import threading
import time
from pathlib import Path

from pneubayes.atomic import write_text_atomic

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; each process compiles on its own
    fcntl = None

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


def kernel_first_call(entry: str, general: bool) -> str:
    """The first-call lock of one compiled variant of the simulation kernel: ``entry``
    "simulate" (:func:`pneubayes.simulation.kernel.simulate_windows`) or "carried"
    (:func:`~pneubayes.simulation.kernel.simulate_carried`), on the general or the
    pressure-only kernel."""
    return f"{entry}-{'general' if general else 'pressure'}"


#: How long :func:`first_call` waits for another process's compile (s) before compiling
#: on its own; a numba compile of the general kernel takes about 2 min on one core.
FIRST_CALL_WAIT_S = 1800.0
#: How often a waiting process tries the lock again (s).
_POLL_S = 0.05
#: How long a first call runs (s) before :func:`first_call` says that it is compiling:
#: loading a variant from numba's cache takes a second or two, compiling one 15 s or more.
COMPILE_NOTICE_AFTER_S = 5.0
_LOG = logging.getLogger(__name__)
#: Variants whose first call this process has made (or whose lock it holds): their
#: compiled code is in numba's in-process dispatcher from then on, so the lock is not
#: taken again (this mirrors that per-process state of numba's own).
_FIRST_CALLS_DONE: set[str] = set()


def lock_folder() -> Path:
    """Where the first-call locks live: numba's cache folder for pneubayes' kernels
    (``NUMBA_CACHE_DIR`` when set, else ``pneubayes/simulation/__pycache__``)."""
    override = os.environ.get("NUMBA_CACHE_DIR")
    if override:
        return Path(override)
    return Path(__file__).resolve().parent / "simulation" / "__pycache__"


def _lock(name: str, wait_s: float):
    """An open descriptor holding ``name``'s exclusive lock, or None (no locks here, or
    ``wait_s`` passed while another process held it)."""
    if fcntl is None:
        return None
    folder = lock_folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder / f"pneubayes-first-call-{name}.lock", os.O_RDWR | os.O_CREAT,
                     0o644)
    except OSError:
        return None
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return fd
        except BlockingIOError:
            if time.monotonic() >= deadline:
                os.close(fd)
                return None
            time.sleep(_POLL_S)
        except OSError:  # a file system without flock
            os.close(fd)
            return None


@contextlib.contextmanager
def first_call(name: str, wait_s: float = FIRST_CALL_WAIT_S,
               notice_after_s: float = COMPILE_NOTICE_AFTER_S):
    """Run the body (a compiled entry point's call) holding ``name``'s first-call lock,
    the first time this process calls it; later calls run without it.

    ``name`` is one compiled variant (e.g. ``"simulate-general"``). If another process
    holds the lock (compiling that variant), this waits up to ``wait_s`` seconds for it,
    then the body loads the variant from numba's cache. A first call still running
    after ``notice_after_s`` seconds (waiting or compiling, not loading) logs a warning
    that says so, once, on the ``pneubayes.compile_cache`` logger (shown on stderr when
    logging is not configured), so a long first call is not taken for a hang.
    """
    if name in _FIRST_CALLS_DONE:
        yield
        return
    notice = threading.Timer(notice_after_s, _LOG.warning, (
        "pneubayes: compiling the simulator's %s kernel for its first use since "
        "installing or updating (once: 20 s to 2 min, then cached; `pneubayes compile` "
        "does it ahead of time)", name))
    notice.daemon = True
    notice.start()
    fd = _lock(name, wait_s)
    try:
        yield
        _FIRST_CALLS_DONE.add(name)
    finally:
        notice.cancel()
        if fd is not None:
            os.close(fd)  # closing the descriptor releases the lock


def assume_first_calls(names) -> None:
    """Mark ``names`` as held by this process's caller: a process spawned to compile
    variants whose locks its parent holds (:func:`hold_first_calls`) must not wait on
    them."""
    _FIRST_CALLS_DONE.update(names)


@contextlib.contextmanager
def hold_first_calls(names, wait_s: float = FIRST_CALL_WAIT_S):
    """Hold the first-call locks of ``names`` for the body (compiling those variants in
    this process or in processes it starts); yields a function that releases one name's
    lock early (``release(name)``), when its variant is in the cache."""
    held = {name: _lock(name, wait_s) for name in names}
    _FIRST_CALLS_DONE.update(names)  # this process's own calls must not wait on itself

    def release(name: str) -> None:
        fd = held.pop(name, None)
        if fd is not None:
            os.close(fd)

    try:
        yield release
    finally:
        for name in list(held):
            release(name)
