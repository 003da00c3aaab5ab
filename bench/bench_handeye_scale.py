"""Hand-eye at scale (issue 13): ``robocal handeye calibrate`` and the library against ``cv2.calibrateHandEye``.

Run: python bench/bench_handeye_scale.py [--sizes 1688 10000] [--opencv-max 5000]

Each run is a fresh interpreter (so its peak RSS is its own): simulated eye-in-hand poses
(:func:`robocal.handeye.simulate_eye_in_hand`, seed 0, 1 mrad / 0.2 mm sensor noise), then

* ``robocal handeye calibrate G.csv C.csv --out DIR`` (default ``--pairs auto``; reading, solving, the
  five closed forms compared, the report),
* ``calibrate_hand_eye(Tg, Tc)`` alone (Tsai on the ``auto`` pairs, then refined, with covariance),
* ``cv2.calibrateHandEye`` (Tsai, Park; OpenCV takes every pose pair), up to ``--opencv-max`` poses.

Prints a Markdown table: wall time of the step, peak RSS of the process (imports included: a bare
``import robocal.handeye, numpy, scipy`` is ~100 MB), rotation / translation error of X against the truth.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, re, sys, time
import numpy as np
from robocal.handeye import calibrate_hand_eye, simulate_eye_in_hand, transform_error
from robocal.geometry import transform_from
kind, n, work = sys.argv[1], int(sys.argv[2]), sys.argv[3]
sim = simulate_eye_in_hand(np.random.default_rng(0), n)
Tg, Tc = sim.T_base_gripper, sim.T_cam_target
t0 = time.perf_counter()
if kind == "command":
    from robocal.cli.main import main
    from robocal.io import load_result
    rc = main(["handeye", "calibrate", f"{work}/g.csv", f"{work}/c.csv", "--out", f"{work}/cal-{time.time_ns()}"])
    assert rc == 0
    import glob
    X = load_result(sorted(glob.glob(f"{work}/cal-*/result.json"))[-1]).pose("T_gripper_cam").T
elif kind == "library":
    X = calibrate_hand_eye(Tg, Tc).X
else:
    import cv2
    m = {"opencv-tsai": cv2.CALIB_HAND_EYE_TSAI, "opencv-park": cv2.CALIB_HAND_EYE_PARK}[kind]
    R, t = cv2.calibrateHandEye(Tg[:, :3, :3], Tg[:, :3, 3], Tc[:, :3, :3], Tc[:, :3, 3], method=m)
    X = transform_from(R, t.ravel())
dt = time.perf_counter() - t0
rot, trans = transform_error(X, sim.X)
# VmHWM, the process's own peak: getrusage's ru_maxrss survives fork + exec (it would count the bench's memory)
hwm = int(re.search(r"VmHWM:\s*(\d+)", open("/proc/self/status").read()).group(1))
print("RESULT", json.dumps({"time_s": dt, "rss_mb": hwm / 1e3,
                            "rot_mrad": 1e3 * rot, "trans_mm": 1e3 * trans}))
"""


def run(kind: str, n: int, work: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, kind, str(n), str(work)], capture_output=True, text=True)
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": last[:80]}
    return json.loads(out.stdout.split("RESULT", 1)[1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[1688])
    ap.add_argument("--opencv-max", type=int, default=5000, help="largest size given to OpenCV (all pairs)")
    ap.add_argument("--runs", nargs="+", default=["command", "library", "opencv-tsai", "opencv-park"])
    a = ap.parse_args()
    import numpy as np

    from robocal.handeye import simulate_eye_in_hand
    from robocal.io import write_poses

    print("| poses | run | time [s] | peak RSS [MB] | rot err [mrad] | t err [mm] |")
    print("|---|---|---|---|---|---|")
    for n in a.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            sim = simulate_eye_in_hand(np.random.default_rng(0), n)
            t = np.arange(n) * 0.05
            write_poses(work / "g.csv", sim.T_base_gripper, t)
            write_poses(work / "c.csv", sim.T_cam_target, t)
            kinds = [k for k in a.runs if not k.startswith("opencv") or n <= a.opencv_max]
            for kind in kinds:
                r = run(kind, n, work)
                if "error" in r:
                    print(f"| {n} | {kind} | failed: {r['error']} | | | |")
                else:
                    print(f"| {n} | {kind} | {r['time_s']:.2f} | {r['rss_mb']:.0f} | {r['rot_mrad']:.4f} | "
                          f"{r['trans_mm']:.4f} |", flush=True)


if __name__ == "__main__":
    main()
