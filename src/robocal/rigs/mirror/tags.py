"""ArUco tags of the mirror rig: the body tags (feature points on the robot) and the mirror's four tags.

Tag frames, the tag bitmaps and the default layout on the published body,
shared by the renderer (:mod:`.render`), the detector (:mod:`.detect`) and the
input files (:mod:`.files`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from robocal.errors import InputError
from robocal.geometry import apply_transform, transform_from

__all__ = ["ARUCO_DICT", "MIRROR_TAG_IDS", "MIRROR_TAG_SIZE", "BodyTags", "MirrorTags", "aruco_dictionary",
           "mirror_symmetric_ids", "tag_rotation", "default_body_tags"]

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



@functools.lru_cache(maxsize=None)
def mirror_symmetric_ids(name: str = ARUCO_DICT) -> frozenset:
    """Ids of a dictionary whose mirror image decodes as the same id (``DICT_4X4_50``: 8, 9, 17, 47).

    On the body such a tag is ambiguous: seen directly it reads like its own
    reflection in the flipped image.
    """
    d = aruco_dictionary(name)
    out = set()
    for i in range(d.bytesList.shape[0]):
        bits = cv2.aruco.Dictionary.getBitsFromByteList(d.bytesList[i:i + 1], d.markerSize)
        ok, idx, _ = d.identify(np.ascontiguousarray(bits[:, ::-1]).astype(np.uint8), 0.0)
        if ok and int(idx) == i:
            out.add(i)
    return frozenset(out)


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
    img = cv2.aruco.generateImageMarker(aruco_dictionary(dictionary), int(tag_id), cells * px_per_cell)
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
    """Six 0.1 m tags on the published body: four on the front face, two on the box (two depths).

    Neighbouring tags on one face are 0.12 m apart, so no tag's white quiet
    zone (1/6 of the side) covers another's black border, as with real prints
    side by side (the earlier layout, 0.11 m apart, lost one or two tags per
    image to that).
    """
    centres = [(0.45, -0.19, 0.09), (0.45, -0.19, 0.21), (0.45, 0.19, 0.09), (0.45, 0.19, 0.21),
               (0.52, -0.06, 0.14), (0.52, 0.06, 0.14)]
    T = np.stack([transform_from(_R_R_TAG_FRONT, c) for c in centres])
    return BodyTags(ids=tuple(range(len(centres))), T_r_tag=T, size=0.1)
