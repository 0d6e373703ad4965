"""``pneubayes compile``: the simulator's kernels (and the virtual test bench's plant)
compiled ahead of their first use."""

from __future__ import annotations


def cmd_compile(args) -> int:
    from pneubayes.simulation.precompile import CALLEES_JOB, compile_kernels

    for state, seconds in compile_kernels(args.jobs).items():
        what = {"bench": "bench plant", CALLEES_JOB: "general kernel's callees (beside it)"
                }.get(state, f"kernel ({state} state)")
        print(f"{what}: {seconds:.1f} s")
    return 0
