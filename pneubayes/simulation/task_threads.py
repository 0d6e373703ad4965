"""Worker threads that run the compiled kernel's task ranges beside the calling thread.

The batched simulator cuts its tasks (a parameter set's windows) into chunks and runs
them on several threads: the calling one and helpers from here. The compiled loop
releases the GIL, so the threads run at once; chunks are handed out as threads come free
(a dynamic schedule: a thread whose core another process shares does less, instead of
the batch waiting for its fixed share).

Starting threads for every call costs about 0.1 ms, as much as a short batch; the helpers
are therefore started once per process, on first use, and wait on a queue (as numba's own
thread pool does). They hold no results between calls. A process forked from one with
helpers starts its own.
"""

from __future__ import annotations

import itertools
import os
import queue
import threading


class _Job:
    """One call's chunks: ``run(i)`` for ``i`` in ``0..n - 1``, each exactly once, by
    whichever threads take them."""

    def __init__(self, run, n: int):
        self._run = run
        self._n = n
        self._taken = itertools.count()  # next() on a count is atomic under the GIL
        self._lock = threading.Lock()
        self._left = n
        self.done = threading.Event()
        self.errors: list[BaseException] = []

    def work(self) -> None:
        while (i := next(self._taken)) < self._n:
            try:
                self._run(i)
            except BaseException as e:  # raised again on the calling thread
                self.errors.append(e)
            with self._lock:
                self._left -= 1
                if self._left == 0:
                    self.done.set()


class _Helpers:
    """Daemon threads taking jobs from one queue; grown to the most ever asked for."""

    def __init__(self):
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.threads: list[threading.Thread] = []
        self.lock = threading.Lock()

    def ensure(self, count: int) -> None:
        with self.lock:
            while len(self.threads) < count:
                th = threading.Thread(target=self._serve, daemon=True,
                                      name=f"pneubayes-task-{len(self.threads)}")
                th.start()
                self.threads.append(th)

    def _serve(self) -> None:
        while True:
            self.queue.get().work()


_helpers: _Helpers | None = None
_helpers_lock = threading.Lock()


def _forget_in_child() -> None:
    """In a forked child: the parent's helpers are not there, and a lock another thread
    held at the fork would never be released."""
    global _helpers, _helpers_lock
    _helpers, _helpers_lock = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_in_child)


def _process_helpers() -> _Helpers:
    global _helpers
    with _helpers_lock:
        if _helpers is None:
            _helpers = _Helpers()
        return _helpers


def run_chunks(run, n_chunks: int, threads: int) -> None:
    """Call ``run(i)`` for every chunk ``i`` in ``0..n_chunks - 1`` once, on up to
    ``threads`` threads (the calling one among them); returns when every chunk is done
    and raises the first exception a chunk raised."""
    if n_chunks < 0 or threads < 1:
        raise ValueError(f"need n_chunks >= 0 and threads >= 1, got {n_chunks}, {threads}")
    threads = min(threads, n_chunks)
    if threads <= 1:
        for i in range(n_chunks):
            run(i)
        return
    helpers = _process_helpers()
    helpers.ensure(threads - 1)
    job = _Job(run, n_chunks)
    for _ in range(threads - 1):
        helpers.queue.put(job)
    job.work()
    job.done.wait()
    if job.errors:
        raise job.errors[0]
