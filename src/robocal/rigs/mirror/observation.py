"""What one mirror image gives, and its validation: markers A-D and the imaged reflections of body points.

:class:`MirrorObservation` is the input of both estimators (the patent's
single-image method, :mod:`.single`, and the joint problem, :mod:`.joint`);
:func:`check_observation` and :func:`check_in_image` reject malformed or
impossible image points with a message naming the image and the field.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle
from robocal.errors import InconsistentDataError, InputError, NotEnoughDataError, ShapeError
from robocal.validation import check_array

__all__ = ["MirrorObservation", "check_observation", "check_in_image", "OUTSIDE_IMAGE_FRACTION",
           "OUTSIDE_IMAGE_MIN_PX"]


@dataclass
class MirrorObservation:
    """What one image gives: the four markers and the imaged reflections.

    Attributes
    ----------
    marker_uv : ndarray, shape (4, 2)
        Markers A, B, C, D [px] in the rectangle's order (A top left, clockwise).
    body_uv : ndarray, shape (N, 2)
        Image of the reflection of each listed body point [px].
    body_ids : ndarray of int, shape (N,)
        Index of each observed point in the body point model.
    name : str
        Label used in messages and reports (file name, "image 3", ...).
    warnings : list of Diagnostic
        From the detection (tags not found, repeated or unknown ids); passed
        on to the calibration's warnings.
    marker_sigma_scale : float
        Noise std of a marker coordinate relative to a body point's (1: the
        same); multiplies ``marker_cov`` when both are given. The joint
        refinement weights the markers by it. The ArUco path leaves it at 1
        and gives ``marker_cov`` instead (a tag centre is ~0.6-0.7 x as
        noisy as a tag corner; the former scalar 0.265 was too optimistic).
    body_cov : ndarray, shape (N // 4, 8, 8), optional
        Noise covariance of the body points in groups of four consecutive
        rows of ``body_uv`` (the corners of one tag, order ``u0, v0, ..., u3,
        v3``), relative: times ``sigma_px^2``. The ArUco path sets it from
        the edge-fit geometry (:func:`~robocal.rigs.mirror.detect.tag_corner_covariance`):
        a tag's corners share its four fitted border lines, so their errors
        are correlated (-0.68 between the ends of one side); the joint
        refinement whitens each tag's residuals with it. None: independent,
        unit variance.
    marker_cov : ndarray, shape (4, 2, 2), optional
        Relative noise covariance of each marker (times
        ``(marker_sigma_scale sigma_px)^2``); None: identity.
    """

    marker_uv: np.ndarray
    body_uv: np.ndarray
    body_ids: np.ndarray | None = None
    name: str = "image"
    warnings: list = field(default_factory=list)
    marker_sigma_scale: float = 1.0
    body_cov: np.ndarray | None = None
    marker_cov: np.ndarray | None = None

    def __post_init__(self):
        s = self.marker_sigma_scale
        if isinstance(s, bool) or not isinstance(s, (int, float, np.floating, np.integer)) or not 0 < s < np.inf:
            raise InputError(f"{self.name}: marker_sigma_scale must be a number > 0, got {s!r}")
        for fld, shape in (("body_cov", (None, 8, 8)), ("marker_cov", (4, 2, 2))):
            c = getattr(self, fld)
            if c is None:
                continue
            c = check_array(c, f"{self.name}: {fld}")
            if c.ndim != 3 or c.shape[1:] != shape[1:] or (shape[0] is not None and c.shape[0] != shape[0]):
                want = "(N // 4, 8, 8)" if shape[0] is None else "(4, 2, 2)"
                raise ShapeError(f"{self.name}: {fld} must have shape {want}, got {c.shape}")
            if not np.allclose(c, np.swapaxes(c, 1, 2), rtol=1e-6, atol=1e-12 * max(np.abs(c).max(), 1e-300)) \
                    or np.any(np.linalg.eigvalsh(0.5 * (c + np.swapaxes(c, 1, 2)))[:, 0] <= 0):
                raise InputError(f"{self.name}: {fld} must be symmetric positive definite matrices")
            object.__setattr__(self, fld, c)

    def to_dict(self) -> dict:
        d = {
            "name": self.name,
            "marker_uv": np.asarray(self.marker_uv).tolist(),
            "body_uv": np.asarray(self.body_uv).tolist(),
            "body_ids": None if self.body_ids is None else [int(i) for i in self.body_ids],
        }
        if self.marker_sigma_scale != 1.0:
            d["marker_sigma_scale"] = float(self.marker_sigma_scale)
        if self.body_cov is not None:
            d["body_cov"] = np.asarray(self.body_cov).tolist()
        if self.marker_cov is not None:
            d["marker_cov"] = np.asarray(self.marker_cov).tolist()
        return d


def _signed_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def check_observation(obs: MirrorObservation, body_points_r: np.ndarray, rectangle: MarkerRectangle):
    """Validate one observation; returns ``(marker_uv, body_uv, body_ids, p_r)`` as arrays.

    Raises a :class:`~robocal.errors.RobocalError` naming the observation and field:
    wrong shapes, mismatched counts, fewer than 4 body points, markers that are
    not a convex quadrilateral in the documented clockwise order.
    """
    src = obs.name
    m = check_array(obs.marker_uv, f"{src}: marker_uv")
    if m.shape != (4, 2):
        raise ShapeError(f"{src}: marker_uv must have shape (4, 2) (markers A, B, C, D), got {m.shape}")
    q = check_array(obs.body_uv, f"{src}: body_uv")
    if q.ndim != 2 or q.shape[1] != 2:
        raise ShapeError(f"{src}: body_uv must have shape (N, 2), got {q.shape}")
    P = check_array(body_points_r, "body_points_r")
    if P.ndim != 2 or P.shape[1] != 3:
        raise ShapeError(f"body_points_r must have shape (N, 3), got {P.shape}")
    if obs.body_ids is None:
        if q.shape[0] != P.shape[0]:
            raise InputError(
                f"{src}: {q.shape[0]} body image points but {P.shape[0]} body model points; "
                "give body_ids to say which model point each image point is"
            )
        ids = np.arange(P.shape[0])
    else:
        ids = np.asarray(obs.body_ids)
        if ids.shape != (q.shape[0],) or not np.issubdtype(ids.dtype, np.integer):
            raise InputError(f"{src}: body_ids must be {q.shape[0]} integers (one per body_uv row), got shape {ids.shape}")
        if ids.size and (ids.min() < 0 or ids.max() >= P.shape[0]):
            raise InputError(f"{src}: body_ids must index the {P.shape[0]} body model points, got {ids.min()}..{ids.max()}")
        if len(np.unique(ids)) != ids.size:
            raise InputError(f"{src}: body_ids has repeated entries")
    if q.shape[0] < 4:
        raise NotEnoughDataError(f"{src}: needs at least 4 imaged body points for PnP, got {q.shape[0]}")
    # markers: a convex quadrilateral A, B, C, D, clockwise in the image (v down)
    e = np.roll(m, -1, axis=0) - m
    cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
    diag = max(np.linalg.norm(m[2] - m[0]), np.linalg.norm(m[3] - m[1]))
    if diag < 4.0:
        raise InconsistentDataError(f"{src}: marker_uv: the four markers are within {diag:.2g} px of each other")
    if not (np.all(cross > 0) or np.all(cross < 0)):
        raise InconsistentDataError(
            f"{src}: marker_uv does not form a convex quadrilateral A-B-C-D (crossed or reflex corners); "
            "check the marker order"
        )
    if _signed_area(m) < 0:
        raise InconsistentDataError(
            f"{src}: marker_uv runs counter-clockwise in the image; expected A (top left), B (top right), "
            "C (bottom right), D (bottom left) as seen on the mirror's front"
        )
    # contiguous copies: cv2.solvePnP rejects strided views (core PnP passes them through)
    return np.ascontiguousarray(m), np.ascontiguousarray(q), ids, np.ascontiguousarray(P[ids])


#: Image points farther than this fraction of the image size outside it are rejected as wrong input.
OUTSIDE_IMAGE_FRACTION = 0.02
#: ... but never less than this many pixels (sub-pixel detections and noise at the border).
OUTSIDE_IMAGE_MIN_PX = 3.0


def check_in_image(camera: CameraModel, uv, what: str) -> None:
    """Reject image points outside the camera's ``width x height`` image [px].

    A detector cannot report such points, so they are a unit or column mix-up
    or points of another image size (e.g. picked in a full-resolution photo
    with a camera calibrated on reduced images); without this check PnP fails
    later with a misleading "behind the camera", or succeeds with a wrong
    answer. The margin (``OUTSIDE_IMAGE_FRACTION`` of the image size, at
    least ``OUTSIDE_IMAGE_MIN_PX``) leaves room for noisy detections at the
    border.
    """
    uv = np.asarray(uv, dtype=float)
    size = np.array([camera.width, camera.height], dtype=float)
    margin = np.maximum(OUTSIDE_IMAGE_FRACTION * size, OUTSIDE_IMAGE_MIN_PX)
    lo, hi = -0.5 - margin, size - 0.5 + margin
    bad = np.flatnonzero(np.any((uv < lo) | (uv > hi), axis=1))
    if bad.size:
        i = int(bad[0])
        raise InconsistentDataError(
            f"{what}: row {i} = ({uv[i, 0]:.4g}, {uv[i, 1]:.4g}) px lies outside the {camera.width} x "
            f"{camera.height} px image{f' ({bad.size} such rows)' if bad.size > 1 else ''}; check the camera "
            "width/height (the size of the images the points come from) and that the points are pixels, "
            "in (u, v) = (column, row) order")
