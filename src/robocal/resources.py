"""Memory checks made before work starts.

A command whose working memory grows with its input is checked against the
memory the machine has free before the first large array is made: a user
gets one line ("needs 21.8 GiB for 10^6 points, 7.9 GiB available") instead
of a MemoryError traceback or the kernel's OOM killer half-way through.
"""

from __future__ import annotations

import os

from robocal.errors import ResourceError

__all__ = ["available_memory", "require_memory", "format_bytes"]


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:  # other POSIX systems: free physical pages
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def format_bytes(n: float) -> str:
    """``1.5 GiB``-style size."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def require_memory(nbytes: float, what: str, *, source: str | None = None, fraction: float = 0.8) -> None:
    """Raise :class:`ResourceError` when ``nbytes`` exceed ``fraction`` of the available memory.

    Parameters
    ----------
    nbytes : float
        Estimated peak working memory of the step (bytes).
    what : str
        The step and its size, for the message ("pairwise distances of 10^6 points").
    source : str, optional
        File / field the size comes from.
    fraction : float
        Share of the available memory the step may take.
    """
    avail = available_memory()
    if avail is None or nbytes <= fraction * avail:
        return
    raise ResourceError(f"{what} needs {format_bytes(nbytes)} of memory, {format_bytes(avail)} available; "
                        "split the input or use a machine with more memory", source=source)
