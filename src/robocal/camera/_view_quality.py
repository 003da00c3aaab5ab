"""Whether a detected view can serve a calibration: edge blur, point count, collinearity, a grid's layout.

Split from :mod:`robocal.camera._board_detect` (which re-exports the
thresholds): :func:`_quality` fills a detection's ``blur_px`` and ``issues``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from robocal.camera._board_detect import TargetDetection
    from robocal.camera._boards import ArucoGridTarget

__all__ = ["BLUR_LIMIT_PX", "LAYOUT_LIMIT", "LAYOUT_MEDIAN_LIMIT"]

#: Edge blur [px] (Gaussian sigma estimated at the corners) above which a view is named "blurred":
#: corner refinement error grows with the edge width, and 2.5 px is where
#: a defocused view starts to pull a calibration (it also flags motion blur).
BLUR_LIMIT_PX = 2.5
#: A marker grid whose neighbouring markers are this many marker sides from where the layout puts them
#: is not the printed board (see ``_grid_layout_error``): rows/cols swapped or another first id put markers
#: ~1 side off (a pitch), in a good share of the pairs. A correct view measures < 0.01 with large markers, but
#: up to 0.43 for a few pairs of ~15 px markers on tilted views at 480 x 360 (median 0.04-0.08): 0.5 per pair.
LAYOUT_LIMIT = 0.5
#: ... and a separation or marker size other than the print's shifts EVERY pair by a fraction of a side
#: (10 mm more separation for 40 mm markers: 0.25): a median over the pairs above this is not the print.
LAYOUT_MEDIAN_LIMIT = 0.15


def _patches(f: np.ndarray, u: np.ndarray, v: np.ndarray, half: int):
    """``(ok, whole, idx, cut)`` of the ``(2 half + 1)^2`` patches of ``f`` around pixels ``(u, v)``.

    ``ok``: patches of at least 3 x 3 pixels inside ``f``; ``idx`` (n_whole, (2 half + 1)^2): flat indices of
    the whole ones (``whole``), gathered at once; ``cut``: ``(k, slice)`` of those cut by ``f``'s edge.
    """
    h, w = f.shape
    r0, r1 = np.maximum(v - half, 0), np.minimum(v + half + 1, h)
    c0, c1 = np.maximum(u - half, 0), np.minimum(u + half + 1, w)
    ok = (r1 - r0 >= 3) & (c1 - c0 >= 3)
    whole = ok & (r1 - r0 == 2 * half + 1) & (c1 - c0 == 2 * half + 1)
    d = np.arange(2 * half + 1)
    rows = (r0[whole][:, None, None] + d[None, :, None]) * w
    idx = (rows + c0[whole][:, None, None] + d[None, None, :]).reshape(int(whole.sum()), -1)
    cut = [(k, np.s_[r0[k]:r1[k], c0[k]:c1[k]]) for k in np.flatnonzero(ok & ~whole)]
    return ok, whole, idx, cut


def _edge_blur(img: np.ndarray, pts: np.ndarray, half: int, half_contrast: int | None = None) -> float:
    """Median over points of the edge blur [px]: steepest gradient in a ``(2 half + 1)^2`` patch around each,
    contrast in a ``(2 half_contrast + 1)^2`` one.

    An ideal step of contrast C blurred by a Gaussian of sigma s has a peak
    gradient C / (s sqrt(2 pi)); so s = C / (sqrt(2 pi) max|grad|), with C
    the patch's 2-98 % grey range. The contrast is read in a patch reaching
    the centres of the squares around the point (``half_contrast``, default
    ``half``): a blur wide against the squares leaves a small patch short of
    full black and white, which read a 4 px blur as 2 px on 20 px squares.
    Pixel integration and the Sobel kernel add ~0.8 px in quadrature:
    measured 0.80 / 1.03 / 1.65 / 2.6 / 4.0 px for a Gaussian blur of 0 / 0.7 /
    1.5 / 2.5 / 4 px (rendered chessboard, noise 2 grey levels, 480 x 360 to
    1280 x 960; ChArUco and grid within 0.15 px of it).
    """
    half_contrast = half if half_contrast is None else int(half_contrast)
    h, w = img.shape
    u, v = np.rint(pts).astype(int).T
    reach = max(half, half_contrast)
    inside = (u + reach >= 0) & (u - reach < w) & (v + reach >= 0) & (v - reach < h)
    if not inside.any():
        return float("nan")
    # The gradient only where the patches are, plus the Sobel kernel's pixel: the same values as on
    # the whole image (a crop edge inside the image is never read; one on the image's edge is its edge).
    R0, R1 = max(int(v[inside].min()) - reach - 1, 0), min(int(v[inside].max()) + reach + 2, h)
    C0, C1 = max(int(u[inside].min()) - reach - 1, 0), min(int(u[inside].max()) + reach + 2, w)
    f = img[R0:R1, C0:C1].astype(np.float32)
    gm = np.hypot(cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)) / 8.0
    u, v = u - C0, v - R0
    n = len(u)
    lo, hi, g = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    ok_g, whole, idx, cut = _patches(f, u, v, half)
    if whole.any():  # the gradient (Sobel / 8, the central difference's scale) of all whole patches at once
        g[whole] = gm.ravel()[idx].max(axis=1)
    for k, sl in cut:
        g[k] = gm[sl].max()
    ok_c, whole, idx, cut = _patches(f, u, v, half_contrast)
    if whole.any():
        lo[whole], hi[whole] = np.percentile(f.ravel()[idx], [2, 98], axis=1)
    for k, sl in cut:
        lo[k], hi[k] = np.percentile(f[sl], [2, 98])
    keep = ok_g & ok_c & (hi - lo > 10) & (g > 0)
    out = (hi - lo)[keep] / (np.sqrt(2 * np.pi) * g[keep])
    return float(np.median(out)) if out.size else float("nan")


def _spacing(pts: np.ndarray) -> float:
    """Median nearest-neighbour distance [px] between points."""
    if len(pts) < 2:
        return float("nan")
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def _grid_layout_error(det: TargetDetection, target: ArucoGridTarget) -> np.ndarray:
    """Distance [marker sides] between each marker's neighbours and where its own homography puts them, per pair.

    A marker's four corners fix a homography from the board plane; extended to
    the markers next to it (within 1.5 pitches on the board) it predicts their
    corners to a small fraction of a side even under strong lens distortion
    (locally the projection is nearly projective). A target file whose
    layout differs from the print (rows and cols swapped, another first id)
    puts ids where other markers are: errors of about a pitch (another first
    id breaks the pairs that wrap a row). Empty when no marker has a
    neighbour in view.
    """
    m = det.ids // 4
    full = [k for k in np.unique(m) if np.count_nonzero(m == k) == 4]
    if len(full) < 2:
        return np.zeros(0)
    obj = {k: det.object_points[m == k][:, :2] for k in full}
    img = {k: det.image_points[m == k] for k in full}
    pitch = target.marker + target.separation
    errs = []
    for k in full:
        H = cv2.getPerspectiveTransform(obj[k].astype(np.float32), img[k].astype(np.float32))
        side = np.sqrt(abs(cv2.contourArea(img[k].astype(np.float32))))
        for j in full:
            if j != k and np.linalg.norm(obj[j].mean(0) - obj[k].mean(0)) <= 1.5 * pitch:
                pred = cv2.perspectiveTransform(obj[j].reshape(-1, 1, 2), H).reshape(-1, 2)
                errs.append(np.max(np.linalg.norm(pred - img[j], axis=1)) / side)
    return np.asarray(errs)


def _quality(det: TargetDetection, img: np.ndarray, target, blur_limit: float) -> None:
    n = det.n_points
    # the blur first: a defocused view is named for it, also when it lost points to it
    if n >= 2:
        spacing = _spacing(det.image_points)
        det.blur_px = _edge_blur(img, det.image_points, int(np.clip(0.4 * spacing, 3, 12)),
                                 int(np.clip(0.6 * spacing, 3, 24)))
    blurred = det.blur_px > blur_limit
    if blurred:
        det.issues.append(f"blurred: edge blur {det.blur_px:.1f} px > {blur_limit:g} px")
    if n < target.min_points:
        det.issues.append(f"too_few_points: {n} < {target.min_points}")
        return
    # Points on one line (a single charuco row, one marker edge) do not fix a homography.
    obj = det.object_points[:, :2] - det.object_points[:, :2].mean(axis=0)
    sv = np.linalg.svd(obj, compute_uv=False)
    if sv[1] < 1e-6 * max(sv[0], 1e-12) or sv[1] < 1e-9:
        det.issues.append(f"collinear: the {n} points lie on one line")
    if target.kind == "aruco_grid":
        err = _grid_layout_error(det, target)
        off = err > LAYOUT_LIMIT
        # A misread marker spoils a pair or two; a wrong layout a good share of them, a wrong spacing all.
        if off.sum() > max(1, 0.1 * err.size):
            det.issues.append(
                f"layout: {int(off.sum())} of {err.size} neighbouring marker pairs are more than {LAYOUT_LIMIT:g} "
                f"marker sides (median {float(np.median(err[off])):.2f}) from where the board layout puts them: "
                "rows/cols, first_id or marker/separation differ from the print?"
            )
        elif err.size >= 4 and np.median(err) > LAYOUT_MEDIAN_LIMIT:
            det.issues.append(
                f"layout: the neighbouring markers are a median {float(np.median(err)):.2f} marker sides from where "
                f"the board layout puts them (> {LAYOUT_MEDIAN_LIMIT:g}, over {err.size} pairs): marker or "
                "separation differ from the print?"
            )
