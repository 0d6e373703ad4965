"""``pneubayes compile``: the simulator's kernels compiled ahead of their first use."""

from __future__ import annotations


def cmd_compile(args) -> int:
    from pneubayes.simulation.precompile import compile_kernels

    for state, seconds in compile_kernels(args.jobs).items():
        print(f"kernel ({state} state): {seconds:.1f} s")
    return 0
