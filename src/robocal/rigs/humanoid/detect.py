"""Board images: rendering a simulated view and detecting the corners of each view.

Both use the shared camera package (:func:`robocal.camera.render_planar_target`,
:func:`robocal.camera.detect_checkerboard`); this module only wires them to the
humanoid model: the pose of the viewed board, and the predicted corners that
pick the ordering of the symmetric 4 x 6 corner grid.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.camera import detect_checkerboard, render_planar_target
from robocal.errors import DetectionError, FileFormatError, InputError
from robocal.rigs.humanoid.model import FEET, HumanoidModel

__all__ = ["render_view", "detect_views", "load_image", "homography_outliers"]


def render_view(model: HumanoidModel, theta, foot: str, params, rng: np.random.Generator, *,
                blur_sigma: float = 0.8, noise_sigma: float = 2.0) -> np.ndarray:
    """Grey uint8 image of ``foot``'s board for joint readings ``theta`` (n_joints,) [rad]
    under the parameter vector ``params`` (offsets added to the readings)."""
    n = len(model.joint_names)
    params = np.asarray(params, dtype=float)
    fi = FEET.index(foot)
    T = model.T_opt_board(np.asarray(theta, dtype=float)[None] + params[:n], foot, params[n:n + 5],
                          params[n + 5 + 3 * fi:n + 8 + 3 * fi])[0]
    # 2 x 2 supersampling: corner accuracy as with 4 x 4 (~0.1 px) at a third of the time
    return render_planar_target(model.camera, T, model.board, blur_sigma=blur_sigma, noise_sigma=noise_sigma,
                                rng=rng, supersample=2)


def load_image(path) -> np.ndarray:
    """Read an image file as grey uint8; a missing or unreadable file is a :class:`FileFormatError`."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"image file not found: {path}")
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileFormatError(f"cannot read image {path} (not an image OpenCV can decode)")
    return img


def detect_views(model: HumanoidModel, data, *, x=None, progress: bool = False, messages: list | None = None):
    """Detect the board's corners in every view's image; returns ``data`` with ``corners`` set.

    A view whose board is not fully found, or whose corners do not all fit a
    homography of the board plane (:func:`homography_outliers`: a corner the
    detector placed wrongly), gets NaN corners and a message (calibration then
    drops it, with a ``dropped`` warning). The expected corners from the nominal model
    (or ``x``) resolve the 180-degree ambiguity of the symmetric grid. An
    image whose size differs from the camera's is an :class:`InputError`.
    """
    n_views = data.n_views
    if len(data.images) != n_views:
        raise InputError(f"{len(data.images)} images for {n_views} joint records")
    x = np.zeros(len(model.parameter_labels())) if x is None else np.asarray(x, dtype=float)
    expected = model.project(data.theta, data.feet, x, check=False)
    corners = np.full((n_views, len(model.object_points), 2), np.nan)
    iterator = range(n_views)
    if progress:
        from robocal.cli import progress as _progress

        iterator = _progress(iterator, desc="detecting corners", total=n_views)
    notes = data.messages if messages is None else messages
    for v in iterator:
        img = data.images[v]
        if img is None:
            raise InputError(f"view {data.names[v]!r} has no image")
        if not isinstance(img, np.ndarray):
            img = load_image(img)
        h, w = img.shape[:2]
        if (w, h) != (model.camera.width, model.camera.height):
            raise InputError(f"view {data.names[v]!r}: image is {w} x {h} px, the camera is "
                             f"{model.camera.width} x {model.camera.height} px")
        exp = expected[v] if np.all(np.isfinite(expected[v])) else None
        try:
            uv = detect_checkerboard(img, model.board, expected_uv=exp)
        except DetectionError as exc:
            notes.append(f"view {data.names[v]!r}: board not fully detected, view dropped ({exc})")
            continue
        bad, err, tol = homography_outliers(model, uv)
        if bad.size:
            notes.append(f"view {data.names[v]!r}: corner(s) {bad.tolist()} lie {err[bad].max():.1f} px off the "
                         f"plane-to-image homography of the others (tolerance {tol:.2f} px): board not found "
                         f"correctly, view dropped")
            continue
        corners[v] = uv
    data.corners = corners
    return data


def homography_outliers(model: HumanoidModel, uv, *, min_tol: float = 1.0, k: float = 6.0):
    """Corners of one view that do not fit a plane-to-image homography (a badly detected corner).

    The board is planar, so its undistorted corners are a homography of the board coordinates
    (Hartley & Zisserman, eq. 4.1). The homography is fitted by least squares to all corners,
    then again without the worst one (so a single gross corner cannot hide by pulling the fit).
    A corner is bad when its distance to the refitted homography exceeds
    ``max(min_tol, k * sigma)`` [px], ``sigma`` the view's robust corner noise
    (median distance / 1.1774, the median of a 2-D Gaussian radius): ``k = 6`` leaves a false
    alarm rate of ``exp(-18)`` per corner for Gaussian noise; ``min_tol = 1 px`` is far above a
    detector's sub-pixel error (0.015 px on the simulator's renders).

    Returns ``(indices of bad corners, distance of every corner [px], tolerance [px])``.
    """
    import cv2

    cam = model.camera
    uv = np.asarray(uv, dtype=float)
    ideal = cam.undistort_points(uv) * [cam.fx, cam.fy] + [cam.cx, cam.cy]
    obj = np.asarray(model.object_points, dtype=float)[:, :2]

    def dist(keep):
        H, _ = cv2.findHomography(obj[keep], ideal[keep], 0)
        if H is None:
            return np.full(len(uv), np.inf)
        p = np.c_[obj, np.ones(len(obj))] @ H.T
        return np.linalg.norm(p[:, :2] / p[:, 2:3] - ideal, axis=1)

    keep = np.ones(len(uv), dtype=bool)
    err = dist(keep)
    keep[int(np.argmax(err))] = False
    err = dist(keep)
    sigma = float(np.median(err[keep])) / 1.1774
    tol = max(min_tol, k * sigma)
    return np.flatnonzero(err > tol), err, tol
