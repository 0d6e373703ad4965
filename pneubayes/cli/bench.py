"""``pneubayes bench``: the virtual test bench's recordings and their truth."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from pneubayes.cli.common import effect_names
from pneubayes.errors import PneubayesError


def cmd_bench(args) -> int:
    from pneubayes.bench.bench import BenchConfig, run_bench
    from pneubayes.bench.sensors import SensorChain
    from pneubayes.effects import CATALOGUE, effects_from_names
    from pneubayes.limits import MAX_BENCH_SAMPLES, check_work
    from pneubayes.physics.cylinder import CYLINDERS
    from pneubayes.physics.valve import VALVES

    for option, name, known in (("--cylinder", args.cylinder, CYLINDERS),
                                ("--valve", args.valve, VALVES)):
        if name not in known:
            raise PneubayesError(f"{option} {name}: unknown; the bench knows "
                                 f"{', '.join(sorted(known))}")
    names = effect_names(args.effects or "")
    if args.leak_form is not None and "cylinder_leak" not in names:
        raise PneubayesError(f"--leak-form {args.leak_form}: only with cylinder_leak among "
                             "--effects (no leak is planted)")
    for option, values, ok, what in (
            ("--ranges", args.ranges, lambda v: 0 < v <= 5, "in (0, 5] V"),
            ("--positions", args.positions, lambda v: 0 <= v <= 1,
             "fractions of the stroke in [0, 1]")):
        bad = [v for v in values or () if not (math.isfinite(v) and ok(v))]
        if bad:
            raise PneubayesError(f"{option} {','.join(f'{v:g}' for v in bad)}: must be "
                                 f"{what}")
    if args.protocol == "moving":
        given = [o for o, v in (("--positions", args.positions), ("--ranges", args.ranges))
                 if v is not None]
        if given:
            raise PneubayesError(f"{' and '.join(given)}: only with --protocol fixed (the "
                                 "moving protocol moves the piston; --count sets its "
                                 "recordings)")
        n_rec = args.count or 2
    else:
        if args.count is not None:
            raise PneubayesError("--count: only with --protocol moving (the fixed "
                                 "protocol writes one recording per --positions x --ranges)")
        n_rec = len(args.positions or (0.1, 0.5, 0.9)) * len(args.ranges or (5.0, 3.0, 0.5))
        if n_rec == 0:
            raise PneubayesError("--positions/--ranges: no recording planned (give at "
                                 "least one value of each)")
    ratio = args.fine_rate / args.rate
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise PneubayesError(f"--fine-rate {args.fine_rate:g}: must be a whole multiple of "
                             f"--rate {args.rate:g} (the truth is simulated on the fine grid "
                             "and sampled at the rate; default 10000 Hz)")
    samples = float(n_rec) * args.duration * args.fine_rate
    check_work(samples, MAX_BENCH_SAMPLES, "--count/--duration/--fine-rate",
               f"{n_rec:,} recording(s) of {args.duration:g} s on a {args.fine_rate:g}-Hz "
               f"grid, {samples:.3g} simulated samples", "plan fewer or shorter recordings, "
               "or pass --force to run it anyway", args.force)
    unknown = [n for n in names if n not in CATALOGUE]
    if unknown:
        raise PneubayesError(f"--effects: unknown effect(s) {unknown}; "
                             f"the catalogue has {sorted(CATALOGUE)}")
    out = Path(args.out)
    if (out.exists() or out.is_symlink()) and not out.is_dir():
        raise PneubayesError(f"--out {out}: is a file, not a folder (bench writes a folder "
                             "of recordings and truth.json)")
    from pneubayes.run_folder import read_stamp

    stamp = read_stamp(out) if out.is_dir() else None
    if stamp is not None:
        raise PneubayesError(f"--out {out}: is the run folder of a 'pneubayes "
                             f"{stamp.get('command')}' ({out / 'run.json'}); bench writes "
                             "its recordings into a folder of their own")
    sensor = SensorChain(sample_rate_Hz=args.rate, pressure_noise_Pa=args.pressure_noise,
                         supply_noise_Pa=args.pressure_noise)
    cfg = BenchConfig(cylinder=args.cylinder, valve=args.valve,
                      effects=effects_from_names(names, args.leak_form or "orifice"),
                      protocol=args.protocol, duration_s=args.duration, seed=args.seed,
                      overrides=dict(args.set or []),
                      ranges_V=args.ranges or (5.0, 3.0, 0.5),
                      positions=args.positions or (0.1, 0.5, 0.9), count=args.count or 2,
                      fine_rate_Hz=args.fine_rate, sensor=sensor)
    made = not out.exists()
    try:
        res = run_bench(cfg, args.out, overwrite=args.overwrite,
                        progress=None if args.quiet else
                        (lambda m: print(m, file=sys.stderr)))
    except FileExistsError as exc:
        raise PneubayesError(f"--out {args.out}: {exc.filename or exc} exists (use "
                             "--overwrite to replace the recordings)") from None
    except BaseException:
        if made and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # nothing written: leave no empty folder behind
        raise
    for p in res.recordings:
        print(p)
    print(res.truth_path)
    return 0
