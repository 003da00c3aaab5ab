"""Atomic file writing and input hashing.

A result is written to a temporary file in the target directory, flushed,
fsync'd and then renamed over the target (``os.replace`` is atomic on POSIX
and Windows), so a crash never leaves a half-written file and a failed run
never destroys an earlier result.
"""

from __future__ import annotations

import contextvars
import hashlib
import itertools
import os
import threading
from pathlib import Path

from robocal._digests import sha256_file  # noqa: F401 (re-exported: a large file's digest is cached)
from robocal.errors import InputError

__all__ = ["atomic_write_bytes", "atomic_write_text", "sha256_file", "sha256_bytes", "protected_paths"]

#: resolved path -> why it must not be replaced (a command's inputs, files kept by --force);
#: set by the running command (:class:`robocal.io.CommandRun`)
_PROTECTED: contextvars.ContextVar[dict] = contextvars.ContextVar("robocal_protected_paths", default={})


def protected_paths() -> dict:
    """The paths the atomic writer refuses to replace now: ``{resolved path: reason}``."""
    return dict(_PROTECTED.get())


#: O_EXCL: never open a file another writer made (tempfile.mkstemp's flags, without its 0600 mode)
_TMP_FLAGS = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
              | getattr(os, "O_BINARY", 0))
_serial = itertools.count()


def _create_temporary(path: Path) -> tuple[int, str]:
    """A new file beside ``path``, opened for writing: ``(fd, name)``.

    Not :func:`tempfile.mkstemp`: its import (with ``random``) is ~2-4 ms of every command's start-up
    (issue 16), and its 0600 mode had to be widened after the fact. The name is unique to this process,
    thread and call; O_EXCL makes a leftover of a crashed process with the same pid a retry, not a reuse.
    Mode 0o666 minus the umask, as any other new file gets, or colleagues cannot read a result.
    """
    stem = f".{path.name}.{os.getpid()}.{threading.get_ident()}"
    for _ in range(100):
        tmp = str(path.parent / f"{stem}.{next(_serial)}.tmp")
        try:
            return os.open(tmp, _TMP_FLAGS, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name for {path.name} in {path.parent}")


def _folder_error(exc: OSError, path: Path) -> OSError:
    """The error names the folder the user chose, not the writer's temporary file."""
    return OSError(exc.errno, f"cannot write {path.name} there ({exc.strerror or exc})", str(path.parent))


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; creates parent directories."""
    path = Path(path)
    protected = _PROTECTED.get()
    if protected:
        why = protected.get(str(path.resolve()))
        if why is not None:
            raise InputError(f"refusing to write over {path}: it is {why}; choose another --out", source="--out")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = _create_temporary(path)
    except OSError as exc:
        raise _folder_error(exc, path) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError) and exc.filename == tmp:
            raise _folder_error(exc, path) from None
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


