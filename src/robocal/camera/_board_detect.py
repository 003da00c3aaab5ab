"""Detection of calibration targets (:mod:`robocal.camera._boards`) in images, with named view quality.

A view that cannot serve a calibration is named with its reason (too few
points, collinear, blurred, duplicate, a marker layout that is not the printed
board), never silently used or dropped; a board found in no image is retried
with the likely slips of the target file (rows/cols counting squares, swapped,
legacy ChArUco layout) and the one that fits is named.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from robocal.camera._boards import (_TARGETS, ArucoGridTarget, CharucoTarget, ChessboardTarget, Target, _dict_size,
                                    aruco_dictionary)
from robocal.camera._targets import Checkerboard
from robocal.camera._view_quality import (BLUR_LIMIT_PX, LAYOUT_LIMIT, LAYOUT_MEDIAN_LIMIT, _edge_blur,  # noqa: F401
                                           _grid_layout_error, _quality, _spacing)
from robocal.camera._detect import REFINE_MAX_HALF_WINDOW, REFINE_SMOOTHING_PX, _grey, detect_checkerboard
from robocal.errors import DetectionError, InconsistentDataError, InputError

__all__ = [
    "TargetDetection",
    "DetectionSet",
    "detect_target",
    "detect_targets",
    "BLUR_LIMIT_PX",
    "DUPLICATE_LIMIT_PX",
    "LAYOUT_LIMIT",
    "LAYOUT_MEDIAN_LIMIT",
]

#: A ChArUco corner is re-refined (see ``_detect_charuco``) where the white gap to the nearest marker
#: is at least this wide [px]; measured on tilted partial views (blur 0.7 px): at 3-4 px the re-refinement
#: moved corners by up to 1.5 px (view RMS 0.14 vs 0.067 px for OpenCV's), from 4 px on it halves
#: OpenCV's error (1280x960: 0.028 vs 0.049 px RMS).
CHARUCO_MIN_GAP_PX = 4.0
#: Two views whose common corners are within this RMS distance [px] are duplicates (the second is dropped).
DUPLICATE_LIMIT_PX = 2.0


# -- detection ---------------------------------------------------------------------------------------------


@dataclass(eq=False)
class TargetDetection:
    """The target's points found in one image.

    ``name``, ``object_points`` (N, 3) [m, board frame], ``image_points`` (N, 2)
    [px] and ``ids`` (N,) are the fields of ``robocal.camera.TargetView``.
    Quality: ``image_size`` (width, height) [px]; ``blur_px`` — edge blur
    estimated at the points (Gaussian sigma [px], ~0.8 on a sharp render,
    ~sqrt(sigma^2 + 0.8^2) for an optical blur sigma);
    ``detector`` — what found it; ``issues`` — named reasons not to use the
    view (``"too_few_points: ..."``, ``"collinear: ..."``, ``"blurred: ..."``,
    ``"duplicate: ..."``), empty for a usable view; ``notes`` — things worth
    saying that do not disqualify it.
    """

    name: str
    object_points: np.ndarray
    image_points: np.ndarray
    ids: np.ndarray
    image_size: tuple[int, int] = (0, 0)
    blur_px: float = float("nan")
    detector: str = ""
    issues: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def usable(self) -> bool:
        return not self.issues

    @property
    def n_points(self) -> int:
        return int(self.ids.size)

    def reason(self) -> str:
        """One line: why the view is not used ("" when it is)."""
        return "; ".join(self.issues)

    def to_view(self):
        """This detection as the estimator's ``robocal.camera.TargetView`` (name, points, ids)."""
        from robocal.camera._calibrate import TargetView

        return TargetView(self.name, self.object_points, self.image_points, self.ids)


def _grid_spacing(ids: np.ndarray, uv: np.ndarray, cols: int) -> np.ndarray:
    """Per point of a ``cols``-wide id grid: distance [px] to its nearest detected 4-neighbour (NaN: none seen)."""
    rows = int(ids.max()) // cols + 1 if ids.size else 0
    g = np.full((rows + 2, cols + 2, 2), np.nan)  # one NaN ring: every point has four neighbour slots
    r, c = ids // cols + 1, ids % cols + 1
    g[r, c] = uv
    d = np.stack([np.linalg.norm(g[r + dr, c + dc] - uv, axis=1) for dr, dc in ((0, 1), (0, -1), (1, 0), (-1, 0))])
    with np.errstate(all="ignore"):
        return np.where(np.isnan(d).all(axis=0), np.nan, np.nanmin(np.where(np.isnan(d), np.inf, d), axis=0))


def _detect_chessboard(img, target: ChessboardTarget):
    corners, info = detect_checkerboard(img, target.board, full_output=True)
    ids = np.arange(target.n_points)
    keep = np.ones(ids.size, dtype=bool)
    keep[list(info["unrefined"])] = False
    notes = []
    if not keep.all():
        notes.append(f"dropped {int((~keep).sum())} corners whose refinement wandered off")
    return ids[keep], corners[keep], info["detector"], notes


def _aruco_params():
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return p


def _refine_in_gaps(image, uv, which, half, gap, crit) -> None:
    """``cornerSubPix`` of the corners ``which`` of ``uv`` (in place), each with its own half-window ``half``
    [px]; a corner that moves by half its ``gap`` or more has left its saddle and keeps its start."""
    for h in np.unique(half[which]):
        sel = which & (half == h)
        start = uv[sel].astype(np.float32).reshape(-1, 1, 2)
        fine = cv2.cornerSubPix(image, start, (int(h), int(h)), (-1, -1), crit).reshape(-1, 2).astype(float)
        moved = np.linalg.norm(fine - uv[sel], axis=1) < 0.5 * gap[sel]
        uv[sel] = np.where(moved[:, None], fine, uv[sel])


def _detect_charuco(img, target: CharucoTarget):
    cd = cv2.aruco.CharucoDetector(target.cv_board)
    cd.setDetectorParameters(_aruco_params())
    corners, ids, _, marker_ids = cd.detectBoard(img)
    if ids is None or len(ids) == 0:
        return None
    ids = ids.reshape(-1).astype(int)
    order = np.argsort(ids)
    ids, uv = ids[order], corners.reshape(-1, 2)[order].astype(float)
    # Re-refine as detect_checkerboard does (cornerSubPix on a 1 px Gaussian-smoothed image:
    # unbiased on sharp saddles), with the half-window inside the white gap between a corner and
    # the nearest marker edge so the markers do not pull the corner (measured on a close partial
    # view: 0.17 px RMS with OpenCV's refinement alone). The gap is each corner's own (a tilted
    # board's far squares are smaller than its near ones); where it is under CHARUCO_MIN_GAP_PX the
    # smoothed marker edges reach into any window and OpenCV's corner is kept.
    gap = 0.5 * (target.square - target.marker) / target.square * _grid_spacing(ids, uv, target.cols - 1)
    todo = gap >= CHARUCO_MIN_GAP_PX
    if todo.any():
        half = np.minimum(np.floor(0.8 * np.where(todo, gap, 0.0)), REFINE_MAX_HALF_WINDOW).astype(int)
        smooth = cv2.GaussianBlur(img.astype(np.float32), (0, 0), REFINE_SMOOTHING_PX)
        _refine_in_gaps(smooth, uv, todo, half, gap, (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-5))
    # Where the gap is narrow, OpenCV's own corner is kept, but OpenCV < 4.11 refined it with a fixed window
    # that reaches the markers (a steep view: 0.69 px RMS on 4.10, 0.19 on 4.14): a window inside the gap,
    # on the unsmoothed image, gives 4.10 what 4.11+ does.
    narrow = ~todo & np.isfinite(gap) & (gap >= 1.5)
    if narrow.any() and tuple(int(v) for v in cv2.__version__.split(".")[:2]) < (4, 11):
        half = np.maximum(np.floor(0.8 * np.where(narrow, gap, 0.0)), 1).astype(int)
        _refine_in_gaps(img.astype(np.float32), uv, narrow, half, gap,
                        (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
    return ids, uv, "charuco", []


def _refine_marker_edges(img: np.ndarray, quad: np.ndarray, bit_px: float) -> np.ndarray | None:
    """Marker corners (4, 2) [px] as the intersections of its four outer edges, fitted to sub-pixel edge points.

    ``cornerSubPix`` on an L-shaped corner (a marker's outer corner) is
    pulled inwards by blur: measured 0.28 / 0.42 / 0.63 px RMS at blur
    0 / 0.7 / 1.5 px (640x480, 40 mm 36h11 markers at 0.55 m, ~5.5 px per
    bit). A symmetrically blurred step crosses the mid-level where the edge
    is, so each side is located along its normal (middle 60 % of the side,
    where the neighbouring sides do not interfere; mid-level between the
    border bit's centre and half a bit outside), a line is fitted through it
    and adjacent lines are intersected: 0.03 / 0.05 / 0.19 px RMS on the same
    views (at 1.5 px blur the data bits next to the border leak into the
    levels). Returns None when an edge
    is not found (the caller keeps the detector's corners).
    """
    r = max(0.5 * bit_px, 1.0)
    offs = np.linspace(-r, r, 2 * int(np.ceil(4 * r)) + 1)
    lines = []
    for k in range(4):
        a, b = quad[k], quad[(k + 1) % 4]
        length = float(np.linalg.norm(b - a))
        if length < 8:
            return None
        t = (b - a) / length
        n = np.array([-t[1], t[0]])
        m = max(5, int(length / 2))
        base = a + np.linspace(0.2, 0.8, m)[:, None] * (b - a)
        pts = base[:, None, :] + offs[None, :, None] * n
        val = cv2.remap(img, pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).astype(float)
        # Mid-level crossing between the border bit's centre and the white beyond it: where a
        # symmetrically blurred step is half-way (a gradient peak on bilinear samples is flat-topped).
        dev = val - 0.5 * (val[:, :1] + val[:, -1:])
        cross = np.signbit(dev[:, :-1]) != np.signbit(dev[:, 1:])
        centre = np.abs(np.arange(cross.shape[1]) + 0.5 - 0.5 * (len(offs) - 1))
        score = np.where(cross, centre, np.inf)
        j = np.argmin(score, axis=1)
        ok = np.isfinite(score[np.arange(len(j)), j]) & (np.abs(val[:, 0] - val[:, -1]) > 10)
        if ok.sum() < 3:
            return None
        rows = np.flatnonzero(ok)
        d0, d1 = dev[rows, j[ok]], dev[rows, j[ok] + 1]
        s = offs[j[ok]] + d0 / (d0 - d1) * (offs[1] - offs[0])
        edge = base[rows] + s[:, None] * n
        c = edge.mean(axis=0)
        _, _, vt = np.linalg.svd(edge - c)
        lines.append((c, vt[0]))
    out = np.empty((4, 2))
    for k in range(4):
        (p1, d1), (p2, d2) = lines[k - 1], lines[k]
        A = np.column_stack([d1, -d2])
        if abs(np.linalg.det(A)) < 1e-6:
            return None
        s1, _ = np.linalg.solve(A, p2 - p1)
        out[k] = p1 + s1 * d1
    return out


def _detect_grid(img, target: ArucoGridTarget):
    board = target.cv_board
    det = cv2.aruco.ArucoDetector(aruco_dictionary(target.dictionary), _aruco_params())
    corners, mids, rejected = det.detectMarkers(img)
    if mids is None or len(mids) == 0:
        return None
    corners, mids, _, _ = det.refineDetectedMarkers(img, board, corners, mids, rejected)
    mids = mids.reshape(-1)
    index = {int(m): k for k, m in enumerate(target.marker_ids)}
    bits = aruco_dictionary(target.dictionary).markerSize + 2
    # Light smoothing so one noisy pixel does not make the gradient peak; symmetric, so edges stay put.
    smooth = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 0.7)
    ids, uv = [], []
    for c, m in zip(corners, mids):
        k = index.get(int(m))
        if k is None:
            continue  # a marker of the dictionary that is not on this board
        quad = c.reshape(4, 2).astype(float)
        bit_px = np.sqrt(abs(cv2.contourArea(quad.astype(np.float32)))) / bits
        fine = _refine_marker_edges(smooth, quad, bit_px)
        # A refinement that moves a corner by more than half a bit met something else: keep the detector's.
        if fine is not None and np.all(np.linalg.norm(fine - quad, axis=1) < 0.5 * bit_px):
            quad = fine
        ids.extend(4 * k + np.arange(4))
        uv.append(quad)
    if not ids:
        return None
    ids = np.asarray(ids)
    uv = np.concatenate(uv).astype(float)
    # A marker id seen twice (a reflection, another board) is ambiguous: drop both.
    uniq, count = np.unique(ids, return_counts=True)
    notes = []
    if (count > 1).any():
        bad = np.isin(ids, uniq[count > 1])
        notes.append(f"dropped markers seen twice: {sorted({int(i) // 4 + target.first_id for i in ids[bad]})}")
        ids, uv = ids[~bad], uv[~bad]
    order = np.argsort(ids)
    return ids[order], uv[order], "aruco", notes


def detect_target(image, target: Target, *, name: str = "image", blur_limit: float = BLUR_LIMIT_PX):
    """The points of ``target`` in ``image``; ``None`` when the target is not found at all.

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, 3)
        Grey or BGR image (uint8, or float 0..255).
    target : ChessboardTarget, CharucoTarget or ArucoGridTarget
    name : str
        The view's name (the image file) used in messages.
    blur_limit : float
        Edge blur [px] above which the view is named ``blurred``.

    Returns
    -------
    TargetDetection or None
        Points sorted by id. Chessboard: through :func:`detect_checkerboard`
        (whole board, sub-pixel refined; corners whose refinement wandered off
        are dropped and noted). ChArUco: ``cv2.aruco.CharucoDetector`` (any
        subset of corners). Grid: ``cv2.aruco.ArucoDetector`` with sub-pixel
        corner refinement and ``refineDetectedMarkers`` (four corners per
        marker). A detection with ``issues`` is returned, not dropped: the
        caller names it.
    """
    if not isinstance(target, _TARGETS):
        raise InputError(f"target must be a ChessboardTarget, CharucoTarget or ArucoGridTarget, got {type(target).__name__}")
    img = _grey(image)
    if target.kind == "chessboard":
        try:
            found = _detect_chessboard(img, target)
        except DetectionError:
            found = None
    elif target.kind == "charuco":
        found = _detect_charuco(img, target)
    else:
        found = _detect_grid(img, target)
    if found is None:
        return None
    ids, uv, detector, notes = found
    det = TargetDetection(
        name, target.object_points(ids), uv, ids, (img.shape[1], img.shape[0]), detector=detector, notes=notes
    )
    _quality(det, img, target, blur_limit)
    return det


@dataclass(eq=False)
class DetectionSet:
    """Detections over a set of images.

    ``detections``: one per image in which the target was found (usable or
    not); ``missing``: names of images without it; ``image_size``: (width,
    height) shared by all; ``notes``: set-level findings (e.g. a chessboard
    whose rows/cols look transposed).
    """

    detections: list
    missing: list
    image_size: tuple[int, int]
    notes: list = field(default_factory=list)

    @property
    def views(self) -> list:
        """The usable detections (``TargetView``-compatible)."""
        return [d for d in self.detections if d.usable]

    def target_views(self) -> list:
        """The usable views as ``TargetView`` objects, for :func:`robocal.camera.calibrate_intrinsics`."""
        return [d.to_view() for d in self.views]

    @property
    def rejected(self) -> dict:
        """``{name: reason}`` of every image not used (target missing or view unusable)."""
        out = {n: "target not found" for n in self.missing}
        out.update({d.name: d.reason() for d in self.detections if not d.usable})
        return out


def _mark_duplicates(dets: list, limit: float) -> None:
    """Name each usable view whose corners repeat an earlier kept view's (see :func:`detect_targets`)."""
    usable = [d for d in dets if d.usable and d.n_points]
    if not usable:
        return
    n = 1 + max(int(d.ids.max()) for d in usable)
    # each kept view's points by id (NaN where unseen): one comparison against all kept views at once
    grid = np.full((len(usable), n, 2), np.nan)
    counts, kept = np.zeros(len(usable)), []
    for d in usable:
        k = len(kept)
        uv = np.full((n, 2), np.nan)
        uv[d.ids] = d.image_points
        if k:
            both = ~np.isnan(grid[:k, :, 0]) & ~np.isnan(uv[:, 0])
            common = both.sum(axis=1)
            sq = np.where(both, np.sum((grid[:k] - uv) ** 2, axis=-1), 0.0).sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                rms = np.sqrt(sq / common)
            dup = (common >= 0.8 * np.maximum(d.n_points, counts[:k])) & (rms < limit)
            if dup.any():
                j = int(np.argmax(dup))  # the first kept view it repeats
                d.issues.append(f"duplicate: same corners as {kept[j].name} (RMS {rms[j]:.2f} px < {limit:g} px)")
                continue
        grid[k], counts[k] = uv, d.n_points
        kept.append(d)


def _x_runs_down(d: TargetDetection, target: ChessboardTarget) -> bool:
    """True when the board's x axis (along a row) runs more vertically than horizontally in the image."""
    g = np.full((target.n_points, 2), np.nan)
    g[d.ids] = d.image_points
    g = g.reshape(target.rows, target.cols, 2)
    vx = np.nanmean(g[:, -1] - g[:, 0], axis=0)
    return bool(abs(vx[1]) > abs(vx[0]))


def _chessboard_alternatives(target: ChessboardTarget):
    r, c = target.rows, target.cols
    yield (r - 1, c - 1), "rows/cols count squares, not inner corners"
    yield (r + 1, c + 1), "rows/cols count one fewer than the inner corners"
    yield (r - 1, c), "rows counts squares, not inner corners"
    yield (r, c - 1), "cols counts squares, not inner corners"


def _layout_alternatives(target, seen_ids=None):
    """Likely slips in a ChArUco or grid target file: ``(target as printed, what the file got wrong)``."""
    from dataclasses import replace

    if target.rows != target.cols:
        yield replace(target, rows=target.cols, cols=target.rows), "rows and cols are swapped in the target file"
    if target.kind == "aruco_grid" and seen_ids is not None and len(seen_ids):
        first = int(np.min(seen_ids))
        if first != target.first_id and first + target.rows * target.cols <= _dict_size(aruco_dictionary(target.dictionary)):
            yield replace(target, first_id=first), f"the lowest marker id seen is {first}: set first_id: {first}"
    if target.kind == "charuco":
        yield replace(target, legacy=not target.legacy), f"the board uses {'the current' if target.legacy else 'the legacy (pre-4.6)'} OpenCV layout: set legacy: {str(not target.legacy).lower()}"


def _diagnose_layout(images, names, target, bad) -> str:
    """Try the likely layout slips on the first images that failed; name the one under which the view is clean."""
    for img, name in list(zip(images, names)):
        if name not in bad:
            continue
        seen = None
        if target.kind == "aruco_grid":
            img = _array(img)
            _, mids, _ = cv2.aruco.ArucoDetector(aruco_dictionary(target.dictionary), _aruco_params()).detectMarkers(
                _grey(img)
            )
            seen = None if mids is None else mids.reshape(-1)
        for alt, why in _layout_alternatives(target, seen):
            try:
                d = detect_target(_array(img), alt, name=name)
            except InputError:
                continue
            if d is not None and not any(i.startswith(("layout", "too_few")) for i in d.issues):
                return f"{name} fits a {alt.describe()}: {why}?"
        break
    return ""


def _diagnose_not_found(images, names, target) -> str:
    """When no image shows the target: try the likely slips on the first images and name the one that fits."""
    if target.kind != "chessboard":
        hint = _diagnose_layout(images, names, target, set(names[:3]))
        return f"; {hint}" if hint else ""
    for img, name in list(zip(images, names))[:3]:
        img = _array(img)
        for (r, c), why in _chessboard_alternatives(target):
            if r < 3 or c < 3:
                continue
            try:
                detect_checkerboard(img, Checkerboard(r, c, target.square), method="classic", refine=False)
            except DetectionError:
                continue
            return (
                f"; {name} shows a {r}x{c} chessboard (inner corners) where the target says "
                f"{target.rows}x{target.cols}: {why}?"
            )
    return ""


class _LazyImage:
    """An image file read when needed (grey, through :func:`robocal.camera.read_image`)."""

    def __init__(self, path):
        self.path = Path(path)

    def read(self) -> np.ndarray:
        from robocal.camera._files import read_image

        return read_image(self.path, grey=True)


def _array(img) -> np.ndarray:
    return img.read() if isinstance(img, _LazyImage) else img


def detect_targets(
    images,
    target: Target,
    *,
    names=None,
    blur_limit: float = BLUR_LIMIT_PX,
    duplicate_limit: float = DUPLICATE_LIMIT_PX,
    progress_desc: str | None = None,
) -> DetectionSet:
    """Detect ``target`` in every image and judge the views as a set.

    ``images``: iterable of arrays, of ``(name, array)`` pairs, or of image
    file paths (read one at a time with :func:`read_image`, named by their
    path; a damaged file is a one-line ``FileFormatError`` naming it). Images must all have the size of the first:
    another size raises :class:`InconsistentDataError` naming the file.
    Duplicates (>= 80 % of the points in common within ``duplicate_limit``
    px RMS of an earlier usable view) are named. When the target is found
    in no image, raises :class:`DetectionError`; for a chessboard it tries
    the likely slips (squares counted instead of inner corners) and names
    the one the images show. A chessboard found with its rows running down
    the image in most views gets a note that rows/cols look transposed
    (harmless for calibration: the board frame is turned by 90 degrees).
    """
    from robocal.progress import progress

    images = list(images)
    if names is None:
        if images and all(isinstance(i, tuple) and len(i) == 2 for i in images):
            names, images = [str(n) for n, _ in images], [i for _, i in images]
        elif images and all(isinstance(i, (str, Path)) for i in images):
            names = [str(i) for i in images]
        else:
            names = [f"image {k}" for k in range(len(images))]
    # Image files are read one at a time (a set of large images need not fit in memory).
    images = [_LazyImage(i) if isinstance(i, (str, Path)) else i for i in images]
    names = [str(n) for n in names]
    if len(names) != len(images):
        raise InputError(f"names must have one entry per image ({len(images)}), got {len(names)}")
    if not images:
        raise InputError("no images given")
    size = None
    dets, missing = [], []
    for img, name in progress(list(zip(images, names)), desc=progress_desc or "detect", total=len(images)):
        arr = img.read() if isinstance(img, _LazyImage) else np.asarray(img)
        if arr.ndim < 2:
            raise InputError(f"image must be 2-D (H, W) or (H, W, 3), got shape {arr.shape}", source=name)
        here = (int(arr.shape[1]), int(arr.shape[0]))
        if size is None:
            size, first = here, name
        elif here != size:
            raise InconsistentDataError(
                f"image size {here[0]}x{here[1]} differs from {size[0]}x{size[1]} of {first} "
                "(one camera, one image size)",
                source=name,
            )
        d = detect_target(arr, target, name=name, blur_limit=blur_limit)
        (missing.append(name) if d is None else dets.append(d))
    if not dets:
        hint = _diagnose_not_found(images, names, target)
        raise DetectionError(f"no {target.describe()} found in any of the {len(images)} images{hint}")
    _mark_duplicates(dets, duplicate_limit)
    out = DetectionSet(dets, missing, size)
    if target.kind != "chessboard":
        bad = {d.name for d in dets if any(i.startswith("layout") for i in d.issues)}
        # Most views at odds with the layout: the file describes another board; say which one fits.
        if len(bad) > len(dets) / 2:
            hint = _diagnose_layout(images, names, target, bad)
            out.notes.append(
                f"layout: {len(bad)} of {len(dets)} views do not fit the {target.describe()}"
                + (f"; {hint}" if hint else "")
            )
    if target.kind == "chessboard" and target.rows != target.cols:
        down = [d for d in dets if d.usable and _x_runs_down(d, target)]
        good = [d for d in dets if d.usable]
        if good and len(down) > len(good) / 2:
            out.notes.append(
                f"transposed: the target says {target.rows} rows x {target.cols} cols of inner corners, but in "
                f"{len(down)} of {len(good)} views the rows run down the image (the images show "
                f"{target.cols} rows x {target.rows} cols); rows and cols look swapped in the target file "
                "(calibration is unaffected: the board frame is turned by 90 degrees)"
            )
    return out
