"""Atomic file writing and input hashing.

A result is written to a temporary file in the target directory, flushed,
fsync'd and then renamed over the target (``os.replace`` is atomic on POSIX
and Windows), so a crash never leaves a half-written file and a failed run
never destroys an earlier result.
"""

from __future__ import annotations

import contextvars
import hashlib
import os
import tempfile
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


def _umask() -> int:
    mask = os.umask(0)  # the only portable way to read it is to set it
    os.umask(mask)
    return mask


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
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise _folder_error(exc, path) from None
    try:
        # mkstemp creates the file 0600; a result file should get the permissions
        # any other new file gets (0666 minus the umask), or colleagues cannot read it
        if hasattr(os, "fchmod"):  # POSIX
            os.fchmod(fd, 0o666 & ~_umask())
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


