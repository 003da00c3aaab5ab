"""Rendered mirror images and the ArUco detection path (beyond the patent).

Practical targets: the robot's feature points are the corners of printed
ArUco markers on its body; the camera sees their *mirror images*. A mirror
image of a tag is the tag reflected left-right, which the ArUco decoder
rejects, so the image is flipped horizontally first (``u' = W - 1 - u``),
the tags are detected there, and the corners are mapped back. The four
markers on the mirror are ArUco tags too (ids 40-43, read in the unflipped
image); each mirror marker point is the tag's centre, found as the
intersection of the tag's diagonals in undistorted coordinates (exact under
perspective, unlike the mean of the corners).

Rendering uses :func:`robocal.camera.render_plane_texture` (distortion
included): the virtual tag is the reflected tag frame with its x axis
flipped (:func:`~robocal.rigs.mirror.model.virtual_transform`), carrying the
left-right mirrored tag bitmap.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from robocal.camera import CameraModel, add_blur_and_noise, blank_image, render_plane_texture
from robocal.errors import DetectionError, InputError
from robocal.geometry import apply_transform, transform_from
from robocal.rigs.mirror.calibrate import MirrorObservation
from robocal.rigs.mirror.model import MirrorScene, mirror_plane, virtual_transform

__all__ = [
    "ARUCO_DICT",
    "MIRROR_TAG_IDS",
    "BodyTags",
    "MirrorTags",
    "aruco_dictionary",
    "tag_rotation",
    "default_body_tags",
    "render_mirror_image",
    "detect_mirror_image",
]

#: Dictionary of every tag (OpenCV name).
ARUCO_DICT = "DICT_4X4_50"
#: Ids of the tags on the mirror at A, B, C, D.
MIRROR_TAG_IDS = (40, 41, 42, 43)
#: Side of the mirror tags [m].
MIRROR_TAG_SIZE = 0.06

# A tag on a face whose outward normal is +x_r, read upright by someone in front:
# x_tag = +y_r (their right), y_tag = -z_r (down), z_tag = -x_r (into the face).
_R_R_TAG_FRONT = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def aruco_dictionary(name: str = ARUCO_DICT):
    """OpenCV predefined ArUco dictionary by name (e.g. ``"DICT_4X4_50"``); InputError if unknown."""
    if not (isinstance(name, str) and name.startswith("DICT_") and hasattr(cv2.aruco, name)):
        raise InputError(f"dictionary: expected an OpenCV ArUco dictionary name such as {ARUCO_DICT!r}, got {name!r}")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def _dictionary(name: str = ARUCO_DICT):
    return aruco_dictionary(name)


def tag_rotation(normal, x_axis=None) -> np.ndarray:
    """Rotation ``R_r_tag`` (3, 3) of a tag on a face with outward ``normal`` (in ``r``).

    Tag frame: x to the right and y down on the printed tag, z into the face
    (``z_tag = -normal``). ``x_axis`` (in ``r``) is the tag's right; without it
    the tag is upright (y_tag along ``-z_r`` projected onto the face), which
    needs a face that is not horizontal.
    """
    n = np.asarray(normal, dtype=float).reshape(3)
    if not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
        raise InputError(f"normal: expected a non-zero 3-vector, got {n.tolist()}")
    z = -n / np.linalg.norm(n)
    if x_axis is None:
        y = np.array([0.0, 0.0, -1.0])
        y = y - (y @ z) * z
        if np.linalg.norm(y) < 1e-6:
            raise InputError("normal: the face is horizontal, so 'upright' is undefined; give x_axis too")
        y /= np.linalg.norm(y)
        x = np.cross(y, z)
    else:
        x = np.asarray(x_axis, dtype=float).reshape(3)
        x = x - (x @ z) * z
        if not np.all(np.isfinite(x)) or np.linalg.norm(x) < 1e-6:
            raise InputError(f"x_axis: must not be parallel to the normal, got {np.asarray(x_axis).tolist()}")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
    return np.column_stack([x, y, z])


def _tag_bitmap(tag_id: int, cells: int = 6, px_per_cell: int = 10, dictionary: str = ARUCO_DICT) -> np.ndarray:
    img = cv2.aruco.generateImageMarker(_dictionary(dictionary), int(tag_id), cells * px_per_cell)
    # a white quiet zone of one cell around the tag so that it reads on any background
    return cv2.copyMakeBorder(img, px_per_cell, px_per_cell, px_per_cell, px_per_cell, cv2.BORDER_CONSTANT,
                              value=255)


@dataclass(frozen=True)
class BodyTags:
    """ArUco tags on the robot body.

    Attributes
    ----------
    ids : tuple of int
    T_r_tag : ndarray, shape (T, 4, 4)
        Tag frames in ``r`` (tag centre at the origin, x right and y down on
        the printed tag, z into the face) [m].
    size : float
        Black-square side [m].
    dictionary : str
        OpenCV ArUco dictionary of the body tags.
    """

    ids: tuple
    T_r_tag: np.ndarray
    size: float
    dictionary: str = ARUCO_DICT

    def corners_tag(self) -> np.ndarray:
        """Corners in the tag frame in OpenCV's order (TL, TR, BR, BL), (4, 3)."""
        h = self.size / 2
        return np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])

    def body_points_r(self) -> np.ndarray:
        """All corners in ``r``, (4 T, 3): tag ``k`` corner ``j`` is row ``4 k + j``."""
        return apply_transform(self.T_r_tag[:, None], self.corners_tag()[None]).reshape(-1, 3)


@dataclass(frozen=True)
class MirrorTags:
    """The four ArUco tags on the mirror, centred at markers A, B, C, D.

    Attributes
    ----------
    ids : tuple of 4 int
        Tag ids at A, B, C, D.
    dictionary : str
        OpenCV ArUco dictionary name.
    """

    ids: tuple = MIRROR_TAG_IDS
    dictionary: str = ARUCO_DICT

    def __post_init__(self):
        ids = tuple(int(i) for i in self.ids)
        if len(ids) != 4 or len(set(ids)) != 4:
            raise InputError(f"mirror_tags.ids: expected 4 distinct ids (A, B, C, D), got {list(self.ids)}")
        n = aruco_dictionary(self.dictionary).bytesList.shape[0]
        if min(ids) < 0 or max(ids) >= n:
            raise InputError(f"mirror_tags.ids: {self.dictionary} has ids 0..{n - 1}, got {list(ids)}")
        object.__setattr__(self, "ids", ids)

    def check_body(self, tags: "BodyTags") -> None:
        """Body tag ids must differ from the mirror's when both use one dictionary."""
        if tags.dictionary != self.dictionary:
            return
        clash = sorted(set(int(i) for i in tags.ids) & set(self.ids))
        if clash:
            raise InputError(f"body_tags.tags: ids {clash} are also mirror tag ids {list(self.ids)} "
                             f"({self.dictionary}); a body tag seen directly would be taken for a mirror marker")


def default_body_tags() -> BodyTags:
    """Six 0.1 m tags on the published body: four on the front face, two on the box (two depths)."""
    centres = [(0.45, -0.19, 0.10), (0.45, -0.19, 0.21), (0.45, 0.19, 0.10), (0.45, 0.19, 0.21),
               (0.52, -0.06, 0.14), (0.52, 0.06, 0.14)]
    T = np.stack([transform_from(_R_R_TAG_FRONT, c) for c in centres])
    return BodyTags(ids=tuple(range(len(centres))), T_r_tag=T, size=0.1)


def render_mirror_image(camera: CameraModel, scene: MirrorScene, tags: BodyTags, *, placement: int = 0,
                        rng: np.random.Generator | None = None, blur_sigma: float = 0.6,
                        noise_sigma: float = 2.0, mirror_tags: MirrorTags | None = None) -> np.ndarray:
    """A grey image of mirror placement ``placement``: reflected body tags and the mirror's tags.

    ``scene.body_points_r`` is ignored; the body points are ``tags``' corners.
    Returns uint8 (height, width).
    """
    T_c_m = scene.T_c_m[placement]
    n, d = mirror_plane(T_c_m)
    img = blank_image(camera, background=150.0)
    cells = 6
    for tag_id, T_r_tag in zip(tags.ids, tags.T_r_tag):
        T_c_tag = scene.T_c_r @ T_r_tag
        T_c_vtag = virtual_transform(T_c_tag, n, d)
        bmp = np.fliplr(_tag_bitmap(tag_id, cells, dictionary=tags.dictionary))
        full = tags.size * (cells + 2) / cells
        img = render_plane_texture(camera, T_c_vtag, bmp, full, origin=(-full / 2, -full / 2), image=img)
    w, h = scene.rectangle.width, scene.rectangle.height
    full = MIRROR_TAG_SIZE * (cells + 2) / cells
    mt = mirror_tags or MirrorTags()
    for tag_id, (x, y) in zip(mt.ids, [(0, 0), (w, 0), (w, h), (0, h)]):
        img = render_plane_texture(camera, T_c_m, _tag_bitmap(tag_id, cells, dictionary=mt.dictionary), full,
                                   origin=(x - full / 2, y - full / 2), image=img)
    return add_blur_and_noise(img, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)


def _detect(gray: np.ndarray, dictionary: str = ARUCO_DICT):
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.cornerRefinementWinSize = 3
    det = cv2.aruco.ArucoDetector(_dictionary(dictionary), params)
    corners, ids, _ = det.detectMarkers(gray)
    if ids is None:
        return {}
    return {int(i): c.reshape(4, 2).astype(float) for i, c in zip(ids.ravel(), corners)}


def _centre(camera: CameraModel, corners_uv: np.ndarray) -> np.ndarray:
    """Image of the tag centre: intersection of the diagonals in undistorted coordinates."""
    xy = camera.undistort_points(corners_uv)
    h = np.hstack([xy, np.ones((4, 1))])
    x = np.cross(np.cross(h[0], h[2]), np.cross(h[1], h[3]))
    return camera.pixel_from_normalized(x[:2] / x[2])


def detect_mirror_image(image, camera: CameraModel, tags: BodyTags, *, name: str = "image",
                        mirror_tags: MirrorTags | None = None) -> MirrorObservation:
    """Find the mirror tags (direct) and the body tags (in the flipped image).

    Returns a :class:`MirrorObservation` whose ``body_ids`` index
    ``tags.body_points_r()`` (tags not found are left out). ``mirror_tags``:
    ids and dictionary of the mirror's tags (default ids 40-43, DICT_4X4_50).

    Raises
    ------
    DetectionError
        A mirror tag is missing, or fewer than one body tag (4 corners) is found.
    """
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise InputError(f"{name}: image must be an 8-bit grey or BGR image, got shape {img.shape} {img.dtype}")
    if img.shape != (camera.height, camera.width):
        raise InputError(f"{name}: image is {img.shape[1]} x {img.shape[0]} px, camera is "
                         f"{camera.width} x {camera.height}")
    mt = mirror_tags or MirrorTags()
    mt.check_body(tags)
    direct = _detect(img, mt.dictionary)
    missing = [i for i in mt.ids if i not in direct]
    if missing:
        raise DetectionError(f"{name}: mirror tag(s) {missing} not found (ids {list(mt.ids)} at A, B, C, D, "
                             f"{mt.dictionary})")
    marker_uv = np.stack([_centre(camera, direct[i]) for i in mt.ids])
    flipped = _detect(np.ascontiguousarray(img[:, ::-1]), tags.dictionary)
    W = img.shape[1]
    uv, ids = [], []
    for k, tag_id in enumerate(tags.ids):
        c = flipped.get(int(tag_id))
        if c is None:
            continue
        c = c.copy()
        c[:, 0] = (W - 1) - c[:, 0]
        uv.append(c)
        ids.extend(range(4 * k, 4 * k + 4))
    if not uv:
        raise DetectionError(f"{name}: no body tag found in the flipped image (ids {list(tags.ids)})")
    return MirrorObservation(marker_uv, np.concatenate(uv), np.array(ids), name)
