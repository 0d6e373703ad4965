"""Helpers the commands share: reading recordings and rig cards, checking windows,
filters and output paths, known values."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from pneubayes.errors import PneubayesError
from pneubayes.run_folder import (
    recorded_number,
)

#: A declared pressure filter's cutoff may lie at most this many times above a
#: recording's sample rate (an oversampling DAQ filters before it decimates, so a cutoff
#: at the sample rate is real, e.g. the bench's 2:1000 at 1 kHz; far above, the filter
#: changes no sample and the value is a slip).
FILTER_MAX_OVER_RATE = 10.0
#: The fewest sample intervals a prediction window spans (--horizon).
MIN_WINDOW_SAMPLES = 4


def print_findings(command: str, recordings) -> None:
    """Plausibility warnings (and accepted findings) of recordings, on stderr."""
    for rec in recordings:
        for f in rec.findings:
            print(f"pneubayes {command}: warning: {f.location}: {f.text()}", file=sys.stderr)


def run_horizon(run: Path) -> float:
    """The window length a run was fitted on (its summary or discovery document), s;
    2 s for runs that do not record it."""
    horizon = recorded_number(run, (("summary.json", ("settings", "horizon_s")),
                                    ("discovery.json", ("horizon_s",))))
    return 2.0 if horizon is None else horizon


def effect_names(text: str, option: str = "--effects") -> list[str]:
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


def no_bound_twice(bounds) -> None:
    names = [n for n, _ in bounds]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PneubayesError(f"--bounds: {', '.join(twice)} given more than once (which "
                             "one did you mean?)")


def check_windows(recs, horizon: float, stride: float | None, force: bool,
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


def check_filter(recs, pressure_filter) -> None:
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


def output_file(path: str, suffix: str, overwrite: bool, *companions: str) -> Path:
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


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (resolved: links, ``..`` and relative paths)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def not_an_input(outputs, inputs, option: str = "--out") -> None:
    """Refuse, before any work, an output that is one of the command's inputs (a
    recording's CSV or JSON, a model card, a run's files): no command writes over what
    it reads, not even with --overwrite."""
    for o in outputs:
        for i in inputs:
            if same_file(Path(o), Path(i)):
                raise PneubayesError(f"{option} {o}: is the input {i}; a command never "
                                     "writes over its own inputs (choose another output)")


def recording_files(paths) -> list[Path]:
    from pneubayes.io.recording import recording_paths

    return [f for p in paths for f in recording_paths(p)]


def read_all(paths, accept, command, rig=None):
    from pneubayes.io.recording import read_recording

    recs = [read_recording(p, accept, rig) for p in paths]
    print_findings(command, recs)
    rig_card_of(recs)
    return recs


def rig_card_of(recs):
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


def known_from(args):
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


def card_known_at(card, known, args):
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


def point_warnings(model, est: dict, summary: dict) -> None:
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
