"""Input files of ``robocal mirror calibrate`` (YAML or JSON).

Layout (lengths in the unit given by ``units.length`` or inline
``{value, unit}``; pixels in px)::

    units: {length: mm}
    camera:                      # robocal.camera layout (or OpenCV/ROS camera_info)
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

With ``body_tags`` the body points are the tag corners (4 per tag, in
OpenCV's corner order, tag ``k`` -> rows ``4k..4k+3``). A tag's ``normal``
is the outward normal of its face in ``r``; ``x_axis`` is the printed tag's
right (needed on horizontal faces, where "upright" is undefined). Image paths
are relative to the input file. Body tag ids must differ from the mirror tag
ids when both use one dictionary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from robocal.camera import CameraModel, MarkerRectangle, camera_from_document
from robocal.errors import RobocalError
from robocal.geometry import transform_from
from robocal.io import atomic_write_text, load_document
from robocal.rigs.mirror.calibrate import MirrorObservation
from robocal.rigs.mirror.render import (
    _R_R_TAG_FRONT,
    ARUCO_DICT,
    BodyTags,
    MirrorTags,
    detect_mirror_image,
    tag_rotation,
)

__all__ = ["MirrorInput", "load_input", "write_input"]


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


def _uv(doc, key, n=None):
    a = doc.array(key, kind="pixel", shape=(None, 2))
    if a.ndim != 2:
        raise doc.error(key, f"must be a list of [u, v] pairs, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise doc.error(key, f"must have {n} rows, got {a.shape[0]}")
    return a


def load_input(path) -> MirrorInput:
    """Read and validate an input file (see the module docstring)."""
    path = Path(path)
    doc = load_document(path)
    src = str(path)
    if "units" in doc and "pixel" not in doc.units:
        doc.units["pixel"] = "px"
    elif "units" not in doc:
        doc.units["pixel"] = "px"
    cam = camera_from_document(doc.sub("camera"))
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
            p = Path(e.raw("image"))
            p = p if p.is_absolute() else path.parent / p
            if not p.exists():
                raise e.error("image", f"file {p} does not exist")
            import cv2

            img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise e.error("image", f"{p} is not a readable image")
            try:
                obs.append(detect_mirror_image(img, cam, tags, name=name, mirror_tags=mirror_tags))
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
        obs.append(MirrorObservation(_uv(e, "marker_uv", 4), _uv(e, "body_uv"), ids, name))
    return MirrorInput(cam, rect, body, obs, sigma, tags, images, src, mirror_tags)


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
        imgs.append(entry)
    doc["images"] = imgs
    text = (f"# {comment}\n" if comment else "") + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    path = Path(path)
    atomic_write_text(path, text)
    return path


