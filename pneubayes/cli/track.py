"""``pneubayes track``: replay a recording as a stream through an online posterior."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pneubayes.cli.common import (
    MIN_WINDOW_SAMPLES,
    not_an_input,
    output_file,
    print_findings,
    recording_files,
    run_horizon,
)
from pneubayes.errors import PneubayesError
from pneubayes.run_folder import check_file


def cmd_track(args) -> int:
    from pneubayes.inference.track import run_track
    from pneubayes.io.recording import read_recording
    from pneubayes.simulation import SolverConfig

    if args.temper <= 0.0:
        raise PneubayesError(f"--temper {args.temper:g}: must be in (0, 1]")
    twice = sorted({n for n in args.vary if args.vary.count(n) > 1})
    if twice:
        raise PneubayesError(f"--vary: {', '.join(twice)} given more than once")
    out = output_file(args.out, ".json", args.overwrite)
    run = Path(args.run)
    if not (run / "model.json").is_file():
        raise PneubayesError(f"{run}: no model.json (a run folder of 'pneubayes fit' or "
                             "'pneubayes discover')")
    check_file(run, "model.json")
    not_an_input([out], [*recording_files([args.recording]),
                          *(p for p in run.iterdir() if p.is_file())])
    rec = read_recording(args.recording, args.accept, args.rig)
    print_findings("track", [rec])
    if not rec.valid_mask().all():
        first = int(np.nonzero(~rec.valid_mask())[0][0])
        raise PneubayesError(f"{rec.source} row {first + 2}: its 'valid' column marks "
                             "samples invalid, and track replays every sample (it does not "
                             "skip invalid stretches): track the valid stretches as "
                             "recordings of their own")
    horizon = args.horizon or run_horizon(run)
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
