"""Rendered mirror images (beyond the patent): reflected body tags and the mirror's tags, for simulation.

Rendering uses :func:`robocal.camera.render_planar_target` (distortion
included) with the tag bitmaps as :class:`~robocal.camera.PlaneTexture`
(``"nearest"``: box-filtered over each sample, edges placed to < 0.01 px at
2 x 2 samples per pixel): the virtual tag is the reflected tag frame
with its x axis flipped (:func:`~robocal.rigs.mirror.model.virtual_transform`),
carrying the left-right mirrored tag bitmap.

The tags are defined in :mod:`.tags` and found again by :mod:`.detect`;
their names are re-exported here, where tests and benchmarks import them from.
"""

from __future__ import annotations

import numpy as np

from robocal.camera import CameraModel, PlaneTexture, add_blur_and_noise, blank_image, render_planar_target
from robocal.rigs.mirror.detect import (  # noqa: F401  (re-exported)
    MIRROR_TAG_SQUARENESS,
    TAG_CENTRE_SIGMA_SCALE,
    _centre,
    _centre_jacobian,
    _detect,
    _EDGE_SPAN,
    _edge_offsets,
    _fit_edges,
    _line_fit,
    _mirror_tag_shape_warnings,
    _size_hint,
    detect_mirror_image,
    refine_tag_corners,
    tag_corner_covariance,
)
from robocal.rigs.mirror.model import MirrorScene, mirror_plane, virtual_transform
from robocal.rigs.mirror.tags import (  # noqa: F401  (re-exported)
    _R_R_TAG_FRONT,
    ARUCO_DICT,
    MIRROR_TAG_IDS,
    MIRROR_TAG_SIZE,
    BodyTags,
    MirrorTags,
    _tag_bitmap,
    aruco_dictionary,
    default_body_tags,
    mirror_symmetric_ids,
    tag_rotation,
)


__all__ = [
    "ARUCO_DICT",
    "MIRROR_TAG_IDS",
    "BodyTags",
    "MirrorTags",
    "aruco_dictionary",
    "mirror_symmetric_ids",
    "tag_rotation",
    "default_body_tags",
    "render_mirror_image",
    "detect_mirror_image",
    "refine_tag_corners",
    "TAG_CENTRE_SIGMA_SCALE",
    "tag_corner_covariance",
]


def render_mirror_image(camera: CameraModel, scene: MirrorScene, tags: BodyTags, *, placement: int = 0,
                        rng: np.random.Generator | None = None, blur_sigma: float = 0.6,
                        noise_sigma: float = 2.0, mirror_tags: MirrorTags | None = None,
                        supersample: int = 2) -> np.ndarray:
    """A grey image of mirror placement ``placement``: reflected body tags and the mirror's tags.

    ``scene.body_points_r`` is ignored; the body points are ``tags``' corners.
    The tags are :class:`~robocal.camera.PlaneTexture` (``"nearest"``: each
    sample is the exact area average of the bitmap over its footprint),
    ``supersample x supersample`` samples per pixel (2: tag edges placed to
    < 0.01 px). Returns uint8 (height, width).
    """
    T_c_m = scene.T_c_m[placement]
    n, d = mirror_plane(T_c_m)
    img = blank_image(camera, background=150.0)
    cells = 6
    for tag_id, T_r_tag in zip(tags.ids, tags.T_r_tag):
        T_c_tag = scene.T_c_r @ T_r_tag
        T_c_vtag = virtual_transform(T_c_tag, n, d)
        bmp = np.fliplr(_tag_bitmap(tag_id, cells, dictionary=tags.dictionary))
        full = tags.size * (cells + 2) / cells
        img = render_planar_target(camera, T_c_vtag, PlaneTexture(bmp, full, origin=(-full / 2, -full / 2)),
                                   supersample=supersample, image=img)
    w, h = scene.rectangle.width, scene.rectangle.height
    full = MIRROR_TAG_SIZE * (cells + 2) / cells
    mt = mirror_tags or MirrorTags()
    for tag_id, (x, y) in zip(mt.ids, [(0, 0), (w, 0), (w, h), (0, h)]):
        tex = PlaneTexture(_tag_bitmap(tag_id, cells, dictionary=mt.dictionary), full,
                           origin=(x - full / 2, y - full / 2))
        img = render_planar_target(camera, T_c_m, tex, supersample=supersample, image=img)
    return add_blur_and_noise(img, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)
