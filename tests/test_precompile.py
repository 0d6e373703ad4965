"""``pneubayes compile``: every variant of the kernel built (or loaded) ahead of use."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from pneubayes.cli import main
from pneubayes.compile_cache import first_call
from pneubayes.simulation.precompile import STATES, compile_kernels, compile_variant


def test_the_command_builds_both_states_and_the_bench_and_says_how_long(capsys):
    assert main(["compile", "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == [
        "bench plant" if s == "bench" else f"kernel ({s} state)" for s in STATES]
    assert "bench" in STATES
    assert all(float(line.split(":")[1].removesuffix(" s")) >= 0.0 for line in lines)


@pytest.mark.parametrize("jobs", [0, -1, 1.5, True])
def test_a_job_count_that_is_not_a_positive_integer_is_refused(jobs):
    with pytest.raises(ValueError, match="jobs must be a positive integer"):
        compile_kernels(jobs)


def test_an_unknown_state_is_refused():
    with pytest.raises(ValueError, match="state must be one of"):
        compile_variant("tube")


def test_the_command_refuses_zero_jobs(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["compile", "--jobs", "0"])
    assert exc.value.code == 2
    assert "--jobs" in capsys.readouterr().err


# ---------------------------------------------------------------- first-call locks
_HOLDER = """
import sys, time
from pneubayes.compile_cache import hold_first_calls
with hold_first_calls([sys.argv[1]]):
    print("held", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _hold(name, seconds):
    """A process holding ``name``'s first-call lock for ``seconds`` (once it prints)."""
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, name, str(seconds)],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_first_call_waits_while_another_process_compiles_that_variant(tmp_path,
                                                                        monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    holder = _hold("test-variant", 1.5)
    start = time.perf_counter()
    with first_call("test-variant"):
        waited = time.perf_counter() - start
    holder.communicate()
    assert holder.returncode == 0
    assert waited > 0.5
    # the variant is in this process now: its later calls take no lock
    holder = _hold("test-variant", 1.5)
    start = time.perf_counter()
    with first_call("test-variant"):
        assert time.perf_counter() - start < 0.5
    holder.communicate()


def test_a_first_call_stops_waiting_after_its_limit(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    holder = _hold("test-stuck", 3.0)
    start = time.perf_counter()
    with first_call("test-stuck", wait_s=0.2):
        waited = time.perf_counter() - start
    assert 0.15 < waited < 2.0  # gave up, then ran the body without the lock
    holder.communicate()


def test_a_long_first_call_says_it_is_compiling_and_a_short_one_does_not(
        tmp_path, monkeypatch, caplog):
    """A first call still running after ``notice_after_s`` (a compile, or a wait for
    another process's) logs one warning naming the variant; one that ends before it (a
    load from the cache) logs nothing, and neither does a later call."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    with caplog.at_level("WARNING", logger="pneubayes.compile_cache"):
        with first_call("test-slow", notice_after_s=0.1):
            time.sleep(0.5)
        with first_call("test-fast", notice_after_s=1.0):
            pass
        time.sleep(1.2)  # past the fast call's timer: it was cancelled
        with first_call("test-slow", notice_after_s=0.1):
            time.sleep(0.3)
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == 1
    assert "compiling the simulator's test-slow kernel" in messages[0]


# ---------------------------------------------------------------- the shared compile
_CALLEES_THEN_KERNEL = """
import json
from pneubayes.simulation.general_callees import CALLEES, compile_general_callees
from pneubayes.simulation.precompile import compile_variant
compile_general_callees()
before = {f.py_func.__name__: len(f.signatures) for f in CALLEES}
compile_variant("general")
print(json.dumps([before, {f.py_func.__name__: len(f.signatures) for f in CALLEES}]))
"""


@pytest.mark.slow
def test_the_general_kernel_calls_its_callees_with_the_types_compiled_beside_it(tmp_path):
    # a fresh cache: the kernel compiles, reusing the callees only if its types match
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", _CALLEES_THEN_KERNEL], env=env, check=True,
                         capture_output=True, text=True).stdout
    before, after = json.loads(out.splitlines()[-1])
    assert before == after
    assert before["chamber_rhs"] == 2 and all(
        n == 1 for name, n in before.items() if name != "chamber_rhs")


def test_a_script_without_a_main_guard_fails_at_once_instead_of_waiting(tmp_path):
    # with spawn, each worker re-runs the script: its compile_kernels must not wait on
    # the locks its parent holds, but reach multiprocessing's bootstrapping error
    script = tmp_path / "unguarded.py"
    script.write_text("from pneubayes.simulation.precompile import compile_kernels\n"
                      "compile_kernels(2)\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode != 0
    assert "bootstrapping phase" in proc.stderr or "BrokenProcessPool" in proc.stderr
