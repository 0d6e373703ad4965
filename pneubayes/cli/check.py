"""``pneubayes check``: read recordings and report every problem in them."""

from __future__ import annotations

import sys


def cmd_check(args) -> int:
    from pneubayes.io.recording import inspect_recording

    bad = 0
    for path in args.files:
        found = inspect_recording(path, args.accept, args.rig)
        if found.problems:
            bad += 1
            for loc, why in found.problems:
                print(f"{loc}: {why}")
            continue
        warned = [f for f in found.warnings if not f.accepted]
        if not args.quiet:
            print(f"{path}: ok" + (f" ({len(warned)} warning(s))" if warned else ""))
            for note in found.conversions:
                print(f"  converted {note}")
        for f in found.warnings:
            print(f"{f.location}: {'note' if f.accepted else 'warning'}: {f.text()}")
    if bad:
        print(f"{bad} of {len(args.files)} recording(s) have problems", file=sys.stderr)
    return 1 if bad else 0
