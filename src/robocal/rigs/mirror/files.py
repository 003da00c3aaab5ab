"""Input files of ``robocal mirror calibrate`` (YAML or JSON).

Layout (lengths in the unit given by ``units.length`` or inline
``{value, unit}``; pixels in px)::

    units: {length: mm}
    camera:                      # robocal.camera layout (or OpenCV/ROS camera_info), or {file: ...}
      fx: 800.0
      fy: 800.0
      cx: 383.5
      cy: 287.5
      dist: [-0.289, -0.06639, 0.0005, 0.00072]   # k1, k2, p1, p2[, k3]
      width: 768
      height: 576
    mirror_rectangle: {width: 366, height: 256}     # marker A..D rectangle
    sigma_px: 0.5                # optional: pixel noise (else estimated)
    body_points:                 # feature points in the robot frame r
      - [450, -250, 50]
      - ...
    images:                      # one entry per image / mirror placement
      - name: placement 0
        marker_uv: [[u, v], ...]   # A (top left), B, C, D, clockwise [px]
        body_uv: [[u, v], ...]     # reflections of body points [px]
        body_ids: [0, 1, ...]      # optional: row of body_points for each body_uv
        marker_sigma_scale: 1.0    # optional: marker noise / body-point noise
        body_cov: [[[...8 x 8...]], ...]  # optional: relative covariance of each 4 body_uv rows (one tag's corners)
        marker_cov: [[[..2 x 2..]], ...]  # optional: relative covariance of each marker (4)
      - name: shot 2
        image: shot2.png           # or a photo: ArUco tags are detected (needs body_tags)
    body_tags:                   # only with image entries; replaces body_points
      size: 100                  # black-square side
      dictionary: DICT_4X4_50    # optional (default)
      tags:                      # default: upright on a face facing +x_r
        - {id: 0, centre: [450, -190, 100]}
        - {id: 1, centre: [300, 260, 150], normal: [0, 1, 0]}              # upright on a +y_r face
        - {id: 2, centre: [500, 0, 300], normal: [0, 0, 1], x_axis: [0, 1, 0]}  # on the top, x_tag = +y_r
    mirror_tags: {dictionary: DICT_4X4_50, ids: [40, 41, 42, 43]}   # optional (default): tags at A..D

Markerless form (issue 14; :mod:`robocal.rigs.mirror.markerless`): no
marker rectangle, the mirror stands in K >= 3 unknown poses::

    units: {length: mm}
    camera: {...}                # as above
    sigma_px: 0.5                # optional
    reference_points:            # >= 3 points in the robot frame r, seen only in the mirror
      - [450, -250, 50]
      - ...
    mirror_poses:                # >= 3 poses, each seeing >= 3 of the points
      - name: pose 0
        uv: [[u, v], ...]        # image points of the reflections [px]
        ids: [0, 1, 2]           # optional: reference_points row of each uv row (default: all, in order)

Instead of ``reference_points``, ``reference_target: {chessboard: {rows,
cols, square}, R_r_t, t_r_t}`` (its corners, id ``i * cols + j``), and
then a pose may be ``{name, image: file}``: the board is detected in the
flipped image (mirrored order, :mod:`robocal.rigs.mirror.mirrored_target`);
``uv`` rows given with a reference target are checked for that order.

A file with ``reference_points``, or ``mirror_poses`` without ``images``, is
read in this form (``load_input`` returns a :class:`MarkerlessInput`). Mixed
data: ``mirror_poses`` next to ``images`` (and ``body_points``,
``mirror_rectangle``) are markerless poses whose ``ids`` index
``body_points`` (``MirrorInput.markerless_poses``), calibrated in one problem
with the marker poses.

With ``body_tags`` the body points are the tag corners (4 per tag, in
OpenCV's corner order, tag ``k`` -> rows ``4k..4k+3``). A tag's ``normal``
is the outward normal of its face in ``r``; ``x_axis`` is the printed tag's
right (needed on horizontal faces, where "upright" is undefined). Image paths
are relative to the input file. Body tag ids must differ from the mirror tag
ids when both use one dictionary.

Your own camera (``camera: {file: my_camera.yaml}``, or ``camera:
my_camera.yaml``, relative to the input file; other keys in ``camera``
override or complete the file's): a file with
``camera_matrix`` (or ``K``), ``dist_coeffs`` / ``distortion_coefficients``
(or ``D``) and the image size (``image_width`` + ``image_height``,
``width`` + ``height``, or ``image_size: [width, height]`` in cv2's order)
as written by ``cv2.FileStorage`` (YAML with ``%YAML:1.0`` and
``!!opencv-matrix``, or XML), by ROS ``camera_calibration`` (or a
``CameraInfo`` echo: ``width``, ``height``, ``K`` as 9 numbers, ``D``,
``distortion_model``) or by a JSON dump of ``cv2.calibrateCamera``'s
``mtx.tolist()`` and ``dist.tolist()``.
Read by the core loader (:func:`robocal.camera.camera_from_section`, any file
:func:`robocal.camera.load_camera` reads). Checked: the distortion vector has
4, 5, 8, 12 or 14 values (the tilted model's ``tau_x, tau_y`` must be 0,
refused by name); an equidistant (fisheye) camera is refused; the
principal point must lie inside the ``width x height`` image. The image size
must be that of the images the points come from: it is compared with each
image file (ArUco path) and bounds the image points.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from robocal.camera import CameraModel, MarkerRectangle, camera_from_section, read_camera_file, read_image
from robocal.errors import FileFormatError, RobocalError
from robocal.geometry import transform_from
from robocal.io import Document, atomic_write_text, load_document
from robocal.rigs.mirror.observation import MirrorObservation
from robocal.rigs.mirror.detect import detect_mirror_image
from robocal.rigs.mirror.tags import _R_R_TAG_FRONT, ARUCO_DICT, BodyTags, MirrorTags, tag_rotation

__all__ = ["MirrorInput", "MarkerlessInput", "load_input", "write_input", "write_markerless_input", "load_camera",
           "read_camera_file"]


@dataclass
class MirrorInput:
    """Everything ``calibrate`` needs, in SI units."""

    camera: CameraModel
    rectangle: MarkerRectangle
    body_points_r: np.ndarray
    observations: list
    sigma_px: float | None = None
    tags: BodyTags | None = None
    image_paths: dict = field(default_factory=dict)  # observation name -> image path
    source: str = "<input>"
    mirror_tags: MirrorTags | None = None
    camera_file: str | None = None  # the file of ``camera: {file: ...}``, if any
    #: units ``mirror_rectangle`` and ``body_points`` were written in (robocal.rigs.mirror.slips.declared_units)
    declared: dict = field(default_factory=dict)
    #: ``T_r_c`` (4, 4) [m] of the file's ``truth`` section (written by ``robocal mirror simulate``), else None
    truth: np.ndarray | None = None
    #: markerless mirror poses (``mirror_poses`` next to ``images``: mixed data), MarkerlessObservation each
    markerless_poses: list = field(default_factory=list)


def _uv(doc, key, n=None):
    a = doc.array(key, kind="pixel", shape=(None, 2))
    if a.ndim != 2:
        raise doc.error(key, f"must be a list of [u, v] pairs, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise doc.error(key, f"must have {n} rows, got {a.shape[0]}")
    return a


def load_camera(doc: Document, *, base_dir=None) -> CameraModel:
    """The ``camera`` section of an input file, inline or ``{file: ...}`` (see the module docstring).

    The layouts and checks are the core loader's,
    :func:`robocal.camera.camera_from_document`: it raises
    :class:`~robocal.errors.InputError` naming the file and field for a
    distortion model robocal does not implement, a wrong number of distortion
    coefficients (non-zero extras name the cv2 flag), a camera matrix with
    skew, or a principal point outside the image (image size of another
    resolution, or width and height swapped). This adds ``file:`` (a
    calibration file; keys next to it override the file's).
    """
    return camera_from_section(doc, base_dir=base_dir)  # the one core loader of every camera rig


def _entry_image(e, base_dir) -> tuple[Path, np.ndarray]:
    """The image file an entry's ``image`` names (relative to ``base_dir`` when given) and its pixels; a missing or
    damaged file is an error naming the entry's field."""
    p = Path(e.raw("image"))
    p = p if p.is_absolute() or base_dir is None else Path(base_dir) / p
    if not p.exists():
        raise e.error("image", f"file {p} does not exist")
    try:
        return p, read_image(p)
    except FileFormatError as exc:
        raise e.error("image", exc.message if str(p) in exc.message else f"{p}: {exc.message}") from None


def load_input(path) -> MirrorInput:
    """Read and validate an input file (see the module docstring)."""
    path = Path(path)
    src = str(path)
    try:
        head = path.read_text(encoding="utf-8-sig")[:200] if path.suffix.lower() in (".yaml", ".yml") else ""
    except (OSError, UnicodeDecodeError):
        head = ""  # load_document says what is wrong
    hint = ("this looks like a camera calibration file (OpenCV), not a mirror input: reference it from the input "
            "file as 'camera: {file: <this file>}' (docs/rigs/mirror.md, 'Your own camera')")
    if head.startswith("%YAML:1.") or (head.startswith("%YAML 1.") and "!!opencv-matrix" in head):  # OpenCV 4 / 5
        raise FileFormatError(hint, source=src)
    doc = load_document(path)
    if "camera" not in doc and ("camera_matrix" in doc or "K" in doc):
        raise FileFormatError(hint, source=src)
    if "units" in doc and "pixel" not in doc.units:
        doc.units["pixel"] = "px"
    elif "units" not in doc:
        doc.units["pixel"] = "px"
    cam_raw = doc.raw("camera")
    if isinstance(cam_raw, str):  # shorthand: camera: my_camera.yaml
        cam_raw = doc.data["camera"] = {"file": cam_raw}
    cam = load_camera(doc.sub("camera"), base_dir=path.parent)
    camera_file = None
    if isinstance(cam_raw, dict) and isinstance(cam_raw.get("file"), str):
        cf = Path(cam_raw["file"])
        camera_file = str(cf if cf.is_absolute() else path.parent / cf)
    if "reference_points" in doc or "reference_target" in doc or ("mirror_poses" in doc and "images" not in doc):
        return _load_markerless(doc, cam, src, camera_file, path.parent)
    r = doc.sub("mirror_rectangle")
    try:
        rect = MarkerRectangle(r.float("width", kind="length", positive=True),
                               r.float("height", kind="length", positive=True))
    except RobocalError as exc:
        raise exc if exc.source else exc.with_source(src)
    sigma = doc.float("sigma_px", kind="pixel", default=None, positive=True) if "sigma_px" in doc else None
    tags = None
    if "body_tags" in doc:
        t = doc.sub("body_tags")
        size = t.float("size", kind="length", positive=True)
        entries = t.items_list("tags")
        if not entries:
            raise t.error("tags", "must list at least one tag")
        ids = tuple(e.int("id", minimum=0) for e in entries)
        if len(set(ids)) != len(ids):
            raise t.error("tags", f"tag ids must be unique, got {list(ids)}")
        centres = np.stack([e.array("centre", kind="length", shape=(3,)) for e in entries])
        rots = []
        for e in entries:
            if "x_axis" in e and "normal" not in e:
                raise e.error("x_axis", "needs 'normal' (the face's outward normal) too")
            try:
                rots.append(tag_rotation(e.array("normal", shape=(3,)),
                                         e.array("x_axis", shape=(3,)) if "x_axis" in e else None)
                            if "normal" in e else _R_R_TAG_FRONT)
            except RobocalError as exc:
                raise exc.with_source(f"{src}: {e.prefix}") from None
        dictionary = t.str("dictionary", default=ARUCO_DICT)
        tags = BodyTags(ids, np.stack([transform_from(R, c) for R, c in zip(rots, centres)]), size, dictionary)
        body = tags.body_points_r()
    else:
        body = doc.array("body_points", kind="length", shape=(None, 3))
        if body.ndim != 2:
            raise doc.error("body_points", f"must be a list of [x, y, z] points, got shape {body.shape}")
    mirror_tags = None
    if "mirror_tags" in doc:
        mdoc = doc.sub("mirror_tags")
        raw_ids = mdoc.raw("ids", default=list(MirrorTags().ids))
        if not isinstance(raw_ids, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in raw_ids):
            raise mdoc.error("ids", f"must be a list of 4 integers (tags at A, B, C, D), got {raw_ids!r}")
        try:
            mirror_tags = MirrorTags(tuple(raw_ids), mdoc.str("dictionary", default=ARUCO_DICT))
        except RobocalError as exc:
            raise (exc if exc.source else exc.with_source(src)) from None
    if tags is not None:
        try:
            (mirror_tags or MirrorTags()).check_body(tags)
        except RobocalError as exc:
            raise exc.with_source(src) from None
    obs, images = [], {}
    entries = doc.items_list("images")
    if not entries:
        raise doc.error("images", "must list at least one image")
    for i, e in enumerate(entries):
        name = e.str("name", default=f"image {i}")
        if "image" in e:
            if tags is None:
                raise e.error("image", "an image entry needs body_tags (the ArUco tags on the body)")
            p, img = _entry_image(e, path.parent)
            try:
                obs.append(detect_mirror_image(img, cam, tags, name=name, mirror_tags=mirror_tags, rectangle=rect))
            except RobocalError as exc:
                raise exc.with_source(f"{src}: {e.prefix}") from None
            images[name] = str(p)
            continue
        ids = None
        if "body_ids" in e:
            raw = e.raw("body_ids")
            if not isinstance(raw, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in raw):
                raise e.error("body_ids", "must be a list of integers")
            ids = np.array(raw, dtype=int)
        scale = e.float("marker_sigma_scale", default=1.0, positive=True) if "marker_sigma_scale" in e else 1.0
        covs = {}
        for fld in ("body_cov", "marker_cov"):  # optional relative covariances (written for ArUco detections)
            if fld in e:
                try:
                    covs[fld] = np.asarray(e.raw(fld), dtype=float)
                except (TypeError, ValueError):
                    raise e.error(fld, "must be a list of square matrices of numbers") from None
        try:
            obs.append(MirrorObservation(_uv(e, "marker_uv", 4), _uv(e, "body_uv"), ids, name,
                                         marker_sigma_scale=scale, **covs))
        except RobocalError as exc:
            raise exc.with_source(f"{src}: {e.prefix}") from None
    from robocal.rigs.mirror.slips import declared_units

    # mixed data: poses with markers (images) and without (mirror_poses, indexing body_points) in one file
    markerless = _markerless_poses(doc, cam, src, body, "body_points") if "mirror_poses" in doc else []
    return MirrorInput(cam, rect, body, obs, sigma, tags, images, src, mirror_tags, camera_file,
                       declared_units(doc), _truth(doc), markerless)


@dataclass
class MarkerlessInput:
    """A markerless input (``reference_points`` + ``mirror_poses``, issue 14), in SI units."""

    camera: CameraModel
    points_r: np.ndarray
    observations: list
    sigma_px: float | None = None
    source: str = "<input>"
    camera_file: str | None = None
    #: unit ``reference_points`` was written in (``{"reference_points": "mm"}``), for the unit-slip check
    declared: dict = field(default_factory=dict)
    truth: np.ndarray | None = None
    image_paths: dict = field(default_factory=dict)  # none: the markerless form takes image points


def _reference_target(doc: Document):
    """``(target, T_r_t)`` of ``reference_target: {chessboard: {rows, cols, square}, R_r_t: 3x3, t_r_t: [x, y, z]}``."""
    from robocal.camera import ChessboardTarget

    t = doc.sub("reference_target")
    if "chessboard" not in t:
        raise t.error("chessboard", "missing: the reference target is a chessboard {rows, cols, square} (inner "
                                    "corners; other targets: give reference_points and uv)")
    c = t.sub("chessboard")
    try:
        target = ChessboardTarget(c.int("rows", minimum=3), c.int("cols", minimum=3),
                                  c.float("square", kind="length", positive=True))
    except RobocalError as exc:
        raise (exc if exc.source else exc.with_source(f"{doc.source}: reference_target.chessboard")) from None
    R = t.array("R_r_t", shape=(3, 3))
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise t.error("R_r_t", f"must be a rotation (target -> robot; det +1), got det {np.linalg.det(R):.3g}: a "
                               f"target frame of the other handedness is a mirrored target file")
    return target, transform_from(R, t.array("t_r_t", kind="length", shape=(3,)))


def _load_markerless(doc: Document, cam: CameraModel, src: str, camera_file, base_dir=None) -> MarkerlessInput:
    """The markerless form (docs/rigs/mirror.md, 'Markerless input'): reference points + per pose their reflections."""
    from robocal.rigs.mirror.markerless import MIN_POINTS

    for key in ("mirror_rectangle", "body_points", "body_tags", "images"):
        if key in doc:
            raise doc.error(key, "a markerless input (reference_points + mirror_poses) takes no marker rectangle, "
                                 "body points or images; for poses with markers and without in one file give "
                                 "body_points (not reference_points), mirror_rectangle, images and mirror_poses")
    target = T_r_t = None
    if "reference_target" in doc:
        if "reference_points" in doc:
            raise doc.error("reference_target", "give reference_points or reference_target, not both")
        target, T_r_t = _reference_target(doc)
        P = target.object_points() @ T_r_t[:3, :3].T + T_r_t[:3, 3]
    for key in ("reference_points", "mirror_poses"):
        if key not in doc and not (key == "reference_points" and target is not None):
            raise doc.error(key, "missing: a markerless input needs reference_points (robot frame) or "
                                 "reference_target, and mirror_poses (per pose the image points of their reflections)")
    if target is None:
        P = doc.array("reference_points", kind="length", shape=(None, 3))
    if P.ndim != 2:
        raise doc.error("reference_points", f"must be a list of [x, y, z] points, got shape {P.shape}")
    if len(P) < MIN_POINTS:
        raise doc.error("reference_points", f"need >= {MIN_POINTS} points (P3P per mirror pose), got {len(P)}")
    sigma = doc.float("sigma_px", kind="pixel", default=None, positive=True) if "sigma_px" in doc else None
    obs = _markerless_poses(doc, cam, src, P, target=target, base_dir=base_dir)
    unit = doc.data.get("reference_points") if isinstance(doc.data, dict) else None
    declared = {"reference_points": str(unit["unit"]) if isinstance(unit, dict) and "unit" in unit
                else doc.units.get("length")}
    if target is not None:
        declared = {"reference_points": _unit_of(doc, "reference_target")}
    images = {o.name: o.image for o in obs if getattr(o, "image", None)}
    return MarkerlessInput(cam, P, obs, sigma, src, camera_file, declared, _truth(doc), images)


def _unit_of(doc: Document, key: str):
    sub = doc.sub(key)
    c = sub.data.get("chessboard") if isinstance(sub.data, dict) else None
    sq = c.get("square") if isinstance(c, dict) else None
    return str(sq["unit"]) if isinstance(sq, dict) and "unit" in sq else doc.units.get("length")


def _markerless_poses(doc: Document, cam: CameraModel, src: str, P, field: str = "reference_points", *,
                      target=None, base_dir=None) -> list:
    """The ``mirror_poses`` entries (``uv``, optional ``ids`` into ``P``; or ``image`` with a
    ``reference_target``, detected in mirrored order) as MarkerlessObservation's.

    With a reference target, points given as ``uv`` are checked for the mirrored order
    (:func:`~robocal.rigs.mirror.mirrored_target.check_mirrored_order`): a direct view's order is refused
    with the fix.
    """
    from robocal.rigs.mirror.markerless import MarkerlessObservation
    from robocal.rigs.mirror.mirrored_target import check_mirrored_order, detect_mirrored_target
    from robocal.rigs.mirror.observation import check_in_image

    obs = []
    for i, e in enumerate(doc.items_list("mirror_poses")):
        name = e.str("name", default=f"mirror pose {i}")
        if "image" in e:
            if target is None:
                raise e.error("image", "an image entry needs reference_target (the chessboard on the robot)")
            p, img = _entry_image(e, base_dir)
            if img.shape[:2] != (cam.height, cam.width):
                raise e.error("image", f"{p} is {img.shape[1]} x {img.shape[0]} px, the camera {cam.width} x "
                                       f"{cam.height}")
            det = detect_mirrored_target(img, target, name=str(p))
            if det is None:
                raise e.error("image", f"no {target.describe()} found in {p} (searched in the flipped image: "
                                       f"a target seen in a mirror is its mirror image)")
            o = MarkerlessObservation(det.image_points, det.ids, name)
            o.image = str(p)  # for the result's input hashes
            obs.append(o)
            continue
        uv = _uv(e, "uv")
        if "ids" in e:
            raw = e.raw("ids")
            if not isinstance(raw, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in raw):
                raise e.error("ids", f"must be a list of integers (rows of {field})")
            if len(raw) != len(uv):
                raise e.error("ids", f"must have one entry per uv row ({len(uv)}), got {len(raw)}")
            bad = [v for v in raw if not 0 <= v < len(P)]
            if bad:
                raise e.error("ids", f"must be rows of {field} (0..{len(P) - 1}), got {bad[0]}")
            ids = np.array(raw, dtype=int)
        else:
            if len(uv) != len(P):
                raise e.error("uv", f"without ids, needs one row per {field} row ({len(P)}), got {len(uv)}; "
                                    f"give ids when a point is missing")
            ids = np.arange(len(P))
        try:
            check_in_image(cam, uv, f"{e.prefix}.uv")
            if target is not None and len(ids) >= 4:
                check_mirrored_order(cam, target.object_points(ids), uv, what=f"{e.prefix}.uv", cols=target.cols)
            obs.append(MarkerlessObservation(uv, ids, name))
        except RobocalError as exc:
            raise (exc if exc.source else exc.with_source(src)) from None
    return obs


def write_markerless_input(path, camera: CameraModel, points_r, observations, *, sigma_px: float | None = None,
                           comment: str = "") -> Path:
    """Write a markerless input file (lengths in mm) that :func:`load_input` reads back."""
    cam = camera.to_dict()
    cam.pop("units", None)
    cam.pop("model", None)
    doc = {"units": {"length": "mm", "pixel": "px"}, "camera": cam}
    if sigma_px is not None:
        doc["sigma_px"] = float(sigma_px)
    doc["reference_points"] = np.round(np.asarray(points_r) * 1e3, 6).tolist()
    poses = []
    for o in observations:
        e = {"name": o.name, "uv": np.round(o.uv, 4).tolist()}
        if len(o.ids) != len(points_r) or np.any(o.ids != np.arange(len(o.ids))):
            e["ids"] = [int(i) for i in o.ids]
        poses.append(e)
    doc["mirror_poses"] = poses
    text = (f"# {comment}\n" if comment else "") + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    path = Path(path)
    atomic_write_text(path, text)
    return path


def _truth(doc: Document) -> np.ndarray | None:
    """The simulated ``T_r_c`` of a ``truth: {R_r_c: 3x3, t_r_c: [x, y, z]}`` section (lengths in the file's unit)."""
    if "truth" not in doc:
        return None
    t = doc.sub("truth")
    return transform_from(t.array("R_r_c", shape=(3, 3)), t.array("t_r_c", kind="length", shape=(3,)))


def write_input(path, camera: CameraModel, rectangle: MarkerRectangle, body_points_r, observations, *,
                sigma_px: float | None = None, tags: BodyTags | None = None, image_files=None,
                comment: str = "", mirror_tags: MirrorTags | None = None) -> Path:
    """Write an input file (lengths in mm) that :func:`load_input` reads back.

    ``image_files``: optional ``{observation index: relative image path}``;
    those entries are written as ``image:`` (ArUco path, needs ``tags``).
    """
    image_files = image_files or {}
    cam = camera.to_dict()
    cam.pop("units", None)
    cam.pop("model", None)
    doc = {
        "units": {"length": "mm", "pixel": "px"},
        "camera": cam,
        "mirror_rectangle": {"width": rectangle.width * 1e3, "height": rectangle.height * 1e3},
    }
    if sigma_px is not None:
        doc["sigma_px"] = float(sigma_px)
    if tags is not None:
        entries = []
        for i, T in zip(tags.ids, tags.T_r_tag):
            e = {"id": int(i), "centre": np.round(T[:3, 3] * 1e3, 6).tolist()}
            if not np.allclose(T[:3, :3], _R_R_TAG_FRONT, atol=1e-12):
                e["normal"] = np.round(-T[:3, 2], 12).tolist()
                e["x_axis"] = np.round(T[:3, 0], 12).tolist()
            entries.append(e)
        doc["body_tags"] = {"size": tags.size * 1e3, "tags": entries}
        if tags.dictionary != ARUCO_DICT:
            doc["body_tags"]["dictionary"] = tags.dictionary
    else:
        doc["body_points"] = np.round(np.asarray(body_points_r) * 1e3, 6).tolist()
    if mirror_tags is not None:
        doc["mirror_tags"] = {"dictionary": mirror_tags.dictionary, "ids": [int(i) for i in mirror_tags.ids]}
    imgs = []
    for k, o in enumerate(observations):
        if k in image_files:
            imgs.append({"name": o.name, "image": str(image_files[k])})
            continue
        entry = {"name": o.name, "marker_uv": np.round(o.marker_uv, 4).tolist(),
                 "body_uv": np.round(o.body_uv, 4).tolist()}
        if o.body_ids is not None:
            entry["body_ids"] = [int(i) for i in o.body_ids]
        if o.marker_sigma_scale != 1.0:
            entry["marker_sigma_scale"] = float(o.marker_sigma_scale)
        for fld, cov in (("body_cov", o.body_cov), ("marker_cov", o.marker_cov)):
            if cov is not None:
                entry[fld] = np.round(np.asarray(cov, dtype=float), 8).tolist()
        imgs.append(entry)
    doc["images"] = imgs
    text = (f"# {comment}\n" if comment else "") + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    path = Path(path)
    atomic_write_text(path, text)
    return path


