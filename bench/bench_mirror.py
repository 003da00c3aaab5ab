"""Mirror rig: accuracy (Monte Carlo on the published scene) and speed.

Run: python bench/bench_mirror.py [--trials 300] [--quick]

Prints (1) the patent's single-image method at 0.5 px vs its first-order
covariance, (2) the joint refinement over K = 1, 4, 9 similar mirror
placements vs prediction and vs 1/sqrt(K), (3) time per single-image
calibration against its peer measured in the same run: the two raw
cv2.solvePnP calls it is made of (the composition and the IPPE choice are
the overhead).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from robocal.rigs.mirror.calibrate import calibrate_single
from robocal.rigs.mirror.model import ri_from_r_points
from robocal.rigs.mirror.montecarlo import multi_placement_study, single_image_study
from robocal.rigs.mirror.simulate import default_setup, simulate_observations


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=300)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    n1 = 60 if a.quick else a.trials
    nK = 30 if a.quick else max(60, a.trials // 4)

    mc, cov = single_image_study(n1, np.random.default_rng(1), sigma_px=0.5)
    e = mc.errors
    print(f"single image, 0.5 px, {e.shape[0]} trials")
    print(f"  rotation RMS {np.degrees(np.sqrt(np.mean(np.sum(e[:, :3]**2, 1)))):.3f} deg"
          f"  predicted {np.degrees(np.sqrt(np.trace(cov[:3, :3]))):.3f} deg")
    print(f"  translation RMS {1e3 * np.sqrt(np.mean(np.sum(e[:, 3:]**2, 1))):.1f} mm"
          f"  predicted {1e3 * np.sqrt(np.trace(cov[3:, 3:])):.1f} mm")
    print("  per component MC/predicted:", np.round(mc.ratio_to_bound, 3).tolist())

    rows = multi_placement_study((1, 4, 9), nK, np.random.default_rng(2), sigma_px=0.5)
    print(f"joint refinement, similar placements, {nK} trials each")
    print("   K  rot RMS [deg]  pred   t RMS [mm]  pred   MC/pred(t)  rms(1)/rms(K)  sqrt(K)")
    for r in rows:
        print(f"  {r.K:2d}  {r.rms_rot_deg:12.3f}  {r.pred_rot_deg:5.3f}  {r.rms_t_mm:10.1f}  {r.pred_t_mm:5.1f}"
              f"  {r.ratio_t:10.3f}  {rows[0].rms_t_mm / r.rms_t_mm:13.2f}  {np.sqrt(r.K):7.2f}")

    cam, scene = default_setup()
    obs = simulate_observations(cam, scene, np.random.default_rng(3))[0]
    n = 300
    t0 = time.perf_counter()
    for _ in range(n):
        calibrate_single(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    t_ours = (time.perf_counter() - t0) / n
    A = scene.rectangle.object_points().reshape(-1, 1, 3)
    P = ri_from_r_points(scene.body_points_r).reshape(-1, 1, 3)
    t0 = time.perf_counter()
    for _ in range(n):
        cv2.solvePnPGeneric(A, obs.marker_uv.reshape(-1, 1, 2), cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
        cv2.solvePnP(P, obs.body_uv.reshape(-1, 1, 2), cam.K, cam.dist, flags=cv2.SOLVEPNP_SQPNP)
    t_cv = (time.perf_counter() - t0) / n
    print(f"single-image calibration {t_ours * 1e3:.2f} ms; raw cv2 IPPE + SQPnP {t_cv * 1e3:.3f} ms; "
          f"ratio {t_ours / t_cv:.1f}x")


if __name__ == "__main__":
    main()
