"""Board images: rendering a simulated view and detecting the corners of each view.

Both use the shared camera package (:func:`robocal.camera.render_planar_target`,
:func:`robocal.camera.detect_checkerboard`); this module wires them to the
humanoid model (the pose of the viewed board, and the predicted corners that
pick the ordering of the symmetric 4 x 6 corner grid) and checks each found
board corner by corner: a corner whose sub-pixel refinement wandered off, or
that lies off the board's plane-to-image homography (:func:`homography_outliers`,
a robust fit), is removed (NaN) and named; a view with too many such corners is
dropped.
"""

from __future__ import annotations


import numpy as np

from robocal.camera import detect_checkerboard, render_planar_target
from robocal.errors import DetectionError, InputError
from robocal.rigs.humanoid.model import FEET, HumanoidModel

__all__ = ["render_view", "detect_views", "load_image", "homography_outliers", "HOMOGRAPHY_MIN_TOL",
           "HOMOGRAPHY_K", "MAX_BAD_FRACTION"]


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
    """Read an image file as grey uint8; a missing, damaged or undecodable file is a :class:`FileFormatError`."""
    from robocal.camera import read_image

    return read_image(path)


#: Defaults of :func:`detect_views` / :func:`homography_outliers`: a corner is bad beyond
#: ``max(HOMOGRAPHY_MIN_TOL, HOMOGRAPHY_K * sigma)`` [px] from the homography of the good ones, and a
#: view with more than ``MAX_BAD_FRACTION`` of its corners bad is dropped (its board, not a corner, is
#: then misdetected).
HOMOGRAPHY_MIN_TOL = 1.0
HOMOGRAPHY_K = 6.0
MAX_BAD_FRACTION = 0.25


def detect_views(model: HumanoidModel, data, *, x=None, progress: bool = False, messages: list | None = None,
                 max_bad_fraction: float = MAX_BAD_FRACTION):
    """Detect the board's corners in every view's image; returns ``data`` with ``corners`` set.

    A view whose board is not fully found gets NaN corners and a message (calibration then drops
    it, with a ``dropped`` warning). In a found board, single corners are removed (set to NaN,
    named in a message by view and corner index; calibration leaves them out and lists them):

    * corners whose sub-pixel refinement wandered off (``detect_checkerboard``'s ``unrefined``:
      only the detector's pixel-level estimate is left);
    * corners off the plane-to-image homography of the others (:func:`homography_outliers`,
      robust to a few bad corners: a corner the detector placed wrongly).

    When more than ``max_bad_fraction`` of a view's corners are bad the whole view is dropped,
    with the counts. The expected corners from the nominal model (or ``x``) resolve the
    180-degree ambiguity of the symmetric grid. An image whose size differs from the camera's is
    an :class:`InputError`.
    """
    if not (0.0 <= max_bad_fraction < 1.0):
        raise InputError(f"max_bad_fraction must be within [0, 1), got {max_bad_fraction}")
    n_views = data.n_views
    if len(data.images) != n_views:
        raise InputError(f"{len(data.images)} images for {n_views} joint records")
    x = np.zeros(len(model.parameter_labels())) if x is None else np.asarray(x, dtype=float)
    expected = model.project(data.theta, data.feet, x, check=False)
    N = len(model.object_points)
    corners = np.full((n_views, N, 2), np.nan)
    iterator = range(n_views)
    if progress:
        from robocal.progress import progress as _progress

        iterator = _progress(iterator, desc="detecting corners", total=n_views)
    notes = data.messages if messages is None else messages
    for v in iterator:
        img = data.images[v]
        name = data.names[v]
        if img is None:
            raise InputError(f"view {name!r} has no image")
        if not isinstance(img, np.ndarray):
            img = load_image(img)
        h, w = img.shape[:2]
        if (w, h) != (model.camera.width, model.camera.height):
            raise InputError(f"view {name!r}: image is {w} x {h} px, the camera is "
                             f"{model.camera.width} x {model.camera.height} px")
        exp = expected[v] if np.all(np.isfinite(expected[v])) else None
        try:
            uv, info = detect_checkerboard(img, model.board, expected_uv=exp, full_output=True)
        except DetectionError as exc:
            notes.append(f"view {name!r}: board not fully detected, view dropped ({exc})")
            continue
        unrefined = list(info["unrefined"])
        uv[unrefined] = np.nan
        bad, err, tol = homography_outliers(model, uv)
        n_bad = len(unrefined) + bad.size
        why = []
        if unrefined:
            why.append(f"corner(s) {unrefined} wandered off in the sub-pixel refinement (moved "
                       f"{', '.join(f'{s:.1f}' for s in info['refine_shift'][unrefined])} px)")
        if bad.size:
            why.append(f"corner(s) {bad.tolist()} lie {', '.join(f'{e:.2f}' for e in err[bad])} px off the "
                       f"plane-to-image homography of the others (tolerance {tol:.2f} px)")
        if n_bad > max_bad_fraction * N:
            notes.append(f"view {name!r}: {n_bad} of {N} corners bad (more than {100 * max_bad_fraction:.0f} %): "
                         + "; ".join(why) + ": board not found correctly, view dropped")
            continue
        if n_bad:
            uv[bad] = np.nan
            notes.append(f"view {name!r}: " + "; ".join(why) + f": removed, view kept with {N - n_bad} of {N} "
                         f"corners")
        corners[v] = uv
    data.corners = corners
    return data


def homography_outliers(model: HumanoidModel, uv, *, min_tol: float = HOMOGRAPHY_MIN_TOL,
                        k: float = HOMOGRAPHY_K, max_iter: int = 20):
    """Corners of one view that do not fit a plane-to-image homography (badly detected corners).

    The board is planar, so its undistorted corners are a homography of the board coordinates
    (Hartley & Zisserman, eq. 4.1). A least-squares fit through all corners would spread a bad
    corner's error over its neighbours (most at the board's corners, where one point steers the
    fit) and inflate the noise estimate, so the fit is made robust to a few bad corners:

    1. start from the half of the corners closest to the least-median-of-squares homography
       (``cv2.findHomography(..., LMEDS)``, Rousseeuw 1984);
    2. fit the homography to the kept corners by least squares; tolerance
       ``max(min_tol, k * sigma)`` [px], ``sigma`` their noise (median distance / 1.1774, the
       median of a 2-D Gaussian radius, times ``sqrt(n / (n - 4))`` for the 8 fitted parameters
       of ``n`` corners);
    3. keep every corner within the tolerance and repeat 2-3 until the kept set stops changing
       (it grows from the clean half to all the good corners; a corner off by more than the
       tolerance stays out).

    A corner is bad when its distance to the final homography exceeds the tolerance. ``k = 6``
    leaves a false alarm rate of ``exp(-18)`` per corner for Gaussian noise; ``min_tol = 1 px`` is
    far above a detector's sub-pixel error (0.015 px on the simulator's renders). NaN corners
    (already removed) take no part and are not returned. Up to about a third of the corners bad
    are named reliably; a board with more is misdetected as a whole (the caller drops the view
    on the count).

    Returns ``(indices of bad corners, distance of every corner [px] (NaN for NaN corners),
    tolerance [px])``.
    """
    import cv2

    cam = model.camera
    uv = np.asarray(uv, dtype=float)
    valid = np.all(np.isfinite(uv), axis=1)
    ideal = np.full_like(uv, np.nan)
    if valid.any():
        ideal[valid] = cam.undistort_points(uv[valid]) * [cam.fx, cam.fy] + [cam.cx, cam.cy]
    obj = np.asarray(model.object_points, dtype=float)[:, :2]

    def dist(keep, method=0):
        H, _ = cv2.findHomography(obj[keep], ideal[keep], method) if keep.sum() >= 4 else (None, None)
        if H is None:
            return None
        p = np.c_[obj, np.ones(len(obj))] @ H.T
        return np.linalg.norm(p[:, :2] / p[:, 2:3] - ideal, axis=1)

    if valid.sum() < 6:  # too little redundancy to test anything
        return np.array([], dtype=int), np.where(valid, 0.0, np.nan), float(min_tol)
    err = dist(valid, cv2.LMEDS)
    if err is None:
        err = dist(valid)
    if err is None:  # degenerate corner set: every corner is suspect
        return np.flatnonzero(valid), np.where(valid, np.inf, np.nan), float(min_tol)
    keep = valid & (err <= np.median(err[valid]))
    tol = float(min_tol)
    for _ in range(max_iter):
        e = dist(keep)
        if e is None:
            break
        err = e
        n = int(keep.sum())  # 2n coordinates fit 8 homography parameters: residuals shrink by sqrt(1 - 4/n)
        tol = max(min_tol, k * float(np.median(err[keep])) / 1.1774 * np.sqrt(n / (n - 4)))
        new = valid & (err <= tol)
        if np.array_equal(new, keep) or new.sum() < 6:
            break
        keep = new
    return np.flatnonzero(valid & ~(err <= tol)), err, tol
