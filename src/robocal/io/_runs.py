"""Run folders: which command wrote the files in an output folder, and whether it finished.

Each command run that writes into a folder (``--out DIR``) records itself in
``DIR/.robocal-run.json`` (schema ``robocal.run/1``: the command, its rig,
the command line, start and finish times in UTC, the state ``running`` /
``complete`` / ``failed`` and the files it wrote) and puts an ``INCOMPLETE``
marker beside it, removed only when the command finishes. A crash, an
interrupt or an error therefore leaves ``INCOMPLETE``, and
:func:`robocal.io.load_result` refuses a result whose folder holds it: a stale
or half-made result is never read as new.

At the start of a run the folder must be new, empty, or hold an earlier run
of the same command (whose files are removed first, so nothing of it
survives). A folder holding another command's run or files robocal did not
write is refused, unless ``force``: then the earlier run's files are removed
and the unknown files are kept (and protected from being written over).
Files that are inputs of the running command are never removed nor written
over (see :func:`robocal.io.protected_paths`).

The bookkeeping belongs to a :class:`CommandRun` (the CLI's ``main`` opens
one around every command); :func:`claim_folder` outside of one only makes the
folder.
"""

from __future__ import annotations

import contextvars
import datetime as _dt
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

from robocal.errors import InputError
from robocal.io._atomic import _PROTECTED, atomic_write_text

__all__ = ["MANIFEST", "INCOMPLETE", "RUN_SCHEMA", "CommandRun", "RunFolder", "claim_folder", "active_run",
           "read_manifest", "preflight"]

MANIFEST = ".robocal-run.json"
INCOMPLETE = "INCOMPLETE"
RUN_SCHEMA = "robocal.run/1"

#: names shown in a refusal before "..."
_SHOWN = 4

_ACTIVE: contextvars.ContextVar["CommandRun | None"] = contextvars.ContextVar("robocal_active_run", default=None)


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def active_run() -> "CommandRun | None":
    """The :class:`CommandRun` open in this context, or None (Python API use)."""
    return _ACTIVE.get()


def _files(folder: Path) -> set[str]:
    """Relative POSIX paths of every file (and symlink) under ``folder``, bookkeeping files excluded."""
    found = set()
    for root, dirs, names in os.walk(folder):
        rel_root = Path(root).relative_to(folder)
        # a symlink to a directory is listed as an entry, never followed (removing it removes the link)
        for d in list(dirs):
            if os.path.islink(os.path.join(root, d)):
                names.append(d)
                dirs.remove(d)
        for n in names:
            found.add((rel_root / n).as_posix())
    found.discard(MANIFEST)
    found.discard(INCOMPLETE)
    return found


def read_manifest(folder) -> dict | None:
    """A folder's run manifest, or None when there is none or it is not one robocal wrote."""
    try:
        d = json.loads((Path(folder) / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) and d.get("schema") == RUN_SCHEMA else None


def _shown(names) -> str:
    names = sorted(names)
    # a folder's files are shown by their top-level name: "images/" rather than 40 image files
    tops = []
    for n in names:
        head, sep, _ = n.partition("/")
        top = head + "/" if sep else head
        if top not in tops:
            tops.append(top)
    text = ", ".join(tops[:_SHOWN])
    return text + (", ..." if len(tops) > _SHOWN else "")


def _remove(folder: Path, names) -> None:
    """Remove ``names`` (relative paths) under ``folder``, then the directories they leave empty."""
    dirs = set()
    for n in names:
        p = folder / n
        try:
            p.unlink()
        except FileNotFoundError:
            pass
        except IsADirectoryError:  # listed as a file, now a directory: not ours to empty
            continue
        dirs.update(q for q in p.parents if folder in q.parents)
    for d in sorted(dirs, key=lambda q: len(q.parts), reverse=True):
        try:
            d.rmdir()
        except OSError:  # not empty: holds files robocal did not write
            pass


@dataclass
class RunFolder:
    """One output folder of a command run (see the module docstring)."""

    path: Path
    label: str
    manifest: dict
    kept: set[str] = field(default_factory=set)
    created: bool = False

    def close(self, state: str, error: str | None = None) -> None:
        """Record the run's end: its files, ``state``; remove ``INCOMPLETE`` when ``state == 'complete'``.

        A failed run that made the folder and wrote nothing into it removes
        the folder: a mistyped input must not leave an empty
        ``robocal-out-*`` folder behind per attempt (the error line is the
        record). Best effort: a folder that became unwritable keeps its
        ``INCOMPLETE``.
        """
        try:
            if state != "complete" and self.created and not _files(self.path):
                for name in (INCOMPLETE, MANIFEST):
                    (self.path / name).unlink(missing_ok=True)
                self.path.rmdir()
                return
            self.write(state, error)
            if state == "complete":
                (self.path / INCOMPLETE).unlink(missing_ok=True)
        except OSError:
            pass

    def write(self, state: str, error: str | None = None) -> None:
        """Write the manifest in ``state``; a finished run lists its files (all but the kept ones)."""
        m = dict(self.manifest, state=state)
        if state != "running":
            m["finished"] = _now()
            m["files"] = sorted(_files(self.path) - self.kept) if self.path.is_dir() else []
        if self.kept:
            m["kept"] = sorted(self.kept)
        if error:
            m["error"] = error
        atomic_write_text(self.path / MANIFEST, json.dumps(m, indent=2) + "\n")


@dataclass
class CommandRun:
    """One command invocation: its output folders, inputs, and whether ``--force`` was given.

    Use as a context manager; :meth:`finish` records the outcome (a run left
    without it, by an exception, is recorded as ``failed``). While it is open,
    :func:`claim_folder` does the folder bookkeeping and the atomic writer
    refuses to replace any of ``inputs``.

    Parameters
    ----------
    command : str
        Human name of the command (``"robocal flow simulate"``).
    command_line : str
        The full command line, shell-quoted.
    rig : str, optional
        The rig the command belongs to.
    force : bool
        Replace another command's run in an output folder (``--force``).
    inputs : iterable of path
        The command's input files; never removed nor written over.
    """

    command: str = ""
    command_line: str = ""
    rig: str | None = None
    force: bool = False
    inputs: tuple = ()
    folders: list[RunFolder] = field(default_factory=list)
    _state: str | None = None
    _error: str | None = None

    def __post_init__(self):
        self.protected: dict[str, str] = {}
        for p in self.inputs:
            try:
                self.protected[str(Path(p).resolve())] = "an input of this command"
            except OSError:
                pass
        self._tokens = []

    def __enter__(self) -> "CommandRun":
        self._tokens = [_ACTIVE.set(self), _PROTECTED.set(self.protected)]
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._state is None:
            self.finish("failed", error=None if exc is None else f"{type(exc).__name__}: {exc}".splitlines()[0])
        _PROTECTED.reset(self._tokens[1])
        _ACTIVE.reset(self._tokens[0])

    def finish(self, state: str = "complete", error: str | None = None) -> None:
        """Record ``state`` (``complete`` or ``failed``) in every output folder of this run."""
        self._state = state
        for f in self.folders:
            f.close(state, error)


def _survey(out: Path, same_command, *, force: bool, protected) -> tuple[set, set, str | None]:
    """``(theirs, foreign, what)`` of a folder about to be claimed, or the one-line refusal.

    ``theirs``: the files of the earlier run recorded there (to remove);
    ``foreign``: files robocal did not write (to keep); ``what``: the earlier
    run's command. ``same_command(manifest)`` tells whether that run was of the
    command now starting.
    """
    try:
        present = _files(out)
    except OSError as exc:
        raise InputError(f"cannot list the directory {out} ({exc.strerror or exc})", source="--out") from None
    earlier = read_manifest(out)
    if earlier is not None:
        listed = earlier.get("files")
        kept_before = set(earlier.get("kept") or ())
        # a run that never recorded its files (killed) owned all but what it kept
        theirs = (set(listed) if isinstance(listed, list) else present - kept_before) & present
    else:
        theirs, kept_before = set(), set()
    foreign = present - theirs
    what = earlier.get("command") or earlier.get("label") if earlier else None
    # the same command again: its files go; files a --force run of it kept may stay
    same = earlier is not None and same_command(earlier) and foreign <= kept_before
    if (theirs or foreign) and not same and not force:
        parts = []
        if theirs:
            parts.append(f"the files of a `{what}` run ({_shown(theirs)})")
        if foreign:
            parts.append(f"files robocal did not write ({_shown(foreign)})")
        fix = ("add --force to replace that run's files (yours are kept)" if theirs and foreign else
               "add --force to replace them" if theirs else "add --force to write beside them (they are kept)")
        raise InputError(f"{out} holds {' and '.join(parts)}; choose another folder or {fix}", source="--out")
    resolved = {str((out / n).resolve()): n for n in theirs}
    clash = sorted(resolved[p] for p in protected if p in resolved)
    if clash:
        raise InputError(f"{out} holds {clash[0]}, an input of this command written by a `{what}` run; "
                         "replacing that run would remove it: choose another folder", source="--out")
    return theirs, foreign, what


def _refuse_a_file(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} is a file, expected a directory (new or existing)", source="--out")


def preflight(out) -> None:
    """Refuse ``--out`` before the command does any work, as :func:`claim_folder` would at its start.

    A command calls :func:`claim_folder` once its inputs are read, often after
    the expensive part; the CLI checks the folder first so that a refusal
    costs nothing. The earlier run is judged by its ``command`` (the label is
    not known yet); nothing is changed.
    """
    run = active_run()
    if run is None or out is None:
        return
    out = Path(out)
    _refuse_a_file(out)
    existing = next((p for p in (out, *out.parents) if p.exists()), None)
    if existing is not None and existing != out and not existing.is_dir():
        raise InputError(f"cannot create the directory {out} ({existing} is a file)", source="--out")
    if out.is_dir():
        _survey(out, lambda m: m.get("command") == run.command, force=run.force, protected=run.protected)


def claim_folder(out: Path, label: str, *, force: bool | None = None) -> Path:
    """Make ``out`` this run's output folder (see the module docstring); return it.

    Outside a :class:`CommandRun` only the folder is made. Raises
    :class:`~robocal.errors.InputError` (one line, naming ``--out``) when the
    folder holds another run or unknown files and ``force`` is off, or when
    it holds an input of the command that replacing it would remove.
    """
    run = active_run()
    out = Path(out)
    _refuse_a_file(out)
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the directory {out} ({exc.strerror or exc})", source="--out") from None
    if run is None:
        return out
    force = run.force if force is None else bool(force)
    if any(f.path.resolve() == out.resolve() for f in run.folders):
        return out  # claimed earlier by this run
    theirs, foreign, what = _survey(out, lambda m: m.get("label") == label, force=force, protected=run.protected)
    kept = foreign
    try:
        if theirs:
            _remove(out, theirs)
            print(f"robocal: removed the {len(theirs)} file(s) of the earlier `{what}` run in {out}"
                  + (f" (kept {len(kept)} file(s) robocal did not write)" if kept else ""), file=sys.stdout)
        manifest = {"schema": RUN_SCHEMA, "label": label, "command": run.command or label, "rig": run.rig,
                    "command_line": run.command_line, "started": _now(), "finished": None, "state": "running",
                    "files": None}
        (out / INCOMPLETE).write_text(
            f"robocal: the `{run.command or label}` run started {manifest['started']} has not finished; "
            f"its files are not a result (see {MANIFEST}).\n", encoding="utf-8")
        folder = RunFolder(out, label, manifest, kept, created=created)
        folder.write("running")
    except OSError as exc:
        raise InputError(f"cannot write into {out} ({exc.strerror or exc})", source="--out") from None
    for n in kept:
        run.protected[str((out / n).resolve())] = "a file robocal did not write (kept by --force)"
    run.folders.append(folder)
    return out
