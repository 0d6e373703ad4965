"""Helpers the commands share: reading recordings and rig cards, checking windows,
filters and output paths, known values."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from pneubayes.errors import PneubayesError
from pneubayes.run_folder import recorded_number

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


def read_all(paths, accept, command, rig=None):
    from pneubayes.io.recording import read_recording

    recs = [read_recording(p, accept, rig) for p in paths]
    print_findings(command, recs)
    rig_card_of(recs)
    return recs


