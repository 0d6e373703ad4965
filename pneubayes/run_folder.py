"""Run folders that protect the user's files: a stamp of what produced each file.

Every command that writes a folder (``fit``, ``discover``, ``ablate``) opens it with
:func:`open_run_folder`. The folder's ``run.json`` (format ``pneubayes-run/1``) records
the command, its *identity* (the digests of its inputs and the settings that define its
result) and, as they are written, the sha256 of each file it produced. Rules:

* a missing or empty folder starts a new run (so does one holding only a stamp: that
  run failed before it wrote anything);
* a folder holding this command's run with the same identity is resumed (a killed fit,
  discovery or study goes on where it stopped);
* anything else (another command's or another identity's run) is refused, naming
  what is there, unless ``overwrite``: then exactly the files the earlier run's stamp
  records are removed (its ``files``, and the outputs it ``created`` when it opened a
  folder that did not hold them) before the new run starts. A stamp listing a path
  outside the folder (absolute, with ``..``, or through a symbolic link) is not trusted
  and nothing is removed; files of the user's are never removed;
* a folder holding files but no stamp is never emptied, even with ``overwrite``: the
  refusal names the folder and what is in it;
* ``resume=True`` insists on a resume: a folder with nothing to resume is an error.

While a command works in a folder it holds the folder's lock file (``.pneubayes.lock``:
its pid, host, command and start time); a second command on the same folder is refused,
naming the holder. A lock whose process is gone (same host, dead pid) is taken over with
a note.

Readers check a file against the stamp (:func:`check_file`), so files of different runs
are never combined (a model card of one fit with the posterior of another).
"""

from __future__ import annotations

import atexit
import hashlib
import json
import os
import shutil
import socket
import sys
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from pneubayes.atomic import json_safe, write_json_atomic
from pneubayes.errors import PneubayesError

STAMP = "run.json"
STAMP_FORMAT = "pneubayes-run/1"
LOCK = ".pneubayes.lock"
#: Names of a folder that are the machinery's, not content (a folder holding only these
#: is free).
_OWN = (STAMP, LOCK)


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

    def release(self) -> None:
        """Give up the folder's lock (also done at exit, see :func:`release_locks`)."""
        _release(self.path / LOCK)


_HELD: set = set()


def _release(lock: Path) -> None:
    _HELD.discard(lock)
    try:
        holder = json.loads(lock.read_text())
        if holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
            lock.unlink()
    except (OSError, ValueError, AttributeError):
        pass


def release_locks() -> None:
    """Release every run-folder lock this process holds."""
    for lock in list(_HELD):
        _release(lock)


atexit.register(release_locks)


def _alive(holder: dict) -> bool:
    """Whether the process a lock names may still run (another host: assume so)."""
    pid = holder.get("pid")
    if holder.get("host") != socket.gethostname() or not isinstance(pid, int) or pid <= 0:
        return holder.get("host") != socket.gethostname()
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _describe_holder(holder: dict) -> str:
    argv = holder.get("argv")
    cmd = "pneubayes " + " ".join(map(str, argv)) if isinstance(argv, list) else \
        f"pneubayes {holder.get('command')}"
    return (f"pid {holder.get('pid')} on {holder.get('host')} ('{cmd}', started "
            f"{holder.get('started')})")


def _acquire_lock(out: Path, command: str, argv, log) -> Path:
    """Take ``out``'s lock file for this process; refuse when a live process holds it."""
    lock = out / LOCK
    me = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
          "argv": argv, "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            try:
                holder = json.loads(lock.read_text())
                if not isinstance(holder, dict):
                    raise ValueError
            except FileNotFoundError:
                continue
            except (OSError, ValueError):
                try:  # being written this instant, or left empty by a killed process
                    young = time.time() - lock.stat().st_mtime < 10
                except OSError:
                    continue
                if young:
                    raise RunFolderError(f"--out {out}: in use (its lock {lock} is being "
                                         "written by another command)") from None
                holder = {}
            if holder.get("pid") == os.getpid() and holder.get("host") == me["host"]:
                _HELD.add(lock)  # this process holds it already
                return lock
            if holder and _alive(holder):
                raise RunFolderError(
                    f"--out {out}: in use by {_describe_holder(holder)}; wait for it to "
                    f"finish or use another folder (if that process is gone, remove {lock})"
                ) from None
            log(f"note: --out {out}: taking over the lock of "
                + (_describe_holder(holder) if holder else "an unreadable lock file")
                + ", which is no longer running")
            try:
                lock.unlink()
            except FileNotFoundError:
                pass
            continue
        with os.fdopen(fd, "w") as fh:
            fh.write(json.dumps(json_safe(me)) + "\n")
        _HELD.add(lock)
        return lock
    raise RunFolderError(f"--out {out}: could not take its lock {lock}")


def _member(out: Path, name) -> Path | None:
    """``out / name`` when ``name`` is a path inside ``out`` (relative, no ``..``, no
    symbolic link on the way), else None."""
    if not isinstance(name, str) or not name or "\x00" in name:
        return None
    rel = Path(name)
    # the raw parts: Path drops "." ("." itself would name the folder)
    if rel.is_absolute() or rel.drive or not rel.parts or any(
            part in ("..", ".", "") for part in name.replace("\\", "/").split("/")):
        return None
    p = out
    for part in rel.parts[:-1]:
        p = p / part
        if p.is_symlink():
            return None
    full = out / rel
    try:
        full.parent.resolve().relative_to(out.resolve())
    except ValueError:
        return None
    return full


def _listing(out: Path, limit: int = 8) -> str:
    names = sorted(p.name + ("/" if p.is_dir() and not p.is_symlink() else "")
                   for p in out.iterdir() if p.name not in _OWN)
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


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


def _describe(doc: dict | None, identity: Mapping | None = None) -> str:
    if doc is None:
        return "files that no pneubayes run stamped"
    differ = _differences(doc.get("identity"), identity) if identity is not None else []
    return (f"a '{doc.get('command')}' run of other inputs or settings"
            + (f" (differing: {', '.join(differ)})" if differ else ""))


def _without_paths(identity):
    """An identity with its inputs by content only (their paths dropped)."""
    doc = json_safe(identity)
    if isinstance(doc, dict):
        return {k: _without_paths(v) for k, v in doc.items()}
    if isinstance(doc, list):
        return [{"sha256": x["sha256"]} if isinstance(x, dict) and "sha256" in x
                else _without_paths(x) for x in doc]
    return doc


def _differences(old, new, where: str = "", limit: int = 6) -> list[str]:
    """The keys (dotted) where two identities differ, inputs by their content."""
    new = json_safe(new)
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new)):
            path = f"{where}.{k}" if where else str(k)
            if k not in old or k not in new:
                out.append(path)
            else:
                out += _differences(old[k], new[k], path, limit)
        return out[:limit]
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new) and \
            all(isinstance(x, dict) and "sha256" in x for x in old + new):
        return [f"{where}: {y.get('path')} (its content)" if x.get("sha256") != y.get("sha256")
                else f"{where}: {x.get('path')} -> {y.get('path')} (the path only)"
                for x, y in zip(old, new) if x != y][:limit]
    return [] if old == new else [where or "identity"]


def _remove_stamped_run(out: Path, stamp: dict, outputs) -> None:
    """Remove exactly what ``stamp`` records as its run's (after checking every entry is
    inside ``out``); refuse when an output of the new run would replace a file the stamp
    does not record."""
    files = list(stamp["files"])
    created = stamp.get("created", [])
    if not isinstance(created, list):
        raise RunFolderError(f"{out / STAMP}: 'created' is not a list; the stamp is not "
                             "trusted, nothing was removed")
    targets = {}
    for name in [*files, *created]:
        p = _member(out, name)
        if p is None:
            raise RunFolderError(
                f"{out / STAMP} lists {name!r}, which is not a path inside {out}; the stamp "
                "is not trusted and nothing was removed (remove the files yourself)")
        targets[name] = p
    stray = [n for n in outputs if n not in targets and n not in _OWN
             and ((out / n).exists() or (out / n).is_symlink())]
    if stray:
        raise RunFolderError(
            f"--out {out}: {', '.join(stray)} not recorded by its stamp {out / STAMP}; "
            "--overwrite removes only a run's recorded files, nothing was removed (move "
            "them or use another folder)")
    for name, p in targets.items():
        if p.is_symlink() or p.is_file():
            p.unlink()
        elif p.is_dir() and name in created:
            shutil.rmtree(p)


def open_run_folder(out, command: str, identity: Mapping, *, overwrite: bool = False,
                    resume: bool = False, outputs: Iterable[str] = (),
                    argv: list | None = None, log=None) -> RunFolder:
    """Open ``out`` for ``command`` with ``identity`` under the module's rules, holding
    its lock (released by :meth:`RunFolder.release` or at exit).

    ``outputs`` names the files and folders the command writes; the new run's stamp
    records those it creates, so a later ``overwrite`` removes them.
    """
    out = Path(out)
    log = log or (lambda m: print(m, file=sys.stderr))
    outputs = tuple(outputs)
    if (out.exists() or out.is_symlink()) and not out.is_dir():
        raise RunFolderError(f"--out {out}: is a file, not a folder")
    made = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    lock = _acquire_lock(out, command, argv, log)
    try:
        return _open_locked(out, command, identity, overwrite, resume, outputs, argv)
    except BaseException:
        _release(lock)
        if made:
            try:
                out.rmdir()
            except OSError:
                pass
        raise


def _open_locked(out: Path, command, identity, overwrite, resume, outputs, argv):
    digest = _identity_digest(identity)
    stamp = read_stamp(out)
    # a stamp alone (a run that failed before writing anything) holds nothing to protect
    busy = any(p.name not in _OWN for p in out.iterdir())
    same = (stamp is not None and stamp.get("command") == command
            and (stamp.get("identity_digest") == digest
                 # the same inputs by another path (absolute, relative): the same run
                 or _without_paths(stamp.get("identity")) == _without_paths(identity)))
    if resume and not same:
        raise RunFolderError(f"--out {out}: nothing to resume (it holds "
                             f"{_describe(stamp, identity)})"
                             if busy else f"--out {out}: nothing to resume (no run there)")
    if busy and stamp is None:
        raise RunFolderError(
            f"--out {out}: holds files that no pneubayes run stamped ({_listing(out)}); "
            f"without a run stamp ({STAMP}) nothing there is removed, not even with "
            "--overwrite: use another folder, or move those files out")
    if busy and not same:
        if not overwrite:
            raise RunFolderError(
                f"--out {out}: holds {_describe(stamp, identity)}; refusing to mix runs. Use "
                f"--overwrite to replace that run's files, or another folder (a run resumes "
                f"only as the same '{command}' on the same inputs and settings)")
        _remove_stamped_run(out, stamp, outputs)
    if same:
        return RunFolder(out, command, digest, resumed=True)
    created = [n for n in outputs if not ((out / n).exists() or (out / n).is_symlink())]
    write_json_atomic(out / STAMP, {
        "format": STAMP_FORMAT, "command": command, "argv": argv,
        "identity_digest": digest, "identity": identity, "files": {},
        "created": created})
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


def recorded_number(run, sources) -> float | None:
    """The first positive number a run folder records at one of ``sources``: ``(file
    name, (key, key, ...))`` pairs, e.g. ``("summary.json", ("settings", "horizon_s"))``,
    tried in order; None when none holds one (a missing or unreadable file counts as
    none)."""
    for name, keys in sources:
        try:
            doc = json.loads((Path(run) / name).read_text())
            for k in keys:
                doc = doc[k]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if isinstance(doc, (int, float)) and not isinstance(doc, bool) and doc > 0:
            return float(doc)
    return None
