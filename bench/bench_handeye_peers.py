"""Hand-eye against OpenCV (issues 13 and 16): the same simulated data through OpenCV's five AX = XB and two
AX = ZB methods and through robocal's, accuracy, time per call and, at scale, peak memory.

Run: python bench/bench_handeye_peers.py [--trials 200] [--sizes 15 50 200 1000 10000] [--opencv-max 1000]

Single core throughout (BLAS and OpenCV threads set to 1 before the imports). Two parts:

1. **15 poses, ``--trials`` data sets** (:func:`robocal.handeye.simulate_eye_in_hand`, seeds 0..trials-1, 1 mrad /
   0.2 mm sensor noise): each solver on each data set, CPU time per call interleaved (one call of each solver
   in turn, so load drifts hit all alike; the median over data sets), errors of X against the truth (mean).
   AX = ZB on the same poses: ``A = T_cam_target``, ``B = T_gripper_base``, ``X = T_target_base``,
   ``Z = T_cam_gripper``. ``robocal tsai+refine`` is the whole ``calibrate_hand_eye`` call (validation, the
   closed form on all 105 pose pairs, the plausibility check, the refinement with covariance); the issue-16
   ratio is its time over the most accurate OpenCV method's. ``refine (finite differences)`` is the same call
   with the refinement's Jacobian by finite differences, the path before the analytic one (same answer).
2. **Scale**: each solver on N poses in a fresh process (peak memory = the process's own VmHWM from
   /proc/self/status, imports included; getrusage's ru_maxrss survives fork + exec and would count this
   script), wall and CPU time of the call (CPU time is the figure that holds on a loaded machine), after a
   warm-up call on 15 poses (lazy imports); ``command`` is the whole ``robocal handeye calibrate`` in-process
   (read two CSVs, solve, the five closed forms compared, the report; its lazy imports included). OpenCV takes every pose pair (n (n - 1) / 2 motions): it runs up to
   ``--opencv-max`` poses and, above, once with a 4 GB address-space limit and a time limit to show where it fails.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

AXXB = ("tsai", "park", "horaud", "andreff", "daniilidis")

# -------------------------------------------------------------------------------------------- part 1: 15 poses


def _solvers():
    import cv2
    import numpy as np

    from robocal.geometry import invert_transform, transform_from
    from robocal.handeye import calibrate_hand_eye, calibrate_robot_world
    from robocal.handeye import refine as _refine

    cv2.setNumThreads(1)
    code = {m: getattr(cv2, f"CALIB_HAND_EYE_{m.upper()}") for m in AXXB}

    def cv_axxb(m):
        def run(Tg, Tc):
            R, t = cv2.calibrateHandEye(Tg[:, :3, :3], Tg[:, :3, 3], Tc[:, :3, :3], Tc[:, :3, 3], method=code[m])
            return transform_from(R, t.ravel()), None
        return run

    def cv_axzb(m):
        flag = getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{m.upper()}")

        def run(Tg, Tc):
            B = invert_transform(Tg)
            Rx, tx, Rz, tz = cv2.calibrateRobotWorldHandEye(Tc[:, :3, :3], Tc[:, :3, 3], B[:, :3, :3], B[:, :3, 3],
                                                            method=flag)
            return transform_from(Rx, tx.ravel()), transform_from(Rz, tz.ravel())
        return run

    def ours(m, refine=True):
        return lambda Tg, Tc: (calibrate_hand_eye(Tg, Tc, m, refine=refine).X, None)

    def ours_fd(Tg, Tc):
        # the refinement's Jacobian by finite differences: the path before issue 16 (same Problem, same answer)
        orig = _refine._refine_closure
        _refine._refine_closure = lambda *a, **k: orig(*a, **k, jac="2-point")
        try:
            return calibrate_hand_eye(Tg, Tc).X, None
        finally:
            _refine._refine_closure = orig

    def ours_rw(refine):
        def run(Tg, Tc):
            r = calibrate_robot_world(Tc, invert_transform(Tg), refine=refine)
            return r.X, r.Z
        return run

    axxb = {f"OpenCV {m}": cv_axxb(m) for m in AXXB}
    axxb |= {f"robocal {m}": ours(m, refine=False) for m in AXXB}
    axxb |= {"robocal tsai+refine": ours("tsai"), "robocal daniilidis+refine": ours("daniilidis"),
             "robocal tsai+refine (finite differences)": ours_fd}
    axzb = {"OpenCV shah": cv_axzb("shah"), "OpenCV li": cv_axzb("li"), "robocal shah": ours_rw(False),
            "robocal shah+refine": ours_rw(True)}
    return axxb, axzb, np


def small(trials: int, n: int) -> None:
    axxb, axzb, np = _solvers()
    from robocal.geometry import invert_transform
    from robocal.handeye import simulate_eye_in_hand, transform_error

    for title, solvers, rw in (("AX = XB", axxb, False), ("AX = ZB", axzb, True)):
        times = {k: [] for k in solvers}
        errs = {k: [] for k in solvers}
        for s in range(trials):
            sim = simulate_eye_in_hand(np.random.default_rng(s), n)
            Tg, Tc = sim.T_base_gripper, sim.T_cam_target
            for k, fn in solvers.items():
                t0 = time.process_time()
                X, Z = fn(Tg, Tc)
                times[k].append(time.process_time() - t0)
                if rw:
                    ex = transform_error(X, invert_transform(sim.Y))
                    ez = transform_error(Z, invert_transform(sim.X))
                    errs[k].append([*ex, *ez])
                else:
                    errs[k].append(transform_error(X, sim.X))
        e = {k: np.mean(v, axis=0) for k, v in errs.items()}
        t = {k: 1e3 * np.median(v) for k, v in times.items()}
        peers = [k for k in solvers if k.startswith("OpenCV")]
        # the most accurate OpenCV method: the smallest sum of its errors relative to the best OpenCV figure of
        # each kind (rotation and translation of X, and of Z for AX = ZB), so that no one figure decides alone
        low = np.min([e[k] for k in peers], axis=0)
        best = min(peers, key=lambda k: float(np.sum(e[k] / low)))
        print(f"\n{title}: {trials} data sets x {n} poses, 1 mrad / 0.2 mm sensor noise; mean error of X"
              f"{' and Z' if rw else ''} against the truth, median CPU time per call, one core; "
              f"reference: {best} (the most accurate OpenCV method: rotation and translation errors together)\n")
        if rw:
            print("| solver | X rot [mrad] | X t [mm] | Z rot [mrad] | Z t [mm] | time [ms] | time / ref |")
            print("|---|---|---|---|---|---|---|")
        else:
            print("| solver | rot [mrad] | t [mm] | rot / ref | t / ref | time [ms] | time / ref |")
            print("|---|---|---|---|---|---|---|")
        for k in solvers:
            if rw:
                a, b, c, d = 1e3 * e[k]
                print(f"| {k} | {a:.4f} | {b:.4f} | {c:.4f} | {d:.4f} | {t[k]:.3f} | {t[k] / t[best]:.2f} |")
            else:
                a, b = 1e3 * e[k]
                print(f"| {k} | {a:.4f} | {b:.4f} | {e[k][0] / e[best][0]:.3f} | {e[k][1] / e[best][1]:.3f} | "
                      f"{t[k]:.3f} | {t[k] / t[best]:.2f} |")
        # the error ratio's sampling noise: the std of the per-set ratio over sqrt(trials)
        if not rw:
            k = "robocal tsai+refine"
            per = np.asarray(errs[k]) / np.asarray(errs[best])
            print(f"\n{k} / {best}: rotation error {e[k][0] / e[best][0]:.3f} (per-set ratio's median "
                  f"{np.median(per[:, 0]):.3f}), translation {e[k][1] / e[best][1]:.3f}; time "
                  f"{t[k] / t[best]:.2f}x; max |X (analytic) - X (finite differences)|: "
                  f"{max(abs(np.subtract(*v)).max() for v in zip(errs[k], errs[k + ' (finite differences)'])):.1e} "
                  "in the errors")


# --------------------------------------------------------------------------------------------- part 2: scale

CHILD = r"""
import json, os, re, sys, time
for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(v, "1")
import cv2
import numpy as np
from robocal.geometry import invert_transform, transform_from
from robocal.handeye import calibrate_hand_eye, calibrate_robot_world, simulate_eye_in_hand, transform_error
cv2.setNumThreads(1)
kind, n, work = sys.argv[1], int(sys.argv[2]), sys.argv[3]


def solve(Tg, Tc):
    # -> X, Z (None for AX = XB), the truths' forms: X = T_gripper_cam, or X = T_target_base and Z = T_cam_gripper
    if kind == "robocal tsai+refine":
        return calibrate_hand_eye(Tg, Tc).X, None
    if kind == "robocal shah+refine":
        r = calibrate_robot_world(Tc, invert_transform(Tg))
        return r.X, r.Z
    m = kind.split()[1]
    if m in ("shah", "li"):
        B = invert_transform(Tg)
        Rx, tx, Rz, tz = cv2.calibrateRobotWorldHandEye(Tc[:, :3, :3], Tc[:, :3, 3], B[:, :3, :3], B[:, :3, 3],
                                                        method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{m.upper()}"))
        return transform_from(Rx, tx.ravel()), transform_from(Rz, tz.ravel())
    R, t = cv2.calibrateHandEye(Tg[:, :3, :3], Tg[:, :3, 3], Tc[:, :3, :3], Tc[:, :3, 3],
                                method=getattr(cv2, f"CALIB_HAND_EYE_{m.upper()}"))
    return transform_from(R, t.ravel()), None


sim = simulate_eye_in_hand(np.random.default_rng(0), n)
Tg, Tc = sim.T_base_gripper, sim.T_cam_target
if kind not in ("imports", "command"):
    warm = simulate_eye_in_hand(np.random.default_rng(1), 15)     # lazy imports and first-call costs out of the timing
    solve(warm.T_base_gripper, warm.T_cam_target)
t0, c0 = time.perf_counter(), time.process_time()
Z = None
if kind == "imports":
    X = sim.X
elif kind == "command":
    from robocal.cli.main import main
    from robocal.io import load_result
    out = f"{work}/cal-{time.time_ns()}"
    assert main(["handeye", "calibrate", f"{work}/g.csv", f"{work}/c.csv", "--out", out]) == 0
    X = load_result(f"{out}/result.json").pose("T_gripper_cam").T
else:
    X, Z = solve(Tg, Tc)
dt, cpu = time.perf_counter() - t0, time.process_time() - c0
if Z is None:
    rot, trans = transform_error(X, sim.X)
    res = {"time_s": dt, "rot_mrad": 1e3 * rot, "trans_mm": 1e3 * trans}
else:
    rot, trans = transform_error(X, invert_transform(sim.Y))
    zr, zt = transform_error(Z, invert_transform(sim.X))
    res = {"time_s": dt, "rot_mrad": 1e3 * rot, "trans_mm": 1e3 * trans, "zrot_mrad": 1e3 * zr, "ztrans_mm": 1e3 * zt}
res["cpu_s"] = cpu
res["hwm_mb"] = int(re.search(r"VmHWM:\s*(\d+)", open("/proc/self/status").read()).group(1)) / 1024
print("RESULT", json.dumps(res))
"""


def _limit(gb: float):
    def f():
        lim = int(gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    return f


def run_child(kind: str, n: int, work: Path, limit_gb: float, timeout: float) -> dict:
    try:
        out = subprocess.run([sys.executable, "-c", CHILD, kind, str(n), str(work)], capture_output=True, text=True,
                             timeout=timeout, preexec_fn=_limit(limit_gb))
    except subprocess.TimeoutExpired:
        return {"error": f"not finished after {timeout:.0f} s (stopped)"}
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or [f"exit {out.returncode}"])[-1]
        return {"error": last[:90]}
    return json.loads(out.stdout.split("RESULT", 1)[1])


def scale(sizes, opencv_max: int, limit_gb: float, timeout: float) -> None:
    import numpy as np

    from robocal.handeye import simulate_eye_in_hand
    from robocal.io import write_poses

    print(f"\nScale: N simulated eye-in-hand poses (seed 0, 1 mrad / 0.2 mm), each run in a fresh process (limit "
          f"{limit_gb:g} GB address space, {timeout:.0f} s); peak memory (VmHWM, imports included: see "
          "'imports'); wall and CPU time of the call; one data set per size; errors of X (AX = ZB: X = "
          "T_target_base | Z = T_cam_gripper)\n")
    print("| poses | run | wall [s] | CPU [s] | peak [MB] | rot [mrad] | t [mm] |")
    print("|---|---|---|---|---|---|---|")
    kinds = ["imports", "command", "robocal tsai+refine", "robocal shah+refine"] + \
        [f"OpenCV {m}" for m in AXXB] + ["OpenCV shah", "OpenCV li"]
    for n in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            sim = simulate_eye_in_hand(np.random.default_rng(0), n)
            stamps = np.arange(n) * 0.05
            write_poses(work / "g.csv", sim.T_base_gripper, stamps)
            write_poses(work / "c.csv", sim.T_cam_target, stamps)
            tried_over = False
            for kind in kinds:
                if kind == "imports" and n != sizes[0]:
                    continue
                all_pairs = kind.startswith("OpenCV") and kind.split()[1] in AXXB
                if all_pairs and n > opencv_max:
                    if tried_over:
                        continue
                    tried_over = True      # one OpenCV method above the limit shows where it fails
                r = run_child(kind, n, work, limit_gb, timeout)
                if "error" in r:
                    print(f"| {n} | {kind} | failed: {r['error']} | | | | |", flush=True)
                    continue
                rot = f"{r['rot_mrad']:.4f}" + (f" \\| {r['zrot_mrad']:.4f}" if "zrot_mrad" in r else "")
                tr = f"{r['trans_mm']:.4f}" + (f" \\| {r['ztrans_mm']:.4f}" if "ztrans_mm" in r else "")
                print(f"| {n} | {kind} | {r['time_s']:.3f} | {r['cpu_s']:.3f} | {r['hwm_mb']:.0f} | {rot} | {tr} |",
                      flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=200, help="data sets of part 1 (0: skip)")
    ap.add_argument("--poses", type=int, default=15, help="poses per data set of part 1")
    ap.add_argument("--sizes", type=int, nargs="*", default=[15, 50, 200, 1000, 10000], help="part 2 (none: skip)")
    ap.add_argument("--opencv-max", type=int, default=1000, help="largest N for OpenCV's all-pairs AX = XB")
    ap.add_argument("--limit-gb", type=float, default=4.0, help="address-space limit of each scale run")
    ap.add_argument("--timeout", type=float, default=120.0, help="time limit of each scale run [s]")
    a = ap.parse_args()
    if a.trials:
        small(a.trials, a.poses)
    if a.sizes:
        scale(a.sizes, a.opencv_max, a.limit_gb, a.timeout)


if __name__ == "__main__":
    main()
