"""Extra points on the mirror's diagonals by the cross-ratio (seed 002, "具体实施").

The patent notes that the four markers A, B, C, D define two diagonals and
their intersection O, and that further "calibration points" P on the
diagonals can be generated from the invariance of the cross-ratio under
central projection, so that the mirror becomes a 2D target with as many
points as one likes.

Read this before using it: **the generated points carry no information
beyond the four corners.** They are a deterministic function of the four
imaged corners, so a PnP fed with them is still a four-point PnP whose corner
noise has been copied into every extra point: its Monte Carlo scatter is that
of the corners alone (ratio 0.97-1.03 over 200 trials at 0.5 px on the
published scene, 24 extra points), while treating them as independent
observations shrinks the reported std to 0.4-0.6 of the true scatter
(``test_cross_ratio_points_add_no_information_to_the_marker_pose``). They are useful for drawing, for checking a
detector, or for seeding a search for extra physical marks — not for
improving the estimate. The calibration in this rig uses the corners only.

The construction runs on *undistorted* (normalised) coordinates, because the
cross-ratio is a projective invariant and lens distortion is not projective;
with a :class:`~robocal.camera.CameraModel` the points are undistorted first
and the results re-distorted to pixels.
"""

from __future__ import annotations

import numpy as np

from robocal.errors import DegenerateGeometryError, InputError
from robocal.validation import check_array

__all__ = ["diagonal_points"]


def _line_intersection(p1, p2, q1, q2):
    """Intersection of lines p1p2 and q1q2 (2D), via homogeneous coordinates."""
    h = lambda a: np.array([a[0], a[1], 1.0])  # noqa: E731
    l1 = np.cross(h(p1), h(p2))
    l2 = np.cross(h(q1), h(q2))
    x = np.cross(l1, l2)
    if abs(x[2]) < 1e-12 * np.linalg.norm(x):
        raise DegenerateGeometryError("marker diagonals are parallel in the image (not a rectangle's corners)")
    return x[:2] / x[2]


def diagonal_points(corners_uv, fractions, *, camera=None, width: float | None = None,
                    height: float | None = None):
    """Image points at given fractions along the two diagonals AC and BD.

    Parameters
    ----------
    corners_uv : array_like, shape (4, 2)
        Imaged markers A, B, C, D [px] (A top left, then around the rectangle).
    fractions : array_like, shape (M,)
        Positions ``s`` along each diagonal, ``P = A + s (C - A)`` and
        ``P = B + s (D - B)`` in the mirror plane (0 = first corner,
        0.5 = centre O, 1 = opposite corner).
    camera : robocal.camera.CameraModel, optional
        Lens model; without it the pixels are taken as distortion-free.
    width, height : float, optional
        Rectangle size [m]; when given, the object points in frame ``m`` are
        returned too.

    Returns
    -------
    uv : ndarray, shape (2, M, 2)
        Image points on diagonal AC (``uv[0]``) and BD (``uv[1]``) [px].
    p_m : ndarray, shape (2, M, 3)
        Their object points in ``m`` [m] (only when ``width`` and ``height``
        are given; the function then returns ``(uv, p_m)``).

    Notes
    -----
    On the image line through ``a`` and ``c`` with ``a -> 0``, ``c -> 1``, the
    1D homography fixed by ``A -> 0``, ``C -> 1`` and ``O -> t_o`` (the
    imaged diagonal intersection) is ``t(s) = alpha s / (1 + (alpha - 1) s)``
    with ``alpha = t_o / (1 - t_o)``; it preserves the cross-ratio
    ``(A, C; O, P)`` (Wei et al. 2003, cited by seed 002). No new information:
    see the module docstring.
    """
    uv = check_array(corners_uv, "corners_uv", shape=(4, 2))
    if uv.shape != (4, 2):
        raise InputError(f"corners_uv must have shape (4, 2), got {uv.shape}")
    s = check_array(fractions, "fractions").reshape(-1)
    xy = camera.undistort_points(uv, check=True) if camera is not None else uv
    a, b, c, d = xy
    o = _line_intersection(a, c, b, d)
    out = []
    for p0, p1 in ((a, c), (b, d)):
        seg = p1 - p0
        L2 = seg @ seg
        if L2 < 1e-24:
            raise DegenerateGeometryError("two opposite markers coincide in the image")
        t_o = (o - p0) @ seg / L2
        if not 0.0 < t_o < 1.0:
            raise DegenerateGeometryError("the diagonals do not cross between the markers (not a convex quadrilateral)")
        alpha = t_o / (1.0 - t_o)
        t = alpha * s / (1.0 + (alpha - 1.0) * s)
        out.append(p0 + t[:, None] * seg)
    pts = np.stack(out)
    if camera is not None:
        pts = camera.pixel_from_normalized(pts)
    if width is None or height is None:
        return pts
    w, h = float(width), float(height)
    A, B, C, D = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], dtype=float)
    p_m = np.stack([A + s[:, None] * (C - A), B + s[:, None] * (D - B)])
    return pts, p_m
