"""Clean stops: SIGINT and SIGTERM are recorded, and long jobs stop at a safe point.

A signal that arrives while compiled code runs cannot be raised there (the compiled call
would fail with a ``SystemError``). :func:`stop_on_signals` installs handlers that only
record the request; long loops call :func:`check` between compiled calls, which raises
:class:`Interrupted`. Finished work is already on disk by then (chains step by step,
studies cell by cell), so the command says how to resume and exits with 130 (SIGINT)
or 143 (SIGTERM).

The request is process state by nature (signals are delivered to the process); it lives
only inside :func:`stop_on_signals` and is cleared when it ends.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

_requests: list[int] = []


class Interrupted(KeyboardInterrupt):
    """A stop was requested by a signal; ``exit_code`` is 128 + the signal number.

    A ``KeyboardInterrupt``, not an error: ``except Exception`` (a failed cell, a failed
    trial) lets it through, and code that keeps finished work on Ctrl-C keeps it here.
    """

    def __init__(self, signum: int):
        self.signum = signum
        self.exit_code = 128 + signum
        super().__init__(f"interrupted by {signal.Signals(signum).name}")


def _record(signum, frame) -> None:
    _requests.append(signum)


@contextmanager
def stop_on_signals():
    """Record SIGINT and SIGTERM instead of raising (main thread only; elsewhere a
    no-op), restore the previous handlers on exit."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, _record) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _requests.clear()


def stop_requested() -> int | None:
    """The first recorded signal number, or None."""
    return _requests[0] if _requests else None


def check() -> None:
    """Raise :class:`Interrupted` if a stop was requested (call between compiled calls)."""
    if _requests:
        raise Interrupted(_requests[0])
