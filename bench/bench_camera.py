"""Camera core: accuracy of render -> detect -> PnP, covariance vs Monte Carlo, and speed vs OpenCV.

Run: ``python bench/bench_camera.py [--poses 20] [--seed 1]``. Prints
the figures quoted in docs/camera.md. Speed figures are ratios to OpenCV
measured in the same run (a shared machine's absolute times vary).
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from robocal.camera import (
    CameraModel,
    Checkerboard,
    detect_checkerboard,
    pnp_covariance,
    render_planar_target,
    solve_pnp,
)
from robocal.geometry import rotation_angle, rotvec_from_matrix, transform_from_rotvec
from _timing import best_of  # bench/ is on sys.path when a script runs

CAM = CameraModel(600.0, 605.0, 321.3, 238.7, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 640, 480)
BOARD = Checkerboard(6, 7, 0.025)


def poses(n, rng):
    out = []
    while len(out) < n:
        rv = rng.normal(0.0, 0.35, 3)
        rv[2] = rng.uniform(-np.pi, np.pi)
        T = transform_from_rotvec(rv, [rng.uniform(-0.12, 0.0), rng.uniform(-0.1, 0.0), rng.uniform(0.4, 0.6)])
        if CAM.in_image(CAM.project_points(BOARD.outline(with_margin=True), T), margin=2).all():
            out.append(T)
    return out


def accuracy(n_poses, seed):
    rng = np.random.default_rng(seed)
    Ts = poses(n_poses, rng)
    print(f"render -> detect -> PnP, {n_poses} poses, board {BOARD.rows}x{BOARD.cols} x {BOARD.square * 1e3:g} mm "
          f"at 0.4-0.6 m, 640x480, f = 600 px, k1 = -0.28")
    print(f"{'condition':34s} {'corner RMS px (mean / max)':>28s} {'rot err deg max':>16s} {'t err mm max':>13s}")
    for label, blur, noise, ss, method in [
        ("clean, supersample 1", 0.0, 0.0, 1, "auto"),
        ("clean, supersample 4", 0.0, 0.0, 4, "auto"),
        ("clean, sb detector", 0.0, 0.0, 1, "sb"),
        ("clean, no refinement (classic)", 0.0, 0.0, 1, "raw"),
        ("blur 0.7 px + noise 2", 0.7, 2.0, 1, "auto"),
        ("blur 1.2 px + noise 4", 1.2, 4.0, 1, "auto"),
    ]:
        rms, rot, tra = [], [], []
        for T in Ts:
            img = render_planar_target(CAM, T, BOARD, blur_sigma=blur, noise_sigma=noise, rng=rng, supersample=ss)
            truth = CAM.project_points(BOARD.object_points(), T)
            if method == "raw":
                uv = detect_checkerboard(img, BOARD, method="classic", refine=False)
            else:
                uv = detect_checkerboard(img, BOARD, method=method)
            rms.append(np.sqrt(np.mean(np.sum((uv - truth) ** 2, axis=1))))
            sol = solve_pnp(CAM, BOARD.object_points(), uv)
            rot.append(np.degrees(rotation_angle(sol.T_cam_obj[:3, :3] @ T[:3, :3].T)))
            tra.append(1e3 * np.linalg.norm(sol.T_cam_obj[:3, 3] - T[:3, 3]))
        print(f"{label:34s} {np.mean(rms):13.4f} / {np.max(rms):.4f} {np.max(rot):16.4f} {np.max(tra):13.4f}")


def covariance(seed, trials=2000, sigma=0.3):
    rng = np.random.default_rng(seed)
    T = transform_from_rotvec([0.35, -0.25, 0.1], [-0.06, -0.04, 0.5])
    p = BOARD.object_points()
    uv0 = CAM.project_points(p, T)
    cov = pnp_covariance(CAM, p, T, sigma)
    x0 = np.concatenate([rotvec_from_matrix(T[:3, :3]), T[:3, 3]])
    xs = []
    for _ in range(trials):
        sol = solve_pnp(CAM, p, uv0 + rng.normal(0, sigma, uv0.shape))
        xs.append(np.concatenate([sol.rvec, sol.tvec]) - x0)
    ratio = np.std(xs, axis=0) / np.sqrt(np.diag(cov))
    names = ["rx", "ry", "rz", "tx", "ty", "tz"]
    print(f"\npnp_covariance vs Monte Carlo ({trials} solves, sigma {sigma} px): std ratio MC/predicted")
    print("  " + "  ".join(f"{n} {r:.3f}" for n, r in zip(names, ratio)))


def speed(seed):
    rng = np.random.default_rng(seed)
    p = np.column_stack([rng.uniform(-0.3, 0.3, (100_000, 2)), rng.uniform(0.5, 1.5, 100_000)])
    t_ours = best_of(lambda: CAM.project(p), 5)
    t_cv = best_of(lambda: cv2.projectPoints(p, np.zeros(3), np.zeros(3), CAM.K, CAM.dist), 5)
    print(f"\nproject 1e5 points: {t_ours * 1e3:.1f} ms vs cv2.projectPoints {t_cv * 1e3:.1f} ms "
          f"(ratio {t_ours / t_cv:.2f})")
    uv = CAM.project(p[:20_000])
    t_ours = best_of(lambda: CAM.undistort_points(uv), 3)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    if not hasattr(cv2, "undistortPointsIter"):  # OpenCV 5 dropped it: robocal's figure alone
        ours = CAM.undistort_points(uv)
        print(f"undistort 2e4 points (to 1e-12): {t_ours * 1e3:.1f} ms (OpenCV {cv2.__version__} has no "
              f"undistortPointsIter to compare with); round-trip error {np.abs(CAM.pixel_from_normalized(ours) - uv).max():.1e} px")
    else:
        _undistort_vs_opencv(uv, t_ours, crit)
    _render_speed()


def _undistort_vs_opencv(uv, t_ours, crit):
    t_cv = best_of(lambda: cv2.undistortPointsIter(uv.reshape(-1, 1, 2), CAM.K, CAM.dist, None, None, crit), 3)
    ref = cv2.undistortPointsIter(uv.reshape(-1, 1, 2), CAM.K, CAM.dist, None, None, crit).reshape(-1, 2)
    ours = CAM.undistort_points(uv)
    print(f"undistort 2e4 points (to 1e-12): {t_ours * 1e3:.1f} ms vs cv2.undistortPointsIter {t_cv * 1e3:.1f} ms "
          f"(ratio {t_ours / t_cv:.2f}); round-trip error ours {np.abs(CAM.pixel_from_normalized(ours) - uv).max():.1e} px, "
          f"OpenCV {np.abs(CAM.pixel_from_normalized(ref) - uv).max():.1e} px")


def _render_speed():
    T = transform_from_rotvec([0.3, -0.2, 0.4], [-0.08, -0.06, 0.5])
    render_planar_target(CAM, T, BOARD)  # warm the per-camera undistortion cache
    for ss in (1, 2, 4):
        t = best_of(lambda: render_planar_target(CAM, T, BOARD, supersample=ss), 3)
        print(f"render 640x480 board view, supersample {ss}: {t * 1e3:.0f} ms")
    img = render_planar_target(CAM, T, BOARD, blur_sigma=0.7)
    for method in ("classic", "sb"):
        t = best_of(lambda: detect_checkerboard(img, BOARD, method=method), 3)
        print(f"detect_checkerboard method={method}: {t * 1e3:.0f} ms")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    accuracy(args.poses, args.seed)
    covariance(args.seed)
    speed(args.seed)


if __name__ == "__main__":
    main()
