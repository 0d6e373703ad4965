"""``pneubayes fit``: identify a model from recordings into a run folder."""

from __future__ import annotations

import sys
from pathlib import Path

from pneubayes.cli.common import (
    check_filter,
    check_windows,
    effect_names,
    not_an_input,
    read_all,
    recording_files,
    rig_card_of,
)
from pneubayes.cli.settings import fit_settings
from pneubayes.errors import ParameterError, PneubayesError
from pneubayes.run_folder import (
    check_file,
    inputs_digest,
    open_run_folder,
)

#: What fit may write (removed by --overwrite when the folder
#: has no stamp listing the earlier run's files).
FIT_OUTPUTS = ("model.json", "summary.json", "posterior.nc", "chain.h5", "refined.json",
               "figures")


def _no_bound_twice(bounds) -> None:
    names = [n for n, _ in bounds]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PneubayesError(f"--bounds: {', '.join(twice)} given more than once (which "
                             "one did you mean?)")


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


def cmd_fit(args) -> int:
    from pneubayes.effects import effects_from_names
    from pneubayes.inference.pipeline import run_fit
    from pneubayes.model import Model

    if args.model and (args.effects is not None or args.leak_form is not None):
        given = [o for o, v in (("--effects", args.effects), ("--leak-form", args.leak_form))
                 if v is not None]
        raise PneubayesError(f"--model {args.model} fixes the effects and their forms; "
                             f"{' and '.join(given)} contradict it (give one or the other)")
    names = effect_names("cylinder_leak" if args.effects is None else args.effects)
    if args.leak_form is not None and "cylinder_leak" not in names:
        raise PneubayesError(f"--leak-form {args.leak_form}: only with cylinder_leak among "
                             "--effects (the fitted model has no leak)")
    _no_bound_twice(args.bounds)
    settings = fit_settings(args)
    sampler = settings.sampler
    known = _known_from(args) if args.known_from or args.refit else None
    recs = read_all(args.recordings, args.accept, "fit", args.rig)
    check_filter(recs, settings.pressure_filter)
    check_windows(recs, settings.horizon_s, settings.stride_s, args.force,
                   windows=args.method != "lsq")
    card = rig_card_of(recs)
    if known is not None:  # the card's quantities known at another fit's values
        card = _card_known_at(card, known, args)
        recs = read_all(args.recordings, args.accept, "fit", card)
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
    identity = {"recordings": inputs_digest(recording_files(args.recordings)),
                "effects": list(model.effect_names),
                "options": {e.name: e.options() for e in model.effects},
                "bounds": model.bound_overrides,
                "rig": None if card is None else card.to_dict(),
                "_known_from": None if known is None else str(known[2]),
                "method": args.method, "walkers": sampler.n_walkers, "seed": sampler.seed,
                "windows": {"horizon_s": settings.horizon_s, "stride_s": settings.stride_s},
                "refine_jacobian_refresh": settings.refine_jacobian_refresh,
                "refine_stall": [settings.refine_stall_evaluations,
                                 settings.refine_stall_tolerance, settings.refine_stall_after],
                # a chain is never resumed with another likelihood solver
                "sample_solver": settings.sample_solver.to_dict(),
                "preparation": settings.preparation(), "accept": list(args.accept)}
    not_an_input([Path(args.out) / n for n in FIT_OUTPUTS],
                  [*recording_files(args.recordings),
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
