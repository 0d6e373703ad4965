"""``pneubayes fit``: identify a model from recordings into a run folder."""

from __future__ import annotations

import sys
from pathlib import Path

from pneubayes.cli.common import (
    card_known_at,
    check_filter,
    check_windows,
    effect_names,
    known_from,
    no_bound_twice,
    not_an_input,
    point_warnings,
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

#: What each folder-writing command may write (removed by --overwrite when the folder
#: has no stamp listing the earlier run's files).
FIT_OUTPUTS = ("model.json", "summary.json", "posterior.nc", "chain.h5", "refined.json",
               "figures")


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
    no_bound_twice(args.bounds)
    settings = fit_settings(args)
    sampler = settings.sampler
    known = known_from(args) if args.known_from or args.refit else None
    recs = read_all(args.recordings, args.accept, "fit", args.rig)
    check_filter(recs, settings.pressure_filter)
    check_windows(recs, settings.horizon_s, settings.stride_s, args.force,
                   windows=args.method != "lsq")
    card = rig_card_of(recs)
    if known is not None:  # the card's quantities known at another fit's values
        card = card_known_at(card, known, args)
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
                "known_from": None if known is None else str(known[2]),
                "method": args.method, "walkers": sampler.n_walkers, "seed": sampler.seed,
                "windows": {"horizon_s": settings.horizon_s, "stride_s": settings.stride_s},
                "refine_jacobian_refresh": settings.refine_jacobian_refresh,
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
        point_warnings(model, est, summary)
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
