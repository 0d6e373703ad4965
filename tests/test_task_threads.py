"""The helper threads that run the kernel's chunks (pneubayes.simulation.task_threads)."""

from __future__ import annotations

import multiprocessing
import threading

import pytest

from pneubayes.simulation.task_threads import run_chunks


@pytest.mark.parametrize("threads", [1, 2, 5])
def test_every_chunk_runs_exactly_once(threads):
    seen, lock = [], threading.Lock()

    def run(i):
        with lock:
            seen.append(i)

    for n in (0, 1, 3, 40):
        seen.clear()
        run_chunks(run, n, threads)
        assert sorted(seen) == list(range(n))


def test_chunks_run_on_more_than_one_thread_when_asked():
    """Each chunk waits until two different threads have entered one: with a single
    thread the barrier would time out."""
    barrier = threading.Barrier(2, timeout=10)
    names = set()

    def run(i):
        names.add(threading.current_thread().name)
        barrier.wait()

    run_chunks(run, 2, 2)
    assert len(names) == 2


def test_a_chunk_s_exception_reaches_the_caller_after_the_others_finish():
    done = []

    def run(i):
        if i == 3:
            raise ValueError("chunk 3")
        done.append(i)

    with pytest.raises(ValueError, match="chunk 3"):
        run_chunks(run, 8, 2)
    assert sorted(done) == [0, 1, 2, 4, 5, 6, 7]


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="threads >= 1"):
        run_chunks(lambda i: None, 3, 0)


def _child(out):
    barrier = threading.Barrier(2, timeout=10)  # broken unless two threads take chunks
    names = set()

    def run(i):
        names.add(threading.current_thread().name)
        barrier.wait()

    run_chunks(run, 2, 2)
    out.put(len(names))


def test_a_forked_child_starts_its_own_helpers():
    """Threads do not survive a fork; a child of a process with helpers must start its
    own instead of queueing chunks for the parent's (absent) ones."""
    run_chunks(lambda i: None, 4, 2)  # the helpers exist in this process
    ctx = multiprocessing.get_context("fork")
    out = ctx.Queue()
    child = ctx.Process(target=_child, args=(out,))
    child.start()
    child.join(timeout=60)
    assert child.exitcode == 0
    assert out.get(timeout=5) == 2
