"""Bounds on what a command reads and the work it starts, checked before it starts.

A careless option (``--stride 1e-6``, ``--walkers 1000000000``, ``--count 1e9``) or a
file that is not a recording (a link to ``/dev/zero``, a named pipe, a 2-GB sparse file)
must not hang or exhaust the machine. Every input file is checked by
:func:`check_input_file` before it is opened: only regular files are read, and none
larger than :func:`max_file_bytes`. The work a command would do is sized by
:func:`check_work` against the limits below; beyond one the command refuses, saying what
it would cost and how to go on anyway (``--force``).

=========================  ===================================================  ==========
limit                      what                                                 default
=========================  ===================================================  ==========
``MAX_FILE_MB``            size of any input file (recording, card, study)       64 MB
                           (``--max-file-mb`` or ``PNEUBAYES_MAX_FILE_MB``)
                           (a CSV recording takes about 20 x its size in memory
                           while it is read and checked: 64 MB, about 1.3 GB)
``MAX_WINDOWS``            prediction windows of a fit or a prediction           20 000
``MAX_WINDOW_SAMPLES``     samples those windows span together (overlap)         1e7
``MAX_PREDICTED_SAMPLES``  a prediction's samples x posterior draws (about   2e7
                           50 bytes each in memory: 2e7, about 1 GB)
``MAX_CHAIN_MB``           an emcee chain on disk (walkers x steps x (dims+1)    4096 MB
                           x 8 bytes)
``MAX_BENCH_SAMPLES``      samples the bench simulates on its fine grid          2e8
                           (recordings x duration x fine rate)
=========================  ===================================================  ==========
"""

from __future__ import annotations

import os
import stat
from contextlib import contextmanager
from pathlib import Path

from pneubayes.errors import PneubayesError

MAX_FILE_MB = 64.0
ENV_MAX_FILE_MB = "PNEUBAYES_MAX_FILE_MB"
MAX_WINDOWS = 20_000
MAX_WINDOW_SAMPLES = 1e7
MAX_PREDICTED_SAMPLES = 2e7
MAX_CHAIN_MB = 4096.0
MAX_BENCH_SAMPLES = 2e8

_max_file_mb: float | None = None


@contextmanager
def max_file_mb(mb: float | None):
    """The input-file limit while the block runs (a command's ``--max-file-mb``), the
    previous one restored after; None: the environment's ``PNEUBAYES_MAX_FILE_MB`` or
    the default."""
    global _max_file_mb
    before, _max_file_mb = _max_file_mb, mb
    try:
        yield
    finally:
        _max_file_mb = before


def max_file_bytes() -> float:
    """The largest input file read, bytes (``--max-file-mb``, else
    ``PNEUBAYES_MAX_FILE_MB``, else 64 MB)."""
    if _max_file_mb is not None:
        return _max_file_mb * 1e6
    text = os.environ.get(ENV_MAX_FILE_MB)
    if text:
        try:
            mb = float(text)
            if mb > 0:
                return mb * 1e6
        except ValueError:
            pass
        raise PneubayesError(f"{ENV_MAX_FILE_MB}={text!r}: must be a number of MB > 0")
    return MAX_FILE_MB * 1e6


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def input_file_problem(path) -> str | None:
    """Why ``path`` may not be read as an input (None: a regular file within the size
    limit; a missing file is left to the reader). Never opens the file, so a named pipe
    cannot block."""
    try:
        st = os.stat(path)  # follows links: a link to /dev/zero is a device
    except FileNotFoundError:
        return None
    except OSError as exc:
        return f"cannot be read: {exc.strerror or exc}"
    if not stat.S_ISREG(st.st_mode):
        link = f" (a link to {os.path.realpath(path)})" if os.path.islink(path) else ""
        return f"is {_kind(st.st_mode)}{link}, not a file; only regular files are read"
    limit = max_file_bytes()
    if st.st_size > limit:
        return (f"is {st.st_size / 1e6:.3g} MB, over the input limit of {limit / 1e6:g} MB "
                f"(raise it with --max-file-mb or {ENV_MAX_FILE_MB} if the file is real)")
    return None


def check_input_file(path, what: str = "") -> Path:
    """Raise a :class:`PneubayesError` naming ``path`` (and ``what``, e.g. the option)
    when it may not be read (:func:`input_file_problem`)."""
    why = input_file_problem(path)
    if why is not None:
        raise PneubayesError(f"{what + ' ' if what else ''}{path}: {why}")
    return Path(path)


def check_work(amount: float, limit: float, what: str, cost: str, override: str,
               force: bool = False) -> None:
    """Refuse work of ``amount`` over ``limit`` unless ``force``: the message says what
    (``what``), what it would cost (``cost``) and how to go on (``override``)."""
    if amount > limit and not force:
        raise PneubayesError(f"{what}: {cost}, over the limit of {limit:,.0f}; refused "
                             f"before any work ({override})")
