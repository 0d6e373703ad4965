"""``pneubayes import``: third-party recordings converted to the recording format."""

from __future__ import annotations

import shutil
from pathlib import Path

from pneubayes.errors import PneubayesError


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
