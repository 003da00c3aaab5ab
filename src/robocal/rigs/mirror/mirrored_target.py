"""Planar targets seen in a mirror: detection in mirrored order and the handedness test (issue 14).

A chessboard, ChArUco board or tag grid seen in a plane mirror is its mirror
image. ArUco codes do not decode mirrored, and a chessboard detector labels
the corners as if the board were seen directly: id ``(i, j)`` lands on the
physical corner ``(i, cols - 1 - j)`` (or another mirror-image labelling),
and every pose computed from it is the mirror image of the truth — with
residuals as low as the right answer's, because a mirror image of a planar
pattern is again a planar pattern (so no fit can tell).

:func:`detect_mirrored_target` detects on the horizontally flipped image
(:func:`robocal.camera.detect_target`, the core detector, unchanged) and maps
the points back (``u -> W - 1 - u``): the ids then name the physical points
("mirrored order"), which is what the mirror model needs (object set
``(-x, y, z)`` for the virtual pose, as :func:`~robocal.rigs.mirror.model.ri_from_r_points`).

:func:`target_orientation` is the handedness test: the sign of the local
Jacobian determinant of the target-plane -> image homography (on undistorted
normalised points). A target seen directly from its front has orientation
+1 (board x, y appear as image u, v up to a rotation), seen in a mirror -1.
:func:`check_mirrored_order` refuses, with the fix, points of a mirror view
that have the direct view's orientation (the unflipped detector's output,
or a target file whose ids run the other way).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.camera import CameraModel, detect_target
from robocal.errors import DegenerateGeometryError, InconsistentDataError

__all__ = ["MirroredDetection", "detect_mirrored_target", "target_orientation", "check_mirrored_order",
           "render_mirrored_target",
           "ORDER_MIRRORED"]

#: How :func:`detect_mirrored_target` ordered the points (kept with the detection, said in reports).
ORDER_MIRRORED = "mirrored: detected on the horizontally flipped image, u mapped back (ids name the physical points)"


@dataclass
class MirroredDetection:
    """A target found in a mirror image: ``ids`` (n,), ``image_points`` (n, 2) [px] in the original image,
    ``object_points`` (n, 3) [m] in the target frame, ``order`` (how the ids were assigned), the core
    detector's ``detector``, ``issues`` and ``notes``."""

    name: str
    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray
    order: str = ORDER_MIRRORED
    detector: str = ""
    issues: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def detect_mirrored_target(image, target, *, name: str = "image") -> MirroredDetection | None:
    """``target`` in a mirror ``image`` (grey or BGR), in mirrored order; None when not found.

    The image is flipped left-right, the core detector runs on it, and each
    point's column is mapped back (``u = W - 1 - u_flipped``, pixel-centre
    convention), so the ids name the physical target points.
    """
    img = np.asarray(image)
    flipped = np.ascontiguousarray(img[:, ::-1])
    det = detect_target(flipped, target, name=name)
    if det is None:
        return None
    uv = np.array(det.image_points, dtype=float, copy=True)
    uv[:, 0] = (img.shape[1] - 1) - uv[:, 0]
    return MirroredDetection(name, np.asarray(det.ids), uv, np.asarray(det.object_points, dtype=float),
                             ORDER_MIRRORED, det.detector, list(det.issues), list(det.notes))


def target_orientation(camera: CameraModel, object_points, image_points) -> tuple[int, float]:
    """``(sign, jacobian)``: the orientation of planar target points in the image (+1 direct, -1 mirrored).

    ``object_points`` (n >= 4, 3) on the target's z = 0 plane [m];
    ``image_points`` (n, 2) [px]. The homography from ``(x, y)`` to the
    undistorted normalised image point, evaluated at the points' centroid:
    its local Jacobian determinant is ``det(H) / w^3``. Raises
    :class:`DegenerateGeometryError` for fewer than 4 points or collinear ones.
    """
    import cv2

    P = np.asarray(object_points, dtype=float)
    uv = np.asarray(image_points, dtype=float)
    if len(P) < 4 or np.linalg.matrix_rank(P[:, :2] - P[:, :2].mean(axis=0), tol=1e-9) < 2:
        raise DegenerateGeometryError("target points: need >= 4 points not on one line for the handedness test")
    xy = camera.undistort_points(uv)
    H, _ = cv2.findHomography(P[:, :2], xy, 0)
    if H is None:
        raise DegenerateGeometryError("target points: no homography from the target plane to the image")
    c = np.append(P[:, :2].mean(axis=0), 1.0)
    w = float(H[2] @ c)
    jac = float(np.linalg.det(H) / w ** 3)
    return (1 if jac > 0 else -1), jac


def check_mirrored_order(camera: CameraModel, object_points, image_points, *, what: str = "target",
                         cols: int | None = None) -> None:
    """Refuse points of a target seen in a mirror whose order is that of a direct view (one line, with the fix).

    ``cols``: the chessboard's inner corners per row, to name the id map of
    the fix. Raises :class:`~robocal.errors.InconsistentDataError`.
    """
    sign, _ = target_orientation(camera, object_points, image_points)
    if sign > 0:
        remap = (f" or renumber the target's ids per row, id i*{cols}+j -> i*{cols}+({cols - 1}-j)"
                 if cols else " or give the target points with x negated")
        raise InconsistentDataError(
            f"{what}: the points are in unmirrored order (their orientation in the image is that of a direct "
            f"view, +1; a target seen in a mirror has -1): the detector labelled the mirror image as a direct "
            f"view, and every pose from it would be the mirror image of the truth with residuals as low as the "
            f"right answer's. Fix: detect on the flipped image (robocal.rigs.mirror.mirrored_target."
            f"detect_mirrored_target){remap}")


def render_mirrored_target(camera: CameraModel, target, T_c_t, n, d, rng: np.random.Generator | None = None, *,
                           blur_sigma: float = 0.0, noise_sigma: float = 0.0) -> np.ndarray:
    """Image (uint8, H x W) of ``target`` at ``T_c_t`` (target -> camera [m]) seen in the mirror ``n . x = d``.

    The mirror view is the view of the reflected camera made right-handed
    (``F = diag(-1, 1, 1)``: target pose ``F H T_c_t`` with the reflection
    ``H``) flipped left-right, drawn by :func:`robocal.camera.render_target_view`
    with the tangential ``p2`` negated (the only distortion term that is odd
    in x). Exact when the principal point is the image centre, ``cx = (W -
    1) / 2``; other cameras are refused.
    """
    import dataclasses

    from robocal.camera import render_target_view
    from robocal.errors import InputError
    from robocal.geometry import transform_from

    if abs(camera.cx - (camera.width - 1) / 2) > 1e-9:
        raise InputError(f"render_mirrored_target: needs cx = (width - 1) / 2 = {(camera.width - 1) / 2:g}, got "
                         f"{camera.cx:g} (the mirror view is rendered as a left-right flipped view)")
    n = np.asarray(n, dtype=float)
    T = np.asarray(T_c_t, dtype=float)
    Hm = np.eye(3) - 2.0 * np.outer(n, n)
    F = np.diag([-1.0, 1.0, 1.0])
    T_v = transform_from(F @ Hm @ T[:3, :3], F @ (Hm @ T[:3, 3] + 2.0 * float(d) * n))
    dist = np.array(camera.dist, dtype=float)
    if dist.size > 3:
        dist[3] = -dist[3]
    cam_f = dataclasses.replace(camera, dist=dist)
    img = render_target_view(cam_f, target, T_v, rng, blur_sigma=blur_sigma, noise_sigma=noise_sigma)
    return np.ascontiguousarray(img[:, ::-1])
