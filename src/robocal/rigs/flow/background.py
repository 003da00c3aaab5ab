"""Reading beside the flow kernel: the inputs' sha256 and the reference and wheel trajectories, started in
background threads when a command starts and collected where they are used (issue 16).

A ``robocal flow odometry`` run spends, besides the kernel on the frames, ~0.12 s hashing the 149 MB
frames file for ``result.json``'s ``inputs`` and ~0.02 s reading each 12,000-row trajectory CSV (30 s
at 400 Hz, quiet machine). None of it depends on the flow, so it runs while the kernel does:
:mod:`hashlib` releases the GIL on buffers over 2 KiB and the C kernel releases it around its loops
(:func:`robocal.rigs.flow.kernel._chunked`), so the threads share the cores, not the interpreter.
:func:`~robocal.rigs.flow.workflow.odometry_run` starts the hashing first and the trajectories (CSV
parsing, which holds the GIL) once the frames are read, when the kernel starts: so the parsing overlaps
the kernel's C loops, not the main thread's own Python work.

Each job remembers its files' ``(path, size, mtime_ns, inode)`` when it started; :func:`collect`
returns the job's value only when the files still match, else it computes afresh, so a file written
between two runs on the same :class:`~robocal.rigs.flow.log.RunSpec` is never described by a stale hash
or read from a stale copy. A job's exception (a damaged reference file) is raised where the value is
collected, with the message the synchronous read gives.
"""

from __future__ import annotations

import os
import threading

from robocal.io import hash_inputs

__all__ = ["start", "collect", "inputs_hash", "JOBS"]

#: what :func:`start` starts by default: the inputs' hashes, the reference and the wheel trajectories
JOBS = ("inputs", "reference", "wheel")

_ATTR = "_robocal_background"       # where a spec keeps its jobs: {name: (stamp, _Job)}


class _Job:
    """``fn(arg)``, run by :func:`_in_thread`; ``result()`` waits for it and returns its value or raises its
    exception. (Not :mod:`concurrent.futures`: importing it is 7 ms of the command's fixed cost, for the
    few lines used here.)"""

    def __init__(self, fn, arg):
        self._fn, self._arg = fn, arg
        self._done = threading.Event()
        self._value = self._error = None

    def run(self):
        try:
            self._value = self._fn(self._arg)
        except BaseException as exc:  # handed to whoever collects it
            self._error = exc
        finally:
            self._done.set()

    def result(self):
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._value


def _in_thread(jobs) -> None:
    """The jobs one after the other in one daemon thread (an error exit does not wait for a hash nobody will
    read). One thread, not one each: a CSV parse holds the GIL, and every thread that does makes the main
    thread wait up to the switch interval (5 ms) each time it wants the GIL back."""
    def work():
        for job in jobs:
            job.run()

    threading.Thread(target=work, name="robocal-flow-background", daemon=True).start()


def _stamp(paths) -> tuple:
    out = []
    for p in paths:
        try:
            st = os.stat(p)
            out.append((str(p), st.st_size, st.st_mtime_ns, st.st_ino))
        except OSError:
            out.append((str(p), None))
    return tuple(out)


def _job(spec, name):
    """``(paths, fn, arg)`` of a job, or None when the spec has nothing for it."""
    from robocal.rigs.flow.log import read_poses_csv

    if name == "inputs":
        paths = [p for p in spec.inputs() if p is not None]
        return paths, hash_inputs, paths
    if name == "reference":
        # a recording's reference is in memory already (robocal.rigs.flow.bag)
        if spec.reference is None or getattr(spec, "reference_data", None) is not None:
            return None
        return [spec.reference], read_poses_csv, spec.reference
    if name == "wheel":
        return None if getattr(spec, "wheel", None) is None else ([spec.wheel], read_poses_csv, spec.wheel)
    raise ValueError(f"unknown background job {name!r} (known: {', '.join(JOBS)})")


def start(spec, jobs=JOBS) -> None:
    """Start ``jobs`` of ``spec``, in this order, in one background thread (those already started on
    unchanged files are kept)."""
    store = spec.__dict__.setdefault(_ATTR, {})
    new = []
    for name in jobs:
        job = _job(spec, name)
        if job is None:
            continue
        paths, fn, arg = job
        stamp = _stamp(paths)
        if name in store and store[name][0] == stamp:
            continue
        store[name] = (stamp, _Job(fn, arg))
        new.append(store[name][1])
    if new:
        _in_thread(new)


def collect(spec, name, compute):
    """The value of the background job ``name`` when it was started on the files as they are now, else
    ``compute()`` (no job, or a file changed since)."""
    entry = spec.__dict__.get(_ATTR, {}).get(name)
    if entry is not None:
        job = _job(spec, name)
        if job is not None and _stamp(job[0]) == entry[0]:
            return entry[1].result()
    return compute()


def inputs_hash(spec) -> dict:
    """``{path: sha256}`` of the spec's input files (:func:`robocal.io.hash_inputs`), from the background job
    when one was started."""
    return collect(spec, "inputs", lambda: hash_inputs(spec.inputs()))
