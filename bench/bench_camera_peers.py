"""Camera intrinsics from rendered images vs peers: robocal, cv2.calibrateCamera, OpenCV's recipe, mrcal.

    python bench/bench_camera_peers.py [--datasets 8] [--views 20] [--size 640x480] [--charuco-datasets 2]
                                       [--speed-views 30] [--seed 2026] [--mrcal-python /tmp/mrcalvenv/bin/python]

Every data set: ``--views`` images of a 9x6 inner-corner chessboard (25 mm
squares, whole board in view, 0.3-0.65 m, tilted up to ~35 deg) rendered by
``render_target_view`` with blur 0.7 px and noise 2 grey levels, seen by a
camera with barrel distortion (f = 600 px at 640x480, scaled with
``--size``); the truth is the renderer's camera and ``visible_target_points``.
Per method, over the data sets: RMSE of fx, fy, cx, cy; the projection error
to the true camera over the whole image (RMS of |pi_est(pi_true^-1(q)) - q|
on a 20 px grid, as is and after the camera rotation that best aligns the
rays, which is what mrcal's uncertainty describes); the predicted projection
std (RMS over the grid of sqrt(trace Cov(q)); robocal's as "camera frame held
fixed / with the compensating rotation", its default); the RMS reprojection error
(OpenCV's definition, sqrt(sum |r|^2 / corners)); the corner error of the
detector vs the truth; CPU time of detection and solve. Methods:

(a) robocal: ``detect_targets`` + ``calibrate_intrinsics`` (opencv5 model).
(b) ``cv2.calibrateCamera`` on robocal's corners (the difference to (a) in
    (a)'s reported stds says whether it is below the noise).
(c) OpenCV's tutorial recipe on the same images: ``findChessboardCorners`` +
    ``cornerSubPix`` (11x11, criteria EPS + MAX_ITER 30, 0.001) +
    ``calibrateCamera``; views where it finds no board are left out (counted).
(d) mrcal (``mrcal.optimize``, LENSMODEL_OPENCV5, flat board, its default
    outlier rejection and regularisation, seeded from (b)) on robocal's
    corners, and ``mrcal.projection_uncertainty`` (at infinity); (d') the
    same without the regularisation (the plain least squares robocal and
    OpenCV solve, so (d') = (a) up to outliers shows the three solvers agree). mrcal runs in
    its own interpreter (``--mrcal-python``; it is never a robocal
    dependency); without it the row says why. mrcal's wheels are built for
    CPython >= 3.12: ``python3.12 -m venv /tmp/mrcalvenv && /tmp/mrcalvenv/bin/pip
    install --no-deps mrcal && /tmp/mrcalvenv/bin/pip install numpy numpysane
    scipy shapely pyyaml`` (its GUI dependency pyfltk needs FLTK's headers and is
    not needed here).

A ChArUco board (7x10 squares of 25 mm, 18 mm markers, DICT_5X5_100; partial views count) is a
second, smaller table (``--charuco-datasets``; its texture is rendered at 4x
supersampling, ~0.5 s a view). Last, the speed goal of issue 12: detection
+ solve of ``--speed-views`` views of the 9x6 board at 640x480 and 1280x960,
CPU time (median of 3), with the one-time import of the estimation layer
(SciPy's optimize) measured apart.

Timing: BLAS and OpenCV on one thread, the process pinned to one core, CPU
time (``time.process_time``); the machine is shared, so wall time would
measure the neighbours. Ratios to cv2 are measured in the same run.
"""

from __future__ import annotations

import os
import sys

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

DEFAULT_MRCAL_PYTHON = os.environ.get("ROBOCAL_MRCAL_PYTHON", "/tmp/mrcalvenv/bin/python")


# -- mrcal, in its own interpreter (imports numpy and mrcal only) ----------------------------------------


def mrcal_worker(inp: str, out: str) -> None:
    """Solve every data set of ``inp`` (npz) with mrcal; write intrinsics, rms, uncertainty and CPU time."""
    import mrcal

    d = np.load(inp)
    res = {}
    for k in range(int(d["n"])):
        for reg in (True, False):
            obs = d[f"obs{k}"].copy()  # (views, H, W, 3): x, y, weight (-1: not seen)
            nv = obs.shape[0]
            idx = np.column_stack([np.arange(nv), np.zeros(nv), -np.ones(nv)]).astype(np.int32)
            inputs = dict(
                intrinsics=d[f"intr{k}"].copy()[None], rt_cam_ref=np.zeros((0, 6)),
                rt_ref_frame=d[f"frames{k}"].copy(), points=None, observations_board=obs,
                indices_frame_camintrinsics_camextrinsics=idx, observations_point=None,
                indices_point_camintrinsics_camextrinsics=None, lensmodel="LENSMODEL_OPENCV5",
                imagersizes=d["size"].astype(np.int32)[None], calobject_warp=None,
                do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=True,
                do_optimize_extrinsics=False, do_optimize_frames=True, do_optimize_calobject_warp=False,
                calibration_object_spacing=float(d["spacing"]), do_apply_outlier_rejection=True,
                do_apply_regularization=reg, verbose=False,
            )
            t0 = time.process_time()
            stats = mrcal.optimize(**inputs)
            t_solve = time.process_time() - t0
            model = mrcal.cameramodel(optimization_inputs=inputs, icam_intrinsics=0)
            t0 = time.process_time()
            p = mrcal.unproject(d["grid"], *model.intrinsics(), normalize=True)
            cov = mrcal.projection_uncertainty(p, model=model, atinfinity=True, what="covariance")
            t_unc = time.process_time() - t0
            tag = f"{k}" if reg else f"{k}_noreg"
            res[f"intr{tag}"] = inputs["intrinsics"][0]
            res[f"cov{tag}"] = cov
            res[f"rms{tag}"] = float(stats["rms_reproj_error__pixels"])
            res[f"outliers{tag}"] = int(np.sum((inputs["observations_board"][..., 2] < 0) & (obs[..., 2] >= 0)))
            res[f"t{tag}"] = np.array([t_solve, t_unc])
    from importlib.metadata import version

    np.savez(out, version=np.array(version("mrcal")), **res)


def run_mrcal(python: str, jobs: list, size, spacing: float, grid: np.ndarray):
    """mrcal on every job ``(obs, intr0, frames0)``; returns ``(results or None, reason)``."""
    if not Path(python).exists():
        return None, f"no interpreter with mrcal at {python} (see the module doc to make one)"
    with tempfile.TemporaryDirectory() as tmp:
        inp, out = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        arrays = {"n": len(jobs), "size": np.asarray(size), "spacing": spacing, "grid": grid}
        for k, (obs, intr, frames) in enumerate(jobs):
            arrays.update({f"obs{k}": obs, f"intr{k}": intr, f"frames{k}": frames})
        np.savez(inp, **arrays)
        r = subprocess.run([python, __file__, "--mrcal-worker", str(inp), str(out)], capture_output=True, text=True,
                           env={**os.environ, "PYTHONPATH": ""})
        if r.returncode != 0:
            lines = (r.stderr or r.stdout).strip().splitlines() or ["(no output)"]
            return None, f"mrcal failed: {lines[-1]}"
        d = np.load(out)
        return {k: d[k] for k in d.files}, f"mrcal {d['version']}"


# -- the data -----------------------------------------------------------------------------------------


def camera(size):
    from robocal.camera import CameraModel

    s = size[0] / 640.0
    return CameraModel(600.0 * s, 605.0 * s, 321.3 * s, 238.7 * s, (-0.28, 0.11, 8e-4, -6e-4, -0.02), size[0], size[1])


def board_poses(cam, target, n, rng, *, whole=True, distance=(0.3, 0.65)):
    """``n`` poses T_cam_board: centre on the ray of a pixel in the middle 70 % of the image, tilted up to ~35 deg.

    ``whole``: the board with its quiet zone inside the image (a chessboard is only detected whole);
    otherwise at least a third of the points in view (ChArUco partial views).
    """
    from scipy.spatial.transform import Rotation

    from robocal.camera import visible_target_points

    out = []
    obj = target.object_points()
    while len(out) < n:
        pix = rng.uniform([0.15 * cam.width, 0.15 * cam.height], [0.85 * cam.width, 0.85 * cam.height])
        ray = np.append(cam.undistort_points(pix), 1.0)
        c = ray / np.linalg.norm(ray) * rng.uniform(*distance)
        R = Rotation.from_rotvec(rng.uniform(-1, 1, 3) * np.array([0.6, 0.6, 0.4])).as_matrix()
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = c - R @ obj.mean(axis=0)
        if whole:
            edge = target.board.outline(with_margin=True)
            ok = cam.in_image(cam.project_points(edge, T, check=False), margin=3).all()
        else:
            ok = len(visible_target_points(cam, target, T, margin=5)[0]) >= obj.shape[0] // 3
        if ok:
            out.append(T)
    return out


def render(cam, target, poses, rng):
    from robocal.camera import render_target_view

    return [render_target_view(cam, target, T, rng, blur_sigma=0.7, noise_sigma=2.0) for T in poses]


# -- metrics --------------------------------------------------------------------------------------------


class Grid:
    """Pixels on a 20 px grid over the image and their true rays (the grid of ``projection_uncertainty``)."""

    STEP = 20.0

    def __init__(self, cam):
        u, v = np.arange(0.0, cam.width - 0.5, self.STEP), np.arange(0.0, cam.height - 0.5, self.STEP)
        q = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
        xy = cam.undistort_points(q)
        ok = np.isfinite(xy).all(axis=1)
        self.cam, self.q = cam, q[ok]
        r = np.column_stack([xy[ok], np.ones(int(ok.sum()))])
        self.rays = r / np.linalg.norm(r, axis=1, keepdims=True)

    def errors(self, est):
        """|pi_est(true ray) - q| [px] per grid pixel, as is and after the best-aligning rotation of the camera."""
        from scipy.spatial.transform import Rotation

        plain = np.linalg.norm(est.project(self.rays, check=False) - self.q, axis=1)
        xy = est.undistort_points(self.q)
        ok = np.isfinite(xy).all(axis=1)
        r = np.column_stack([xy[ok], np.ones(int(ok.sum()))])
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        R, _ = Rotation.align_vectors(self.rays[ok], r)  # R r_est ~ r_true
        aligned = np.full(len(self.q), np.nan)
        aligned[ok] = np.linalg.norm(self.cam.project(R.apply(r), check=False) - self.q[ok], axis=1)
        return plain, aligned


def cam_from(K, dist, size):
    from robocal.camera import CameraModel

    d = np.zeros(5)
    dist = np.ravel(dist)
    d[:min(5, dist.size)] = dist[:5]
    return CameraModel(K[0, 0], K[1, 1], K[0, 2], K[1, 2], d, size[0], size[1])


def corner_errors(cam, target, T, ids, uv):
    """Detected minus true [px] per point (matched by id)."""
    from robocal.camera import visible_target_points

    tids, tuv = visible_target_points(cam, target, T)
    truth = dict(zip(tids.tolist(), tuv))
    return np.array([p - truth[i] for i, p in zip(np.asarray(ids).tolist(), uv) if i in truth])


def nearest_errors(cam, target, T, uv):
    """Detected minus the nearest true point [px] (OpenCV's corner order is its own)."""
    from robocal.camera import visible_target_points

    _, tuv = visible_target_points(cam, target, T)
    d = np.linalg.norm(uv[:, None] - tuv[None], axis=-1)
    return uv - tuv[np.argmin(d, axis=1)]


def rms(x):
    """RMS of the values of ``x`` (NaN left out)."""
    return float(np.sqrt(np.nanmean(np.square(x))))


def rms_norm(e):
    """RMS length of the rows of ``e`` (N, 2) [px]: OpenCV's definition of a reprojection RMS."""
    return float(np.sqrt(np.mean(np.sum(np.square(e), axis=1))))


class Method:
    def __init__(self, name):
        self.name = name
        self.err, self.plain, self.aligned, self.pred, self.reproj = [], [], [], [], []
        self.pred_aligned = []  # robocal: its map with the compensating rotation (compare with "after rotation")
        self.corner, self.t_det, self.t_solve, self.views = [], [], [], []
        self.note = ""

    def add(self, grid, est_cam, reproj, t_solve, *, pred_cov=None, pred_cov_aligned=None):
        self.err.append(np.array([est_cam.fx, est_cam.fy, est_cam.cx, est_cam.cy])
                        - [grid.cam.fx, grid.cam.fy, grid.cam.cx, grid.cam.cy])
        p, a = grid.errors(est_cam)
        self.plain.append(p)
        self.aligned.append(a)
        self.reproj.append(reproj)
        self.t_solve.append(t_solve)
        if pred_cov is not None:
            self.pred.append(rms(np.sqrt(np.trace(pred_cov, axis1=-2, axis2=-1))))
        if pred_cov_aligned is not None:
            self.pred_aligned.append(rms(np.sqrt(np.trace(pred_cov_aligned, axis1=-2, axis2=-1))))

    def row(self, n_views):
        if not self.err:
            return f"| {self.name} | " + " | ".join(["-"] * 12) + f" | {self.note} |"
        e = np.array(self.err)
        rm = np.sqrt(np.mean(e ** 2, axis=0))
        corner = f"{rms_norm(np.concatenate(self.corner)):.4f}" if self.corner else "(robocal's)"
        det = f"{np.median(self.t_det) * 1e3 / n_views:.1f}" if self.t_det else "-"
        pred = f"{rms(self.pred):.3f}" if self.pred else "-"
        if self.pred_aligned:
            pred += f" / {rms(self.pred_aligned):.3f}"
        views = f"{np.mean(self.views):.1f}" if self.views else f"{n_views}"
        return (f"| {self.name} | {rm[0]:.3f} | {rm[1]:.3f} | {rm[2]:.3f} | {rm[3]:.3f} | "
                f"{rms(np.concatenate(self.plain)):.3f} | {rms(np.concatenate(self.aligned)):.3f} | {pred} | "
                f"{np.mean(self.reproj):.4f} | {corner} | {views} | {det} | "
                f"{np.median(self.t_solve) * 1e3:.0f} |" + (f" {self.note} |" if self.note else " |"))


HEADER = ("| method | fx RMSE px | fy RMSE px | cx RMSE px | cy RMSE px | proj. err RMS px | after rotation px | "
          "predicted px | reproj. RMS px | corner err RMS px | views used | detect ms/view | solve ms | note |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")


# -- the peers ------------------------------------------------------------------------------------------


def mrcal_rows(args, jobs, size, spacing, grid):
    """Rows (d): mrcal with its default regularisation and without, on the jobs' corners."""
    rows = [Method("(d) mrcal, robocal's corners"), Method("(d') mrcal without regularisation")]
    res, why = run_mrcal(args.mrcal_python, jobs, size, spacing, grid.q)
    for m, suffix in zip(rows, ("", "_noreg")):
        if res is None:
            m.note = f"not run: {why}"
            continue
        m.t_unc = []
        n_out = 0
        for k in range(len(jobs)):
            intr = res[f"intr{k}{suffix}"]
            K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1]])
            m.add(grid, cam_from(K, intr[4:], size), float(res[f"rms{k}{suffix}"]) * np.sqrt(2),
                  float(res[f"t{k}{suffix}"][0]), pred_cov=res[f"cov{k}{suffix}"])
            m.t_unc.append(float(res[f"t{k}{suffix}"][1]))
            n_out += int(res[f"outliers{k}{suffix}"])
        m.note = f"{why}; {n_out} corners rejected as outliers"
    return rows


def summary(rob, same, recipe, mr, mr0, diff_std):
    """The ratios measured in this run: robocal's errors and CPU time over each peer's, predicted vs observed."""
    d = np.array(diff_std)
    print(f"\n(b) - (a): max {np.nanmax(d):.2g}, median {np.nanmedian(d):.2g} of robocal's reported std (9 "
          "intrinsics, all data sets; robocal's outlier removal is the difference where it removed corners)")

    def fx(m):
        return np.sqrt(np.mean(np.array(m.err)[:, 0] ** 2))

    def plain(m):
        return rms(np.concatenate(m.plain))

    def aligned(m):
        return rms(np.concatenate(m.aligned))

    print("robocal's error / peer's: fx RMSE, projection error RMS, after rotation")
    for m in (same, recipe, mr, mr0):
        if m.err:
            print(f"  vs {m.name}: {fx(rob) / fx(m):.2f}, {plain(rob) / plain(m):.2f}, {aligned(rob) / aligned(m):.2f}")
    print(f"observed / predicted projection error: robocal {plain(rob) / rms(rob.pred):.2f} as is (its map with "
          f"the camera frame held fixed), {aligned(rob) / rms(rob.pred_aligned):.2f} after rotation (its default "
          "map, with the compensating rotation)", end="")
    for m in (mr, mr0):
        if m.err:
            print(f"; {m.name} {aligned(m) / rms(m.pred):.2f} (after rotation, as mrcal's "
                  f"uncertainty; mrcal.projection_uncertainty {np.median(m.t_unc) * 1e3:.0f} ms CPU)", end="")
    ratio_solve = np.median(rob.t_solve) / np.median(same.t_solve)
    print(f"\nCPU: robocal's solve / cv2.calibrateCamera's on the same corners {ratio_solve:.1f}x"
          f"; robocal's detection / the OpenCV recipe's {np.median(rob.t_det) / np.median(recipe.t_det):.2f}x\n")


def robocal_and_same_corners(cam, target, poses, imgs, size, grid, rob, same, diff_std):
    """(a) robocal's detection + calibration and (b) cv2.calibrateCamera on its corners, recorded into ``rob``,
    ``same`` and ``diff_std``; returns the views, robocal's calibration and cv2's ``(K, dist, rvecs, tvecs)``."""
    import cv2

    from robocal.camera import calibrate_intrinsics, detect_targets, projection_uncertainty

    t0 = time.process_time()
    ds = detect_targets(imgs, target)
    t1 = time.process_time()
    views = ds.target_views()
    cal = calibrate_intrinsics(views, size)
    t2 = time.process_time()
    rob.t_det.append(t1 - t0)
    rob.views.append(len(views))
    rob.corner.append(np.concatenate([corner_errors(cam, target, poses[int(d.name.split()[-1])], d.ids,
                                                    d.image_points) for d in ds.views]))
    pu = projection_uncertainty(cal, grid_step_px=Grid.STEP, compensate_rotation=False)
    pa = projection_uncertainty(cal, grid_step_px=Grid.STEP)
    rob.add(grid, cal.camera, cal.rms * np.sqrt(2), t2 - t1, pred_cov=pu.cov[np.isfinite(pu.std)],
            pred_cov_aligned=pa.cov[np.isfinite(pa.std)])
    obj = [v.object_points.astype(np.float32) for v in views]
    img = [v.image_points.astype(np.float32) for v in views]
    t0 = time.process_time()
    r_cv, K, dist, rv, tv = cv2.calibrateCamera(obj, img, size, None, None)
    same.add(grid, cam_from(K, dist, size), r_cv, time.process_time() - t0)
    diff_std.append(np.abs(cal.values - np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.ravel(dist)[:5]])
                    / cal.std_array)
    return views, cal, (K, dist, rv, tv)


def chessboard_datasets(args, size):
    import cv2

    from robocal.camera import ChessboardTarget

    cam = camera(size)
    target = ChessboardTarget(6, 9, 0.025)
    grid = Grid(cam)
    rob, same, recipe = Method("(a) robocal"), Method("(b) cv2.calibrateCamera, robocal's corners"), \
        Method("(c) OpenCV recipe (findChessboardCorners + cornerSubPix 11x11)")
    diff_std, jobs, t_render, n_out = [], [], 0.0, 0
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    objp = np.zeros((6 * 9, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * target.square
    for k in range(args.datasets):
        rng = np.random.default_rng([args.seed, k])
        poses = board_poses(cam, target, args.views, rng)
        t0 = time.perf_counter()
        imgs = render(cam, target, poses, rng)
        t_render += time.perf_counter() - t0
        # (a) and (b)
        views, cal, (K, dist, rv, tv) = robocal_and_same_corners(cam, target, poses, imgs, size, grid, rob, same,
                                                                 diff_std)
        n_out += len(cal.outliers)
        # (d)'s input: robocal's corners on mrcal's grid, seeded from (b)
        obs = np.zeros((len(views), 6, 9, 3))
        obs[..., 2] = -1.0
        for i, v in enumerate(views):
            obs.reshape(len(views), -1, 3)[i, v.ids, :2] = v.image_points
            obs.reshape(len(views), -1, 3)[i, v.ids, 2] = 1.0
        jobs.append((obs, np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.ravel(dist)[:5]],
                     np.column_stack([np.reshape(rv, (-1, 3)), np.reshape(tv, (-1, 3))])))
        # (c)
        t0 = time.process_time()
        found = []
        for i, im in enumerate(imgs):
            ok, c = cv2.findChessboardCorners(im, (9, 6), None)
            if ok:
                found.append((i, cv2.cornerSubPix(im, c, (11, 11), (-1, -1), crit)))
        t1 = time.process_time()
        recipe.t_det.append(t1 - t0)
        recipe.views.append(len(found))
        recipe.corner.append(np.concatenate([nearest_errors(cam, target, poses[i], c.reshape(-1, 2))
                                             for i, c in found]))
        t0 = time.process_time()
        r_cv, K, dist, _, _ = cv2.calibrateCamera([objp] * len(found), [c for _, c in found], size, None, None)
        recipe.add(grid, cam_from(K, dist, size), r_cv, time.process_time() - t0)
    mr, mr0 = mrcal_rows(args, jobs, size, target.square, grid)
    rob.note = f"{n_out} corners removed as outliers"
    print(f"### 9x6 chessboard, {size[0]}x{size[1]}, {args.datasets} data sets x {args.views} views "
          f"(render {t_render:.0f} s wall)\n")
    print(HEADER)
    for m in (rob, same, recipe, mr, mr0):
        print(m.row(args.views))
    summary(rob, same, recipe, mr, mr0, diff_std)


def charuco_datasets(args, size):
    import cv2

    from robocal.camera import CharucoTarget

    if args.charuco_datasets <= 0:
        return
    cam = camera(size)
    target = CharucoTarget(7, 10, 0.025, 0.018, "DICT_5X5_100")
    grid = Grid(cam)
    rob, same, recipe = Method("(a) robocal"), Method("(b) cv2.calibrateCamera, robocal's corners"), \
        Method("(c) OpenCV recipe (CharucoDetector + calibrateCamera)")
    diff_std, jobs, t_render, n_out = [], [], 0.0, 0
    nr, nc = target.rows - 1, target.cols - 1
    for k in range(args.charuco_datasets):
        rng = np.random.default_rng([args.seed, 1000 + k])
        poses = board_poses(cam, target, args.views, rng, whole=False)
        t0 = time.perf_counter()
        imgs = render(cam, target, poses, rng)
        t_render += time.perf_counter() - t0
        views, cal, (K, dist, rv, tv) = robocal_and_same_corners(cam, target, poses, imgs, size, grid, rob, same,
                                                                 diff_std)
        n_out += len(cal.outliers)
        obs = np.zeros((len(views), nr, nc, 3))
        obs[..., 2] = -1.0
        frames = []
        for i, v in enumerate(views):
            obs.reshape(len(views), -1, 3)[i, v.ids, :2] = v.image_points
            obs.reshape(len(views), -1, 3)[i, v.ids, 2] = 1.0
            # mrcal's board origin is corner 0, at (square, square) in robocal's (OpenCV's) board frame
            R = cv2.Rodrigues(np.asarray(rv[i], float))[0]
            frames.append(np.r_[np.ravel(rv[i]), np.ravel(tv[i]) + R @ [target.square, target.square, 0.0]])
        jobs.append((obs, np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.ravel(dist)[:5]], np.array(frames)))
        # (c) OpenCV's own ChArUco pipeline (default parameters)
        det = cv2.aruco.CharucoDetector(target.cv_board)
        t0 = time.process_time()
        found = []
        for i, im in enumerate(imgs):
            c, ids, _, _ = det.detectBoard(im)
            if ids is not None and len(ids) >= 6:
                found.append((i, c.reshape(-1, 2), ids.reshape(-1)))
        t1 = time.process_time()
        recipe.t_det.append(t1 - t0)
        recipe.views.append(len(found))
        recipe.corner.append(np.concatenate([corner_errors(cam, target, poses[i], ids, c) for i, c, ids in found]))
        objs, imps = [], []
        for _, c, ids in found:
            o, p = target.cv_board.matchImagePoints(c.reshape(-1, 1, 2), ids.reshape(-1, 1))
            objs.append(o), imps.append(p)
        t0 = time.process_time()
        r_cv, K, dist, _, _ = cv2.calibrateCamera(objs, imps, size, None, None)
        recipe.add(grid, cam_from(K, dist, size), r_cv, time.process_time() - t0)
    mr, mr0 = mrcal_rows(args, jobs, size, target.square, grid)
    rob.note = f"{n_out} corners removed as outliers"
    print(f"### ChArUco 7x10 squares (6x9 corners), {size[0]}x{size[1]}, {args.charuco_datasets} data sets x "
          f"{args.views} views, partial views (render {t_render:.0f} s wall)\n")
    print(HEADER)
    for m in (rob, same, recipe, mr, mr0):
        print(m.row(args.views))
    summary(rob, same, recipe, mr, mr0, diff_std)


# -- the speed goal -------------------------------------------------------------------------------------


def speed(args, t_import):
    from robocal.camera import ChessboardTarget, calibrate_intrinsics, detect_targets

    target = ChessboardTarget(6, 9, 0.025)
    print(f"### Speed goal: detection + solve of {args.speed_views} views of a 9x6 board, one core, CPU time "
          "(median of 3)\n")
    print("| image | detect s | solve s | total s | corner err RMS px | goal < 2 s |")
    print("|---|---|---|---|---|---|")
    for size in ((640, 480), (1280, 960)):
        cam = camera(size)
        rng = np.random.default_rng([args.seed, 99])
        poses = board_poses(cam, target, args.speed_views, rng)
        imgs = render(cam, target, poses, rng)
        t = []
        for _ in range(3):
            t0 = time.process_time()
            ds = detect_targets(imgs, target)
            t1 = time.process_time()
            calibrate_intrinsics(ds.target_views(), size)
            t.append((t1 - t0, time.process_time() - t1))
        td, ts = np.median(t, axis=0)
        e = np.concatenate([corner_errors(cam, target, poses[int(d.name.split()[-1])], d.ids, d.image_points)
                            for d in ds.views])
        print(f"| {size[0]}x{size[1]} | {td:.2f} | {ts:.2f} | {td + ts:.2f} | {rms_norm(e):.4f} | "
              f"{'yes' if td + ts < 2 else 'no'} |")
    print(f"\nonce per process: importing the estimation layer (SciPy's optimize) {t_import:.2f} s CPU")


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--mrcal-worker":
        mrcal_worker(sys.argv[2], sys.argv[3])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", type=int, default=8, help="chessboard data sets (the Monte Carlo trials)")
    ap.add_argument("--views", type=int, default=20, help="views per data set")
    ap.add_argument("--size", default="640x480", help="image size of the peer tables, WxH")
    ap.add_argument("--charuco-datasets", type=int, default=2, help="ChArUco data sets (0: skip)")
    ap.add_argument("--speed-views", type=int, default=30)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--mrcal-python", default=DEFAULT_MRCAL_PYTHON, help="an interpreter that imports mrcal")
    ap.add_argument("--skip-speed", action="store_true")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, as `taskset -c N`
    t0 = time.process_time()
    import robocal.estimation  # noqa: F401  (its one-time cost, measured apart from the solves)

    t_import = time.process_time() - t0
    import cv2

    cv2.setNumThreads(1)
    size = tuple(int(s) for s in args.size.lower().split("x"))
    print(f"OpenCV {cv2.__version__}, NumPy {np.__version__}, Python {sys.version.split()[0]}, "
          f"seed {args.seed}; blur 0.7 px, noise 2 grey levels\n")
    chessboard_datasets(args, size)
    charuco_datasets(args, size)
    if not args.skip_speed:
        speed(args, t_import)


if __name__ == "__main__":
    main()
