"""Run folders that protect the user's files: a stamp of what produced each file.

Every command that writes a folder (``fit``, ``discover``, ``ablate``) opens it with
:func:`open_run_folder`. The folder's ``run.json`` (format ``pneubayes-run/1``) records
the command, its *identity* (the digests of its inputs and the settings that define its
result) and, as they are written, the sha256 of each file it produced. Rules:

* a missing or empty folder starts a new run (so does one holding only a stamp: that
  run failed before it wrote anything);
* a folder holding this command's run with the same identity is resumed (a killed fit,
  discovery or study goes on where it stopped);
* anything else (another command's or another identity's run, or files with no stamp)
  is refused, naming what is there, unless ``overwrite``: then the files the earlier run
  produced (its stamp's list, or the command's known outputs when there is no stamp)
  are removed before the new run starts; files of the user's are never removed;
* ``resume=True`` insists on a resume: a folder with nothing to resume is an error.

Readers check a file against the stamp (:func:`check_file`), so files of different runs
are never combined (a model card of one fit with the posterior of another).
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from pneubayes.atomic import json_safe, write_json_atomic
from pneubayes.errors import PneubayesError

STAMP = "run.json"
STAMP_FORMAT = "pneubayes-run/1"


class RunFolderError(PneubayesError):
    """An output folder cannot be used as asked; the message says what to do."""


def file_digest(path) -> str:
    """sha256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def inputs_digest(paths: Iterable) -> list[dict]:
    """``[{"path", "sha256"}]`` of input files, in order (a recording is its CSV and
    JSON)."""
    return [{"path": str(p), "sha256": file_digest(p)} for p in paths]


def _identity_digest(identity: Mapping) -> str:
    text = json.dumps(json_safe(dict(identity)), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass
class RunFolder:
    """An opened run folder. ``resumed`` is True when an earlier run of the same command
    and identity is continued; :meth:`record` stamps files as they are written."""

    path: Path
    command: str
    identity_digest: str
    resumed: bool

    @property
    def stamp_path(self) -> Path:
        return self.path / STAMP

    def stamp(self) -> dict:
        return json.loads(self.stamp_path.read_text())

    def record(self, *names: str) -> None:
        """Stamp the files ``names`` (relative to the folder) as this run's products."""
        doc = self.stamp()
        for name in names:
            p = self.path / name
            if p.is_file():
                doc["files"][name] = file_digest(p)
        write_json_atomic(self.stamp_path, doc)


def read_stamp(folder) -> dict | None:
    """The folder's stamp, or None when it has none; a stamp that does not parse is an
    error naming it."""
    path = Path(folder) / STAMP
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise RunFolderError(f"{path}: unreadable run stamp ({exc}); remove it or use "
                             "another folder") from None
    if not isinstance(doc, dict) or doc.get("format") != STAMP_FORMAT \
            or not isinstance(doc.get("files"), dict):
        raise RunFolderError(f"{path}: not a {STAMP_FORMAT} run stamp")
    return doc


def _describe(doc: dict | None) -> str:
    if doc is None:
        return "files that no pneubayes run stamped"
    return f"a '{doc.get('command')}' run of other inputs or settings"


def open_run_folder(out, command: str, identity: Mapping, *, overwrite: bool = False,
                    resume: bool = False, outputs: Iterable[str] = (),
                    argv: list | None = None) -> RunFolder:
    """Open ``out`` for ``command`` with ``identity`` under the module's rules.

    ``outputs`` names the files and folders the command writes (removed on
    ``overwrite`` when the folder has no stamp to list them).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RunFolderError(f"--out {out}: is a file, not a folder")
    digest = _identity_digest(identity)
    stamp = read_stamp(out) if out.is_dir() else None
    # a stamp alone (a run that failed before writing anything) holds nothing to protect
    busy = out.is_dir() and any(p.name != STAMP for p in out.iterdir())
    same = (stamp is not None and stamp.get("command") == command
            and stamp.get("identity_digest") == digest)
    if resume and not same:
        raise RunFolderError(f"--out {out}: nothing to resume (it holds {_describe(stamp)})"
                             if busy else f"--out {out}: nothing to resume (no run there)")
    if busy and not same:
        if not overwrite:
            raise RunFolderError(
                f"--out {out}: holds {_describe(stamp)}; refusing to mix runs. Use "
                f"--overwrite to replace that run's files, or another folder (--resume "
                f"continues only the same '{command}' on the same inputs and settings)")
        names = set(stamp["files"]) | {STAMP} if stamp is not None else set()
        for name in names | set(outputs):
            p = out / name
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            elif p.exists() or p.is_symlink():
                p.unlink()
    if same:
        return RunFolder(out, command, digest, resumed=True)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / STAMP, {
        "format": STAMP_FORMAT, "command": command, "argv": argv,
        "identity_digest": digest, "identity": identity, "files": {}})
    return RunFolder(out, command, digest, resumed=False)


def check_file(folder, name: str) -> None:
    """Refuse ``folder/name`` unless the folder's stamp records exactly this file as its
    run's product (a file replaced, or copied in from another run, is refused). Folders
    without a stamp (written before stamps, or by the library directly) are not checked
    here."""
    stamp = read_stamp(folder)
    if stamp is None:
        return
    path = Path(folder) / name
    if name not in stamp["files"]:
        raise RunFolderError(f"{path}: not produced by the '{stamp.get('command')}' run "
                             f"stamped in {Path(folder) / STAMP}; files of different runs "
                             "are never combined")
    if file_digest(path) != stamp["files"][name]:
        raise RunFolderError(f"{path}: not the file its run produced ({Path(folder) / STAMP} "
                             "records another); files of different runs are never combined")
