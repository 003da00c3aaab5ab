"""Small statistics on NumPy arrays that the hot paths need without ``np.median``'s costs.

``np.median``'s first call imports ``numpy.ma`` (to test for a masked array: 14 ms of a
``robocal flow odometry`` call's fixed cost, issue 16) and its wrapper costs more than the
partition itself on the few dozen values of a hand-eye motion check.
"""

from __future__ import annotations

import numpy as np

__all__ = ["median"]


def median(a) -> float:
    """``np.median`` of the values of ``a`` (NaN when one is NaN or there are none), the same bits: the
    middle of a partition, or the mean ``(x + y) / 2`` of the middle two as ``np.median`` takes it."""
    a = np.asarray(a, float).ravel()
    n = a.size
    if n == 0 or np.isnan(a).any():
        return float("nan")
    h = n // 2
    if n % 2:
        return float(np.partition(a, h)[h])
    p = np.partition(a, (h - 1, h))
    return float((p[h - 1] + p[h]) / 2.0)
