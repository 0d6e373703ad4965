"""``pneubayes discover``: the discovery loop into a run folder."""

from __future__ import annotations

import sys
from pathlib import Path

from pneubayes.cli.common import (
    check_filter,
    check_windows,
    not_an_input,
    read_all,
    recording_files,
)
from pneubayes.cli.settings import discovery_settings
from pneubayes.run_folder import (
    inputs_digest,
    open_run_folder,
)

#: What the command may write (removed by --overwrite when the folder has no stamp
#: listing the earlier run's files).
DISCOVER_OUTPUTS = ("discovery.json", "model.json", "posterior.nc", "chain.h5",
                    "disagreement.json", "report.md", "figures", "steps", "found_effect.py",
                    "found_reading.py", "found_volume.py")


def cmd_discover(args) -> int:
    from pneubayes.discovery.report import run_discover

    settings = discovery_settings(args)
    recs = read_all([*args.recordings, *args.held_out], args.accept, "discover", args.rig)
    check_filter(recs, settings.fit.pressure_filter)
    check_windows(recs, settings.fit.horizon_s, settings.fit.stride_s, args.force)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    identity = {"recordings": inputs_digest(recording_files([*args.recordings,
                                                              *args.held_out])),
                "settings": settings.to_dict(), "accept": list(args.accept),
                "rig": None if recs[0].rig_card is None else recs[0].rig_card.to_dict()}
    not_an_input([Path(args.out) / n for n in DISCOVER_OUTPUTS],
                  recording_files([*args.recordings, *args.held_out]))
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
    for line in summary_lines(doc):
        print(line)
    print(f"{args.out}/report.md")
    return 0


def summary_lines(doc: dict) -> list[str]:
    """What a discovery added, one line each: the named effects (+), the open-form terms
    (*) and the stand-ins kept at a bound (~)."""
    if not any(doc.get(k) for k in ("effects", "stand_ins", "found_terms",
                                     "found_reading_terms", "found_volume_terms",
                                     "found_command_terms", "found_port_terms")):
        return ["  no missing effect is supported"]
    out = []
    for e in doc["effects"]:
        ps = ", ".join(
            f"{n} = {p.get('median', p.get('estimate')):.4g}"
            + (f" [{p['q05']:.4g}, {p['q95']:.4g}]" if "q05" in p else "")
            for n, p in e["parameters"].items())
        incl = e["evidence"]["inclusion_probability"]  # (None: a stage proposed it)
        out.append(f"  + {e['name']}: {ps}; inclusion "
                   f"{'-' if incl is None else format(incl, '.2f')}, RMSE "
                   f"{e['rmse_before_Pa']:.0f} -> {e['rmse_after_Pa']:.0f} Pa")
    for key in ("found_terms", "found_reading_terms", "found_volume_terms",
                "found_command_terms", "found_port_terms"):
        for t in doc.get(key, []):
            ps = ", ".join(f"{n} = {p.get('median', p.get('estimate')):.4g} {p['unit']}"
                           for n, p in t["parameters"].items())
            out.append(f"  * open form, on {t['acts_on']}: {t['formula']}; {ps}")
    for e in doc.get("stand_ins", []):
        where = ", ".join(f"{b['parameter']} at its {b['bound']} bound" for b in e["at_bounds"])
        out.append(f"  ~ {e['name']}: kept as a stand-in, not named ({where}); RMSE "
                   f"{e['rmse_before_Pa']:.0f} -> {e['rmse_after_Pa']:.0f} Pa")
    return out
