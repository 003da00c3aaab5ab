"""AX = XB and AX = ZB solvers: accuracy and time, robocal vs OpenCV on the same data.

Run: python bench/bench_lineprofiler.py [--trials 50]
Prints two Markdown tables (mean rotation / translation error vs truth, time per call, ratio to
OpenCV): the five hand-eye methods against ``cv2.calibrateHandEye``, and the robot-world solver
(Shah's closed form, then refined) against ``cv2.calibrateRobotWorldHandEye`` (Shah and Li).
"""

import argparse
import time

import cv2
import numpy as np

from robocal.geometry import invert_transform, matrix_from_rotvec, transform_from
from robocal.handeye import AXXB_METHODS, calibrate_hand_eye, calibrate_robot_world, transform_error

CV = {"tsai": cv2.CALIB_HAND_EYE_TSAI, "park": cv2.CALIB_HAND_EYE_PARK, "horaud": cv2.CALIB_HAND_EYE_HORAUD,
      "andreff": cv2.CALIB_HAND_EYE_ANDREFF, "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS}


def scene(rng, n, s_r, s_t):
    def T(ang=1.0, tr=0.5):
        return transform_from(matrix_from_rotvec(rng.normal(size=3) * ang), rng.normal(size=3) * tr)

    X, Y = T(), T()
    Tg = np.array([T() for _ in range(n)])
    Tc = invert_transform(X) @ invert_transform(Tg) @ Y
    Tc = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * s_r) @ Tc[:, :3, :3],
                        Tc[:, :3, 3] + rng.normal(size=(n, 3)) * s_t)
    return X, Tg, Tc


def robot_world_scene(rng, n, s_r, s_t):
    """``A_i X = Z B_i``: A = T_cam_world (noisy, as seen by the camera), B = T_gripper_base."""
    def T(ang=1.0, tr=0.5):
        return transform_from(matrix_from_rotvec(rng.normal(size=3) * ang), rng.normal(size=3) * tr)

    X, Z = T(), T()
    TB = invert_transform(np.array([T() for _ in range(n)]))
    TA = Z @ TB @ invert_transform(X)
    TA = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * s_r) @ TA[:, :3, :3],
                        TA[:, :3, 3] + rng.normal(size=(n, 3)) * s_t)
    return X, Z, TA, TB


def cv_robot_world(TA, TB, method):
    Rb, tb, Rg, tg = cv2.calibrateRobotWorldHandEye(TA[:, :3, :3], TA[:, :3, 3], TB[:, :3, :3], TB[:, :3, 3],
                                                    method=method)
    return transform_from(Rb, tb.ravel()), transform_from(Rg, tg.ravel())


def timed(f, reps=5):
    t = time.perf_counter()
    for _ in range(reps):
        out = f()
    return out, (time.perf_counter() - t) / reps


def main():
    if not hasattr(cv2, "calibrateHandEye"):
        # the comparison is the point of this bench; BENCHMARKS.md's tables were measured with OpenCV 4.x
        raise SystemExit(f"bench_lineprofiler compares with cv2.calibrateHandEye / calibrateRobotWorldHandEye, "
                         f"which OpenCV {cv2.__version__} no longer has: run it with opencv-python-headless 4.x")
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--poses", type=int, default=12)
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    scenes = [scene(rng, a.poses, 1e-3, 1e-3) for _ in range(a.trials)]
    print(f"{a.trials} trials, {a.poses} poses, noise 1 mrad / 1 mm on the sensor poses\n")
    print("| method | solver | rot err [mrad] | t err [mm] | time [ms] | time / OpenCV |")
    print("|---|---|---|---|---|---|")
    for m in AXXB_METHODS:
        rows = {}
        for name, f in (("OpenCV", lambda Tg, Tc: transform_from(*[(R, t.ravel()) for R, t in [cv2.calibrateHandEye(
                Tg[:, :3, :3], Tg[:, :3, 3], Tc[:, :3, :3], Tc[:, :3, 3], method=CV[m])]][0])),
                        ("robocal", lambda Tg, Tc: calibrate_hand_eye(Tg, Tc, m, refine=False).X),
                        ("robocal+refine", lambda Tg, Tc: calibrate_hand_eye(Tg, Tc, m).X)):
            errs, ts = [], []
            for X, Tg, Tc in scenes:
                Xe, dt = timed(lambda: f(Tg, Tc), reps=3)
                errs.append(transform_error(Xe, X))
                ts.append(dt)
            e = np.array(errs)
            rows[name] = (1e3 * e[:, 0].mean(), 1e3 * e[:, 1].mean(), 1e3 * np.median(ts))
        for name, (er, et, tm) in rows.items():
            print(f"| {m} | {name} | {er:.3f} | {et:.3f} | {tm:.3f} | {tm / rows['OpenCV'][2]:.1f} |")

    rw = [robot_world_scene(rng, a.poses, 1e-3, 1e-3) for _ in range(a.trials)]
    print("\nAX = ZB (X = T_world_base, Z = T_cam_gripper), same noise on A = T_cam_world; errors of X | Z\n")
    print("| solver | X rot [mrad] | X t [mm] | Z rot [mrad] | Z t [mm] | time [ms] | time / OpenCV Shah |")
    print("|---|---|---|---|---|---|---|")
    rows = {}
    for name, f in (("OpenCV Shah", lambda TA, TB: cv_robot_world(TA, TB, cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH)),
                    ("OpenCV Li", lambda TA, TB: cv_robot_world(TA, TB, cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI)),
                    ("robocal (Shah)", lambda TA, TB: (lambda r: (r.X, r.Z))(calibrate_robot_world(TA, TB,
                                                                                                   refine=False))),
                    ("robocal+refine", lambda TA, TB: (lambda r: (r.X, r.Z))(calibrate_robot_world(TA, TB)))):
        errs, ts = [], []
        for X, Z, TA, TB in rw:
            (Xe, Ze), dt = timed(lambda: f(TA, TB), reps=3)
            errs.append([*transform_error(Xe, X), *transform_error(Ze, Z)])
            ts.append(dt)
        rows[name] = (*(1e3 * np.array(errs).mean(axis=0)), 1e3 * np.median(ts))
    for name, v in rows.items():
        print(f"| {name} | {v[0]:.3f} | {v[1]:.3f} | {v[2]:.3f} | {v[3]:.3f} | {v[4]:.3f} | "
              f"{v[4] / rows['OpenCV Shah'][4]:.1f} |")


if __name__ == "__main__":
    main()
