"""SHA-256 of large input files, remembered between commands while the file is unchanged.

Every result records its inputs' SHA-256 (``result.json``'s ``inputs``), and
for a large input that hash is a real share of a command: the flow rig's 30 s
frames log is 149 MB, ~0.12 s of hashing at ~1.2 GB/s, more than the rest of
the command's start-up (issue 16). A user re-running a command on the same
recording (another option, another calibration) re-hashes bytes that did not
change. So, as ``git``'s index and ``ccache``'s direct mode do, a file's
digest is kept beside the user's other robocal caches and reused while the
file's identity and change times are those it was hashed with.

The key is ``(device, inode, size, mtime_ns, ctime_ns)`` of the resolved
path. ``ctime`` cannot be set by a user's tools (``touch -d`` and ``rsync -t``
set ``mtime`` only): any write, rename over or metadata change moves it to
the time of the change. Two races are closed:

* a write while the file is hashed: the file is stat'ed before and after,
  and a digest whose stats differ is used for this call but not stored;
* a write in the same timestamp tick as the change the entry recorded (a
  coarse-clock file system would then show equal times for different
  content): a digest is stored only when the file's last change is at least
  :data:`SETTLE_NS` (2 s, FAT's granularity, the coarsest in use) older
  than the moment hashing started, so any later write lands in a later tick.

Files under :data:`MIN_BYTES` are hashed every time (reading an entry costs
more than hashing them), so the cache holds entries for large inputs only,
one small JSON file each under ``<cache>/sha256/``. ``ROBOCAL_NO_CACHE=1``
hashes every file every time; ``ROBOCAL_CACHE_DIR`` moves the cache
(:func:`robocal._metadata.cache_dir`). An unreadable, corrupt or foreign
entry is ignored and rewritten; a cache that cannot be written is not used.
"""

from __future__ import annotations

import hashlib
import json
import os
import time

from robocal._metadata import cache_dir, store_cache_file

__all__ = ["sha256_file", "entry_path", "MIN_BYTES", "SETTLE_NS"]

#: smaller files are hashed every call (~3 ms at this size: about what reading a cache entry costs)
MIN_BYTES = 4 << 20
#: a digest is stored only for a file whose last change is this much older than the hashing's start
SETTLE_NS = 2_000_000_000
_SCHEMA = "robocal.sha256-cache/1"


def _hash(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)  # hashlib releases the GIL on buffers this size: other threads run meanwhile
    return h.hexdigest()


def _identity(st: os.stat_result) -> list:
    return [st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns]


def entry_path(path) -> os.PathLike | None:
    """Where the digest of ``path`` is kept (None when caching is off)."""
    return _entry(os.path.realpath(path))


def _entry(real: str):
    root = cache_dir()
    if root is None:
        return None
    name = hashlib.blake2s(os.fsencode(real), digest_size=16).hexdigest()
    return root / "sha256" / f"{name}.json"


def _read_entry(where, real: str, ident: list) -> str | None:
    try:
        with open(where, encoding="utf-8") as fh:
            doc = json.load(fh)
        if doc.get("schema") == _SCHEMA and doc.get("path") == real and doc.get("stat") == ident:
            digest = doc.get("sha256")
            if isinstance(digest, str) and len(digest) == 64:
                return digest
    except (OSError, ValueError, TypeError, AttributeError):
        pass  # absent or damaged: hashed afresh and rewritten
    return None


def sha256_file(path) -> str:
    """SHA-256 (hex) of the content of the file ``path``; for a file of at least :data:`MIN_BYTES`, the
    digest stored by an earlier call when the file has not changed since (module docstring)."""
    st = os.stat(path)
    real = os.path.realpath(path) if st.st_size >= MIN_BYTES else None
    where = _entry(real) if real is not None else None
    if where is None:
        return _hash(path)
    ident = _identity(st)
    digest = _read_entry(where, real, ident)
    if digest is not None:
        return digest
    started = time.time_ns()
    digest = _hash(path)
    settled = max(st.st_mtime_ns, st.st_ctime_ns) <= started - SETTLE_NS
    if settled and _identity(os.stat(path)) == ident:
        store_cache_file(where, {"schema": _SCHEMA, "path": real, "stat": ident, "sha256": digest})
    return digest
