"""AX = XB solvers: accuracy and time, robocal vs OpenCV's calibrateHandEye on the same data.

Run: python bench/bench_lineprofiler.py [--trials 50]
Prints a Markdown table (mean rotation / translation error vs truth, time per call, ratio to OpenCV).
"""

import argparse
import time

import cv2
import numpy as np

from robocal.geometry import invert_transform, matrix_from_rotvec, transform_from
from robocal.rigs.lineprofiler.handeye import AXXB_METHODS, calibrate_hand_eye, transform_error

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


def timed(f, reps=5):
    t = time.perf_counter()
    for _ in range(reps):
        out = f()
    return out, (time.perf_counter() - t) / reps


def main():
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


if __name__ == "__main__":
    main()
