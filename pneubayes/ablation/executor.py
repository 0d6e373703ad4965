"""Where cells run: one small interface, local processes or a Dask cluster.

An executor has ``submit(fn, *args) -> future``, ``as_completed(futures)`` (yields each
future as it finishes), ``shutdown(cancel=False)`` and is a context manager (leaving the
block on an exception, e.g. Ctrl-C, cancels what has not finished). A future has
``result()``. ``fn`` and its arguments must be picklable (module-level functions).

- :class:`LocalExecutor` (default): ``workers`` processes
  (:class:`concurrent.futures.ProcessPoolExecutor`, started with ``spawn``; workers
  ignore Ctrl-C, which the parent handles, and each runs its BLAS and numba thread pools
  on its share of the cores); ``workers=1`` runs each task in this process when
  :meth:`as_completed` reaches it.
- :class:`DaskExecutor`: a ``dask.distributed`` cluster at a scheduler address (or a
  cluster object such as ``LocalCluster``). Dask is imported only here (``pip install
  pneubayes[dask]``).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from concurrent import futures as cf

from pneubayes import interrupt


class Executor(ABC):
    """The interface the runner uses (an abstract base: subclasses implement all three)."""

    @abstractmethod
    def submit(self, fn: Callable, *args):
        """Start ``fn(*args)``; return a future."""

    @abstractmethod
    def as_completed(self, futures: Iterable) -> Iterator:
        """Yield each future as it finishes."""

    @abstractmethod
    def shutdown(self, cancel: bool = False) -> None:
        """Release the workers; with ``cancel`` drop what has not started."""

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.shutdown(cancel=exc_type is not None)
        return False


class _DeferredFuture(cf.Future):
    """A future run in this process when :meth:`LocalExecutor.as_completed` reaches it."""

    def __init__(self, fn, args):
        super().__init__()
        self._call = (fn, args)

    def run(self) -> None:
        if not self.set_running_or_notify_cancel():
            return
        fn, args = self._call
        try:
            self.set_result(fn(*args))
        except Exception as exc:  # delivered by result(), as a process pool would
            self.set_exception(exc)


def _start_worker(threads: int) -> None:
    """A worker process's start: Ctrl-C is the parent's; its BLAS and numba thread pools
    get ``threads`` threads (each would start one per core, and the workers' threads
    together would outnumber the cores: OpenBLAS threads then spin waiting for each
    other)."""
    import numba
    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # numba first: it loads its threading layer (an OpenMP library), which the limit
    # then covers too
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    threadpool_limits(limits=threads)


class LocalExecutor(Executor):
    """Run tasks on this machine: ``workers`` processes, or in-process for ``workers=1``.

    ``threads_per_worker``: the BLAS and numba threads of each worker process (None: the
    cores divided among the workers, at least one; ignored for ``workers=1``).
    """

    def __init__(self, workers: int = 1, threads_per_worker: int | None = None):
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"LocalExecutor: workers must be an integer >= 1, got {workers!r}")
        if threads_per_worker is None:
            threads_per_worker = max(1, (os.cpu_count() or 1) // workers)
        if (isinstance(threads_per_worker, bool) or not isinstance(threads_per_worker, int)
                or threads_per_worker < 1):
            raise ValueError("LocalExecutor: threads_per_worker must be an integer >= 1, "
                             f"got {threads_per_worker!r}")
        self.workers = workers
        self.threads_per_worker = threads_per_worker
        self._pool = None
        if workers > 1:
            self._pool = cf.ProcessPoolExecutor(
                max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                initializer=_start_worker, initargs=(threads_per_worker,))

    def submit(self, fn: Callable, *args):
        if self._pool is None:
            return _DeferredFuture(fn, args)
        return self._pool.submit(fn, *args)

    def as_completed(self, futures: Iterable) -> Iterator:
        futures = list(futures)
        if self._pool is None:
            for f in futures:
                f.run()
                yield f
            return
        # wait in short slices: a stop request (pneubayes.interrupt) is seen within a
        # second, not when the next cell happens to finish
        waiting = set(futures)
        while waiting:
            done, waiting = cf.wait(waiting, timeout=0.5, return_when=cf.FIRST_COMPLETED)
            yield from done
            interrupt.check()

    def shutdown(self, cancel: bool = False) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if not cancel:
            pool.shutdown(wait=True)
            return
        # Running cells would otherwise finish first: end the worker processes we started.
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                p.terminate()
        for p in processes:
            p.join(timeout=10)


class DaskExecutor(Executor):
    """Run tasks on a ``dask.distributed`` cluster.

    Parameters
    ----------
    address : str or cluster
        Scheduler address (e.g. ``tcp://10.0.0.5:8786``) or a cluster object (e.g.
        ``dask.distributed.LocalCluster``), as :class:`dask.distributed.Client` takes.
    """

    def __init__(self, address):
        try:
            from dask.distributed import Client
        except ImportError:
            raise ImportError("--scheduler needs dask.distributed: pip install "
                              "'pneubayes[dask]' (or 'dask[distributed]')") from None
        self.address = address
        self._client = Client(address)
        self._futures: list = []

    @property
    def client(self):
        return self._client

    def submit(self, fn: Callable, *args):
        f = self._client.submit(fn, *args, pure=False)
        self._futures.append(f)
        return f

    def as_completed(self, futures: Iterable) -> Iterator:
        from dask.distributed import as_completed

        futures = list(futures)
        if futures:
            yield from as_completed(futures)

    def shutdown(self, cancel: bool = False) -> None:
        client, self._client = self._client, None
        if client is None:
            return
        if cancel and self._futures:
            client.cancel(self._futures)
        self._futures = []
        client.close()
