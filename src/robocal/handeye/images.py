"""Camera poses from images of a target, with their covariance, for AX = XB (issue 13).

Each image: the target detected (:func:`robocal.camera.detect_targets`), both planar PnP poses solved
(:func:`robocal.camera.solve_pnp_planar`, IPPE + LM), the better kept with its first-order covariance
(:func:`robocal.camera.pnp_covariance`, pixel noise = the view's own reprojection RMS, floored). Views whose
pose is ambiguous (the second IPPE pose fits nearly as well) or badly conditioned (pose std far above the
set's median) are named and down-weighted; :func:`calibrate_hand_eye` takes the per-view stds as weights
(``pose_sigmas``). Written here, not in :mod:`robocal.camera`, which other work owns this session.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.diagnostics import Diagnostic

__all__ = ["AMBIGUITY_LIMIT", "CONDITION_FACTOR", "ViewPoses", "view_poses", "view_pose", "pose_sigmas_of",
           "simulate_image_files"]

#: rms_best / rms_second of the two planar PnP poses above which a view is ambiguous (0: clear, 1: a tie)
AMBIGUITY_LIMIT = 0.5
#: a view whose pose std exceeds this many times the median is badly conditioned
CONDITION_FACTOR = 5.0
#: an ambiguous view's stds are multiplied by this (its weight by its inverse square)
AMBIGUOUS_INFLATION = 10.0
#: floor of the pixel noise (px): a rendered or very clean view's RMS can be far below a detector's real noise
MIN_SIGMA_PX = 0.05


@dataclass
class ViewPoses:
    """``T_cam_target`` per usable image with its covariance and quality.

    ``index``: the image's position in the input (the robot pose it pairs with); ``cov`` (N, 6, 6) over
    (OpenCV rotation vector [rad], translation [m]); ``sigmas`` (N, 2): rotation [rad] and translation [m]
    std used as weights (ambiguous views inflated); ``ambiguity`` rms_best / rms_second.
    """

    names: list
    index: np.ndarray
    T_cam_target: np.ndarray
    cov: np.ndarray
    rms_px: np.ndarray
    ambiguity: np.ndarray
    sigmas: np.ndarray
    missing: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


def view_poses(images, camera, target, *, names=None) -> ViewPoses:
    """Camera poses of ``target`` in ``images`` (paths or arrays), see the module docstring."""
    from robocal.camera import detect_targets
    from robocal.errors import DegenerateGeometryError, NotEnoughDataError

    images = list(images)
    names = [str(Path(i).name) if isinstance(i, (str, Path)) else f"image {k}" for k, i in enumerate(images)] \
        if names is None else [str(n) for n in names]
    dets = detect_targets(images, target, names=names)
    pos = {n: k for k, n in enumerate(names)}
    rows = []
    missing = dict(dets.rejected)
    for d in dets.views:
        try:
            T, cov, rms, amb = view_pose(camera, d.object_points, d.image_points)
        except DegenerateGeometryError as exc:
            missing[d.name] = f"pose not determined ({exc.message})"
            continue
        rows.append((d.name, pos[d.name], T, cov, rms, amb))
    if len(rows) < 3:
        raise NotEnoughDataError(f"the target's pose was found in {len(rows)} of {len(images)} images; hand-eye "
                                 "calibration needs at least 3")
    nm, idx, T, C, rms, amb = (list(x) for x in zip(*rows))
    C = np.array(C)
    amb = np.array(amb, float)
    sig = np.column_stack([np.sqrt(np.trace(C[:, :3, :3], axis1=1, axis2=2) / 3),
                           np.sqrt(np.trace(C[:, 3:, 3:], axis1=1, axis2=2) / 3)])
    warns = []
    ambiguous = np.flatnonzero(amb > AMBIGUITY_LIMIT)
    if ambiguous.size:
        sig[ambiguous] *= AMBIGUOUS_INFLATION
        warns.append(Diagnostic(
            "ambiguous_views", f"{', '.join(nm[k] for k in ambiguous)}: the two planar poses of the target fit "
            f"nearly alike (rms ratio > {AMBIGUITY_LIMIT:g}): down-weighted {AMBIGUOUS_INFLATION ** 2:g} x",
            indices=tuple(int(idx[k]) for k in ambiguous)))
    med = np.median(sig, axis=0)
    weak = np.flatnonzero(np.any(sig > CONDITION_FACTOR * med, axis=1) & ~np.isin(np.arange(len(nm)), ambiguous))
    if weak.size:
        warns.append(Diagnostic(
            "badly_conditioned_views", f"{', '.join(nm[k] for k in weak)}: pose std > {CONDITION_FACTOR:g} x the "
            "median (few corners, far or oblique target): down-weighted by its covariance",
            indices=tuple(int(idx[k]) for k in weak)))
    if missing:
        warns.append(Diagnostic("dropped_views", f"{len(missing)} image(s) without a usable target pose: "
                                + "; ".join(f"{k}: {v}" for k, v in list(missing.items())[:6]),
                                indices=tuple(pos[k] for k in missing if k in pos)))
    return ViewPoses(nm, np.array(idx), np.array(T), C, np.array(rms), amb, sig, missing, warns)


def view_pose(camera, object_points, image_points):
    """One view's target pose from its corners: ``(T_cam_target, cov (6, 6), rms_px, ambiguity)``.

    Both planar PnP poses (IPPE + LM), the better kept; its first-order covariance with the pixel noise
    = the view's reprojection RMS corrected for the 6 pose parameters, floored at :data:`MIN_SIGMA_PX`;
    ``ambiguity`` rms_best / rms_second (0 when both refine into one pose). Raises
    :class:`~robocal.errors.DegenerateGeometryError` when the pose is not determined.
    """
    from robocal.camera import pnp_covariance, solve_pnp_planar

    cand = solve_pnp_planar(camera, object_points, image_points)
    best = cand.best
    n = len(object_points)
    sigma = max(best.rms_px * np.sqrt(2 * n / max(2 * n - 6, 1)), MIN_SIGMA_PX)
    cov = pnp_covariance(camera, object_points, best.T_cam_obj, sigma)
    amb = cand.ambiguity
    if len(cand) > 1:
        # both IPPE poses refined into the same one: nothing to choose between
        R2 = cand[1].T_cam_obj[:3, :3] @ best.T_cam_obj[:3, :3].T
        if np.arccos(np.clip((np.trace(R2) - 1) / 2, -1, 1)) < np.deg2rad(1.0):
            amb = 0.0
    return best.T_cam_obj, cov, best.rms_px, amb


def pose_sigmas_of(view: ViewPoses) -> np.ndarray:
    """The (N, 2) rotation [rad] / translation [m] stds :func:`~robocal.handeye.calibrate_hand_eye` takes."""
    return view.sigmas


def simulate_image_files(out_dir, rng: np.random.Generator, *, poses: int = 8,
                         setup: str = "eye-in-hand") -> list:
    """Rendered views of a 7 x 5 chessboard (20 mm squares) with the robot poses that go with them.

    ``out_dir/images/view_NN.png`` (640 x 480, :func:`robocal.camera.render_target_view`, 1 grey level of
    noise), ``robot_poses.csv`` (``T_base_gripper``, one per image in name order), ``camera.yaml``
    (OpenCV), ``target.yaml`` and ``truth.yaml``. The camera-target geometry is that of
    :func:`~robocal.handeye.simulate_eye_in_hand` (0.30-0.45 m, tilted up to 35 deg), centred on the board.
    """
    import cv2

    from robocal.camera import CameraModel, ChessboardTarget, render_target_view, write_camera
    from robocal.geometry import transform_from
    from robocal.handeye import SETUPS
    from robocal.handeye.simulate import simulate_eye_in_hand, simulate_eye_to_hand
    from robocal.io import atomic_write_text, write_poses

    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    cam = CameraModel(fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640, height=480)
    board = ChessboardTarget(5, 7, 0.020)
    sim = (simulate_eye_in_hand if setup == "eye-in-hand" else simulate_eye_to_hand)(rng, poses, noise=False)
    # the views look at the target frame's origin; put it at the board's centre
    centre = transform_from(np.eye(3), [-0.5 * 0.020 * (board.cols - 1), -0.5 * 0.020 * (board.rows - 1), 0.0])
    T_cam_board = sim.T_cam_target @ centre
    paths = []
    for k, T in enumerate(T_cam_board):
        img = render_target_view(cam, board, T, rng, noise_sigma=1.0)
        p = out / "images" / f"view_{k:02d}.png"
        cv2.imwrite(str(p), img)
        paths.append(p)
    paths.append(write_poses(out / "robot_poses.csv", sim.T_base_gripper))
    paths.append(write_camera(out / "camera.yaml", cam))
    paths.append(atomic_write_text(out / "target.yaml", "type: chessboard\nrows: 5\ncols: 7\n"
                                                        "square: {value: 20, unit: mm}\n"))
    Y = sim.Y @ centre                          # the board frame is the target's moved to the first corner
    xn, yn = SETUPS[setup]["X"][0], SETUPS[setup]["Y"][0]

    def pose(T):
        return "{rotation: %s, translation: %s}" % (np.round(T[:3, :3], 12).tolist(), np.round(T[:3, 3], 12).tolist())
    # the target pose is written in the renderer's board frame; the detector numbers the corners from
    # another corner of this symmetric board (its frame turned 180 deg about the board's y), so only X is
    # comparable as it stands
    paths.append(atomic_write_text(out / "truth.yaml", (
        "# ground truth of the rendered views (m). X is comparable; the target pose is in the renderer's board\n"
        "# frame, which the chessboard detector may number from another corner (a board symmetry)\n"
        f"setup: {setup}\n{xn}: {pose(sim.X)}\n{yn}_rendered_board: {pose(Y)}\n")))
    return [Path(p) for p in paths]
