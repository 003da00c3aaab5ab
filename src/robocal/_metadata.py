"""robocal's version and the ``robocal.rigs`` entry points, without importing ``importlib.metadata`` each call.

Every ``robocal`` command needs both: the entry-point group to find the rig
it runs (:mod:`robocal.cli._rig`) and the version for ``result.json``. With
the standard library alone they cost ~60-90 ms per process, most of it the
import of ``importlib.metadata`` itself (``email``, ``zipfile``, ``csv``,
``inspect``) and a scan of every distribution on ``sys.path``: a fifth of a
flow command's start-up budget (issue 16: < 0.3 s). So the answer is kept in
a small JSON cache beside the user's other caches and reused while nothing it
was read from has changed.

The cache's key is the modification time of every ``sys.path`` folder but
the script's or current one (pip installing or removing any distribution
creates or deletes a ``*.dist-info`` folder there, which changes the
folder's time) and of each providing distribution's ``entry_points.txt``.
A missing, unreadable, corrupt or stale
cache is rebuilt from ``importlib.metadata``; a cache folder that cannot be
written is ignored. Set ``ROBOCAL_CACHE_DIR`` to move it, or
``ROBOCAL_NO_CACHE=1`` to read the metadata every time.
"""

from __future__ import annotations

import json
import os
import sys
import zlib
from importlib import import_module
from pathlib import Path
from typing import NamedTuple

__all__ = ["version", "entry_points", "cache_dir", "cache_path", "store_cache_file", "forget", "RIG_GROUP"]

RIG_GROUP = "robocal.rigs"
_SCHEMA = "robocal.metadata-cache/1"
_UNKNOWN_VERSION = "0.0.0+unknown"  # running from a source tree without an install


class EntryPoint(NamedTuple):
    """The part of :class:`importlib.metadata.EntryPoint` the CLI uses (``name``, ``value``, ``load``)."""

    name: str
    value: str
    group: str

    def load(self):
        """The object ``value`` names (``"package.module:attr"``), imported now."""
        module, _, attr = self.value.partition(":")
        obj = import_module(module.strip())
        for part in filter(None, attr.strip().split(".")):
            obj = getattr(obj, part)
        return obj


_memo: dict | None = None  # this process's answer: read once


def cache_dir() -> Path | None:
    """robocal's cache folder: ``ROBOCAL_CACHE_DIR``, else ``$XDG_CACHE_HOME/robocal`` or
    ``~/.cache/robocal`` (None when ``ROBOCAL_NO_CACHE`` is set: no cache at all)."""
    if os.environ.get("ROBOCAL_NO_CACHE", "").strip() not in ("", "0"):
        return None
    return Path(os.environ.get("ROBOCAL_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "robocal"))


def cache_path() -> Path | None:
    """Where the cache lives (None when ``ROBOCAL_NO_CACHE`` is set).

    One file per environment, Python and search path (``sys.prefix`` +
    ``sys.version`` + ``sys.path`` as :func:`_key` reads it): two virtual
    environments never share an answer, and a process with another search
    path (pytest's, a ``PYTHONPATH`` checkout) keeps its own file instead of
    rewriting the commands' one (each rewrite: importlib.metadata again,
    ~60-70 ms of the next command's start-up, issue 16).
    """
    root = cache_dir()
    if root is None:
        return None
    # crc32, not ``hash`` (salted per process); not sys.executable: the launcher's shebang names
    # bin/python3 where a shell says bin/python
    paths = sys.path if getattr(sys.flags, "safe_path", False) else sys.path[1:]
    tag = zlib.crc32("\0".join((sys.prefix, sys.version, *paths)).encode("utf-8", "surrogateescape"))
    return root / f"metadata-{tag:08x}.json"


def _mtime(path: str) -> int | None:
    try:
        return os.stat(path or ".").st_mtime_ns
    except OSError:
        return None


def _key(files) -> list:
    """What the answer was read from, with modification times: equal keys, equal answers.

    ``sys.path[0]`` is left out: Python puts there the folder of the script
    that runs (the ``robocal`` launcher's ``bin/``) or the current folder
    (``python -m``/``-c``), which differ between two ways of running the same
    install (each would rebuild the cache for the other), and the current
    folder's time changes with every ``--out`` folder a command makes there.
    A rig is registered by installing it into an environment, never by a
    ``*.dist-info`` beside a script or in the folder a command is run from.
    """
    paths = sys.path if getattr(sys.flags, "safe_path", False) else sys.path[1:]
    return [[p, _mtime(p)] for p in (*paths, *files)]


def _read_metadata() -> dict:
    """The answer from ``importlib.metadata`` (the slow path), with the files it came from."""
    from importlib import metadata

    files = set()
    rigs = []
    for ep in metadata.entry_points(group=RIG_GROUP):
        rigs.append([ep.name, ep.value])
        # PathDistribution keeps its folder in a private attribute; without it only sys.path's times key
        # the cache, which still changes on every pip install or uninstall
        where = getattr(getattr(ep, "dist", None), "_path", None)
        if where is not None:
            files.add(str(Path(str(where)) / "entry_points.txt"))
    try:
        ver = metadata.version("robocal")
        dist = getattr(metadata.distribution("robocal"), "_path", None)
        if dist is not None:
            files.add(str(Path(str(dist)) / "METADATA"))
    except metadata.PackageNotFoundError:
        ver = _UNKNOWN_VERSION
    files = sorted(files)
    return {"schema": _SCHEMA, "files": files, "key": _key(files), "version": ver, "rigs": sorted(rigs)}


def _load_cache(path: Path) -> dict | None:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if (doc.get("schema") == _SCHEMA and isinstance(doc.get("version"), str)
                and all(isinstance(n, str) and isinstance(v, str) for n, v in doc["rigs"])
                and doc.get("key") == _key(doc["files"])):
            return doc
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        pass  # absent, unreadable or from another robocal: rebuilt below
    return None


def store_cache_file(path: Path, doc) -> None:
    """Write ``doc`` as JSON to the cache file ``path`` whole or not at all; a cache that cannot be written
    (a read-only home) is left as it is: the caller works without it."""
    import tempfile  # only when a cache file is (re)written: its imports cost ~9 ms

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError:
        return
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(doc, fh)
        os.replace(tmp, path)  # concurrent commands each write a whole file; the last one stays
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass


def _answer() -> dict:
    global _memo
    if _memo is None:
        path = cache_path()
        doc = _load_cache(path) if path is not None else None
        if doc is None:
            doc = _read_metadata()
            if path is not None:
                store_cache_file(path, doc)
        _memo = doc
    return _memo


def forget() -> None:
    """Drop this process's answer (the next call checks the cache again); for tests and long sessions."""
    global _memo
    _memo = None


def version() -> str:
    """robocal's installed version (``"0.0.0+unknown"`` from a source tree without an install)."""
    return _answer()["version"]


def entry_points(group: str = RIG_GROUP) -> list[EntryPoint]:
    """The ``robocal.rigs`` entry points, sorted by name (other groups: ask ``importlib.metadata``)."""
    if group != RIG_GROUP:
        from importlib import metadata

        return [EntryPoint(ep.name, ep.value, group) for ep in metadata.entry_points(group=group)]
    return [EntryPoint(n, v, group) for n, v in _answer()["rigs"]]
