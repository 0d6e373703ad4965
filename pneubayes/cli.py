"""The ``pneubayes`` command: ``check``, ``bench``, ``simulate``, ``fit``, ``predict``,
``discover``, ``ablate``, ``import``, ``compile``, ``track``.

Each subcommand is a thin layer over the library; errors are printed as one clear
message naming the file, row, key or argument (exit 2 for usage or input errors,
1 for ``check`` when any file has problems). The arguments and their checks are in
:mod:`pneubayes.cli_args`.
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import traceback
from pathlib import Path

import numpy as np

from pneubayes import interrupt
from pneubayes.cli_args import build_parser, check_single_values
from pneubayes.cli_settings import discovery_settings, fit_settings
from pneubayes.errors import ParameterError, PneubayesError
from pneubayes.run_folder import (
    RunFolderError,
    check_file,
    inputs_digest,
    open_run_folder,
    recorded_number,
    release_locks,
)

#: What each folder-writing command may write (removed by --overwrite when the folder
#: has no stamp listing the earlier run's files).
FIT_OUTPUTS = ("model.json", "summary.json", "posterior.nc", "chain.h5", "refined.json",
               "figures")
DISCOVER_OUTPUTS = ("discovery.json", "model.json", "posterior.nc", "chain.h5",
                    "disagreement.json", "report.md", "figures", "steps", "found_effect.py")


def _print_findings(command: str, recordings) -> None:
    """Plausibility warnings (and accepted findings) of recordings, on stderr."""
    for rec in recordings:
        for f in rec.findings:
            print(f"pneubayes {command}: warning: {f.location}: {f.text()}", file=sys.stderr)


def _run_horizon(run: Path) -> float:
    """The window length a run was fitted on (its summary or discovery document), s;
    2 s for runs that do not record it."""
    horizon = recorded_number(run, (("summary.json", ("settings", "horizon_s")),
                                    ("discovery.json", ("horizon_s",))))
    return 2.0 if horizon is None else horizon


def _effect_names(text: str, option: str = "--effects") -> list[str]:
    """Effect names of a comma-separated option; an empty name between commas or a name
    given twice is an error naming the option ('' is no effect)."""
    if not text.strip():
        return []
    names = [n.strip() for n in text.split(",")]
    if not all(names):
        raise PneubayesError(f"{option} {text!r}: an empty name between commas (give "
                             "effect names, e.g. cylinder_leak,tube_delay, or '' for none)")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PneubayesError(f"{option}: {', '.join(twice)} given more than once")
    from pneubayes.effects import CATALOGUE

    unknown = [n for n in names if n not in CATALOGUE]
    if unknown:
        raise PneubayesError(f"{option}: unknown effect(s) {', '.join(unknown)}; the "
                             f"catalogue has {', '.join(sorted(CATALOGUE))}")
    return names


def _no_bound_twice(bounds) -> None:
    names = [n for n, _ in bounds]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PneubayesError(f"--bounds: {', '.join(twice)} given more than once (which "
                             "one did you mean?)")


def _check_windows(recs, horizon: float, stride: float | None, force: bool,
                   draws: int | None = None, windows: bool = True) -> None:
    """Before any work: a window holds at least a few samples of every recording
    (--horizon), no --pressure-filter above a recording's Nyquist frequency is done by
    the callers, and the windows number no more than the limit (--stride) unless
    --force."""
    from pneubayes.limits import (
        MAX_PREDICTED_SAMPLES,
        MAX_WINDOW_SAMPLES,
        MAX_WINDOWS,
        check_work,
    )

    stride = stride or horizon
    total = samples = 0
    for r in recs:
        t = np.asarray(r.time_s, dtype=np.float64)
        if t.size < 2:
            raise PneubayesError(f"{r.source}: {t.size} sample(s); a fit needs a recording "
                                 "of many samples")
        dt = float(np.median(np.diff(t)))
        if horizon < MIN_WINDOW_SAMPLES * dt:
            raise PneubayesError(
                f"--horizon {horizon:g}: shorter than {MIN_WINDOW_SAMPLES} sample intervals "
                f"of {r.source} (sampled every {dt:.3g} s); a window needs several samples "
                f"(at least {MIN_WINDOW_SAMPLES * dt:.3g} s)")
        if stride < 0.5 * dt:
            raise PneubayesError(
                f"--stride {stride:g}: under half a sample interval of {r.source} (sampled "
                f"every {dt:.3g} s); windows start on samples, at most one per sample")
        length = int(round(horizon / dt)) + 1
        step = max(1, int(round(stride / dt)))
        if length > t.size:
            if not windows:  # fit --method lsq: no prediction windows
                continue
            raise PneubayesError(
                f"--horizon {horizon:g}: longer than {r.source} ({t[-1] - t[0]:.3g} s); "
                "every recording must hold at least one window")
        n = (t.size - length) // step + 1
        valid = r.valid_mask()
        if not valid.all() and n <= 10 * MAX_WINDOWS:  # windows on valid samples only
            starts = np.arange(0, t.size - length + 1, step)
            bad = np.concatenate([[0], np.cumsum(~valid)])
            n = int(np.count_nonzero(bad[starts + length] - bad[starts] == 0))
            if n == 0:
                raise PneubayesError(f"{r.source}: no {horizon:g}-s window (--horizon) lies "
                                     "within the samples its 'valid' column marks valid")
        total += n
        samples += n * length
    what = f"--horizon {horizon:g} --stride {stride:g}"
    override = "raise --stride, or pass --force to run it anyway"
    check_work(total, MAX_WINDOWS, what,
               f"{total:,} prediction windows (each simulated at every evaluation)",
               override, force)
    check_work(samples, MAX_WINDOW_SAMPLES, what,
               f"windows overlapping into {samples:,} simulated samples per evaluation",
               override, force)
    if draws is not None:
        check_work(samples * draws, MAX_PREDICTED_SAMPLES, f"{what} --draws {draws}",
                   f"{samples:,} window samples x {draws} draws, "
                   f"{samples * draws:,.0f} simulated samples", override + " (or fewer "
                   "--draws)", force)


#: A declared pressure filter's cutoff may lie at most this many times above a
#: recording's sample rate (an oversampling DAQ filters before it decimates, so a cutoff
#: at the sample rate is real, e.g. the bench's 2:1000 at 1 kHz; far above, the filter
#: changes no sample and the value is a slip).
FILTER_MAX_OVER_RATE = 10.0


def _check_filter(recs, pressure_filter) -> None:
    """A --pressure-filter cutoff far above a recording's sample rate (more than
    :data:`FILTER_MAX_OVER_RATE` x) is an error naming both."""
    if pressure_filter is None:
        return
    for r in recs:
        t = np.asarray(r.time_s, dtype=np.float64)
        if t.size < 2:
            continue
        rate = 1.0 / float(np.median(np.diff(t)))
        if pressure_filter.cutoff_Hz > FILTER_MAX_OVER_RATE * rate:
            raise PneubayesError(
                f"--pressure-filter {pressure_filter.order}:{pressure_filter.cutoff_Hz:g}: "
                f"the cutoff is over {FILTER_MAX_OVER_RATE:g} x the sample rate of "
                f"{r.source} ({rate:g} Hz), where the filter changes no sample; a DAQ's "
                "anti-alias filter lies near or below its sample rate")


#: The fewest sample intervals a prediction window spans (--horizon).
MIN_WINDOW_SAMPLES = 4
#: The fewest posterior draws a prediction's bands are drawn from (--draws).
MIN_DRAWS = 20


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
    names = _effect_names(args.effects or "")
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


#: simulate --atol must be under this, Pa (an error of an atmosphere is no accuracy).
ATOL_MAX_PA = 1e5


def cmd_simulate(args) -> int:
    from pneubayes.atomic import write_text_atomic
    from pneubayes.io.recording import read_recording
    from pneubayes.model import Model
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    if args.rtol >= 1.0:
        raise PneubayesError(f"--rtol {args.rtol:g}: a relative tolerance must be under 1 "
                             "(3e-5 by default; 1 or more asks for no accuracy at all)")
    if args.atol >= ATOL_MAX_PA:
        raise PneubayesError(f"--atol {args.atol:g}: an absolute tolerance must be under "
                             f"{ATOL_MAX_PA:g} Pa, an atmosphere (10 Pa by default)")
    out = _output_file(args.out, ".csv", args.overwrite)
    _not_an_input([out], [*_recording_files([args.recording]), args.model])
    rec = read_recording(args.recording, args.accept, args.rig)
    model, params = Model.load_card(args.model)
    _print_findings("simulate", [rec])
    if model.rig_card != rec.rig_card:
        raise PneubayesError(f"--model {args.model} and {rec.source} describe different "
                             "rigs (rig cards)")
    if args.max_step <= 1e-12:
        raise PneubayesError(f"--max-step {args.max_step:g}: must be above 1e-12 s, the "
                             "integrator's smallest step")
    solver = SolverConfig(rtol=args.rtol, atol_Pa=args.atol, atol_K=0.01,
                          max_step_s=args.max_step, min_step_s=1e-12, max_steps_per_s=2.5e7)
    traj = simulate(model, params, Inputs.from_recording(rec), rec.rig(),
                    float(rec.pressure_Pa[0]), solver)
    p = traj.pressure_Pa[0]
    if not np.all(np.isfinite(p)):
        raise PneubayesError(f"--model {args.model} on {rec.source}: the simulated pressure "
                             "is not finite; nothing written")
    write_text_atomic(out, "time_s,pressure_Pa\n" + "".join(
        f"{t:.9g},{v:.6f}\n" for t, v in zip(rec.time_s, p)))
    rmse = float(np.sqrt(np.mean((p - rec.pressure_Pa) ** 2)))
    lo, hi = np.percentile(rec.pressure_Pa, [1, 99])
    print(f"{out}: {p.size} samples; open-loop RMSE against the measured pressure "
          f"{rmse:.0f} Pa ({100 * rmse / max(hi - lo, 1e-9):.2f} % of the measured span)")
    return 0


def _output_file(path: str, suffix: str, overwrite: bool, *companions: str) -> Path:
    """Check an output file name before any work: its suffix, not a folder, and neither
    it nor its ``companions`` (suffixes written beside it) existing without --overwrite."""
    out = Path(path)
    if out.suffix != suffix:
        raise PneubayesError(f"--out {out}: must end in {suffix}" + (
            f" (written beside it: {', '.join(out.stem + c for c in companions)})"
            if companions else ""))
    parent = next((q for q in out.parents if q.exists()), None)
    if parent is not None and not parent.is_dir():
        raise PneubayesError(f"--out {out}: {parent} is a file, not a folder")
    for p in (out, *(out.with_suffix(c) for c in companions)):
        if p.is_dir():
            raise PneubayesError(f"--out {out}: {p} is a folder")
        if p.exists() and not overwrite:
            raise PneubayesError(f"--out {out}: {p} exists (use --overwrite to replace it)")
    return out


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (resolved: links, ``..`` and relative paths)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _not_an_input(outputs, inputs, option: str = "--out") -> None:
    """Refuse, before any work, an output that is one of the command's inputs (a
    recording's CSV or JSON, a model card, a run's files): no command writes over what
    it reads, not even with --overwrite."""
    for o in outputs:
        for i in inputs:
            if _same_file(Path(o), Path(i)):
                raise PneubayesError(f"{option} {o}: is the input {i}; a command never "
                                     "writes over its own inputs (choose another output)")


def _recording_files(paths) -> list[Path]:
    from pneubayes.io.recording import recording_paths

    return [f for p in paths for f in recording_paths(p)]


def _read_all(paths, accept, command, rig=None):
    from pneubayes.io.recording import read_recording

    recs = [read_recording(p, accept, rig) for p in paths]
    _print_findings(command, recs)
    _rig_card_of(recs)
    return recs


def _rig_card_of(recs):
    """The one rig card the recordings share (None: the paper's cylinders); mixing
    rigs in one fit is an error naming two recordings that differ."""
    first = recs[0]
    for r in recs[1:]:
        if r.rig_card != first.rig_card:
            def name(x):
                return x.rig_card.source if x.rig_card is not None else "no rig card"
            raise PneubayesError(f"{r.source} ({name(r)}) and {first.source} ({name(first)}) "
                                 "describe different rigs; fit one rig at a time")
    return first.rig_card


def _known_from(args):
    """``(rig card, parameters)`` of the fit ``--known-from`` names (a run folder or its
    model.json); --refit without it is a usage error."""
    from pneubayes.model import Model

    if not args.known_from:
        raise PneubayesError("--refit needs --known-from (the fit whose values the other "
                             "quantities keep)")
    path = Path(args.known_from)
    if path.is_dir():
        path = path / "model.json"
    model, params = Model.load_card(path)
    if model.rig_card is None:
        raise PneubayesError(f"--known-from {path}: the model has no rig card (the paper's "
                             "cylinders); --known-from fixes a rig card's quantities")
    return model.rig_card, params, path


def _card_known_at(card, known, args):
    """The recordings' card with its fitted quantities known at ``known``'s values but
    those --refit names; errors name what does not match."""
    from pneubayes.model import Model

    known_card, params, path = known
    if card != known_card:
        raise PneubayesError(f"--known-from {path} was fitted on the rig "
                             f"{known_card.name!r}, the recordings are of "
                             + (f"the rig {card.name!r}" if card else "the paper's cylinders"))
    fitted = Model(rig_card=card).parameter_names
    stray = [n for n in args.refit if n not in fitted]
    if stray:
        raise PneubayesError(f"--refit: {stray} are not fitted quantities of the rig card "
                             f"{card.name!r}; its are {list(fitted)}")
    return card.known_at(params, keep_unknown=args.refit)


def cmd_fit(args) -> int:
    from pneubayes.effects import effects_from_names
    from pneubayes.inference.pipeline import run_fit
    from pneubayes.model import Model

    if args.model and (args.effects is not None or args.leak_form is not None):
        given = [o for o, v in (("--effects", args.effects), ("--leak-form", args.leak_form))
                 if v is not None]
        raise PneubayesError(f"--model {args.model} fixes the effects and their forms; "
                             f"{' and '.join(given)} contradict it (give one or the other)")
    names = _effect_names("cylinder_leak" if args.effects is None else args.effects)
    if args.leak_form is not None and "cylinder_leak" not in names:
        raise PneubayesError(f"--leak-form {args.leak_form}: only with cylinder_leak among "
                             "--effects (the fitted model has no leak)")
    _no_bound_twice(args.bounds)
    settings = fit_settings(args)
    sampler = settings.sampler
    known = _known_from(args) if args.known_from or args.refit else None
    recs = _read_all(args.recordings, args.accept, "fit", args.rig)
    _check_filter(recs, settings.pressure_filter)
    _check_windows(recs, settings.horizon_s, settings.stride_s, args.force,
                   windows=args.method != "lsq")
    card = _rig_card_of(recs)
    if known is not None:  # the card's quantities known at another fit's values
        card = _card_known_at(card, known, args)
        recs = _read_all(args.recordings, args.accept, "fit", card)
    if args.model:
        model, _ = Model.load_card(args.model)
        if model.rig_card != card:
            raise PneubayesError(f"--model {args.model} describes "
                                 + (f"the rig {model.rig_card.name!r}" if model.rig_card
                                    else "the paper's cylinders")
                                 + ", the recordings " + (f"the rig {card.name!r}" if card
                                                          else "the paper's cylinders"))
    else:
        model = Model(effects_from_names(names, args.leak_form or "orifice"), rig_card=card)
    if args.bounds:
        model = Model(model.effects, {**model.bound_overrides, **dict(args.bounds)},
                      model.rig_card)
    try:
        n_dims = model.n_parameters  # a bound for a parameter the model lacks fails here
    except ParameterError as exc:
        if not args.bounds:
            raise
        raise PneubayesError(f"--bounds: {str(exc).removeprefix('bounds: ')}") from None
    walkers_opt = (f"--walkers {sampler.n_walkers}" if args.walkers is not None
                   else f"sampler.n_walkers = {sampler.n_walkers} (--settings)")
    if sampler.n_walkers and sampler.n_walkers < 2 * n_dims:
        raise PneubayesError(f"{walkers_opt}: emcee needs at least twice the "
                             f"{model.n_parameters} sampled dimensions of this model, >= "
                             f"{2 * model.n_parameters} (or 0: automatic)")
    if args.method == "mcmc":
        from pneubayes.limits import MAX_CHAIN_MB, check_work

        walkers = sampler.n_walkers or max(32, 4 * n_dims)
        walkers += walkers % 2
        mb = walkers * float(sampler.max_steps) * (n_dims + 1) * 8 / 1e6
        check_work(mb, MAX_CHAIN_MB, f"--walkers {sampler.n_walkers} --max-steps "
                   f"{sampler.max_steps}",
                   f"a chain of {walkers:,} walkers x {sampler.max_steps:,} steps x "
                   f"{n_dims + 1} values, up to {mb:,.0f} MB on disk in chain.h5 (and as "
                   "much in memory)", "use fewer walkers or steps, or pass --force to run it "
                   "anyway", args.force)
    identity = {"recordings": inputs_digest(_recording_files(args.recordings)),
                "effects": list(model.effect_names),
                "options": {e.name: e.options() for e in model.effects},
                "bounds": model.bound_overrides,
                "rig": None if card is None else card.to_dict(),
                "known_from": None if known is None else str(known[2]),
                "method": args.method, "walkers": sampler.n_walkers, "seed": sampler.seed,
                "windows": {"horizon_s": settings.horizon_s, "stride_s": settings.stride_s},
                "refine_jacobian_refresh": settings.refine_jacobian_refresh,
                # a chain is never resumed with another likelihood solver
                "sample_solver": settings.sample_solver.to_dict(),
                "preparation": settings.preparation(), "accept": list(args.accept)}
    _not_an_input([Path(args.out) / n for n in FIT_OUTPUTS],
                  [*_recording_files(args.recordings),
                   *([args.model] if args.model else []),
                   *([known[2]] if known is not None else [])])
    folder = open_run_folder(args.out, "fit", identity, overwrite=args.overwrite,
                             resume=args.resume, outputs=FIT_OUTPUTS, argv=args.argv)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    if folder.resumed:
        # a saved stage the stamp records must be the file the run wrote (not edited)
        if "refined.json" in folder.stamp()["files"] and (folder.path / "refined.json").exists():
            check_file(folder.path, "refined.json")
        log(f"fit: resuming the run in {args.out}")
    summary = run_fit(recs, model, settings, args.out, progress=not args.quiet, log=log,
                      figures=not args.no_figures, method=args.method)
    folder.record(*(n for n in FIT_OUTPUTS if n != "figures"))
    if args.method not in ("mcmc", "laplace"):
        est = summary["start"] if args.method == "lsq" else summary["refined"]
        print(f"{args.out}/model.json  ({args.method} estimate, "
              f"{summary['wall_time_s']:.1f} s)")
        for name, v in est["parameters"].items():
            print(f"  {name:32s} {v:12.5g}")
        for note in summary["start"]["notes"]:
            print(f"  note: {note}")
        _point_warnings(model, est, summary)
        return 0
    how = (f"Laplace, {summary['draws']} draws, concave at the mode and its draws "
           f"reliable {summary['converged']}" if args.method == "laplace" else
           f"converged={summary['converged']}, {summary['steps']} steps")
    print(f"{args.out}/model.json  (posterior median; {how}, "
          f"{summary['wall_time_s']:.0f} s)")
    for name, s in summary["parameters"].items():
        # independent draws (laplace) have no R-hat to show
        chain = "" if args.method == "laplace" else f"  R-hat {s['rhat']:.3f}  ESS {s['ess']:.0f}"
        print(f"  {name:32s} {s['median']:12.5g}  90% [{s['q05']:.5g}, {s['q95']:.5g}]{chain}")
    if summary["misfit"]["note"]:
        print(f"  misfit: {summary['misfit']['note']}")
    for b in summary["at_bounds"]:
        print(f"  at its {b['bound']} bound: {b['parameter']} (90 % [{b['q05']:.4g}, "
              f"{b['q95']:.4g}], bound {b['value']:.4g}): the data push it there")
    for g in summary["identifiability"]["groups"]:
        why = g.get("reason") or f"correlation {g.get('correlation', 0.0):.2f}"
        print(f"  confounded: {' ~ '.join(g['parameters'])}: {why}")
    return 0


def _point_warnings(model, est: dict, summary: dict) -> None:
    """A point estimate's misfit and parameters at their bounds, said as mcmc says them."""
    from pneubayes.inference.fit import MISFIT_RATIO, at_bounds

    rmse, noise = est.get("rmse_Pa"), summary.get("noise_floor_Pa")
    if isinstance(rmse, (int, float)) and isinstance(noise, (int, float)) and noise > 0 \
            and rmse > MISFIT_RATIO * noise:
        print(f"  misfit: the model misses by {rmse / noise:.1f} x the noise floor "
              f"({rmse:.0f} Pa against {noise:.0f} Pa)")
    values = {k: {"q05": v, "q95": v} for k, v in est["parameters"].items()
              if isinstance(v, (int, float))}
    for b in at_bounds(model, values):
        print(f"  at its {b['bound']} bound: {b['parameter']} = {b['q05']:.4g} (bound "
              f"{b['value']:.4g}): the data push it there, or the bound is sized for "
              "another rig (--bounds)")


def cmd_predict(args) -> int:
    from pneubayes.inference.pipeline import MISFIT_RATIO, run_predict
    from pneubayes.io.recording import read_recording
    from pneubayes.simulation import SolverConfig

    if args.draws < MIN_DRAWS:
        raise PneubayesError(f"--draws {args.draws}: the 5-95 % bands and their coverage "
                             f"need at least {MIN_DRAWS} posterior draws (default 200)")
    companions = (".metrics.json",) + (() if args.no_figure else (".png",))
    out = _output_file(args.out, ".csv", args.overwrite, *companions)
    run = Path(args.run)
    _not_an_input([out, *(out.with_suffix(c) for c in companions)],
                  [*_recording_files([args.recording]),
                   *(p for p in run.iterdir() if p.is_file())] if run.is_dir() else
                  _recording_files([args.recording]))
    for name in ("model.json", "posterior.nc"):
        if not (run / name).is_file():
            raise PneubayesError(f"{run}: no {name} (a run folder of 'pneubayes fit' with "
                                 "the default --method mcmc, or of 'pneubayes discover')")
        check_file(run, name)
    rec = read_recording(args.recording, args.accept, args.rig)
    _print_findings("predict", [rec])
    figure = None if args.no_figure else out.with_suffix(".png")
    horizon = args.horizon or _run_horizon(run)
    _check_windows([rec], horizon, args.stride, args.force, args.draws)
    m = run_predict(args.run, rec, horizon, out, args.draws, args.seed,
                    SolverConfig.standard(), stride_s=args.stride, figure_path=figure)
    span = m["rmse_percent_of_span"]
    print(f"{out}: RMSE {m['rmse_Pa']:.0f} Pa ("
          + (f"{span:.2f} % of the measured span, " if span is not None else "")
          + f"{m['rmse_over_noise_floor']:.2f} x the noise floor of "
          f"{m['noise_floor_Pa']:.0f} Pa); coverage 50 % -> {m['coverage_50']:.2f}, "
          f"90 % -> {m['coverage_90']:.2f} with a 90 % band {m['band_90_width_Pa']:.0f} Pa "
          f"wide ({m['band_90_width_over_sensor_noise']:.1f} x what sensor noise alone gives)")
    if m["rmse_over_noise_floor"] > MISFIT_RATIO:
        print(f"  misfit: the model misses by {m['rmse_over_noise_floor']:.1f} x the noise "
              "floor" + (" and its bands cover only by being wide (the noise model "
                         "absorbs the misfit)"
                         if m["band_90_width_over_sensor_noise"] > 2 else ""))
    if figure is not None:
        print(figure)
    return 0


def cmd_track(args) -> int:
    from pneubayes.inference.track import run_track
    from pneubayes.io.recording import read_recording
    from pneubayes.simulation import SolverConfig

    if args.temper <= 0.0:
        raise PneubayesError(f"--temper {args.temper:g}: must be in (0, 1]")
    twice = sorted({n for n in args.vary if args.vary.count(n) > 1})
    if twice:
        raise PneubayesError(f"--vary: {', '.join(twice)} given more than once")
    out = _output_file(args.out, ".json", args.overwrite)
    run = Path(args.run)
    if not (run / "model.json").is_file():
        raise PneubayesError(f"{run}: no model.json (a run folder of 'pneubayes fit' or "
                             "'pneubayes discover')")
    check_file(run, "model.json")
    _not_an_input([out], [*_recording_files([args.recording]),
                          *(p for p in run.iterdir() if p.is_file())])
    rec = read_recording(args.recording, args.accept, args.rig)
    _print_findings("track", [rec])
    if not rec.valid_mask().all():
        first = int(np.nonzero(~rec.valid_mask())[0][0])
        raise PneubayesError(f"{rec.source} row {first + 2}: its 'valid' column marks "
                             "samples invalid, and track replays every sample (it does not "
                             "skip invalid stretches): track the valid stretches as "
                             "recordings of their own")
    horizon = args.horizon or _run_horizon(run)
    t = np.asarray(rec.time_s)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    if args.tick < dt:
        raise PneubayesError(f"--tick {args.tick:g}: shorter than the sample interval "
                             f"{dt:.3g} s of {rec.source}")
    if horizon < MIN_WINDOW_SAMPLES * dt:
        raise PneubayesError(f"--horizon {horizon:g}: shorter than {MIN_WINDOW_SAMPLES} "
                             f"sample intervals of {rec.source} (sampled every {dt:.3g} s)")
    if t[-1] - t[0] <= horizon:
        raise PneubayesError(f"--horizon {horizon:g}: as long as {rec.source} "
                             f"({t[-1] - t[0]:.3g} s); nothing to predict")
    if args.tick > (t[-1] - t[0]) / 2:
        raise PneubayesError(f"--tick {args.tick:g}: over half of {rec.source} "
                             f"({t[-1] - t[0]:.3g} s); a stream of one or two updates "
                             "tracks nothing")
    from pneubayes.model import Model

    model, _ = Model.load_card(run / "model.json")
    if args.vary == ("all",):  # every parameter of the run's model
        if args.method != "refit":
            raise PneubayesError("--vary all: only with --method refit (the particle filter "
                                 "tracks a few quantities with a lower bound > 0)")
        args.vary = tuple(model.parameter_names)
    for name in args.vary if args.method == "particles" else ():
        if name in model.parameter_names and not model.parameter(name).lower > 0:
            raise PneubayesError(f"--vary {name}: its lower bound is "
                                 f"{model.parameter(name).lower:g}; the tracker works in log "
                                 "space and needs quantities with a lower bound > 0")
    s = run_track(run, rec, args.vary, out, tick_s=args.tick, horizon_s=horizon,
                  n_particles=args.particles, n_draws=args.draws, seed=args.seed,
                  noise_std_Pa=args.noise_std, prior=args.prior,
                  prior_log_sd=args.prior_log_sd, solver=SolverConfig.standard(),
                  predict_every=args.predict_every,
                  tracker_options={"lookback_s": args.lookback, "temper": args.temper,
                                   "memory_s": args.lookback,
                                   "update_mode": args.update_mode,
                                   "pressure_gain": args.pressure_gain},
                  method=args.method,
                  refit_options={"relative_sd": args.relative_sd,
                                 "refit_every_s": args.refit_every or horizon})
    def fmt(v):
        return "n/a" if v is None else f"{v:.0f} Pa"
    cov, ccov = s["coverage_90"], s["conformal_coverage_90"]
    print(f"{out}: {s['ticks']} ticks; {horizon:g}-s predictions from {s['predicted_ticks']} "
          f"of them: online RMSE {fmt(s['online_rmse_Pa'])} (frozen fit "
          f"{fmt(s['frozen_rmse_Pa'])}), 90 % band coverage "
          + ("n/a" if cov is None else f"{cov:.2f}")
          + " (rescaled by the run's own errors "
          + ("n/a" if ccov is None else f"{ccov:.2f}") + ")"
          + f"; update {s['update_ms_median']:.1f} ms median per tick")
    return 0


def cmd_discover(args) -> int:
    from pneubayes.discovery.report import run_discover

    settings = discovery_settings(args)
    recs = _read_all([*args.recordings, *args.held_out], args.accept, "discover", args.rig)
    _check_filter(recs, settings.fit.pressure_filter)
    _check_windows(recs, settings.fit.horizon_s, settings.fit.stride_s, args.force)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    identity = {"recordings": inputs_digest(_recording_files([*args.recordings,
                                                              *args.held_out])),
                "settings": settings.to_dict(), "accept": list(args.accept),
                "rig": None if recs[0].rig_card is None else recs[0].rig_card.to_dict()}
    _not_an_input([Path(args.out) / n for n in DISCOVER_OUTPUTS],
                  _recording_files([*args.recordings, *args.held_out]))
    folder = open_run_folder(args.out, "discover", identity, overwrite=args.overwrite,
                             resume=args.resume, outputs=DISCOVER_OUTPUTS,
                             argv=args.argv)
    if folder.resumed:
        log(f"discover: resuming the run in {args.out} (finished fits are reused)")
    doc = run_discover(recs, settings, args.out, log=log, figures=not args.no_figures)
    from pneubayes.inference.fit_folder import _non_finite_rmse

    bad = _non_finite_rmse(doc)
    if bad:
        raise FloatingPointError(f"{args.out}/discovery.json: {bad[0][0]} is {bad[0][1]}; "
                                 "not a result (a simulation failed on the data)")
    folder.record("discovery.json", "model.json", "posterior.nc", "disagreement.json",
                  "report.md")
    print(f"{args.out}/discovery.json: base held-out {settings.fit.horizon_s:g}-s RMSE "
          f"{doc['rmse_base_Pa']:.0f} Pa, "
          f"final {doc['rmse_final_Pa']:.0f} Pa (noise floor {doc['noise_floor_Pa']:.0f} Pa)")
    if not doc["effects"]:
        print("  no missing effect is supported")
    for e in doc["effects"]:
        ps = ", ".join(
            f"{n} = {p.get('median', p.get('estimate')):.4g}"
            + (f" [{p['q05']:.4g}, {p['q95']:.4g}]" if "q05" in p else "")
            for n, p in e["parameters"].items())
        print(f"  + {e['name']}: {ps}; inclusion "
              f"{e['evidence']['inclusion_probability']:.2f}, RMSE {e['rmse_before_Pa']:.0f}"
              f" -> {e['rmse_after_Pa']:.0f} Pa")
    print(f"{args.out}/report.md")
    return 0


def cmd_import(args) -> int:
    from pneubayes.io.importers import IMPORTERS

    out = Path(args.out)
    if out.exists() and any(out.iterdir()) and not args.overwrite:
        raise PneubayesError(f"--out {out}: exists and is not empty (pass --overwrite to "
                             "write into it)")
    if args.end and args.source != "gtdynamics":
        raise PneubayesError("--end: only the gtdynamics importer cuts its trials")
    from pneubayes.run_folder import read_stamp

    stamp = read_stamp(out) if out.is_dir() else None
    if stamp is not None:
        raise PneubayesError(f"--out {out}: is the run folder of a 'pneubayes "
                             f"{stamp.get('command')}' ({out / 'run.json'}); import writes "
                             "its recordings into a folder of their own")
    made = not (out.exists() or out.is_symlink())
    try:
        written = IMPORTERS[args.source](args.inputs, out, **({"end_s": args.end}
                                                             if args.end else {}))
    except BaseException:
        if made:  # refused: the folder it made goes (nothing of the user's was in it)
            shutil.rmtree(out, ignore_errors=True)
        raise
    for p in written:
        print(p)
    print(f"{len(written)} recording(s) and their rig card in {out}; check them with "
          f"'pneubayes check {out}/*/*.csv'")
    return 0


def cmd_compile(args) -> int:
    from pneubayes.simulation.precompile import compile_kernels

    for state, seconds in compile_kernels(args.jobs).items():
        print(f"kernel ({state} state): {seconds:.1f} s")
    return 0


def cmd_ablate(args) -> int:
    from pneubayes.ablation.executor import DaskExecutor, LocalExecutor
    from pneubayes.ablation.runner import run_study
    from pneubayes.ablation.study import load_study

    study = load_study(args.study)
    if args.smoke:
        study = study.smoke()
    if args.scheduler and args.workers is not None:
        raise PneubayesError("--workers: not with --scheduler (the Dask cluster has its own "
                             "workers)")
    if args.dry_run:
        for cell in study.cells():
            print(cell.id)
        print(f"{args.study}: valid; {study.n_cells} cell(s) (nothing run)")
        return 0
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    folder = open_run_folder(args.out, "ablate", {"study": study.to_dict()},
                             overwrite=args.overwrite, resume=args.resume,
                             outputs=("results.json", "results.csv", "cells", "work"),
                             argv=args.argv)
    if folder.resumed:
        log(f"ablate: resuming the study in {args.out}")
    try:
        executor = (DaskExecutor(args.scheduler) if args.scheduler
                    else LocalExecutor(args.workers or 1))
    except (ImportError, OSError) as exc:
        raise PneubayesError(f"--scheduler {args.scheduler}: {exc}") from None
    except (MemoryError, ValueError, RuntimeError) as exc:  # a scheduler that does not answer
        raise PneubayesError(f"--scheduler {args.scheduler}: no Dask scheduler answers "
                             f"there ({type(exc).__name__}: {exc})") from None
    # SIGINT or SIGTERM (a batch system's stop) ends the study between cells: running
    # cells are cancelled (local worker processes ended), finished ones are on disk
    with executor:
        doc = run_study(study, args.out, executor, progress=not args.quiet, log=log,
                        keep_work=args.keep_work)
    folder.record("results.json", "results.csv")
    c = doc["counts"]
    print(f"{args.out}/results.json  ({c['cells']} cells: {c['ok']} ok, {c['error']} failed; "
          f"{c['run_now']} run now, {c['cached']} cached)")
    print(f"{args.out}/results.csv")
    return 1 if c["error"] else 0


def _stopped_message(args, exc) -> str:
    out = getattr(args, "out", None)
    kept = f"finished work is kept in {out}; " if out else ""
    return (f"pneubayes {args.command}: {exc}; {kept}run the same command again to "
            "resume")


def _resumed(parser, run):
    """``pneubayes resume RUN``: the command line recorded in RUN's stamp and its parsed
    arguments, set to insist on a resume (:func:`pneubayes.run_folder.open_run_folder`'s
    ``resume``)."""
    from pneubayes.run_folder import STAMP, read_stamp

    stamp = read_stamp(run)
    if stamp is None:
        raise RunFolderError(f"{run}: nothing to resume (no {STAMP} there)")
    argv = stamp.get("argv")
    if (not isinstance(argv, list) or not argv or not all(isinstance(a, str) for a in argv)
            or argv[0] not in ("fit", "discover", "ablate")
            or argv[0] != stamp.get("command")):
        raise RunFolderError(f"{Path(run) / STAMP}: records no fit, discover or ablate "
                             "command line to resume")
    argv = [a for a in argv if a != "--resume"]  # stamped before it went
    args = parser.parse_args(argv)
    check_single_values(parser, args)
    if Path(args.out).resolve() != Path(run).resolve():
        raise RunFolderError(f"{run}: its command writes to --out {args.out}, which is "
                             "another folder from here; run 'pneubayes resume' from the "
                             "folder the command was started in")
    args.resume = True
    return argv, args


def main(argv=None) -> int:
    """Run one command. Errors are one message naming the file, option or key (exit 2;
    ``check`` exits 1 when a file has problems); a stop by SIGINT or SIGTERM keeps the
    finished work and exits 130 or 143; an unexpected failure is reported as an internal
    error (exit 70), with the traceback only when ``PNEUBAYES_TRACEBACK=1``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    check_single_values(parser, args)
    if args.command == "resume":
        try:
            argv, args = _resumed(parser, args.run)
        except PneubayesError as exc:
            print(f"pneubayes resume: error: {exc}", file=sys.stderr)
            return 2
    args.func = {"check": cmd_check, "bench": cmd_bench, "simulate": cmd_simulate,
                 "fit": cmd_fit, "predict": cmd_predict, "discover": cmd_discover,
                 "ablate": cmd_ablate, "import": cmd_import,
                 "compile": cmd_compile, "track": cmd_track}[args.command]
    args.argv = list(sys.argv[1:] if argv is None else argv)  # stamped in run folders
    if getattr(args, "accept", None) == () and any(
            a == "--accept" or a.startswith("--accept=") for a in args.argv):
        print(f"pneubayes {args.command}: error: --accept: names no rule (give "
              "RULE[,RULE], e.g. sample-interval)", file=sys.stderr)
        return 2
    from pneubayes import limits

    limits.set_max_file_mb(getattr(args, "max_file_mb", None))

    def fail(message: str, code: int = 2) -> int:
        print(f"pneubayes {args.command}: error: {message}", file=sys.stderr)
        return code
    try:
        with interrupt.stop_on_signals():
            return args.func(args)
    except interrupt.Interrupted as exc:
        print(_stopped_message(args, exc), file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(_stopped_message(args, "interrupted by SIGINT"), file=sys.stderr)
        return 130
    except (PneubayesError, KeyError, ValueError) as exc:
        return fail(exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc))
    except OSError as exc:  # permissions, a full disk, a folder for a file, HDF5 files
        where = exc.filename or ""
        what = exc.strerror or str(exc)
        return fail(f"{where}: {what}" if where else what)
    except MemoryError as exc:
        return fail(f"out of memory ({exc or 'MemoryError'}); the work is larger than this "
                    "machine holds: fewer recordings, windows, walkers or draws")
    except ArithmeticError as exc:
        return fail(f"numerical failure ({type(exc).__name__}: {exc})")
    except Exception as exc:  # a bug: say so, in one message
        if os.environ.get("PNEUBAYES_TRACEBACK"):
            traceback.print_exc()
        return fail(f"internal error ({type(exc).__name__}: {exc}); this is a bug in "
                    "pneubayes, please report it with the command line (set "
                    "PNEUBAYES_TRACEBACK=1 to see where it happened)", 70)
    finally:
        release_locks()


if __name__ == "__main__":
    sys.exit(main())
