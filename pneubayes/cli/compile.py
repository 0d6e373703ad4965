"""``pneubayes compile``: the simulator's kernels (and the virtual test bench's plant)
compiled ahead of their first use."""

from __future__ import annotations


def cmd_compile(args) -> int:
    from pneubayes.simulation.precompile import compile_kernels

    for state, seconds in compile_kernels(args.jobs).items():
        what = "bench plant" if state == "bench" else f"kernel ({state} state)"
        print(f"{what}: {seconds:.1f} s")
    return 0
