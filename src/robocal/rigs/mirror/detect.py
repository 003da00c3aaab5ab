"""The ArUco detection path (beyond the patent): mirror and body tags found in an image.

Practical targets: the robot's feature points are the corners of printed
ArUco markers on its body; the camera sees their *mirror images*. A mirror
image of a tag is the tag reflected left-right, which the ArUco decoder
rejects, so the image is flipped horizontally first (``u' = W - 1 - u``),
the tags are detected there, and the corners are mapped back. The four
markers on the mirror are ArUco tags too (ids 40-43, read in the unflipped
image); each mirror marker point is the tag's centre, found as the
intersection of the tag's diagonals in undistorted coordinates (exact under
perspective, unlike the mean of the corners). The observation carries each
tag's corner covariance and each marker's from the edge-fit geometry
(:func:`tag_corner_covariance`: a tag's corners share its fitted lines), in
units of the mean body-corner variance.

Corners: OpenCV's ArUco detector places a corner on the centre of the
outermost black pixels, i.e. about half a pixel inside the black border along
each axis, and its ``CORNER_REFINE_SUBPIX`` (``cornerSubPix``, made for
saddle points) only partly undoes that on an L-shaped corner: 0.3-0.5 px
inward along the diagonal on rendered mirror scenes, 0.5-0.7 px RMS. Every
tag's corners are therefore re-measured by :func:`refine_tag_corners`
(the four border edges located to sub-pixel on profiles across them, lines
fitted in undistorted coordinates and intersected): ~0.013 px RMS on
noise-free renders (``bench/bench_mirror_corners.py``).
"""

from __future__ import annotations

import cv2
import numpy as np

from robocal.camera import CameraModel
from robocal.diagnostics import Diagnostic
from robocal.errors import DetectionError, InputError
from robocal.rigs.mirror.observation import MirrorObservation
from robocal.rigs.mirror.tags import ARUCO_DICT, BodyTags, MirrorTags, aruco_dictionary, mirror_symmetric_ids

__all__ = ["detect_mirror_image", "refine_tag_corners", "TAG_CENTRE_SIGMA_SCALE", "tag_corner_covariance",
           "MIRROR_TAG_SQUARENESS"]


#: Where along each tag side the edge is measured (fractions of the side, away from the corners).
_EDGE_SPAN = (0.15, 0.85)
#: Former scalar weight of a tag centre (a mirror marker) relative to a tag corner, no longer set by
#: :func:`detect_mirror_image` (kept for comparisons, ``bench/bench_mirror_corners.py``): it took the
#: centre as the mean of two opposite lines at their middles, sqrt(1 / (2 (1 + 3 / w^2))) = 0.265 at
#: w = 0.7, but the centre is the diagonals' intersection, which also takes the lines' angles: 0.70 x a
#: corner's std measured (0.0097 vs 0.0138 px, blur 0.6, grey noise 2), 0.59 by
#: :func:`tag_corner_covariance`. Detection now gives per-tag covariances (``body_cov``, ``marker_cov``).
TAG_CENTRE_SIGMA_SCALE = float(np.sqrt(1.0 / (2.0 * (1.0 + 3.0 / (_EDGE_SPAN[1] - _EDGE_SPAN[0]) ** 2))))


def tag_corner_covariance(corners, *, span=_EDGE_SPAN) -> np.ndarray:
    """Relative covariance (8, 8) of a tag's four corners from :func:`refine_tag_corners`' line fits.

    Order ``(u0, v0, u1, v1, u2, v2, u3, v3)``, units: the variance of one
    edge point's offset (``sigma_e = 1``). Each side's edge is located at
    ``m = max(5, ceil(L (span[1] - span[0])))`` points spread uniformly over
    ``span`` of its length ``L`` [px]; a least-squares line through them has
    independent errors in its offset at the side's middle (variance ``1/m``)
    and in its angle (``1 / sum u_j^2``, ``u_j`` the points' positions from
    the middle). A corner is the intersection of two sides' lines: its error
    ``d`` solves ``n_a . d = delta_a``, ``n_b . d = delta_b`` with
    ``delta = offset + angle x (+-L/2)`` the line's normal displacement at
    the corner. So the two corners at the ends of one side share that side's
    errors: the angle (which dominates, 3 / w^2 = 6.1 x the offset's variance
    at w = 0.7) moves them in opposite directions along the normal
    (correlation -0.68 on a square tag), the offset together. Measured on
    300 noise draws of the published scene (blur 0.6, grey noise 2): the
    empirical covariance of every body tag agrees with this one times a
    scale to 0.17-0.31 (relative Frobenius norm; the off-diagonal part is
    0.6 of the matrix), ``bench/bench_mirror_corners.py`` section (3).
    Distortion is ignored (it is nearly affine over a tag). ``sigma_e`` is
    taken equal for all tags: measured 0.024 px on the mirror tags (sides
    28 px, seen square) vs 0.018-0.023 px on the body tags (24 x 17 px), so
    the model puts the mirror markers' std ~15 % low relative to the corners.
    """
    c = np.asarray(corners, dtype=float).reshape(4, 2)
    centre = c.mean(axis=0)
    nrm, half, var = [], [], []
    w = span[1] - span[0]
    for i in range(4):
        a, b = c[i], c[(i + 1) % 4]
        L = float(np.linalg.norm(b - a))
        t = (b - a) / max(L, 1e-12)
        n = np.array([t[1], -t[0]])
        if n @ (0.5 * (a + b) - centre) < 0:
            n = -n
        m = max(5, int(np.ceil(L * w)))
        u = (np.linspace(*span, m) - 0.5) * L
        nrm.append(n)
        half.append(0.5 * L)
        var += [1.0 / m, 1.0 / max(float(np.sum(u**2)), 1e-12)]
    G = np.zeros((8, 8))  # corner coordinates from (offset, angle) of the four sides
    for i in range(4):
        p = (i - 1) % 4  # side p ends at corner i (u = +L/2), side i starts there (u = -L/2)
        rows = np.zeros((2, 8))
        rows[0, 2 * p], rows[0, 2 * p + 1] = 1.0, half[p]
        rows[1, 2 * i], rows[1, 2 * i + 1] = 1.0, -half[i]
        G[2 * i:2 * i + 2] = np.linalg.solve(np.array([nrm[p], nrm[i]]), rows)
    return G @ np.diag(var) @ G.T


def _centre_jacobian(camera: CameraModel, corners_uv: np.ndarray) -> np.ndarray:
    """(2, 8) derivative of :func:`_centre` with respect to the corners (central differences)."""
    c = np.asarray(corners_uv, dtype=float).reshape(8)
    J = np.empty((2, 8))
    h = 1e-3
    for j in range(8):
        e = np.zeros(8)
        e[j] = h
        J[:, j] = (_centre(camera, (c + e).reshape(4, 2)) - _centre(camera, (c - e).reshape(4, 2))) / (2 * h)
    return J


#: Profile sampling step along the edge normal [px].
_EDGE_STEP = 0.25


def _edge_offsets(img: np.ndarray, pts: np.ndarray, normal: np.ndarray, half: float) -> tuple:
    """Sub-pixel offsets of a dark-inside / bright-outside edge along ``normal`` from each of ``pts`` (M, 2).

    Area (first-moment) method: the centroid of the positive part of the
    intensity derivative over a window of ``+-half`` px, re-centred three
    times. On area-sampled pixels interpolated bilinearly it is exact for a
    step edge, and unbiased under any symmetric blur. Returns ``(offset (M,),
    contrast (M,))``.
    """
    s = np.arange(-half, half + 0.5 * _EDGE_STEP, _EDGE_STEP)
    mid = 0.5 * (s[1:] + s[:-1])
    off = np.zeros(len(pts))
    contrast = np.zeros(len(pts))
    for _ in range(3):
        q = pts[:, None, :] + (off[:, None] + s[None, :])[..., None] * normal
        prof = cv2.remap(img, q[..., 0].astype(np.float32), q[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE).astype(float)
        g = np.clip(np.diff(prof, axis=1), 0.0, None)
        contrast = g.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            step = (g * mid).sum(axis=1) / contrast
        off = np.clip(off + np.nan_to_num(step), -1.5 * half, 1.5 * half)
    return off, contrast


def _line_fit(xy: np.ndarray):
    """Total-least-squares line ``(a, b, c)`` (``a x + b y + c = 0``, ``a^2 + b^2 = 1``) with one rejection pass."""
    keep = np.ones(len(xy), dtype=bool)
    for _ in range(2):
        c0 = xy[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(xy[keep] - c0)
        nrm = vt[1]
        r = (xy - c0) @ nrm
        mad = np.median(np.abs(r[keep] - np.median(r[keep])))
        new = np.abs(r) <= max(4.0 * 1.4826 * mad, 1e-12)
        if new.sum() < 3 or np.array_equal(new, keep):
            break
        keep = new
    return np.array([nrm[0], nrm[1], -nrm @ c0])


def refine_tag_corners(image, corners, camera: CameraModel | None = None, *, cells: int = 6) -> np.ndarray:
    """Sub-pixel corners of a square tag's outer black border by fitting its four edges.

    ``corners`` (4, 2): a detector's estimate (within about a pixel) in the
    OpenCV pixel convention (pixel centres at integers), in any cyclic order.
    Along the middle 70 % of each side, the edge (dark inside, bright
    outside) is located on profiles across it (:func:`_edge_offsets`); the
    edge points are undistorted with ``camera`` (straight lines there), a
    line is fitted to each side and neighbouring lines are intersected; a
    second pass repeats this along the refined sides (at 1.2 px blur it takes
    the corner error from 0.41 to 0.15 px RMS).
    ``cells``: black-border width is ``side / cells`` (6 for 4x4 ArUco),
    which sets the profile window (half a cell, so the next cell's edges
    stay out).

    Why: OpenCV's ArUco detector puts a corner on the centre of the outermost
    black pixels (0.5 px inside the border along both axes with
    ``CORNER_REFINE_NONE``) and its ``SUBPIX`` refinement (``cornerSubPix``,
    made for saddle points) only partly undoes that on an L-shaped corner
    (measured 0.19 px per axis on a sharp 24 px tag, 0.3-0.5 px inward along
    the diagonal on rendered mirror scenes). Returns (4, 2) in the input order;
    the input corners come back unchanged when a side cannot be fitted (too
    short, no contrast) or the fit moves a corner by more than
    ``max(2 px, 3/4 cell)`` (it met something else: a neighbouring tag, an
    occluder); :func:`detect_mirror_image` names such tags in a
    ``low_quality`` warning.
    """
    img = np.asarray(image)
    img = img.astype(np.float32) if img.dtype != np.float32 else img
    c = np.asarray(corners, dtype=float).reshape(4, 2)
    cell = float(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).max()) / cells
    out = c
    for _ in range(2):  # the second pass samples along the refined sides, windows centred on the edges
        nxt = _fit_edges(img, out, camera, cells)
        if nxt is None:
            break
        out = nxt
    # a fit that moved a corner by more than 3/4 of a cell met something else: keep the detector's corners
    if not np.all(np.linalg.norm(out - c, axis=1) < max(2.0, 0.75 * cell)):
        return c
    return out


def _fit_edges(img: np.ndarray, c: np.ndarray, camera, cells: int):
    """One pass of :func:`refine_tag_corners`; None when a side cannot be fitted."""
    centre = c.mean(axis=0)
    sides = np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)
    # half a cell of the most foreshortened side: the next cell's edges stay out of the window
    half = float(np.clip(0.5 * sides.min() / cells, 1.0, 8.0))
    lines = []
    for i in range(4):
        a, b = c[i], c[(i + 1) % 4]
        L = float(np.linalg.norm(b - a))
        if not L > 4.0:
            return None
        t = (b - a) / L
        n = np.array([t[1], -t[0]])
        if n @ (0.5 * (a + b) - centre) < 0:
            n = -n
        m = max(5, int(np.ceil(L * (_EDGE_SPAN[1] - _EDGE_SPAN[0]))))
        pts = a + np.linspace(*_EDGE_SPAN, m)[:, None] * (b - a)
        off, contrast = _edge_offsets(img, pts, n, half)
        ok = contrast > 0.3 * np.median(contrast)
        if ok.sum() < 3 or not np.median(contrast) > 0:
            return None
        q = pts[ok] + off[ok, None] * n
        xy = camera.undistort_points(q) if camera is not None else q
        if not np.all(np.isfinite(xy)):
            return None
        lines.append(_line_fit(xy))
    out = np.empty((4, 2))
    for i in range(4):
        h = np.cross(lines[i - 1], lines[i])
        if abs(h[2]) < 1e-12:
            return None
        out[i] = h[:2] / h[2]
    if camera is not None:
        out = camera.pixel_from_normalized(out)
    return out if np.all(np.isfinite(out)) else None


def _detect(gray: np.ndarray, dictionary: str = ARUCO_DICT) -> dict:
    """``{id: [corners (4, 2), ...]}``: every detection of each id (a list, so repeated ids are seen).

    Corners are OpenCV's (``CORNER_REFINE_NONE``: pixel-accurate, on the
    outermost black pixels); :func:`refine_tag_corners` makes them sub-pixel.
    """
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    det = cv2.aruco.ArucoDetector(aruco_dictionary(dictionary), params)
    corners, ids, _ = det.detectMarkers(gray)
    out: dict = {}
    if ids is None:
        return out
    for i, c in zip(ids.ravel(), corners):
        out.setdefault(int(i), []).append(c.reshape(4, 2).astype(float))
    return out


def _centre(camera: CameraModel, corners_uv: np.ndarray) -> np.ndarray:
    """Image of the tag centre: intersection of the diagonals in undistorted coordinates."""
    xy = camera.undistort_points(corners_uv)
    h = np.hstack([xy, np.ones((4, 1))])
    x = np.cross(np.cross(h[0], h[2]), np.cross(h[1], h[3]))
    return camera.pixel_from_normalized(x[:2] / x[2])


def _size_hint(img_w: int, img_h: int, camera: CameraModel) -> str:
    """Why an image's size differs from the camera's, when it can be told."""
    if (img_w, img_h) == (camera.height, camera.width):
        return "; the camera's width and height look swapped"
    s = img_w / camera.width
    if abs(img_h / camera.height - s) < 1e-3 * max(s, 1.0):
        return (f"; the image is {s:.4g} x the calibration resolution: use images at {camera.width} x "
                f"{camera.height} px, or scale fx, fy, cx, cy by {s:.4g} (cx' = {s:.4g} (cx + 0.5) - 0.5) "
                "and set width/height to the image's")
    return "; the camera was calibrated at another resolution or crop: calibrate at the image's size"


#: A mirror tag whose corners, mapped onto the mirror plane, deviate from a square by more than this
#: (relative side or diagonal difference) is warned about: clean renders reach 0.05 (0.09 at 1.2 px blur
#: and grey noise 5); a corner bitten off by an 8 px occluder gives 0.13 and moves the centre 1.8 px.
MIRROR_TAG_SQUARENESS = 0.10


def _mirror_tag_shape_warnings(camera: CameraModel, corners: list, marker_uv: np.ndarray, rectangle, mt: "MirrorTags",
                               name: str) -> list:
    """Warn about mirror tags whose corners are not a square on the mirror (partly occluded, glare)."""
    src = camera.undistort_points(marker_uv)
    H, _ = cv2.findHomography(src, rectangle.object_points()[:, :2])
    if H is None:
        return []
    out = []
    for letter, tag_id, c in zip("ABCD", mt.ids, corners):
        q = cv2.perspectiveTransform(camera.undistort_points(c).reshape(-1, 1, 2), H).reshape(-1, 2)
        sides = np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1)
        diag = np.array([np.linalg.norm(q[2] - q[0]), np.linalg.norm(q[3] - q[1])])
        dev = max(float(np.abs(sides / sides.mean() - 1.0).max()), float(abs(diag[0] - diag[1]) / diag.mean()))
        if dev > MIRROR_TAG_SQUARENESS:
            out.append(Diagnostic(
                "inconsistent_data", f"{name}: mirror tag {letter} (id {tag_id}): its corners are not a square on "
                f"the mirror (sides or diagonals differ by {dev:.0%}): partly occluded, glare or bent? Its centre "
                f"(marker {letter}) may be off by a pixel or more, which moves t_r_c by tens of mm",
                params=("T_c_m",), indices=(int("ABCD".index(letter)),)))
    return out


def detect_mirror_image(image, camera: CameraModel, tags: BodyTags, *, name: str = "image",
                        mirror_tags: MirrorTags | None = None, rectangle=None) -> MirrorObservation:
    """Find the mirror tags (direct) and the body tags (in the flipped image).

    Returns a :class:`MirrorObservation` whose ``body_ids`` index
    ``tags.body_points_r()`` (tags not found are left out). ``mirror_tags``:
    ids and dictionary of the mirror's tags (default ids 40-43, DICT_4X4_50).

    Named warnings (``observation.warnings``, code ``dropped``, ``indices`` =
    ``body_points`` rows, i.e. ``4 k .. 4 k + 3`` for tag ``k``): body tags
    not found; body tag ids found more than once in the flipped image (all
    their detections are left out: which one is the reflection cannot be
    told); ids found in the flipped image that are not in ``tags`` (a tag
    missing from the body model?). With ``rectangle`` (the marker
    rectangle), also ``inconsistent_data`` for a mirror tag whose corners,
    mapped onto the mirror, are not a square (``MIRROR_TAG_SQUARENESS``):
    a partly occluded tag can still decode with one corner off. Code
    ``low_quality`` when :func:`refine_tag_corners` could not fit a tag's
    edges and its detector corners (about 0.5 px inside) were kept: one
    warning for the body tags (``indices`` = their ``body_points`` rows),
    one for the mirror tags (``indices`` = markers 0-3).

    Raises
    ------
    InputError
        The image is not 8-bit, or its size is not the camera's.
    DetectionError
        A mirror tag is missing or found more than once, or no body tag
        (4 corners) is left.
    """
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise InputError(f"{name}: image must be an 8-bit grey or BGR image, got shape {img.shape} {img.dtype}")
    if img.shape != (camera.height, camera.width):
        raise InputError(f"{name}: image is {img.shape[1]} x {img.shape[0]} px but the camera (width x height) is "
                         f"{camera.width} x {camera.height} px{_size_hint(img.shape[1], img.shape[0], camera)}")
    mt = mirror_tags or MirrorTags()
    mt.check_body(tags)
    direct = _detect(img, mt.dictionary)
    missing = [i for i in mt.ids if i not in direct]
    if missing:
        letters = ", ".join(f"{'ABCD'[mt.ids.index(i)]} (id {i})" for i in missing)
        seen = sorted(direct)
        raise DetectionError(
            f"{name}: mirror tag(s) {letters} not found ({mt.dictionary}; ids {list(mt.ids)} at A, B, C, D); "
            f"ids found in the image: {seen if seen else 'none'}. All four must be fully visible: check for "
            "occlusion, glare or a tag outside the image, and mirror_tags.ids / dictionary")
    repeated = {i: len(direct[i]) for i in mt.ids if len(direct[i]) > 1}
    if repeated:
        raise DetectionError(
            f"{name}: mirror tag id(s) {sorted(repeated)} found {sorted(repeated.values())} times; each of A-D must "
            "appear once (another print of the tag in view, or a body tag with a mirror tag's id?)")
    cells = aruco_dictionary(mt.dictionary).markerSize + 2
    unrefined_mirror = []  # letters of mirror tags whose edge fit failed (detector corners kept)
    for letter, i in zip("ABCD", mt.ids):
        raw = direct[i][0]
        direct[i][0] = refine_tag_corners(img, raw, camera, cells=cells)
        if np.array_equal(direct[i][0], raw):  # refine_tag_corners gives its input back when the fit fails
            unrefined_mirror.append(letter)
    marker_uv = np.stack([_centre(camera, direct[i][0]) for i in mt.ids])
    marker_cov = []
    for i in mt.ids:
        J = _centre_jacobian(camera, direct[i][0])
        marker_cov.append(J @ tag_corner_covariance(direct[i][0]) @ J.T)
    warnings = [] if rectangle is None else _mirror_tag_shape_warnings(
        camera, [direct[i][0] for i in mt.ids], marker_uv, rectangle, mt, name)
    flipped = _detect(np.ascontiguousarray(img[:, ::-1]), tags.dictionary)
    W = img.shape[1]
    body_cells = aruco_dictionary(tags.dictionary).markerSize + 2
    uv, ids, body_cov = [], [], []
    not_found, twice, unrefined = [], [], []
    for k, tag_id in enumerate(tags.ids):
        found = flipped.get(int(tag_id), [])
        if len(found) != 1:
            (twice if found else not_found).append(k)
            continue
        c = found[0].copy()
        c[:, 0] = (W - 1) - c[:, 0]  # pixel centres at integers: column j of the flip is column W - 1 - j
        uv.append(refine_tag_corners(img, c, camera, cells=body_cells))
        body_cov.append(tag_corner_covariance(uv[-1]))
        if np.array_equal(uv[-1], c):
            unrefined.append(k)
        ids.extend(range(4 * k, 4 * k + 4))

    def rows(ks):
        return tuple(4 * k + j for k in ks for j in range(4))

    if twice:
        warnings.append(Diagnostic(
            "dropped", f"{name}: body tag id(s) {[tags.ids[k] for k in twice]} found more than once in the flipped "
            "image; left out (a second print of the tag, or a tag that reads the same in a mirror seen directly)",
            params=("body_uv",), indices=rows(twice)))
    if not_found:
        warnings.append(Diagnostic(
            "dropped", f"{name}: body tag id(s) {[tags.ids[k] for k in not_found]} not found in the flipped image "
            f"({len(ids) // 4} of {len(tags.ids)} found): occluded, outside the image or too small; their corners "
            "are left out", params=("body_uv",), indices=rows(not_found)))
    why = ("the sub-pixel edge fit failed (a side too short or without contrast, or the fit moved a corner by more "
           "than max(2 px, 3/4 cell): an occluder, a neighbouring tag)")
    if unrefined:
        warnings.append(Diagnostic(
            "low_quality", f"{name}: body tag id(s) {[tags.ids[k] for k in unrefined]} ({4 * len(unrefined)} "
            f"corners): {why}; the detector's corners are kept, about 0.5 px inside the tag along each axis",
            params=("body_uv",), indices=rows(unrefined)))
    if unrefined_mirror:
        warnings.append(Diagnostic(
            "low_quality", f"{name}: mirror tag(s) {', '.join(unrefined_mirror)} ({4 * len(unrefined_mirror)} "
            f"corners): {why}; the detector's corners are kept, about 0.5 px inside the tag along each axis (the "
            "tag's centre, the marker, moves less)",
            params=("marker_uv",), indices=tuple("ABCD".index(x) for x in unrefined_mirror)))
    symmetric = sorted(int(tags.ids[k]) for k in range(len(tags.ids))
                       if int(tags.ids[k]) in mirror_symmetric_ids(tags.dictionary) and int(tags.ids[k]) in flipped)
    if symmetric:
        warnings.append(Diagnostic(
            "inconsistent_data", f"{name}: body tag id(s) {symmetric} read the same in a mirror ({tags.dictionary}): "
            "a direct view of such a tag is indistinguishable from its reflection; prefer other ids",
            params=("body_uv",)))
    unknown = sorted(set(flipped) - {int(i) for i in tags.ids} - (set(mt.ids) if mt.dictionary == tags.dictionary
                                                                    else set()))
    if unknown:
        warnings.append(Diagnostic(
            "dropped", f"{name}: tag id(s) {unknown} seen in the mirror ({tags.dictionary}) but not in body_tags; "
            "ignored (add them to body_tags.tags to use them)", params=("body_uv",)))
    if not uv:
        rep = f"; repeated ids {[tags.ids[k] for k in twice]}" if twice else ""
        raise DetectionError(f"{name}: no body tag found in the flipped image (ids {list(tags.ids)}, "
                             f"{tags.dictionary}{rep})")
    # relative covariances in units of the mean body-corner variance per coordinate (so sigma_px keeps
    # meaning "corner noise"); the markers (tag centres) in the same units
    body_cov = np.stack(body_cov)
    unit = float(np.mean(np.trace(body_cov, axis1=1, axis2=2))) / 8.0
    return MirrorObservation(marker_uv, np.concatenate(uv), np.array(ids), name, warnings,
                             body_cov=body_cov / unit, marker_cov=np.stack(marker_cov) / unit)
