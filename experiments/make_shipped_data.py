"""Regenerate the small bench data sets shipped in ``data/`` and ``data/registry.json``.

    python experiments/make_shipped_data.py            # writes data/ (overwrites)

Every set is made by the ``pneubayes bench`` command line recorded in the registry, with
a fixed seed; the registry lists each file with its sha256, and the bench DAQ's pressure
anti-alias filter, as a rig's data sheet gives it (the recording format does not carry
it; the demo declares it to its fits).
"""

from __future__ import annotations

import argparse
import hashlib
import shlex
import sys
from pathlib import Path

from pneubayes.atomic import write_json_atomic
from pneubayes.bench.sensors import SensorChain
from pneubayes.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]

#: name -> (what it is, bench arguments without --out)
SETS = {
    "air37_leak_tube/fixed": (
        "AIR37 + valve1 with the paper's orifice leak and a hidden 3 ms connecting tube; "
        "fixed volume at 25 % and 75 % of the stroke, random steps in +-5, +-3 and +-0.5 V, "
        "10 s each",
        "--cylinder AIR37 --valve valve1 --effects cylinder_leak,tube_delay --protocol fixed "
        "--positions 0.25,0.75 --duration 10 --seed 11"),
    "air37_leak_tube/moving": (
        "same rig; aggressive piston motion with random steps in +-5 V, 2 x 10 s",
        "--cylinder AIR37 --valve valve1 --effects cylinder_leak,tube_delay --protocol moving "
        "--count 2 --duration 10 --seed 11"),
}


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "data"), help="output folder (data/)")
    args = ap.parse_args(argv)
    data = Path(args.data)
    entries = []
    for name, (what, bench_args) in SETS.items():
        out = data / name
        argv_bench = ["bench", *shlex.split(bench_args), "--out", str(out), "--overwrite", "-q"]
        if cli_main(argv_bench) != 0:
            return 1
        for f in sorted(out.iterdir()):
            entries.append({"file": str(f.relative_to(data)), "sha256": sha256(f),
                            "set": name, "what": what,
                            "regenerate": f"pneubayes bench {bench_args} --out data/{name}"})
    write_json_atomic(data / "registry.json", {
        "format": "pneubayes-data-registry/1",
        "how_to_regenerate": "python experiments/make_shipped_data.py",
        "pressure_filter": SensorChain().declared_filter().to_dict(),
        "files": entries})
    print(f"wrote {len(entries)} files and {data / 'registry.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
