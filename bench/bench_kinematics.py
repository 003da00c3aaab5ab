"""Forward-kinematics throughput: robocal.kinematics.DHChain.fk vs per-configuration loops.

A 6-DOF chain (modified D-H, a PUMA-like table plus base and tool transforms),
measured in one run on the same joint configurations:

* ``robocal vectorised`` -- :meth:`DHChain.fk` on all N configurations in one
  call, shape (N, 6) -> (N, 4, 4) (input validation included);
* ``robocal per config`` -- the same method called once per configuration
  in a Python loop (what a caller who does not batch gets);
* ``numpy vectorised`` -- plain NumPy without checks on all N at once: one
  (N, 4, 4) stack of link matrices per link, chained with batched ``@``
  (issue 16's peer: the API's ratio to it is printed below the table);
* ``numpy per config`` -- a plain Python loop over configurations, each
  building six 4x4 ``numpy`` link matrices and multiplying them with ``@``;
* ``pure Python`` -- lists and ``math.sin``/``math.cos``, the 4x4 products
  written out in Python loops.

All four are checked to agree to 1e-12 before timing. Then ``fk_all``, ``jacobian`` and
``param_jacobian`` (base and tool parameters on) against the previous implementation, written out here:
one (N, 4, 4) stack of link matrices per link chained with batched ``@``, twist columns from
``screw_column`` on those frames (checked to agree to 1e-12 first). Per-configuration
loops are timed on a subset and reported per configuration. Ratios > 1 mean
the vectorised call is faster.

Run: ``python bench/bench_kinematics.py`` (``--quick`` for a shorter run,
``-n`` for the number of configurations).
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time

import numpy as np

import robocal
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain
from robocal.kinematics._common import origin_screws, screw_column, xyz_rpy_from_transform

# alpha_{i-1}, a_{i-1}, theta_i, d_i (m, rad): PUMA 560 in Craig's modified convention.
PUMA = [
    [0.0, 0.0, 0.0, 0.0],
    [-math.pi / 2, 0.0, 0.0, 0.2435],
    [0.0, 0.4318, 0.0, -0.0934],
    [math.pi / 2, -0.0203, 0.0, 0.4331],
    [-math.pi / 2, 0.0, 0.0, 0.0],
    [math.pi / 2, 0.0, 0.0, 0.0],
]


def numpy_link(alpha, a, theta, d):
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array([
        [ct, -st, 0.0, a],
        [st * ca, ct * ca, -sa, -sa * d],
        [st * sa, ct * sa, ca, ca * d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def numpy_links(alpha, a, theta, d):
    """Modified D-H link matrices for an array of theta, (N, 4, 4)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), np.cos(theta), np.sin(theta)
    A = np.zeros(theta.shape + (4, 4))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 3] = ct, -st, a
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2], A[:, 1, 3] = st * ca, ct * ca, -sa, -sa * d
    A[:, 2, 0], A[:, 2, 1], A[:, 2, 2], A[:, 2, 3] = st * sa, ct * sa, ca, ca * d
    A[:, 3, 3] = 1.0
    return A


def stacked_frames(chain, q):
    """The previous ``fk_all``: ``T_base @ A_1 @ ... @ A_i`` as (N, 4, 4) stacks, (N, n + 1, 4, 4)."""
    T = np.broadcast_to(chain.T_base, q.shape[:-1] + (4, 4))
    frames = [T]
    for (alpha, a, theta, d), qi in zip(chain.table, q.T):
        T = T @ numpy_links(alpha, a, theta + qi, d)
        frames.append(T)
    return np.stack(np.broadcast_arrays(*frames), axis=-3)


def stacked_jacobian(chain, q, params: bool):
    """The previous ``jacobian`` (``params=False``) or ``param_jacobian`` of a revolute modified chain:
    ``screw_column`` on the stacked frames."""
    ex, ez = np.eye(3)[0], np.eye(3)[2]
    frames = stacked_frames(chain, q)
    p = (frames[:, -1] @ chain.T_tool)[:, :3, 3]
    cols = []
    for i in range(chain.n_links):
        b, a = frames[:, i], frames[:, i + 1]
        screws = [(b, ex, True), (b, ex, False), (a, ez, True), (a, ez, False)] if params else [(a, ez, True)]
        cols += [screw_column(G, ax, rev, p) for G, ax, rev in screws]
    if params:
        G0, Gn = np.broadcast_to(np.eye(4), (len(q), 4, 4)), frames[:, -1]
        for G_parent, T in ((G0, chain.T_base), (Gn, chain.T_tool)):
            cols += [screw_column(G, ax, r, p) for G, ax, r in origin_screws(G_parent, xyz_rpy_from_transform(T))]
    return np.stack(cols, axis=-1)

def numpy_fk_batch(table, T_base, T_tool, q):
    T = T_base
    for (alpha, a, theta, d), qi in zip(table, q.T):
        T = T @ numpy_links(alpha, a, theta + qi, d)
    return T @ T_tool


def numpy_fk(table, T_base, T_tool, q):
    T = T_base
    for (alpha, a, theta, d), qi in zip(table, q):
        T = T @ numpy_link(alpha, a, theta + qi, d)
    return T @ T_tool


def matmul4(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def python_fk(table, T_base, T_tool, q):
    T = T_base
    for (alpha, a, theta, d), qi in zip(table, q):
        ca, sa = math.cos(alpha), math.sin(alpha)
        ct, st = math.cos(theta + qi), math.sin(theta + qi)
        A = [[ct, -st, 0.0, a], [st * ca, ct * ca, -sa, -sa * d], [st * sa, ct * sa, ca, ca * d], [0.0, 0.0, 0.0, 1.0]]
        T = matmul4(T, A)
    return matmul4(T, T_tool)


def best_time(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats and a smaller loop subset")
    ap.add_argument("-n", type=int, default=100_000, help="number of configurations (default 1e5)")
    args = ap.parse_args(argv)
    repeats = 2 if args.quick else 5
    n_loop = min(500 if args.quick else 3000, args.n)

    rng = np.random.default_rng(3)
    T_base = transform_from(matrix_from_rotvec([0.0, 0.0, 0.3]), [0.1, -0.2, 0.5])
    T_tool = transform_from(matrix_from_rotvec([0.1, -0.2, 0.0]), [0.0, 0.0, 0.12])
    chain = DHChain.from_table(PUMA, convention="modified", T_base=T_base, T_tool=T_tool)
    q = rng.uniform(-math.pi, math.pi, size=(args.n, chain.dof))
    table = chain.table
    table_l, base_l, tool_l = table.tolist(), T_base.tolist(), T_tool.tolist()
    q_sub, q_sub_l = q[:n_loop], q[:n_loop].tolist()

    T_all = chain.fk(q)
    assert np.abs(numpy_fk_batch(table, T_base, T_tool, q) - T_all).max() < 1e-12
    for k in range(0, n_loop, max(1, n_loop // 50)):
        ref = T_all[k]
        assert np.abs(chain.fk(q[k]) - ref).max() < 1e-12
        assert np.abs(numpy_fk(table, T_base, T_tool, q[k]) - ref).max() < 1e-12
        assert np.abs(np.array(python_fk(table_l, base_l, tool_l, q_sub_l[k])) - ref).max() < 1e-12

    t_vec = best_time(lambda: chain.fk(q), repeats)
    t_npv = best_time(lambda: numpy_fk_batch(table, T_base, T_tool, q), repeats)
    t_rob = best_time(lambda: [chain.fk(x) for x in q_sub], max(1, repeats // 2))
    t_np = best_time(lambda: [numpy_fk(table, T_base, T_tool, x) for x in q_sub], max(1, repeats // 2))
    t_py = best_time(lambda: [python_fk(table_l, base_l, tool_l, x) for x in q_sub_l], max(1, repeats // 2))
    rates = {
        "robocal vectorised": args.n / t_vec,
        "numpy vectorised": args.n / t_npv,
        "robocal per config": n_loop / t_rob,
        "numpy per config": n_loop / t_np,
        "pure Python": n_loop / t_py,
    }

    print(f"command: python {' '.join(['bench/bench_kinematics.py', *sys.argv[1:]])}")
    print(f"robocal {robocal.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}")
    print(f"6-DOF modified D-H chain with base and tool; {args.n:,} configurations vectorised, "
          f"{n_loop:,} per-configuration loop; best of {repeats} (vectorised) runs")
    print()
    header = f"{'method':<20} | {'configs/s':>14} | {'vectorised is x faster':>22}"
    print(header)
    print("-" * len(header))
    for name, r in rates.items():
        print(f"{name:<20} | {r:>14,.0f} | {rates['robocal vectorised'] / r:>22.1f}")
    print(f"\nrobocal vectorised / numpy vectorised (same N): {t_npv / t_vec:.2f}x (issue 16 goal >= 0.9)")

    # frames and Jacobians (calibration's inner loop) against the previous stacked implementation
    pchain = DHChain.from_table(PUMA, convention="modified", T_base=T_base, T_tool=T_tool, base_params=True,
                                tool_params=True)
    print(f"\n{'method (base + tool params)':<28} | {'configs/s':>12} | {'previous (4x4 stacks)':>21} | "
          f"{'speed-up':>8}")
    print("-" * 80)
    # unit rotations and lever arms <= ~1.5 m: round-off of a few ulps; 1e-12 leaves ~1000 ulps
    assert np.abs(pchain.fk_all(q) - stacked_frames(pchain, q)).max() < 1e-12
    assert np.abs(pchain.jacobian(q) - stacked_jacobian(pchain, q, False)).max() < 1e-12
    assert np.abs(pchain.param_jacobian(q) - stacked_jacobian(pchain, q, True)).max() < 1e-12
    for name, new, old in (("fk_all", lambda: pchain.fk_all(q), lambda: stacked_frames(pchain, q)),
                           ("jacobian", lambda: pchain.jacobian(q), lambda: stacked_jacobian(pchain, q, False)),
                           ("param_jacobian", lambda: pchain.param_jacobian(q),
                            lambda: stacked_jacobian(pchain, q, True))):
        t_new, t_old = best_time(new, repeats), best_time(old, repeats)
        print(f"{name:<28} | {args.n / t_new:>12,.0f} | {args.n / t_old:>21,.0f} | {t_old / t_new:>7.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
