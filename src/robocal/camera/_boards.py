"""Calibration targets from a file, and their rendering (detection: :mod:`robocal.camera._board_detect`).

Three target types (``type:`` in a target file, see :func:`load_target`):

* ``chessboard`` — :class:`ChessboardTarget`: ``rows x cols`` **inner
  corners**; board frame and corner order of :class:`Checkerboard` (corner
  ``(i, j)`` at ``(j * square, i * square, 0)``, id ``i * cols + j``).
* ``charuco`` — :class:`CharucoTarget`: ``rows x cols`` **squares** with ArUco
  markers in the white squares (OpenCV's ``cv2.aruco.CharucoBoard((cols,
  rows), square, marker, dictionary)``); the points are the ``(rows - 1) x
  (cols - 1)`` inner chessboard corners, id ``k`` at ``((k % (cols - 1) + 1)
  * square, (k // (cols - 1) + 1) * square, 0)`` (OpenCV's ids). Partial
  views count: a detection lists the ids it found.
* ``aruco_grid`` — :class:`ArucoGridTarget`: ``rows x cols`` **markers** of
  side ``marker`` spaced by ``separation`` (``cv2.aruco.GridBoard``); the
  points are the four corners of each marker, id ``4 * marker_index + k``
  (``k``: top-left, top-right, bottom-right, bottom-left of the printed
  marker).

Board frame of ChArUco and grids: OpenCV's — origin at the board's top-left
outer corner, x along the first row, y down the printed board, z = 0 on the
board (z = x cross y points away from a camera seeing the printed face, as
for :class:`Checkerboard`). Lengths in metres, image points in pixels
(OpenCV pixel-centre convention).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Union

import cv2
import numpy as np

from robocal.camera._model import CameraModel
from robocal.camera._render import add_blur_and_noise, render_planar_target
from robocal.camera._targets import Checkerboard, PlaneTexture
from robocal.errors import FileFormatError, InputError

__all__ = [
    "ChessboardTarget",
    "CharucoTarget",
    "ArucoGridTarget",
    "Target",
    "load_target",
    "target_from_document",
    "aruco_dictionary",
    "render_target_view",
    "visible_target_points",
]

def aruco_dictionary(name: str, *, source: str | None = None):
    """``cv2.aruco`` predefined dictionary by name (``DICT_5X5_100``, ``DICT_APRILTAG_36h11``; case-insensitive)."""
    known = {n.upper(): n for n in dir(cv2.aruco) if n.startswith("DICT_")}
    key = str(name).upper()
    if not key.startswith("DICT_"):
        key = "DICT_" + key
    if key not in known:
        close = sorted({n for n in known.values() if not any(c.islower() for c in n)})
        raise InputError(f"unknown ArUco dictionary {name!r}; known: {', '.join(close)}", source=source)
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, known[key]))


def _dict_size(dictionary) -> int:
    return int(dictionary.bytesList.shape[0])


def _int_at_least(value, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _length(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not float(value) > 0:
        raise InputError(f"{name} must be a length > 0 [m], got {value!r}")
    return float(value)


def _select(points: np.ndarray, ids, n: int, what: str) -> np.ndarray:
    if ids is None:
        return points.copy()
    ids = np.asarray(ids)
    if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer) or (ids.size and (ids.min() < 0 or ids.max() >= n)):
        raise InputError(f"{what} point ids must be integers in 0..{n - 1}, got {ids!r}")
    return points[ids]


@dataclass(frozen=True)
class ChessboardTarget:
    """Chessboard of ``rows x cols`` inner corners, squares of ``square`` [m] (see :class:`Checkerboard`)."""

    rows: int
    cols: int
    square: float

    kind = "chessboard"

    def __post_init__(self):
        object.__setattr__(self, "rows", _int_at_least(self.rows, "chessboard rows (inner corners)", 3))
        object.__setattr__(self, "cols", _int_at_least(self.cols, "chessboard cols (inner corners)", 3))
        object.__setattr__(self, "square", _length(self.square, "chessboard square"))

    @property
    def board(self) -> Checkerboard:
        return Checkerboard(self.rows, self.cols, self.square)

    @property
    def n_points(self) -> int:
        return self.rows * self.cols

    @property
    def min_points(self) -> int:
        """A chessboard is found only whole, but a corner whose sub-pixel refinement wandered is dropped
        (and noted); the rest of the view serves as a partial ChArUco view does: at least 6, or all of a
        smaller board."""
        return min(6, self.n_points)

    def object_points(self, ids=None) -> np.ndarray:
        """Corners ``ids`` (default all, id = ``i * cols + j``) in the board frame, (N, 3) [m], z = 0."""
        return _select(self.board.object_points(), ids, self.n_points, "chessboard")

    def pattern(self):
        """The planar pattern the renderer draws."""
        return self.board

    def describe(self) -> str:
        return f"{self.rows}x{self.cols} chessboard (inner corners), {self.square * 1e3:g} mm squares"


@dataclass(frozen=True)
class CharucoTarget:
    """ChArUco board of ``rows x cols`` squares of ``square`` [m], markers of side ``marker`` [m].

    ``dictionary``: a ``cv2.aruco`` predefined dictionary name. ``legacy``:
    OpenCV's pre-4.6 layout (for boards with an even number of rows printed by
    old OpenCV). ``min_points``: fewest corners a view must show (default 6).
    """

    rows: int
    cols: int
    square: float
    marker: float
    dictionary: str = "DICT_5X5_100"
    legacy: bool = False
    min_points: int = 6

    kind = "charuco"

    def __post_init__(self):
        object.__setattr__(self, "rows", _int_at_least(self.rows, "charuco rows (squares)", 2))
        object.__setattr__(self, "cols", _int_at_least(self.cols, "charuco cols (squares)", 2))
        if self.rows * self.cols < 5:
            raise InputError(f"charuco board needs at least 5 squares, got {self.rows}x{self.cols}")
        object.__setattr__(self, "square", _length(self.square, "charuco square"))
        object.__setattr__(self, "marker", _length(self.marker, "charuco marker"))
        if not self.marker < self.square:
            raise InputError(
                f"charuco marker ({self.marker * 1e3:g} mm) must be smaller than the square ({self.square * 1e3:g} mm)"
            )
        d = aruco_dictionary(self.dictionary)
        need = (self.rows * self.cols) // 2
        if need > _dict_size(d):
            raise InputError(
                f"a {self.rows}x{self.cols} charuco board needs {need} markers, "
                f"dictionary {self.dictionary} has {_dict_size(d)}"
            )
        object.__setattr__(self, "min_points", _int_at_least(self.min_points, "charuco min_points", 4))

    @property
    def cv_board(self):
        b = cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker, aruco_dictionary(self.dictionary))
        b.setLegacyPattern(bool(self.legacy))
        return b

    @property
    def n_points(self) -> int:
        return (self.rows - 1) * (self.cols - 1)

    def object_points(self, ids=None) -> np.ndarray:
        """Inner corners ``ids`` (default all) in the board frame, (N, 3) [m], z = 0."""
        k = np.arange(self.n_points)
        c = self.cols - 1
        pts = np.stack([(k % c + 1) * self.square, (k // c + 1) * self.square, np.zeros(k.size)], axis=1)
        return _select(pts, ids, self.n_points, "charuco")

    def size_m(self) -> tuple[float, float]:
        return (self.cols * self.square, self.rows * self.square)

    def pattern(self, pixels_per_square: int = 64):
        """The board image (``generateImage``) as a :class:`PlaneTexture`, with a white quiet zone of one square."""
        return _texture(self.cv_board, self.size_m(), self.square, self.square / pixels_per_square)

    def describe(self) -> str:
        return (
            f"{self.rows}x{self.cols} charuco (squares), {self.square * 1e3:g} mm squares, "
            f"{self.marker * 1e3:g} mm markers, {self.dictionary}"
        )


@dataclass(frozen=True)
class ArucoGridTarget:
    """Grid of ``rows x cols`` ArUco/AprilTag markers of side ``marker`` [m] spaced by ``separation`` [m].

    ``first_id``: the first marker's id in ``dictionary`` (markers are
    numbered row by row from it). ``min_points``: fewest corners a view must
    show (default 8, two markers).
    """

    rows: int
    cols: int
    marker: float
    separation: float
    dictionary: str = "DICT_APRILTAG_36h11"
    first_id: int = 0
    min_points: int = 8

    kind = "aruco_grid"

    def __post_init__(self):
        object.__setattr__(self, "rows", _int_at_least(self.rows, "aruco_grid rows (markers)", 1))
        object.__setattr__(self, "cols", _int_at_least(self.cols, "aruco_grid cols (markers)", 1))
        object.__setattr__(self, "marker", _length(self.marker, "aruco_grid marker"))
        object.__setattr__(self, "separation", _length(self.separation, "aruco_grid separation"))
        object.__setattr__(self, "first_id", _int_at_least(self.first_id, "aruco_grid first_id", 0))
        d = aruco_dictionary(self.dictionary)
        last = self.first_id + self.rows * self.cols
        if last > _dict_size(d):
            raise InputError(
                f"a {self.rows}x{self.cols} grid from id {self.first_id} needs ids up to {last - 1}, "
                f"dictionary {self.dictionary} has {_dict_size(d)}"
            )
        object.__setattr__(self, "min_points", _int_at_least(self.min_points, "aruco_grid min_points", 4))

    @property
    def marker_ids(self) -> np.ndarray:
        return np.arange(self.first_id, self.first_id + self.rows * self.cols)

    @property
    def cv_board(self):
        return cv2.aruco.GridBoard(
            (self.cols, self.rows), self.marker, self.separation, aruco_dictionary(self.dictionary), self.marker_ids
        )

    @property
    def n_points(self) -> int:
        return 4 * self.rows * self.cols

    def object_points(self, ids=None) -> np.ndarray:
        """Marker corners ``ids`` (default all; id = 4 * marker index + corner) in the board frame, (N, 3) [m]."""
        m = np.arange(self.rows * self.cols)
        pitch = self.marker + self.separation
        x0, y0 = (m % self.cols) * pitch, (m // self.cols) * pitch
        dx = np.array([0.0, 1.0, 1.0, 0.0]) * self.marker
        dy = np.array([0.0, 0.0, 1.0, 1.0]) * self.marker
        pts = np.stack([(x0[:, None] + dx).ravel(), (y0[:, None] + dy).ravel(), np.zeros(4 * m.size)], axis=1)
        return _select(pts, ids, self.n_points, "aruco_grid")

    def size_m(self) -> tuple[float, float]:
        pitch = self.marker + self.separation
        return (self.cols * pitch - self.separation, self.rows * pitch - self.separation)

    def pattern(self, pixels_per_marker: int = 96):
        """The board image as a :class:`PlaneTexture`, with a white quiet zone of one separation (>= 1 module)."""
        bits = aruco_dictionary(self.dictionary).markerSize + 2
        texel = self.marker / (bits * max(1, round(pixels_per_marker / bits)))
        return _texture(self.cv_board, self.size_m(), max(self.separation, self.marker / bits), texel)

    def describe(self) -> str:
        return (
            f"{self.rows}x{self.cols} {self.dictionary} grid, {self.marker * 1e3:g} mm markers, "
            f"{self.separation * 1e3:g} mm apart"
        )


Target = Union[ChessboardTarget, CharucoTarget, ArucoGridTarget]
_TARGETS = (ChessboardTarget, CharucoTarget, ArucoGridTarget)


def _texture(cv_board, size_m, margin_m: float, texel_m: float) -> PlaneTexture:
    """``cv_board.generateImage`` laid on the board plane; the board's outer corner at the origin.

    The texel is chosen so the board size and margin are whole texels (the
    image's edges then fall exactly where the board frame says; marker bits
    may be rounded to a texel by ``generateImage`` when they do not divide).
    """
    w, h = size_m
    nx, ny = round(w / texel_m), round(h / texel_m)
    nm = max(1, round(margin_m / texel_m))
    img = cv_board.generateImage((nx + 2 * nm, ny + 2 * nm), marginSize=nm, borderBits=1)
    tx, ty = w / nx, h / ny
    return PlaneTexture(img, ((nx + 2 * nm) * tx, (ny + 2 * nm) * ty), origin=(-nm * tx, -nm * ty))


# -- target files ------------------------------------------------------------------------------------------

_KEYS = {
    "chessboard": ("type", "units", "rows", "cols", "square"),
    "charuco": ("type", "units", "rows", "cols", "square", "marker", "dictionary", "legacy", "min_points"),
    "aruco_grid": ("type", "units", "rows", "cols", "marker", "separation", "dictionary", "first_id", "min_points"),
}


def target_from_document(doc) -> Target:
    """A target from a :class:`robocal.io.Document` (the schema of :func:`load_target`)."""
    kind = doc.str("type", choices=tuple(_KEYS))
    doc.require_known_keys(_KEYS[kind])
    rows = doc.int("rows", minimum=1)
    cols = doc.int("cols", minimum=1)

    def length(key):
        return doc.float(key, kind="length", positive=True)

    try:
        if kind == "chessboard":
            return ChessboardTarget(rows, cols, length("square"))
        if kind == "charuco":
            kw = {}
            if "min_points" in doc:
                kw["min_points"] = doc.int("min_points", minimum=4)
            return CharucoTarget(
                rows, cols, length("square"), length("marker"), _dict_name(doc, "DICT_5X5_100"),
                doc.bool("legacy", default=False), **kw,
            )
        kw = {}
        if "min_points" in doc:
            kw["min_points"] = doc.int("min_points", minimum=4)
        return ArucoGridTarget(
            rows, cols, length("marker"), length("separation"), _dict_name(doc, "DICT_APRILTAG_36h11"),
            doc.int("first_id", default=0, minimum=0), **kw,
        )
    except InputError as exc:
        if exc.source:
            raise
        raise FileFormatError(exc.message, source=doc.source) from None


def _dict_name(doc, default: str) -> str:
    name = doc.str("dictionary", default=default)
    try:
        aruco_dictionary(name)
    except InputError as exc:
        raise doc.error("dictionary", exc.message) from None
    return name


def load_target(path) -> Target:
    """Read a target file (YAML or JSON).

    Schema (lengths as ``{value: 25, unit: mm}`` or plain numbers with a
    document-level ``units: {length: mm}``)::

        type: chessboard        # rows x cols INNER CORNERS
        rows: 6
        cols: 9
        square: {value: 25, unit: mm}

        type: charuco           # rows x cols SQUARES; optional legacy: false, min_points: 6
        rows: 7
        cols: 5
        square: {value: 40, unit: mm}
        marker: {value: 30, unit: mm}
        dictionary: DICT_5X5_100

        type: aruco_grid        # rows x cols MARKERS; optional first_id: 0, min_points: 8
        rows: 4
        cols: 6
        marker: {value: 40, unit: mm}
        separation: {value: 10, unit: mm}
        dictionary: DICT_APRILTAG_36h11

    Errors name the file and the field (``FileFormatError``/``UnitError``).
    """
    from robocal.io import load_document

    return target_from_document(load_document(Path(path)))


# -- rendering ---------------------------------------------------------------------------------------------


def visible_target_points(camera: CameraModel, target: Target, T_cam_board, *, margin: float = 0.0):
    """Ids and true image points [px] of the target's points in front of ``camera`` and inside its image.

    Returns ``(ids (N,), uv (N, 2))``, the truth a detection of a rendered view is compared with.
    """
    T = np.asarray(T_cam_board, dtype=float)
    p = target.object_points() @ T[:3, :3].T + T[:3, 3]
    ids = np.flatnonzero(p[:, 2] > 1e-9)
    uv = camera.project(p[ids], check=False)
    ok = camera.in_image(uv, margin=margin)
    return ids[ok], uv[ok]


def render_target_view(
    camera: CameraModel,
    target: Target,
    T_cam_board,
    rng: np.random.Generator | None = None,
    *,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    vignetting: float = 0.0,
    background: float = 128.0,
    black: float = 20.0,
    white: float = 235.0,
    supersample: int | None = None,
) -> np.ndarray:
    """Image of ``target`` at pose ``T_cam_board`` (board frame -> camera frame [m]), uint8 (height, width).

    Drawn by :func:`render_planar_target` (exact under distortion): a
    chessboard analytically, ChArUco and grid boards as their
    ``cv2.aruco`` ``generateImage`` texture (area-sampled, white quiet zone).
    Then ``vignetting`` (relative brightness loss at the image corners,
    gain ``1 - vignetting * (r / r_corner)^2`` about the principal point),
    Gaussian blur ``blur_sigma`` [px] and noise ``noise_sigma`` [grey levels]
    drawn from ``rng`` (required when ``noise_sigma > 0``).
    """
    if not isinstance(target, _TARGETS):
        raise InputError(f"target must be a ChessboardTarget, CharucoTarget or ArucoGridTarget, got {type(target).__name__}")
    v = float(vignetting)
    if not 0.0 <= v < 1.0:
        raise InputError(f"vignetting must be in [0, 1), got {vignetting!r}")
    img = render_planar_target(
        camera, T_cam_board, target.pattern(), supersample=supersample, background=background, black=black, white=white
    )
    img = img.astype(np.float64)
    if v > 0:
        u, w = np.meshgrid(np.arange(camera.width) - camera.cx, np.arange(camera.height) - camera.cy)
        corner = max(np.hypot(camera.cx, camera.cy), np.hypot(camera.width - camera.cx, camera.height - camera.cy))
        img *= 1.0 - v * (u**2 + w**2) / corner**2
    return add_blur_and_noise(img, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)
