"""What a calibration is judged by, drawn over the image, and simulated views to calibrate.

:func:`projection_uncertainty` (mrcal-style map of where a ray lands, px),
:func:`coverage` (where the corners fell) and :func:`simulate_target_views`
(synthetic corners of a known camera, for tests and Monte Carlo), split from
:mod:`robocal.camera._calibrate` (the estimator), which re-exports them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.camera._calibrate import (MIN_CORNERS_PER_VIEW, IntrinsicCalibration, TargetView, _check_views,
                                       _is_fisheye, _rodrigues)
from robocal.camera._model import CameraModel
from robocal.errors import InputError
from robocal.validation import check_array

__all__ = ["ProjectionUncertainty", "projection_uncertainty", "coverage", "simulate_target_views"]


@dataclass(frozen=True, eq=False)
class ProjectionUncertainty:
    """Std [px] of where a ray lands, on a pixel grid (see :func:`projection_uncertainty`).

    ``u`` (nu,), ``v`` (nv,): grid pixel coordinates; ``std`` (nv, nu): worst
    direction std [px] (sqrt of the largest eigenvalue of the 2x2
    covariance); ``cov`` (nv, nu, 2, 2) [px^2]; ``compensated``: whether the
    part a camera rotation explains was taken out. Draw with
    ``plt.pcolormesh(u, v, std)`` or ``plt.contourf``.
    """

    u: np.ndarray
    v: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    compensated: bool = True


def _rotation_jacobian(cam, rays: np.ndarray) -> np.ndarray:
    """d pixel / d (small camera rotation) of each ray, (G, 3) -> (G, 2, 3), by central differences.

    Model-agnostic (pinhole or fisheye ``project``); a step of 1e-6 rad keeps the truncation (~1e-12 of the
    value) and the rounding (~1e-10) far below the intrinsics' effect.
    """
    h = 1e-6
    cols = []
    for k in range(3):
        w = np.zeros(3)
        w[k] = h
        plus = cam.project(rays @ _rodrigues(w).T, check=False)
        minus = cam.project(rays @ _rodrigues(-w).T, check=False)
        cols.append((plus - minus) / (2 * h))
    return np.stack(cols, axis=-1)


def projection_uncertainty(calibration: IntrinsicCalibration, grid_step_px: float = 20.0, *,
                           compensate_rotation: bool = True) -> ProjectionUncertainty:
    """mrcal-style map of the projection uncertainty over the image.

    For each grid pixel ``q``, the ray ``v = pi^-1(q)`` of the estimated
    camera is re-projected with the intrinsics' covariance ``C``:
    ``Cov(q) = A C A^T``, ``A = d pi(v; theta) / d theta`` (a point at
    infinity, or at any distance along the ray: only the intrinsics vary).

    ``compensate_rotation`` (default): the part of an intrinsics error that a
    small rotation of the camera reproduces over the whole image is taken out
    (``A -> (I - P) A``, ``P`` the least-squares projector onto the rotation
    Jacobians of all grid rays, the image weighted uniformly). That part is
    not an error of the camera as it is used: every pose estimated with these
    intrinsics (the calibration's own board poses, a later PnP or hand-eye)
    absorbs it, as a principal point shifted by ``d`` px comes with views
    turned by ``d / f`` rad. This is mrcal's compensating rotation (Kogan,
    mrcal docs, "Projection uncertainty"), fitted here over the image rather
    than from the board poses; measured on a 12-view 640x480 set, the map
    falls from 0.16 to 0.05 px at the centre (pixel noise 0.02 px), where the
    principal point's own std is 0.16 px. ``False``: the ray held fixed in the
    camera frame (what a user needs who takes the camera's optical axis as a
    reference). Grid points whose ray cannot be found (outside the invertible
    region) are NaN.
    """
    import cv2

    if not isinstance(calibration, IntrinsicCalibration):
        raise InputError(f"calibration must be an IntrinsicCalibration, got {type(calibration).__name__}")
    if not grid_step_px > 0:
        raise InputError(f"grid_step_px must be > 0 [px], got {grid_step_px!r}")
    cam = calibration.camera
    u = np.arange(0.0, cam.width - 0.5, grid_step_px)
    v = np.arange(0.0, cam.height - 0.5, grid_step_px)
    uu, vv = np.meshgrid(u, v)
    xy = cam.undistort_points(np.stack([uu, vv], axis=-1))
    ok = np.isfinite(xy[..., 0])
    rays = np.concatenate([xy[ok], np.ones((int(ok.sum()), 1))], axis=1)
    n = len(calibration.labels)
    if _is_fisheye(calibration.labels):
        _, J = cv2.fisheye.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, np.asarray(cam.k))
        J = J[:, 0:8].reshape(-1, 2, n)
    else:
        _, J = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, np.asarray(cam.dist))
        J = J[:, 6:6 + n].reshape(-1, 2, n)
    if compensate_rotation and rays.shape[0] >= 2:
        A = J.reshape(-1, n)
        B = _rotation_jacobian(cam, rays).reshape(-1, 3)
        A = A - B @ np.linalg.lstsq(B, A, rcond=None)[0]
        J = A.reshape(-1, 2, n)
    C = np.nan_to_num(calibration.cov)  # unidentifiable terms contribute nothing (they are named in warnings)
    cq = np.einsum("nij,jk,nlk->nil", J, C, J)
    cov = np.full(uu.shape + (2, 2), np.nan)
    cov[ok] = cq
    std = np.full(uu.shape, np.nan)
    std[ok] = np.sqrt(np.maximum(np.linalg.eigvalsh(cq)[:, -1], 0.0))
    return ProjectionUncertainty(u, v, std, cov, bool(compensate_rotation))


def coverage(calibration_or_views, image_size=None, *, cell_px: float = 40.0):
    """Where corners fell: counts per ``cell_px`` x ``cell_px`` cell of the image.

    Accepts an :class:`IntrinsicCalibration` (its used corners) or a list of
    :class:`TargetView` with ``image_size = (width, height)``. Returns
    ``(u_edges, v_edges, counts)`` with ``counts`` shape (nv, nu), for
    ``plt.pcolormesh(u_edges, v_edges, counts)``. Empty cells, mostly at the
    image corners, are where the distortion is extrapolated.
    """
    if isinstance(calibration_or_views, IntrinsicCalibration):
        views = calibration_or_views.views
        image_size = calibration_or_views.camera.size
    else:
        views = _check_views(list(calibration_or_views))
        if image_size is None:
            raise InputError("coverage: image_size (width, height) is needed with a list of views")
    w, h = image_size
    ue = np.arange(-0.5, w - 0.5 + cell_px, cell_px)
    ve = np.arange(-0.5, h - 0.5 + cell_px, cell_px)
    q = np.concatenate([v.image_points for v in views]) if views else np.zeros((0, 2))
    counts, _, _ = np.histogram2d(q[:, 1], q[:, 0], bins=[ve, ue])
    return ue, ve, counts.astype(int)


def simulate_target_views(camera: CameraModel, object_points, n_views: int, rng: np.random.Generator, *,
                          noise_px: float = 0.0, distance=(0.35, 0.8), tilt_rad: float = 0.6,
                          margin_px: float = 2.0) -> tuple[list, list]:
    """Synthetic corners of a planar target seen in random poses, for tests and Monte Carlo.

    The target's centre is placed on the ray of a uniformly drawn pixel at a
    uniform distance in ``distance`` [m], tilted about its x and y axes by up
    to ``tilt_rad`` and turned about z by up to ``tilt_rad / 2`` [rad]
    (uniform). Corners outside the image (less ``margin_px``) are left out
    (partial views); ``noise_px`` is the std of the isotropic Gaussian pixel
    noise. Returns ``(views, poses)``: :class:`TargetView` named
    ``view000, ...`` and the true ``T_cam_obj`` (4, 4) of each.
    """
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    obj = check_array(object_points, "object_points", shape=(None, 3))
    centre = obj.mean(axis=0)
    views, poses = [], []
    while len(views) < n_views:
        pix = rng.uniform([0.1 * camera.width, 0.1 * camera.height], [0.9 * camera.width, 0.9 * camera.height])
        ray = np.append(camera.undistort_points(pix), 1.0)
        c = ray / np.linalg.norm(ray) * rng.uniform(*distance)
        rvec = rng.uniform(-1, 1, 3) * np.array([tilt_rad, tilt_rad, tilt_rad / 2])
        R = _rodrigues(rvec)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = c - R @ centre
        uv = camera.project_points(obj, T, check=False)
        ok = camera.in_image(uv, margin_px)
        if ok.sum() < max(MIN_CORNERS_PER_VIEW, obj.shape[0] // 2):
            continue
        uv = uv + rng.normal(0.0, noise_px, uv.shape) if noise_px > 0 else uv
        ids = np.flatnonzero(ok)
        views.append(TargetView(f"view{len(views):03d}", obj[ok], uv[ok], ids))
        poses.append(T)
    return views, poses
