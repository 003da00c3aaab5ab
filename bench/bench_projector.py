"""Projector rig throughput: the API against plain NumPy, vectorised vs per-point loops; calibration time.

First (issue 16), the library API against a plain NumPy implementation of the same seed equations, written
here without validation, at 1, 100, 10^4 and 10^6 points, each pair timed alternately in the same run
(median CPU time of 5 x ``--repeats`` short samples each; ratio = peer time / API time, so 1.0 is parity
and the goal is >= 0.9 from 100 points up; a last line gives the ratio of each pair's fastest samples, the
figure least disturbed by other processes on a shared machine):

* ``FK eq. 6`` -- :meth:`ProjectorModel.spot` vs ``h tan(t2 + o2) (sin, cos)(t1 + o1)`` into an (N, 3) array;
* ``IK eq. 8`` -- :meth:`ProjectorModel.ik` on (N, 3) floor points vs ``atan2(x, y) - o1`` wrapped to
  ``[-pi, pi)`` with the usual ``mod(a + pi, 2 pi) - pi`` and ``atan(hypot(x, y) / h) - o2``;
* ``FK D-H chain`` -- :meth:`ProjectorModel.spot_from_chain` vs the seed Table 1 chain in plain NumPy:
  one (N, 4, 4) stack per joint link from the modified D-H link matrix, ``@`` products, the beam ``z_E``
  met with the floor ``z_0 = -H``.

The API validates (shapes, NaN/inf, floor height, reach, nadir and horizon) and the peer does not; both
are checked to agree first. Then, measured in one run on the same data (seed 000's projector A, tilt up
to 75 deg):

* ``FK eq. 6 vectorised``  -- :meth:`ProjectorModel.spot` on N angle pairs in one call;
* ``FK D-H chain vectorised`` -- :meth:`ProjectorModel.spot_from_chain` (DHChain.fk + beam/floor
  intersection) on N pairs in one call;
* ``FK eq. 6 per point``   -- the same method called once per angle pair (Python loop);
* ``FK pure Python``       -- eq. (6) with ``math`` in a loop (the floor a caller could write);
* ``IK ...``               -- the same four for :meth:`ProjectorModel.ik` / eq. (8).

All variants are checked to agree (1e-12) before timing. Spot paths: :func:`joint_trajectory` (one
projector) and :func:`plan_multi` (the seed's room, A and B, a partition wall: reach, occlusion, rate
limits, assignment and hand-overs) against naive per-sample loops that apply the same rules, checked to
give the same joint rates / the same assignment first. Calibration: median wall time
of each solver on simulated data with N points (seed method, closed form, nonlinear
pose only, nonlinear with h and tilt offset, the full ``calibrate`` driver).

Run: ``python bench/bench_projector.py`` (``--quick`` for a shorter run, ``--ratios-only`` for the first
table alone).
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time

import numpy as np

import robocal
from robocal.rigs.projector.calibrate import calibrate, closed_form, nonlinear, seed_method
from robocal.rigs.projector.path import joint_trajectory, plan_multi, sample_polyline, segments_blocked
from robocal.rigs.projector.simulate import default_nominal, default_truth, seed_room_projectors, simulate_calibration
from _timing import best_of  # bench/ is on sys.path when a script runs


def median_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def pure_fk(th, h, H):
    out = []
    for t1, t2 in th:
        r = h * math.tan(t2)
        out.append((r * math.sin(t1), r * math.cos(t1), -H))
    return out


def pure_ik(pts, h):
    return [(math.atan2(x, y), math.atan(math.hypot(x, y) / h)) for x, y, _ in pts]


def numpy_fk(th, h, H, o1, o2):
    """Seed eq. (6) in plain NumPy (no checks): spot in {0}, (N, 3)."""
    a1, a2 = th[:, 0] + o1, th[:, 1] + o2
    r = h * np.tan(a2)
    out = np.empty((len(th), 3))
    out[:, 0] = r * np.sin(a1)
    out[:, 1] = r * np.cos(a1)
    out[:, 2] = -H
    return out


def numpy_ik(p, h, o1, o2):
    """Seed eq. (8) in plain NumPy (no checks): joint commands (N, 2), pan wrapped to [-pi, pi)."""
    x, y = p[:, 0], p[:, 1]
    out = np.empty((len(p), 2))
    out[:, 0] = np.mod(np.arctan2(x, y) - o1 + np.pi, 2 * np.pi) - np.pi
    out[:, 1] = np.arctan(np.hypot(x, y) / h) - o2
    return out


def numpy_dh_link(alpha, a, theta, d):
    """Modified (Craig) D-H link matrices ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` for an array of theta, (N, 4, 4)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), np.cos(theta), np.sin(theta)
    A = np.zeros(np.shape(theta) + (4, 4))
    A[..., 0, 0], A[..., 0, 1], A[..., 0, 3] = ct, -st, a
    A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st * ca, ct * ca, -sa, -sa * d
    A[..., 2, 0], A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = st * sa, ct * sa, ca, ca * d
    A[..., 3, 3] = 1.0
    return A


def numpy_chain_spot(th, d1, d2, H, o1, o2):
    """Seed Table 1 chain in plain NumPy, then the beam z_E met with the floor z_0 = -H: spot (N, 3)."""
    T = (numpy_dh_link(math.pi, 0.0, -math.pi / 2 + o1 + th[:, 0], d1)
         @ numpy_dh_link(-math.pi / 2, 0.0, o2 + th[:, 1], 0.0) @ numpy_dh_link(math.pi / 2, 0.0, 0.0, d2))
    p, z = T[:, :3, 3], T[:, :3, 2]
    s = (-H - p[:, 2]) / z[:, 2]
    return p + s[:, None] * z


def api_vs_numpy(sizes, repeats: int) -> None:
    """The ratio table of issue 16 (module docstring): API vs plain NumPy on the same equations, same run."""
    m = default_truth().with_(offsets=(0.004, 0.005))  # both offsets in play: the peer adds and wraps them too
    o1, o2 = m.offsets
    rng = np.random.default_rng(16)
    print(f"API vs plain NumPy on the same seed equations (projector {m.name}: h = {m.h:g} m, offsets {o1:g}, "
          f"{o2:g} rad; tilt 0.01 rad to the limit); median CPU time of {5 * repeats} alternating samples; "
          f"ratio = NumPy time / API time (goal >= 0.9 from 100 points)")
    print(f"| {'N':>9s} | {'FK eq. 6 API':>12s} | {'NumPy':>10s} | {'ratio':>5s} | {'IK eq. 8 API':>12s} | "
          f"{'NumPy':>10s} | {'ratio':>5s} | {'D-H chain API':>13s} | {'NumPy':>10s} | {'ratio':>5s} |")
    print("|" + "|".join("-" * w for w in (11, 14, 12, 7, 14, 12, 7, 15, 12, 7)) + "|")
    best_rows = []
    for n in sizes:
        th = np.column_stack([rng.uniform(-math.pi, math.pi, n), rng.uniform(0.01, m.tilt_limit - o2, n)])
        pts = m.spot(th)
        # agreement first (the API's results, not only its speed): metres and radians, round-off of
        # |spot| <= h tan(75 deg) ~ 10 m and of the angles
        assert np.abs(numpy_fk(th, m.h, m.H, o1, o2) - pts).max() < 1e-12
        assert np.abs(numpy_chain_spot(th, m.d1, m.d2, m.H, o1, o2) - m.spot_from_chain(th)).max() < 1e-12
        dk = m.ik(pts) - numpy_ik(pts, m.h, o1, o2)
        assert np.abs(np.mod(dk + math.pi, 2 * math.pi) - math.pi).max() < 1e-12  # pi and -pi are one pan
        cells, best = [], []
        for api, peer in ((lambda: m.spot(th), lambda: numpy_fk(th, m.h, m.H, o1, o2)),
                          (lambda: m.ik(pts), lambda: numpy_ik(pts, m.h, o1, o2)),
                          (lambda: m.spot_from_chain(th), lambda: numpy_chain_spot(th, m.d1, m.d2, m.H, o1, o2))):
            (t_api, t_peer), (b_api, b_peer) = paired_medians(api, peer, n, repeats, minima=True)
            cells += [f"{n / t_api:10.3g}/s", f"{n / t_peer:8.3g}/s", f"{t_peer / t_api:5.2f}"]
            best.append(b_peer / b_api)
        w = (12, 10, 5, 12, 10, 5, 13, 10, 5)
        print(f"| {n:9,d} | " + " | ".join(f"{c:>{k}s}" for c, k in zip(cells, w)) + " |")
        best_rows.append(f"{n:,}: " + " / ".join(f"{b:.2f}" for b in best))
    # the fastest of the 5 x repeats samples each: the least disturbed by other processes (a loaded machine's
    # medians swing by +-0.1 at 100 points; these estimate the ratio on a quiet one)
    print("ratio of the fastest samples (FK / IK / chain), " + "; ".join(best_rows))


def paired_medians(api, peer, n: int, repeats: int, minima: bool = False):
    """Median CPU time per call [s] of ``api`` and ``peer``, timed alternately in short samples (and, with
    ``minima``, their fastest samples' times as a second pair).

    CPU time of this process (``time.process_time``), not wall time: on a shared machine the wall clock
    also counts the time other processes hold the core; alternating ~5 ms samples puts load drifts on both.
    """
    k = max(1, min(5_000, 50_000 // n))  # calls per sample: ~5 ms per sample below 10^6 points
    ta, tp = [], []
    for _ in range(5 * repeats):
        for fn, ts in ((api, ta), (peer, tp)):
            t0 = time.process_time()
            for _ in range(k):
                fn()
            ts.append((time.process_time() - t0) / k)
    med = float(np.median(ta)), float(np.median(tp))
    return (med, (min(ta), min(tp))) if minima else med


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=100_000, help="points for the vectorised calls")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--ratios-only", action="store_true", help="only the API vs plain NumPy table")
    ap.add_argument("--repeats", type=int, default=None, help="repeats of the API vs NumPy table (default 9, quick 3)")
    args = ap.parse_args()
    print(f"command: python bench/bench_projector.py {' '.join(sys.argv[1:])}".rstrip())
    print(f"robocal {robocal.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}\n")
    api_vs_numpy([1, 100, 10_000, 1_000_000], args.repeats or (3 if args.quick else 9))
    if args.ratios_only:
        return
    print()
    n = 10_000 if args.quick else args.n
    n_loop = 2_000 if args.quick else 10_000
    rep = 3 if args.quick else 7
    rng = np.random.default_rng(0)
    m = default_truth().with_(offsets=(0.0, 0.0))
    th = np.column_stack([rng.uniform(-math.pi + 1e-6, math.pi, n), rng.uniform(0.01, m.tilt_limit, n)])
    p = m.spot(th)
    # agreement first
    assert np.abs(m.spot_from_chain(th[:1000]) - p[:1000]).max() < 1e-12
    assert np.abs(np.array(pure_fk(th[:1000], m.h, m.H)) - p[:1000]).max() < 1e-12
    assert np.abs(m.ik(p) - th).max() < 1e-12
    assert np.abs(np.array(pure_ik(p[:1000], m.h)) - th[:1000]).max() < 1e-12

    print(f"robocal {robocal.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}; N = {n} vectorised, {n_loop} per-point")
    rows = []
    t_vec = best_of(lambda: m.spot(th), rep)
    t_chain = best_of(lambda: m.spot_from_chain(th), rep)
    t_loop = best_of(lambda: [m.spot(x) for x in th[:n_loop]], 1) / n_loop
    t_pure = best_of(lambda: pure_fk(th[:n_loop], m.h, m.H), rep) / n_loop
    rows += [("FK eq. 6 vectorised", n / t_vec, 1.0), ("FK D-H chain vectorised", n / t_chain, t_chain / t_vec),
             ("FK eq. 6 per point (robocal loop)", 1 / t_loop, t_loop * n / t_vec),
             ("FK pure Python loop", 1 / t_pure, t_pure * n / t_vec)]
    i_vec = best_of(lambda: m.ik(p), rep)
    i_loop = best_of(lambda: [m.ik(x) for x in p[:n_loop]], 1) / n_loop
    i_pure = best_of(lambda: pure_ik(p[:n_loop], m.h), rep) / n_loop
    rows += [("IK eq. 8 vectorised", n / i_vec, 1.0), ("IK eq. 8 per point (robocal loop)", 1 / i_loop,
                                                       i_loop * n / i_vec),
             ("IK pure Python loop", 1 / i_pure, i_pure * n / i_vec)]
    print(f"\n| {'variant':36s} | {'points/s':>12s} | {'slower than vectorised':>22s} |")
    print(f"|{'-' * 38}|{'-' * 14}|{'-' * 24}|")
    for name, rate, ratio in rows:
        print(f"| {name:36s} | {rate:12.3g} | {ratio:21.1f}x |")

    print("\ncalibration (median wall time per solve):")
    print(f"| {'solver':44s} | {'N = 8':>9s} | {'N = 50':>9s} |")
    print(f"|{'-' * 46}|{'-' * 11}|{'-' * 11}|")
    truth = default_truth()
    nominal = default_nominal(truth)
    scs = {k: simulate_calibration(np.random.default_rng(k), truth=truth, nominal=nominal, n_points=k, sigma=0.005)
           for k in (8, 50)}
    solvers = [
        ("seed method (eqs. 12-29, alpha 0.5)", lambda s: seed_method(s.points_W, nominal.spot(s.theta))),
        ("closed form (Umeyama)", lambda s: closed_form(s.points_W, nominal.spot(s.theta))),
        ("nonlinear LS, pose", lambda s: nonlinear(s.points_W, theta=s.theta, model=nominal)),
        ("nonlinear LS, pose + h + tilt offset",
         lambda s: nonlinear(s.points_W, theta=s.theta, model=nominal, estimate=("h", "tilt_offset"))),
        ("calibrate(): check + all three methods",
         lambda s: calibrate(s.points_W, theta=s.theta, model=nominal, estimate=("h", "tilt_offset"), sigma=0.005)),
    ]
    r = 5 if args.quick else 21
    for name, fn in solvers:
        ts = [median_of(lambda s=s: fn(s), r) for s in scs.values()]
        print(f"| {name:44s} | {1e3 * ts[0]:6.2f} ms | {1e3 * ts[1]:6.2f} ms |")

    # spot path -> timed joint angles and rates (IK branch choice, rate and angle limits included),
    # against the naive per-sample loop: IK of each world point, then finite-difference rates
    k = 2_000 if args.quick else 20_000
    t = np.linspace(0.0, 20.0, k)
    nadir_W = -truth.R_0_W.T @ truth.t_0_W  # the floor point under the head (t_0_W = -R_0_W nadir + ...)
    c = nadir_W[:2] + np.array([3.0, 1.0])  # 3.2 m from the nadir: pan rates well inside the limits
    path = c + 1.2 * np.column_stack([np.cos(2 * math.pi * t / 10), np.sin(2 * math.pi * t / 10)])
    traj = joint_trajectory(truth, t, path)
    assert traj.feasible.all()

    def naive():
        th = np.array([truth.ik_world(np.array([x, y, 0.0])) for x, y in path])
        return np.gradient(np.unwrap(th, axis=0), t, axis=0)

    assert np.abs(naive()[5:-5] - traj.theta_dot[5:-5]).max() < 1e-3  # same path, same rates (interior)
    t_traj = best_of(lambda: joint_trajectory(truth, t, path), rep)
    t_naive = best_of(naive, 1)
    print(f"\nspot path -> joint trajectory ({k} samples, circle of 1.2 m, limits checked): "
          f"{k / t_traj:,.0f} samples/s; per-sample IK loop {k / t_naive:,.0f} samples/s "
          f"({t_naive / t_traj:.0f}x slower)")

    # several projectors: assignment of samples to A or B (reach with the tilt margin, nadir margin, beam not
    # blocked by the wall, rate limits), keep-the-current-projector rule and hand-overs
    A, B = seed_room_projectors()
    wall = [[-0.5, -3.0, -0.5, 0.5]]
    way = [[-2.0, -1.5], [-2.0, 1.0], [1.5, 1.5], [3.5, -1.0], [1.0, -4.0]]  # the demo's path across the room
    length = float(np.sum(np.linalg.norm(np.diff(way, axis=0), axis=1)))
    tp, pp, vp = sample_polyline(way, 0.3, length / 0.3 / (k - 1))
    plan = plan_multi([A, B], tp, pp, vp, walls=wall)
    assert plan.ok and len(plan.handovers) >= 1
    margin = math.radians(2.0)

    def naive_multi():
        projs = (A, B)
        ths = [np.array([q.ik_world(np.array([x, y, 0.0]), check_reach=False) for x, y in pp]) for q in projs]
        rates = [np.gradient(np.unwrap(th, axis=0), tp, axis=0) for th in ths]
        assign, cur = [], -1
        for i in range(len(tp)):
            ok, score = [], []
            for j, q in enumerate(projs):
                tilt = ths[j][i, 1] + q.offsets[1]
                good = (margin <= tilt <= q.tilt_limit - margin
                        and abs(rates[j][i, 0]) <= q.rate_limits[0] and abs(rates[j][i, 1]) <= q.rate_limits[1]
                        and not segments_blocked(q.nadir_world, pp[i], wall))
                ok.append(good)
                score.append(min(tilt, q.tilt_limit - tilt) if good else -np.inf)
            if not (cur >= 0 and ok[cur]):
                best = int(np.argmax(score))
                cur = best if ok[best] else -1
            assign.append(cur)
        return np.array(assign)

    agree = float(np.mean(naive_multi() == plan.assignment))
    assert agree > 0.999, agree  # the same rules give the same assignment (finite-difference vs eq. 9 rates)
    t_plan = best_of(lambda: plan_multi([A, B], tp, pp, vp, walls=wall), rep)
    t_cmd = best_of(lambda: plan.projector_commands(), rep)
    t_nm = best_of(naive_multi, 1)
    print(f"\nplan_multi, 2 projectors + 1 wall ({k} samples, {len(plan.handovers)} hand-over(s), assignment agrees "
          f"on {100 * agree:.2f} % of samples): {k / t_plan:,.0f} samples/s; per-sample loop (IK, reach, wall, "
          f"rates, keep-current rule) {k / t_nm:,.0f} samples/s ({t_nm / t_plan:.0f}x slower); per-head command "
          f"streams with pre-aiming (projector_commands) {k / t_cmd:,.0f} samples/s")

    bench_sizes([1_000, 10_000] if args.quick else [1_000, 10_000, 100_000])


def bench_sizes(sizes) -> None:
    """calibrate() (check + all three methods, h and tilt offset, joint noise) at growing N: time and the peak
    of Python-traced memory (tracemalloc). Linear in N since the pairwise check stopped building N x N x 3."""
    import time
    import tracemalloc

    from robocal.rigs.projector.calibrate import calibrate
    from robocal.rigs.projector.simulate import simulate_calibration

    print("\ncalibrate() at growing N (all methods, h + tilt offset, joint_noise 0.05 deg; CPU time, traced peak):")
    for n in sizes:
        sc = simulate_calibration(np.random.default_rng(n), n_points=n, sigma=0.005,
                                  theta_sigma=math.radians(0.05))
        tracemalloc.start()
        t0 = time.process_time()
        run = calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"),
                        sigma=sc.sigma, joint_noise=(sc.theta_sigma, sc.theta_sigma))
        dt = time.process_time() - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        print(f"  N = {n:>7,}: {dt:6.2f} s CPU, peak {peak / 2**20:7.1f} MiB ({peak / n:,.0f} B/point), "
              f"{run.consistency.n_pairs:,} pairs checked")


if __name__ == "__main__":
    main()
