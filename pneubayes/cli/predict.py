"""``pneubayes predict``: a run's prediction bands and metrics on a recording."""

from __future__ import annotations

from pathlib import Path

from pneubayes.cli.common import (
    check_windows,
    not_an_input,
    output_file,
    print_findings,
    recording_files,
    run_horizon,
)
from pneubayes.errors import PneubayesError
from pneubayes.run_folder import check_file

#: The fewest posterior draws a prediction's bands are drawn from (--draws).
MIN_DRAWS = 20


def cmd_predict(args) -> int:
    from pneubayes.inference.pipeline import MISFIT_RATIO, run_predict
    from pneubayes.io.recording import read_recording
    from pneubayes.simulation import SolverConfig

    if args.draws < MIN_DRAWS:
        raise PneubayesError(f"--draws {args.draws}: the 5-95 % bands and their coverage "
                             f"need at least {MIN_DRAWS} posterior draws (default 200)")
    companions = (".metrics.json",) + (() if args.no_figure else (".png",))
    out = output_file(args.out, ".csv", args.overwrite, *companions)
    run = Path(args.run)
    not_an_input([out, *(out.with_suffix(c) for c in companions)],
                  [*recording_files([args.recording]),
                   *(p for p in run.iterdir() if p.is_file())] if run.is_dir() else
                  recording_files([args.recording]))
    for name in ("model.json", "posterior.nc"):
        if not (run / name).is_file():
            raise PneubayesError(f"{run}: no {name} (a run folder of 'pneubayes fit' with "
                                 "the default --method mcmc, or of 'pneubayes discover')")
        check_file(run, name)
    rec = read_recording(args.recording, args.accept, args.rig)
    print_findings("predict", [rec])
    figure = None if args.no_figure else out.with_suffix(".png")
    horizon = args.horizon or run_horizon(run)
    check_windows([rec], horizon, args.stride, args.force, args.draws)
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
