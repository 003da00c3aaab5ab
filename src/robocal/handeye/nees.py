"""Is X's reported covariance honest when the camera poses come from images? The NEES Monte Carlo (issue 13).

Each trial: the views of :func:`~robocal.handeye.simulate_eye_in_hand` (or eye-to-hand) of the 7 x 5
chessboard of :func:`~robocal.handeye.images.simulate_image_files` (20 mm squares, a 600 px camera at
640 x 480), its corners projected and perturbed by Gaussian pixel noise, each view's pose and covariance
solved as for images (:func:`~robocal.handeye.images.view_pose`: planar PnP, first-order covariance from
the view's own RMS), X calibrated with the per-view stds as weights
(:func:`~robocal.handeye.calibrate_hand_eye`, ``pose_sigmas``), and its error against the truth scored
by the normalised estimation error squared ``NEES = e^T C^-1 e`` (6 dof; Bar-Shalom, Li, Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, sec. 5.4.2). Honest covariances give a
mean NEES / 6 near 1; the refinement estimates the noise scale from ``6 N - 12`` residuals, which raises
it to ``nu / (nu - 2)`` (an F distribution; 8 views: 36 dof, 1.06).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["NeesStudy", "image_noise_trial", "nees_image_noise"]


@dataclass(frozen=True)
class NeesStudy:
    """Per trial: ``nees`` (6 dof), ``errors`` (n, 6) of X (rad x3, m x3, left side) and its reported ``std``
    (n, 6); ``n_views``, ``sigma_px``. ``mean`` = mean NEES / 6 and ``se`` its standard error."""

    nees: np.ndarray
    errors: np.ndarray
    std: np.ndarray
    n_views: int
    sigma_px: float

    @property
    def mean(self) -> float:
        return float(np.mean(self.nees) / 6)

    @property
    def se(self) -> float:
        return float(np.std(self.nees, ddof=1) / 6 / np.sqrt(len(self.nees)))


def _board():
    from robocal.camera import CameraModel, ChessboardTarget
    from robocal.geometry import transform_from

    cam = CameraModel(fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640, height=480)
    board = ChessboardTarget(5, 7, 0.020)
    sq, rows, cols = 0.020, 5, 7
    obj = np.array([[c * sq, r * sq, 0.0] for r in range(rows) for c in range(cols)])
    # the views look at the target frame's origin: the board's centre, as in simulate_image_files
    centre = transform_from(np.eye(3), [-0.5 * sq * (cols - 1), -0.5 * sq * (rows - 1), 0.0])
    return cam, board, obj, centre


def image_noise_trial(rng: np.random.Generator, *, n_views: int = 8, sigma_px: float = 0.3,
                      setup: str = "eye-in-hand", full_covariance: bool = True):
    """One trial: ``(HandEyeResult, truth X, T_cam_target (n, 4, 4), their covariances (n, 6, 6))``.

    ``full_covariance``: refined on closures whitened by each view's covariance
    (:func:`~robocal.handeye.weighted.refine_with_pose_covariances`, as ``calibrate-images`` does); else
    with the per-view stds only (``calibrate_hand_eye(pose_sigmas=)``).
    """
    from robocal.geometry import invert_transform
    from robocal.handeye import calibrate_hand_eye, simulate_eye_in_hand, simulate_eye_to_hand
    from robocal.handeye.images import view_pose
    from robocal.handeye.weighted import refine_with_pose_covariances

    cam, _, obj, centre = _board()
    sim = (simulate_eye_in_hand if setup == "eye-in-hand" else simulate_eye_to_hand)(rng, n_views, noise=False)
    T_out, covs, sig = [], [], []
    # the target frame is the board's (its first corner), where PnP gives the pose and its covariance: X
    # does not depend on where the target frame is
    for T in sim.T_cam_target @ centre:
        uv = cam.project_points(obj, T) + rng.normal(size=(len(obj), 2)) * sigma_px
        Tb, C, _, _ = view_pose(cam, obj, uv)
        T_out.append(Tb)
        covs.append(C)
        sig.append([np.sqrt(np.trace(C[:3, :3]) / 3), np.sqrt(np.trace(C[3:, 3:]) / 3)])   # as view_poses
    Tc, covs, sig = np.array(T_out), np.array(covs), np.array(sig)
    res = calibrate_hand_eye(sim.T_base_gripper, Tc, setup=setup, pose_sigmas=sig)
    if full_covariance:
        G = sim.T_base_gripper if setup == "eye-in-hand" else invert_transform(sim.T_base_gripper)
        w = refine_with_pose_covariances(G, Tc, covs, res.X, res.Y)
        res = replace(res, X=w.X, Y=w.Y, cov=w.cov, std=w.std, lsq=w.lsq, method=res.method + "+cov")
    return res, sim.X, Tc, covs


def nees_image_noise(rng: np.random.Generator, n_trials: int, *, n_views: int = 8, sigma_px: float = 0.3,
                     setup: str = "eye-in-hand", full_covariance: bool = True, progress: bool = False) -> NeesStudy:
    """``n_trials`` trials of :func:`image_noise_trial`, their NEES."""
    from robocal.geometry import PoseWithCovariance
    from robocal.progress import progress as _progress

    nees, errs, stds = [], [], []
    for _ in _progress(range(n_trials), desc="NEES trials", total=n_trials, enabled=progress):
        res, X, _, _ = image_noise_trial(rng, n_views=n_views, sigma_px=sigma_px, setup=setup,
                                         full_covariance=full_covariance)
        e = PoseWithCovariance(res.X, res.cov).error_to(X).vector
        nees.append(float(e @ np.linalg.solve(res.cov, e)))
        errs.append(e)
        stds.append(np.sqrt(np.diag(res.cov)))
    return NeesStudy(np.array(nees), np.array(errs), np.array(stds), int(n_views), float(sigma_px))
