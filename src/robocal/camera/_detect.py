"""Checkerboard detection with sub-pixel corners, in the board's own corner order.

OpenCV's detectors return the corner grid in an order that depends on the
view. :func:`detect_checkerboard` re-orders it to ``Checkerboard.object_points()``:

1. Among the grid's symmetries (reversals of rows / columns, transposition
   for square grids) keep those whose handedness matches a view of the
   printed face (board x then y turn clockwise in the image, as they do when
   the camera sees the side the board's z axis points away from).
2. Keep those where the outer square at corner 0 is black (the
   :class:`Checkerboard` convention), tested on the interior squares'
   brightness. For boards with rows + cols odd this leaves one ordering.
3. Boards with rows + cols even look the same after a 180-degree turn: two
   orderings remain. With ``expected_uv`` (e.g. corners predicted from a
   pose guess) the one closer to it is returned; otherwise the one whose
   corner 0 is nearer the image's top-left (smaller u + v). Without
   ``expected_uv`` such a board's orientation is therefore a convention, not
   a measurement; prefer a board with rows + cols odd.

With ``expected_uv`` steps 1-2 are skipped and all symmetries compete on
distance (so mirror images work too).
"""

from __future__ import annotations

import cv2
import numpy as np

from robocal.camera._targets import Checkerboard
from robocal.errors import DetectionError, InputError
from robocal.validation import check_array

__all__ = ["detect_checkerboard", "order_checkerboard_corners"]


def _grey(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        if img.dtype != np.uint8:
            raise InputError(f"colour image must be uint8, got {img.dtype}")
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.ndim != 2 or img.shape[0] < 8 or img.shape[1] < 8:
        raise InputError(f"image must be a grey (H, W) or colour (H, W, 3) image, got shape {img.shape}")
    if img.dtype != np.uint8:
        f = check_array(img, "image")
        if f.min() < 0 or f.max() > 255:
            raise InputError(f"image must be uint8 or float in 0..255, got range {f.min():g}..{f.max():g}")
        img = np.clip(np.rint(f), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img)


def _candidates(grid: np.ndarray, rows: int, cols: int):
    """The grid re-ordered by each symmetry compatible with (rows, cols)."""
    out = []
    bases = [grid]
    if rows == cols:
        bases.append(grid.transpose(1, 0, 2))
    for g in bases:
        for fr in (False, True):
            for fc in (False, True):
                h = g[::-1] if fr else g
                h = h[:, ::-1] if fc else h
                out.append(np.ascontiguousarray(h))
    return out


def _handedness(g: np.ndarray) -> float:
    """Median sign of (board x) cross (board y) in the image (u right, v down)."""
    vx = g[:-1, 1:] - g[:-1, :-1]
    vy = g[1:, :-1] - g[:-1, :-1]
    return float(np.median(vx[..., 0] * vy[..., 1] - vx[..., 1] * vy[..., 0]))


def _sample(blurred: np.ndarray, pts: np.ndarray) -> np.ndarray:
    m = pts.astype(np.float32).reshape(1, -1, 2)
    return cv2.remap(blurred, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(-1)


def _colour_ok(blurred: np.ndarray, g: np.ndarray) -> bool:
    """Interior square (a, b) of the corner grid is square (a+1, b+1) of the board: black iff a + b even.

    ``blurred``: the image under a 3x3 box filter (one noisy pixel does not decide a square).
    """
    centres = 0.25 * (g[:-1, :-1] + g[1:, :-1] + g[:-1, 1:] + g[1:, 1:])
    a, b = np.meshgrid(np.arange(centres.shape[0]), np.arange(centres.shape[1]), indexing="ij")
    val = _sample(blurred, centres.reshape(-1, 2)).astype(float)
    even = ((a + b) % 2 == 0).reshape(-1)
    return val[even].mean() < val[~even].mean()


def order_checkerboard_corners(image, corners, board: Checkerboard, expected_uv=None) -> np.ndarray:
    """Re-order detected corners (any grid order) to ``board.object_points()`` order (see module doc)."""
    c = check_array(corners, "corners", shape=(2,)).reshape(-1, 2)
    return c[_ordering(image, c, board, expected_uv)]


def _ordering(image, c: np.ndarray, board: Checkerboard, expected_uv=None) -> np.ndarray:
    """Index array ``perm`` (rows * cols,) such that ``c[perm]`` is in ``board.object_points()`` order."""
    rows, cols = board.rows, board.cols
    if c.shape[0] != rows * cols:
        raise InputError(f"corners must hold {rows * cols} points for a {rows}x{cols} board, got {c.shape[0]}")
    cands = _candidates(c.reshape(rows, cols, 2), rows, cols)
    perms = [p.reshape(-1) for p in _candidates(np.arange(rows * cols).reshape(rows, cols, 1), rows, cols)]
    if expected_uv is not None:
        e = check_array(expected_uv, "expected_uv", shape=(2,)).reshape(-1, 2)
        if e.shape[0] != rows * cols:
            raise InputError(f"expected_uv must have shape ({rows * cols}, 2), got {np.shape(expected_uv)}")
        d = [np.mean(np.sum((g.reshape(-1, 2) - e) ** 2, axis=1)) for g in cands]
        return perms[int(np.argmin(d))]
    img = _grey(image)
    keep = [k for k, g in enumerate(cands) if _handedness(g) > 0]
    blurred = cv2.blur(img, (3, 3)) if keep else img
    coloured = [k for k in keep if _colour_ok(blurred, cands[k])]
    keep = coloured or keep
    keep.sort(key=lambda k: float(cands[k][0, 0, 0] + cands[k][0, 0, 1]))
    return perms[keep[0]]


#: Gaussian pre-smoothing [px] of the refinement image: ``cornerSubPix`` is
#: biased on razor-sharp edges (few gradient pixels); a symmetric blur keeps
#: the saddle point where it is and spreads the gradient over the window.
REFINE_SMOOTHING_PX = 1.0
#: Largest half-window [px] of the refinement.
REFINE_MAX_HALF_WINDOW = 7
#: A refinement that moves a corner by this fraction of the corner spacing or more
#: has wandered off (the detector's own estimate is kept and the corner named).
REFINE_MAX_SHIFT = 0.25


#: With ``refine``, "classic" searches the image reduced first, to about this longer side [px]
#: (integer reduction ``ceil(side / DETECT_MAX_SIDE)``, area-averaged), then at half that reduction, ...,
#: down to full size, stopping where it finds the board; its corners only seed the sub-pixel
#: refinement on the full image, which converges to the same saddle points. ``cv2.findChessboardCorners``
#: is slow on large squares, not only on large images (measured, 9x6 board, one core: 2-5 ms a view
#: whose squares are ~20 px, 80-100 ms at 40-60 px in a 640x480 image, 0.6-1.3 s at 1280x960; at
#: 320x240 all of them 3-8 ms). A board too small for the reduced search is found at a finer step.
DETECT_MAX_SIDE = 400


def _detect_scales(shape) -> list[int]:
    """Reductions to search at, coarse to fine, ending with 1 (full size)."""
    s, out = max(1, int(np.ceil(max(shape[:2]) / DETECT_MAX_SIDE))), []
    while s > 1:
        out.append(s)
        s //= 2
    return out + [1]


#: A corner farther than this fraction of the corner spacing from where its grid neighbours put it
#: (parallelogram rule) is not on the grid: perspective and lens distortion bend a grid by a few per
#: cent of a square from one square to the next (measured up to 0.08 on 120 true 9x6 grids tilted by
#: up to 35 deg under k1 = -0.28).
GRID_TOLERANCE = 0.2


def _grid_outliers(corners: np.ndarray, board: Checkerboard) -> np.ndarray:
    """(rows * cols,) bool: corners off the grid their neighbours span.

    Each of the (up to four) grid cells a corner belongs to predicts it from
    the cell's three other corners, ``p = a + b - c`` (``c`` diagonal); a
    corner is off when even its best prediction misses by more than
    :data:`GRID_TOLERANCE` x the cell's shortest side.
    """
    g = corners.reshape(board.rows, board.cols, 2)
    best = np.full((board.rows, board.cols), np.inf)
    for dr in (-1, 1):
        for dc in (-1, 1):
            r0, r1 = max(0, -dr), board.rows - max(0, dr)
            c0, c1 = max(0, -dc), board.cols - max(0, dc)
            p = g[r0:r1, c0:c1]
            a, b, c = g[r0 + dr:r1 + dr, c0:c1], g[r0:r1, c0 + dc:c1 + dc], g[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
            side = np.minimum(np.linalg.norm(a - c, axis=-1), np.linalg.norm(b - c, axis=-1))
            with np.errstate(divide="ignore", invalid="ignore"):  # a collapsed cell: NaN, off the grid
                err = np.linalg.norm(a + b - c - p, axis=-1) / side
            best[r0:r1, c0:c1] = np.minimum(best[r0:r1, c0:c1], err)
    return ~(best <= GRID_TOLERANCE).reshape(-1)


def _refine_corners(img: np.ndarray, corners: np.ndarray, board: Checkerboard):
    """``cv2.cornerSubPix`` on the smoothed image; returns ``(corners (N, 2), shift (N,) [px],
    wandered (N,) bool)``.

    ``shift`` is how far the refinement moved each corner. A corner it moves by
    :data:`REFINE_MAX_SHIFT` x the corner spacing or more met something else (an edge,
    a reflection, a neighbour): it keeps the detector's estimate (pixel-level for
    "classic"), and :func:`detect_checkerboard` names it in its ``full_output``.
    """
    g = corners.reshape(board.rows, board.cols, 2)
    spacing = min(
        np.min(np.linalg.norm(np.diff(g, axis=0), axis=-1)),
        np.min(np.linalg.norm(np.diff(g, axis=1), axis=-1)),
    )
    # Half-window below 0.4 x the corner spacing keeps neighbouring corners out.
    win = int(np.clip(np.floor(0.4 * spacing), 2, REFINE_MAX_HALF_WINDOW))
    # Smooth only the board's region: every pixel an accepted corner's window reads (a move below
    # REFINE_MAX_SHIFT x spacing, the window, getRectSubPix's pixel and the Gaussian's 4-sigma radius)
    # gets the value it has on the whole image (a 1280x960 image costs 4 ms per view otherwise).
    m = int(np.ceil(REFINE_MAX_SHIFT * spacing)) + win + 2 + int(np.ceil(4 * REFINE_SMOOTHING_PX)) + 1
    h, w = img.shape
    lo = np.floor(np.nanmin(corners, axis=0)).astype(int) - m
    hi = np.ceil(np.nanmax(corners, axis=0)).astype(int) + m + 1
    c0, r0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    c1, r1 = min(int(hi[0]), w), min(int(hi[1]), h)
    smooth = cv2.GaussianBlur(img[r0:r1, c0:c1].astype(np.float32), (0, 0), REFINE_SMOOTHING_PX)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-5)
    start = (corners - [c0, r0]).astype(np.float32).reshape(-1, 1, 2)
    out = cv2.cornerSubPix(smooth, start, (win, win), (-1, -1), crit)
    out = out.reshape(-1, 2).astype(np.float64) + [c0, r0]
    shift = np.linalg.norm(out - corners, axis=1)
    wandered = ~(shift < REFINE_MAX_SHIFT * spacing)  # NaN counts as wandered
    return np.where(wandered[:, None], corners, out), shift, wandered


def detect_checkerboard(
    image,
    board: Checkerboard,
    *,
    expected_uv=None,
    refine: bool = True,
    method: str = "auto",
    full_output: bool = False,
):
    """Sub-pixel inner corners of ``board`` in ``image``, in ``board.object_points()`` order.

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, 3)
        Grey (uint8, or float 0..255) or BGR image.
    board : Checkerboard
    expected_uv : array_like, shape (rows * cols, 2), optional
        Predicted corners [px]; picks the ordering of a symmetric board (see
        the module doc).
    refine : bool
        Refine every corner with ``cv2.cornerSubPix`` on the image smoothed by
        a 1 px Gaussian (half-window up to 7 px, below 0.4 x the corner
        spacing). Without it, "sb" corners are OpenCV's own sub-pixel
        estimate and "classic" corners only pixel-accurate.
    method : {"auto", "classic", "sb"}
        ``"classic"``: ``cv2.findChessboardCorners`` (with ``refine``, on the
        image reduced first, see :data:`DETECT_MAX_SIDE`); ``"sb"``: ``cv2.findChessboardCornersSB``
        (sector-based, more robust on blurred/noisy/distorted images, ~0.1 s
        at 640x480); ``"auto"`` tries classic, then sb. After refinement both
        give the same corners.

    full_output : bool
        Also return a dict: ``"detector"`` (``"classic"`` or ``"sb"``, the one
        that found the board), ``"unrefined"`` (tuple of indices, in the
        returned order, of corners whose sub-pixel refinement wandered off by
        :data:`REFINE_MAX_SHIFT` (a quarter) of the corner spacing or more and
        that keep the detector's estimate: only pixel-accurate for
        ``"classic"``; a careful caller drops them or the view) and
        ``"refine_shift"`` (ndarray (rows * cols,) [px], returned order: how
        far the refinement moved each corner, the wandered ones included;
        zeros with ``refine=False``) and ``"scale"`` (the reduction at which
        the detector found the board, 1 = full size; a corner that wandered
        keeps the detector's estimate at that reduction, ~``scale / 2`` px).

    Returns
    -------
    ndarray, shape (rows * cols, 2) [px], OpenCV pixel-centre convention
        (and the dict when ``full_output``).

    Raises
    ------
    DetectionError
        The full board was not found.
    """
    if not isinstance(board, Checkerboard):
        raise InputError(f"board must be a robocal.camera.Checkerboard, got {type(board).__name__}")
    if board.rows < 3 or board.cols < 3:
        raise InputError(f"detection needs at least 3x3 inner corners, got {board.rows}x{board.cols}")
    if method not in ("auto", "sb", "classic"):
        raise InputError(f"method must be 'auto', 'classic' or 'sb', got {method!r}")
    img = _grey(image)
    size = board.pattern_size
    found, corners, detector, scale, refined = False, None, None, 1, None
    if method in ("auto", "classic"):
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        for scale in _detect_scales(img.shape) if refine else [1]:
            small = img if scale == 1 else cv2.resize(img, None, fx=1.0 / scale, fy=1.0 / scale,
                                                      interpolation=cv2.INTER_AREA)
            found, corners = cv2.findChessboardCorners(small, size, flags=flags)
            if not found or scale == 1:
                continue
            # a reduced pixel k averages full pixels scale*k .. scale*k + scale - 1 (pixel-centre convention)
            corners = corners.reshape(-1, 2).astype(np.float64) * scale + 0.5 * (scale - 1)
            refined = _refine_corners(img, corners, board)
            # A reduced corner out of the refinement's reach (inside a flat square) stays where it is
            # (measured once in 600 views: 9 px off, squares of 11 reduced px): the grid shows it; and one
            # whose refinement wandered from the reduced estimate may not from a finer one: search finer.
            if refined[2].any() or _grid_outliers(refined[0], board).any():
                found, refined = False, None
                continue
            break
        detector = "classic"
    if not found and method in ("auto", "sb"):
        # (CALIB_CB_ACCURACY would cost ~0.5 s; the refinement below does that job.)
        flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE
        found, corners = cv2.findChessboardCornersSB(img, size, flags=flags)
        detector, scale = "sb", 1
    if not found or corners is None or len(corners) != board.n_corners:
        raise DetectionError(
            f"no {board.rows}x{board.cols} checkerboard (inner corners) found in image "
            f"of size {img.shape[1]}x{img.shape[0]} (method {method!r})"
        )
    corners = corners.reshape(-1, 2).astype(np.float64)
    shift, wandered = np.zeros(len(corners)), np.zeros(len(corners), dtype=bool)
    if refined is not None:
        corners, shift, wandered = refined
    elif refine:
        corners, shift, wandered = _refine_corners(img, corners, board)
    perm = _ordering(img, corners, board, expected_uv)
    ordered = corners[perm]
    if not full_output:
        return ordered
    unrefined = tuple(int(i) for i in np.flatnonzero(wandered[perm]))
    return ordered, {"detector": detector, "unrefined": unrefined, "refine_shift": shift[perm], "scale": scale}
