"""``pneubayes compile``: every variant of the kernel built (or loaded) ahead of use."""

from __future__ import annotations

import pytest

from pneubayes.cli import main
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
