"""Planar calibration targets and the planar-pattern protocol the renderer draws.

Target frame: origin at the first feature, x along the first row, y along the
columns (down the board when it faces the camera upright), z = x cross y,
pointing *away* from a camera that sees the printed face. Lengths in metres.

A *planar pattern* is any object with

* ``extent() -> (xmin, xmax, ymin, ymax)`` [m]: the plane region it draws;
* ``shade(x, y, dx, dy) -> (reflectance, alpha)``: reflectance in [0, 1]
  (0 black, 1 white) and coverage alpha in [0, 1] at plane points ``(x, y)``
  [m] whose sampling footprint is ``dx``, ``dy`` [m] along x and y (the
  pattern may use it to anti-alias edges analytically).

:func:`robocal.camera.render_planar_target` draws any of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError
from robocal.validation import check_array

__all__ = ["Checkerboard", "MarkerRectangle", "DotPattern", "PlaneTexture"]


def _positive(value, name: str) -> float:
    val = check_array(value, name)
    if val.ndim != 0 or not float(val) > 0:
        raise InputError(f"{name} must be a single number > 0, got {value!r}")
    return float(val)


def _ramp(d):
    """Coverage of a 1-sample-wide box by a half-plane at signed distance d [samples]."""
    return np.clip(d + 0.5, 0.0, 1.0)


@dataclass(frozen=True)
class Checkerboard:
    """Checkerboard with ``rows x cols`` inner corners and squares of side ``square`` [m].

    Board frame: corner ``(i, j)`` (row i, column j) is at ``(j * square,
    i * square, 0)``; ``object_points()`` lists them row by row, the order
    ``cv2.findChessboardCorners(image, (cols, rows))`` returns. The board has
    ``(cols + 1) x (rows + 1)`` squares; the outer square touching corner 0
    (spanning ``x, y in [-square, 0]``) is **black**, which fixes the
    orientation for boards without 180-degree symmetry (rows + cols odd).
    A white quiet zone of ``margin`` [m] (default one square) surrounds the
    squares when rendered.
    """

    rows: int
    cols: int
    square: float
    margin: float | None = None

    #: shade() anti-aliases its edges itself (the renderer needs no supersampling).
    analytic_aa = True

    def __post_init__(self):
        for name in ("rows", "cols"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 2:
                raise InputError(f"Checkerboard.{name} (inner corners) must be an integer >= 2, got {val!r}")
            object.__setattr__(self, name, int(val))
        object.__setattr__(self, "square", _positive(self.square, "Checkerboard.square [m]"))
        margin = self.square if self.margin is None else self.margin
        val = check_array(margin, "Checkerboard.margin [m]")
        if val.ndim != 0 or float(val) < 0:
            raise InputError(f"Checkerboard.margin [m] must be a single number >= 0, got {margin!r}")
        object.__setattr__(self, "margin", float(val))

    @classmethod
    def from_squares(cls, nx: int, ny: int, square: float, margin: float | None = None) -> "Checkerboard":
        """From the number of squares: ``nx`` along x (columns), ``ny`` along y; 5 x 7 squares -> 4 x 6 corners."""
        for name, val in (("nx", nx), ("ny", ny)):
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 3:
                raise InputError(f"Checkerboard.from_squares: {name} (squares) must be an integer >= 3, got {val!r}")
        return cls(rows=int(ny) - 1, cols=int(nx) - 1, square=square, margin=margin)

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)``: OpenCV's ``patternSize`` argument."""
        return (self.cols, self.rows)

    @property
    def n_corners(self) -> int:
        return self.rows * self.cols

    @property
    def squares_x(self) -> int:
        return self.cols + 1

    @property
    def squares_y(self) -> int:
        return self.rows + 1

    @property
    def symmetric(self) -> bool:
        """True when a 180-degree rotation maps the board onto itself (rows + cols even)."""
        return (self.rows + self.cols) % 2 == 0

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame, shape (rows * cols, 3) [m], row by row, z = 0."""
        j, i = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.stack([j.ravel() * self.square, i.ravel() * self.square, np.zeros(self.n_corners)], axis=1)

    def outline(self, *, with_margin: bool = False) -> np.ndarray:
        """Outer corners of the squared area (or of the quiet zone), shape (4, 3) [m].

        Order: ``(xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax)`` —
        clockwise in an image of the board's printed face.
        """
        xmin, xmax, ymin, ymax = self.extent() if with_margin else self._squares_extent()
        return np.array([[xmin, ymin, 0.0], [xmax, ymin, 0.0], [xmax, ymax, 0.0], [xmin, ymax, 0.0]])

    def _squares_extent(self):
        s = self.square
        return (-s, self.cols * s, -s, self.rows * s)

    def extent(self) -> tuple[float, float, float, float]:
        """Drawn region including the quiet zone: ``(xmin, xmax, ymin, ymax)`` [m]."""
        xmin, xmax, ymin, ymax = self._squares_extent()
        m = self.margin
        return (xmin - m, xmax + m, ymin - m, ymax + m)

    def black_squares(self) -> np.ndarray:
        """Corners of each black square, shape (M, 4, 3) [m], in :meth:`outline` order."""
        s = self.square
        out = []
        for a in range(self.squares_y):
            for b in range(self.squares_x):
                if (a + b) % 2 == 0:
                    x0, y0 = (b - 1) * s, (a - 1) * s
                    out.append([[x0, y0, 0], [x0 + s, y0, 0], [x0 + s, y0 + s, 0], [x0, y0 + s, 0]])
        return np.asarray(out, dtype=float)

    def square_is_black(self, a, b) -> np.ndarray:
        """Colour of square (row a, column b), 0-based over all squares (square (0, 0) is black)."""
        return (np.asarray(a) + np.asarray(b)) % 2 == 0

    def shade(self, x, y, dx, dy):
        """Reflectance and coverage (see the module doc); edges anti-aliased with a 1-sample box."""
        s = self.square

        def axis(q, n, d):
            # Square index clamped to the board, its parity, and the distance
            # [samples] to the nearest *interior* edge (the board's outer edge is
            # handled by the coverage ramp below, not as a colour change).
            k = np.clip(np.floor(q), 0, n - 1)
            left = np.where(k >= 1, q - k, np.inf)
            right = np.where(k + 1 <= n - 1, k + 1 - q, np.inf)
            e = np.minimum(left, right) * s / d
            parity = np.where(k % 2 == 0, 1.0, -1.0)
            return parity * (2.0 * _ramp(e) - 1.0)

        # Square coordinates: square (0, 0) spans [-1, 0) in units of s; a smooth
        # +-1 field per axis whose product is the board (+1: black).
        sx = axis(x / s + 1.0, self.squares_x, dx)
        sy = axis(y / s + 1.0, self.squares_y, dy)
        xmin, xmax, ymin, ymax = self._squares_extent()
        inside = _ramp(np.minimum(x - xmin, xmax - x) / dx) * _ramp(np.minimum(y - ymin, ymax - y) / dy)
        black = inside * (0.5 + 0.5 * sx * sy)
        refl = 1.0 - black
        # Coverage by the whole board (squares + quiet zone).
        Xmin, Xmax, Ymin, Ymax = self.extent()
        alpha = _ramp(np.minimum(x - Xmin, Xmax - x) / dx) * _ramp(np.minimum(y - Ymin, Ymax - y) / dy)
        return refl, alpha


@dataclass(frozen=True)
class MarkerRectangle:
    """Four markers at the corners of a ``width x height`` [m] rectangle.

    Corner order (target frame, x along the width, y along the height,
    origin at the first marker): ``0: (0, 0)``, ``1: (width, 0)``,
    ``2: (width, height)``, ``3: (0, height)`` — clockwise in an image of the
    front face (top-left, top-right, bottom-right, bottom-left when upright).
    ``marker_radius`` [m] (default 4 % of the shorter side) is used when
    drawing the markers as black discs.
    """

    width: float
    height: float
    marker_radius: float | None = None

    analytic_aa = True

    def __post_init__(self):
        object.__setattr__(self, "width", _positive(self.width, "MarkerRectangle.width [m]"))
        object.__setattr__(self, "height", _positive(self.height, "MarkerRectangle.height [m]"))
        r = 0.04 * min(self.width, self.height) if self.marker_radius is None else self.marker_radius
        object.__setattr__(self, "marker_radius", _positive(r, "MarkerRectangle.marker_radius [m]"))

    def object_points(self) -> np.ndarray:
        """The four corners, shape (4, 3) [m], z = 0, in the documented order."""
        w, h = self.width, self.height
        return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])

    corners = object_points

    def dots(self, radius: float | None = None) -> "DotPattern":
        """The markers as a :class:`DotPattern` (black discs on a transparent plane)."""
        return DotPattern(self.object_points()[:, :2], self.marker_radius if radius is None else radius)

    def extent(self):
        return self.dots().extent()

    def shade(self, x, y, dx, dy):
        return self.dots().shade(x, y, dx, dy)


class DotPattern:
    """Discs of ``radius`` [m] at plane points ``centers`` (N, 2) [m]; transparent elsewhere.

    ``reflectance`` is the discs' grey (0 black). Useful for marker dots,
    feature points, retro-reflectors.
    """

    analytic_aa = True

    def __init__(self, centers, radius: float, reflectance: float = 0.0):
        c = check_array(centers, "centers", shape=("N", 2))
        if c.ndim != 2 or c.shape[0] < 1:
            raise InputError(f"centers must have shape (N, 2) with N >= 1, got {c.shape}")
        self.centers = c
        self.radius = _positive(radius, "radius [m]")
        self.reflectance = float(reflectance)

    def extent(self):
        r = self.radius
        return (
            float(self.centers[:, 0].min() - r),
            float(self.centers[:, 0].max() + r),
            float(self.centers[:, 1].min() - r),
            float(self.centers[:, 1].max() + r),
        )

    def shade(self, x, y, dx, dy):
        foot = 0.5 * (dx + dy)
        alpha = np.zeros(np.shape(x))
        for cx, cy in self.centers:
            d = (self.radius - np.hypot(x - cx, y - cy)) / foot
            alpha = np.maximum(alpha, _ramp(d))
        return np.full(np.shape(x), self.reflectance), alpha


class PlaneTexture:
    """An image laid on the plane: pixel (row i, col j) covers ``origin + ([j, j+1] * sx, [i, i+1] * sy)``.

    Parameters
    ----------
    image : array_like, shape (H, W)
        Grey texture, uint8 (0..255) or float in [0, 1].
    size : float or (float, float)
        Physical width (and height) of the whole texture [m]; one number
        keeps the pixels square.
    origin : (float, float)
        Plane coordinates of the texture's top-left corner [m]. Texture
        columns run along +x, rows along +y.
    interpolation : {"nearest", "linear"}
        "nearest" is exact area-sampling of a piecewise-constant texture
        (markers, ArUco/AprilTag images); "linear" suits photographs.
    """

    analytic_aa = False

    def __init__(self, image, size, origin=(0.0, 0.0), interpolation: str = "nearest"):
        img = np.asarray(image)
        if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
            raise InputError(f"texture image must be a 2-D grey image (H, W), got shape {img.shape}")
        tex = img.astype(float) / 255.0 if img.dtype == np.uint8 else check_array(img, "texture image")
        if np.any(tex < 0) or np.any(tex > 1):
            raise InputError("texture image must be uint8 or float in [0, 1]")
        self.texture = tex
        size = np.atleast_1d(np.asarray(size, dtype=float))
        if size.shape == (1,):
            size = np.array([size[0], size[0] * tex.shape[0] / tex.shape[1]])
        if size.shape != (2,) or np.any(~(size > 0)):
            raise InputError(f"texture size must be a width [m] or (width, height) > 0, got {size.tolist()}")
        self.size = (float(size[0]), float(size[1]))
        o = check_array(origin, "origin", shape=(2,))
        self.origin = (float(o[0]), float(o[1]))
        if interpolation not in ("nearest", "linear"):
            raise InputError(f"interpolation must be 'nearest' or 'linear', got {interpolation!r}")
        self.interpolation = interpolation

    def extent(self):
        x0, y0 = self.origin
        return (x0, x0 + self.size[0], y0, y0 + self.size[1])

    def shade(self, x, y, dx, dy):
        import cv2

        h, w = self.texture.shape
        x0, y0 = self.origin
        # Texture pixel coordinates in OpenCV's centre convention.
        with np.errstate(invalid="ignore"):
            mx = (x - x0) / self.size[0] * w - 0.5
            my = (y - y0) / self.size[1] * h - 0.5
        # Points off the plane (inf/NaN) read the border; their alpha is 0 anyway.
        mx = np.where(np.isfinite(mx), np.clip(mx, -2.0, w + 1.0), -2.0).astype(np.float32)
        my = np.where(np.isfinite(my), np.clip(my, -2.0, h + 1.0), -2.0).astype(np.float32)
        inter = cv2.INTER_NEAREST if self.interpolation == "nearest" else cv2.INTER_LINEAR
        if self.interpolation == "nearest":
            # floor(m + 0.5) is the texel covering the point (no rounding-mode surprises).
            mx = np.floor(mx + 0.5)
            my = np.floor(my + 0.5)
        # cv2.remap maps must be 2-D with sides < 32767: lay the samples out in rows of 4096.
        n = mx.size
        width = 4096
        pad = (-n) % width
        fx = np.concatenate([mx.ravel(), np.zeros(pad, np.float32)]).reshape(-1, width)
        fy = np.concatenate([my.ravel(), np.zeros(pad, np.float32)]).reshape(-1, width)
        val = cv2.remap(self.texture.astype(np.float32), fx, fy, inter, borderMode=cv2.BORDER_REPLICATE)
        val = val.ravel()[:n].reshape(np.shape(x))
        xmin, xmax, ymin, ymax = self.extent()
        alpha = _ramp(np.minimum(x - xmin, xmax - x) / dx) * _ramp(np.minimum(y - ymin, ymax - y) / dy)
        return val.astype(float), alpha
