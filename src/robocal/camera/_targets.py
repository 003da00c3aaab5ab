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
        "nearest": the texture is piecewise constant (markers, ArUco/AprilTag
        images) and each render sample gets its exact area average over the
        sample's footprint box (``dx`` x ``dy`` around the sample, see the
        module doc): texel edges are box-filtered like a
        :class:`Checkerboard`'s, so an edge lands where it is, not on the
        sub-sample grid (point sampling put an edge parallel to the pixel
        grid up to 1/(2 s) px off, 0.125 px at s = 4; now 0.0014 px, the
        uint8 output's rounding, and < 0.01 px for slanted edges at s >= 2).
        Footprints wider than a texel (a minified
        texture) are averaged exactly too (summed-area table).
        "linear": bilinear point samples, for photographs.
        "point": the texel under each sample point, no area average (what
        "nearest" did before; aliased, kept to reproduce and compare).
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
        if interpolation not in ("nearest", "linear", "point"):
            raise InputError(f"interpolation must be 'nearest', 'linear' or 'point', got {interpolation!r}")
        self.interpolation = interpolation

    def extent(self):
        x0, y0 = self.origin
        return (x0, x0 + self.size[0], y0, y0 + self.size[1])

    def shade(self, x, y, dx, dy):
        xmin, xmax, ymin, ymax = self.extent()
        with np.errstate(invalid="ignore"):
            alpha = _ramp(np.minimum(x - xmin, xmax - x) / dx) * _ramp(np.minimum(y - ymin, ymax - y) / dy)
        if self.interpolation == "nearest":
            return self._box_average(x, y, dx, dy), alpha
        if self.interpolation == "point":
            h, w = self.texture.shape
            px, py, _, _ = self._texel_coords(x, y, dx, dy)
            i = np.clip(np.floor(py), 0, h - 1).astype(np.intp)
            j = np.clip(np.floor(px), 0, w - 1).astype(np.intp)
            return self.texture[i, j], alpha
        return self._bilinear(x, y), alpha

    def _texel_coords(self, x, y, dx, dy):
        """Sample centres and footprint widths in texel units (texel k covers [k, k + 1)); off-plane -> -1."""
        h, w = self.texture.shape
        x0, y0 = self.origin
        kx, ky = w / self.size[0], h / self.size[1]
        with np.errstate(invalid="ignore", over="ignore"):
            # Points off the plane (the renderer passes inf) read the border; their alpha is 0 anyway.
            px = np.asarray(np.clip((np.asarray(x, dtype=float) - x0) * kx, -2.0, w + 2.0))
            py = np.asarray(np.clip((np.asarray(y, dtype=float) - y0) * ky, -2.0, h + 2.0))
            wx = np.asarray(np.abs(np.asarray(dx, dtype=float)) * kx)
            wy = np.asarray(np.abs(np.asarray(dy, dtype=float)) * ky)
        for a, fill in ((px, -1.0), (py, -1.0), (wx, 0.0), (wy, 0.0)):
            bad = ~np.isfinite(a)
            if bad.any():
                a[bad] = fill
        return px, py, wx, wy

    def _box_average(self, x, y, dx, dy):
        """Exact mean of the piecewise-constant texture over the box ``(x, y) +- (dx, dy) / 2``.

        A box reaching off the texture gets the mean over its part on the
        texture (``alpha`` is the covered fraction). A box at most one texel
        wide along both axes meets at most 2 x 2 texels: their overlap
        fractions weight them (float64, no interpolation-grid quantisation).
        Wider boxes use a summed-area table, whose bilinear interpolation is
        exact for a piecewise-constant texture.
        """
        px, py, wx, wy = self._texel_coords(x, y, dx, dy)
        shape = np.broadcast_shapes(px.shape, py.shape, wx.shape, wy.shape)
        small = (wx <= 1.0) & (wy <= 1.0)
        if small.all():
            out = self._two_by_two(px, py, wx, wy)
            return out if out.shape == shape else np.broadcast_to(out, shape).copy()
        px, py, wx, wy = (np.broadcast_to(a, shape) for a in (px, py, wx, wy))
        small = np.broadcast_to(small, shape)
        out = np.empty(shape)
        if small.any():
            out[small] = self._two_by_two(px[small], py[small], wx[small], wy[small])
        big = ~small
        out[big] = self._sat_average(px[big], py[big], wx[big], wy[big])
        return out

    def _two_by_two(self, px, py, wx, wy):
        """Box mean for boxes at most one texel wide: the 2 x 2 texels met, weighted by their overlap."""
        h, w = self.texture.shape
        flat = self.texture.ravel()
        ix, fx = _box_axis(px, wx)
        iy, fy = _box_axis(py, wy)
        ix0, ix1 = np.clip(ix, 0, w - 1), np.clip(ix + 1, 0, w - 1)
        r0, r1 = np.clip(iy, 0, h - 1) * w, np.clip(iy + 1, 0, h - 1) * w
        t01 = flat.take(r0 + ix1)
        top = t01 + fx * (flat.take(r0 + ix0) - t01)
        t11 = flat.take(r1 + ix1)
        bottom = t11 + fx * (flat.take(r1 + ix0) - t11)
        return bottom + fy * (top - bottom)

    def _sat_average(self, px, py, wx, wy):
        """Box mean via the summed-area table over the part of the box on the texture."""
        tex = self.texture
        h, w = tex.shape
        sat = getattr(self, "_sat", None)
        if sat is None:
            sat = np.zeros((h + 1, w + 1))
            sat[1:, 1:] = tex.cumsum(axis=0).cumsum(axis=1)
            self._sat = sat
        x_lo, x_hi = _clip_box(px - 0.5 * wx, px + 0.5 * wx, w)
        y_lo, y_hi = _clip_box(py - 0.5 * wy, py + 0.5 * wy, h)

        flat, stride = sat.ravel(), w + 1

        def integral(u, v):  # bilinear read of the SAT at (u, v): exact, the integral is bilinear in each texel
            i = np.clip(np.floor(u).astype(np.intp), 0, w - 1)
            j = np.clip(np.floor(v).astype(np.intp), 0, h - 1)
            a, b = u - i, v - j
            k = j * stride + i
            s00, s01, s10, s11 = flat.take(k), flat.take(k + 1), flat.take(k + stride), flat.take(k + stride + 1)
            top = s00 + a * (s01 - s00)
            return top + b * (s10 + a * (s11 - s10) - top)

        total = integral(x_hi, y_hi) - integral(x_lo, y_hi) - integral(x_hi, y_lo) + integral(x_lo, y_lo)
        return total / ((x_hi - x_lo) * (y_hi - y_lo))

    def _bilinear(self, x, y):
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
        # cv2.remap maps must be 2-D with sides < 32767: lay the samples out in rows of 4096.
        n = mx.size
        width = 4096
        pad = (-n) % width
        fx = np.concatenate([mx.ravel(), np.zeros(pad, np.float32)]).reshape(-1, width)
        fy = np.concatenate([my.ravel(), np.zeros(pad, np.float32)]).reshape(-1, width)
        val = cv2.remap(self.texture.astype(np.float32), fx, fy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return val.ravel()[:n].reshape(np.shape(x)).astype(float)


def _box_axis(p, wd):
    """Box ``p +- wd / 2`` (texel units, ``wd <= 1``) on one axis: first texel ``k`` it meets and its share.

    The box meets texels ``k = floor(p - wd / 2)`` and ``k + 1``; the share of
    texel ``k`` is ``(k + 1 - (p - wd / 2)) / wd`` clipped to [0, 1] (a
    zero-width box is a point sample).
    """
    lo = p - 0.5 * wd
    k = np.floor(lo)
    share = np.minimum((k + 1.0 - lo) / np.maximum(wd, 1e-12), 1.0)  # k + 1 - lo is in (0, 1]
    return k.astype(np.intp), share


def _clip_box(lo, hi, n):
    """Clip ``[lo, hi]`` to ``[0, n]``; a box off the texture becomes its nearest border texel's span."""
    lo_c = np.clip(lo, 0.0, float(n))
    hi_c = np.clip(hi, 0.0, float(n))
    empty = hi_c - lo_c <= 0.0
    left = hi <= 0.0
    lo_c = np.where(empty, np.where(left, 0.0, n - 1.0), lo_c)
    hi_c = np.where(empty, np.where(left, 1.0, float(n)), hi_c)
    return lo_c, hi_c
