"""The engine: a Dask ``distributed`` cluster, or none (serial) for one worker.

``open_executor(workers=None)`` starts an embedded ``LocalCluster`` (one
single-threaded worker *process* per core: the trials and calibrations are
Python code holding the GIL, so threads would not run them side by side);
``open_executor(scheduler="tcp://host:8786")`` connects to a cluster someone
else runs, unchanged; ``open_executor(workers=1)`` yields ``None`` and
imports no Dask. Whatever it yields is what :func:`robocal.estimation.monte_carlo`
and :func:`robocal.batch.run_batch` take as ``executor``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import sys

from robocal.errors import InputError, ResourceError

__all__ = ["open_executor", "available_cores"]


def available_cores() -> int:
    """Cores this process may run on (the affinity mask where the OS has one, else ``os.cpu_count``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _echo_default(line: str) -> None:
    print(line, file=sys.stderr)


@contextlib.contextmanager
def open_executor(workers: int | None = None, scheduler: str | None = None, *, echo=_echo_default,
                  dashboard: bool = True):
    """A Dask ``Client`` (or None for a serial run) for the duration of the ``with`` block.

    Parameters
    ----------
    workers : int, optional
        Worker processes of the embedded ``LocalCluster`` (default: one per
        available core). ``1`` runs serially: yields ``None``, starts nothing.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://10.0.0.5:8786``); the
        cluster is used as it is (``workers`` must then be None).
    echo : callable or None
        Where the one line naming the cluster and its dashboard goes
        (default: stderr; None: silent).
    dashboard : bool
        Serve the Dask dashboard on a free port (needs ``bokeh``; said when
        it is missing).

    Raises
    ------
    InputError
        ``workers < 1``, both arguments, or a scheduler that cannot be reached.
    """
    if workers is not None and int(workers) < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    if scheduler is not None and workers is not None:
        raise InputError("--workers and --scheduler exclude each other: an existing cluster has its own workers")
    if scheduler is None and (workers == 1 or (workers is None and available_cores() == 1)):
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ResourceError(f"parallel runs need Dask's 'distributed' package ({exc}); "
                            "pip install 'distributed' or run with --workers 1") from None
    say = echo or (lambda line: None)
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({exc})", source="--scheduler") from None
        with client:
            n = sum(client.nthreads().values())
            say(f"dask: scheduler {scheduler}, {len(client.nthreads())} worker(s), {n} thread(s); "
                f"dashboard {client.dashboard_link}")
            yield client
        return
    n = int(workers or available_cores())
    has_bokeh = importlib.util.find_spec("bokeh") is not None
    # ":0": a free port, never a clash with another user's 8787. Always given: the scheduler serves its HTTP
    # endpoints even without bokeh (no dashboard then), and with None it takes 8787 and warns when that is busy
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=40) as cluster, Client(cluster) as client:
        board = cluster.dashboard_link if dashboard and has_bokeh else "off (pip install bokeh to get it)"
        say(f"dask: local cluster of {n} worker process(es); dashboard {board}")
        yield client
