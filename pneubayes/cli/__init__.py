"""The ``pneubayes`` command: ``check``, ``bench``, ``simulate``, ``fit``, ``predict``,
``discover``, ``ablate``, ``import``, ``compile``, ``track``.

Each subcommand is a thin layer over the library, one module each (``fit`` in
:mod:`pneubayes.cli.fit`, ...); errors are printed as one clear message naming the file,
row, key or argument (exit 2 for usage or input errors, 1 for ``check`` when any file has
problems). The arguments and their checks are in :mod:`pneubayes.cli.args`, the settings
they build in :mod:`pneubayes.cli.settings`, the helpers the commands share in
:mod:`pneubayes.cli.common`.
"""

from __future__ import annotations

import os
import sys
import traceback
from pathlib import Path

from pneubayes import interrupt
from pneubayes.cli.ablate import cmd_ablate
from pneubayes.cli.args import build_parser, check_single_values
from pneubayes.cli.bench import cmd_bench
from pneubayes.cli.check import cmd_check
from pneubayes.cli.compile import cmd_compile
from pneubayes.cli.discover import cmd_discover
from pneubayes.cli.fit import cmd_fit
from pneubayes.cli.import_ import cmd_import
from pneubayes.cli.predict import cmd_predict
from pneubayes.cli.simulate import cmd_simulate
from pneubayes.cli.track import cmd_track
from pneubayes.errors import PneubayesError
from pneubayes.run_folder import RunFolderError, release_locks


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

    def fail(message: str, code: int = 2) -> int:
        print(f"pneubayes {args.command}: error: {message}", file=sys.stderr)
        return code
    try:
        with interrupt.stop_on_signals(), limits.max_file_mb(getattr(args, "max_file_mb",
                                                                         None)):
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

