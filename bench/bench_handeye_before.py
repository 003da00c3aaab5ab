"""Hand-eye calibration before and after issue 16 on the same data: ``calibrate_hand_eye`` (refined) and
``calibrate_robot_world`` at 15 poses, beside ``cv2.calibrateHandEye`` (Horaud) timed in the same process.

Run::

    git archive 222e31e src | tar -x -C /tmp/before        # the tree before the analytic Jacobians
    python bench/bench_handeye_before.py --before /tmp/before/src [--sets 100]

Each tree runs in its own process (``PYTHONPATH``), one BLAS / OpenCV thread; median CPU time per call over
``--sets`` simulated data sets (:func:`robocal.handeye.simulate_eye_in_hand`, seeds 0..sets-1); the ratio to
OpenCV is taken within each process, so load drift between the two runs cancels. The errors of X against
the truth must agree (same estimator, same minimum).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CHILD = r'''
import json, sys, time
import cv2
import numpy as np
from robocal.geometry import invert_transform
from robocal.handeye import calibrate_hand_eye, calibrate_robot_world, simulate_eye_in_hand, transform_error
cv2.setNumThreads(1)
out = {"he": [], "rw": [], "cv": [], "err": [], "where": __import__("robocal").__file__}
for s in range(int(sys.argv[1])):
    sim = simulate_eye_in_hand(np.random.default_rng(s), 15)
    Tg, Tc = sim.T_base_gripper, sim.T_cam_target
    t0 = time.process_time(); r = calibrate_hand_eye(Tg, Tc); out["he"].append(time.process_time() - t0)
    t0 = time.process_time(); calibrate_robot_world(Tc, invert_transform(Tg)); out["rw"].append(time.process_time() - t0)
    t0 = time.process_time()
    cv2.calibrateHandEye(Tg[:, :3, :3], Tg[:, :3, 3], Tc[:, :3, :3], Tc[:, :3, 3], method=cv2.CALIB_HAND_EYE_HORAUD)
    out["cv"].append(time.process_time() - t0)
    out["err"].append(transform_error(r.X, sim.X))
print("RESULT", json.dumps(out))
'''


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True, help="the src/ folder of the earlier tree")
    ap.add_argument("--sets", type=int, default=100)
    a = ap.parse_args()
    import numpy as np

    here = str(Path(__file__).resolve().parents[1] / "src")
    res = {}
    for name, path in (("before", a.before), ("after", here)):
        env = dict(os.environ, PYTHONPATH=path, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
        o = subprocess.run([sys.executable, "-c", CHILD, str(a.sets)], env=env, capture_output=True, text=True)
        if o.returncode:
            sys.exit(f"{name}: {(o.stderr.strip().splitlines() or ['?'])[-1]}")
        res[name] = json.loads(o.stdout.split("RESULT", 1)[1])
    print(f"15 poses, {a.sets} data sets, median CPU time per call, one core")
    for name, r in res.items():
        he, rw, cv = (1e3 * np.median(r[k]) for k in ("he", "rw", "cv"))
        e = 1e3 * np.mean(r["err"], axis=0)
        print(f"{name:6s} ({r['where']}): calibrate_hand_eye {he:.2f} ms = {he / cv:.1f}x cv2 Horaud ({cv:.2f} ms); "
              f"calibrate_robot_world {rw:.2f} ms; X error {e[0]:.4f} mrad, {e[1]:.4f} mm")
    d = np.abs(np.subtract(res["before"]["err"], res["after"]["err"])).max()
    print(f"max |X error after - before| over the sets: {d:.1e} (rad or m)")


if __name__ == "__main__":
    main()
