"""Timing shared by the bench scripts (run as ``python bench/<script>.py``, so this folder is on sys.path)."""

from __future__ import annotations

import time


def best_of(fn, repeat: int = 3) -> float:
    """The shortest of ``repeat`` wall-clock timings of ``fn()`` [s] (the least disturbed by other load)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best
