"""Rigid-fit throughput: robocal.geometry.rigid_fit vs a plain-Python baseline and OpenCV.

Measured in one run, on the same data:

* ``robocal`` -- :func:`robocal.geometry.rigid_fit`, one call per fit (input
  validation, degeneracy checks and residuals included);
* ``robocal batched`` -- the same function fitting a batch of point sets in
  one call (how Monte Carlo studies use it);
* ``plain Python`` -- lists of tuples, centroids and the 3x3 cross-covariance
  accumulated point by point in Python, then ``numpy.linalg.svd`` with the
  det = -1 guard (a pure-Python 3x3 SVD would only make the baseline slower);
* ``cv2`` -- ``cv2.estimateAffine3D(src, dst, force_rotation=True)`` (Umeyama
  with scale; its rotation equals the rigid one).

All three are checked to agree before timing. Ratios > 1 mean robocal is faster.

Run: ``python bench/bench_geometry.py`` (``--quick`` for a shorter run).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import cv2
import numpy as np

import robocal
from robocal.geometry import matrix_from_rotvec, rigid_fit


def plain_python_rigid_fit(src: list, dst: list):
    """Kabsch with per-point Python accumulation; numpy only for the 3x3 SVD."""
    n = len(src)
    sx = sy = sz = dx = dy = dz = 0.0
    for (a, b, c), (d, e, f) in zip(src, dst):
        sx += a
        sy += b
        sz += c
        dx += d
        dy += e
        dz += f
    ms = (sx / n, sy / n, sz / n)
    md = (dx / n, dy / n, dz / n)
    H = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    for p, q in zip(src, dst):
        pc = (p[0] - ms[0], p[1] - ms[1], p[2] - ms[2])
        qc = (q[0] - md[0], q[1] - md[1], q[2] - md[2])
        for i in range(3):
            row = H[i]
            qi = qc[i]
            row[0] += qi * pc[0]
            row[1] += qi * pc[1]
            row[2] += qi * pc[2]
    U, _, Vt = np.linalg.svd(np.array(H))
    if np.linalg.det(U @ Vt) < 0:
        U[:, 2] = -U[:, 2]
    R = U @ Vt
    t = [md[i] - (R[i, 0] * ms[0] + R[i, 1] * ms[1] + R[i, 2] * ms[2]) for i in range(3)]
    return R, t


def rate(fn, min_time: float) -> float:
    """Calls per second: best of 3 runs of a loop lasting >= min_time."""
    loops = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(loops):
            fn()
        dt = time.perf_counter() - t0
        if dt >= min_time:
            break
        loops = max(loops * 2, int(loops * min_time / max(dt, 1e-9) * 1.2))
    best = dt
    for _ in range(2):
        t0 = time.perf_counter()
        for _ in range(loops):
            fn()
        best = min(best, time.perf_counter() - t0)
    return loops / best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="shorter timing loops")
    args = ap.parse_args(argv)
    min_time = 0.05 if args.quick else 0.3

    rng = np.random.default_rng(7)
    R = matrix_from_rotvec([0.3, -0.7, 1.1])
    t = np.array([0.2, -0.1, 0.5])
    print(f"command: python {' '.join(['bench/bench_geometry.py', *sys.argv[1:]])}")
    print(
        f"robocal {robocal.__version__}, numpy {np.__version__}, opencv {cv2.__version__}, "
        f"Python {platform.python_version()}, {platform.machine()}"
    )
    print()
    header = f"{'N points':>9} | {'robocal fits/s':>14} | {'plain Python':>12} | {'cv2':>10} | {'vs Python':>9} | {'vs cv2':>7}"
    print(header)
    print("-" * len(header))
    for n in (4, 100, 10000):
        X = rng.uniform(-0.5, 0.5, size=(n, 3))
        Y = X @ R.T + t + 1e-3 * rng.normal(size=(n, 3))
        Xl, Yl = [tuple(p) for p in X.tolist()], [tuple(p) for p in Y.tolist()]
        ours = rigid_fit(X, Y)
        Rp, tp = plain_python_rigid_fit(Xl, Yl)
        M, _ = cv2.estimateAffine3D(X, Y, force_rotation=True)
        assert np.abs(ours.R - Rp).max() < 1e-9 and np.abs(ours.t - tp).max() < 1e-9
        assert np.abs(ours.R - M[:, :3]).max() < 1e-9
        r_ours = rate(lambda: rigid_fit(X, Y), min_time)
        r_py = rate(lambda: plain_python_rigid_fit(Xl, Yl), min_time)
        r_cv = rate(lambda: cv2.estimateAffine3D(X, Y, force_rotation=True), min_time)
        print(f"{n:>9} | {r_ours:>14,.0f} | {r_py:>12,.0f} | {r_cv:>10,.0f} | {r_ours / r_py:>9.2f} | {r_ours / r_cv:>7.2f}")

    # Batched: B independent 4-point fits in one call vs B single calls of each peer.
    B = 10000
    X = rng.uniform(-0.5, 0.5, size=(B, 4, 3))
    Y = np.einsum("ij,bnj->bni", R, X) + t + 1e-3 * rng.normal(size=(B, 4, 3))
    batch_rate = B * rate(lambda: rigid_fit(X, Y), min_time)
    Xl = [[tuple(p) for p in s] for s in X[:200].tolist()]
    Yl = [[tuple(p) for p in s] for s in Y[:200].tolist()]
    py_rate = 200 * rate(lambda: [plain_python_rigid_fit(a, b) for a, b in zip(Xl, Yl)], min_time)
    cv_rate = 200 * rate(lambda: [cv2.estimateAffine3D(a, b, force_rotation=True) for a, b in zip(X[:200], Y[:200])], min_time)
    print()
    print(
        f"batched, N=4, {B} fits per call: {batch_rate:,.0f} fits/s "
        f"({batch_rate / py_rate:.1f}x plain Python, {batch_rate / cv_rate:.1f}x cv2 one call per fit)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
