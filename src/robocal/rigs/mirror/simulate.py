"""Simulated mirror images with known ground truth.

:func:`simulate_observations` projects a :class:`MirrorScene` through a
:class:`~robocal.camera.CameraModel` (with its distortion) and adds Gaussian
pixel noise; points outside the image are dropped. The default scene is the
patent's published example (:func:`default_setup`). For the image path see
:mod:`robocal.rigs.mirror.render`.
"""

from __future__ import annotations

import numpy as np

from robocal.camera import CameraModel
from robocal.errors import DegenerateGeometryError, NotEnoughDataError
from robocal.rigs.mirror.observation import MirrorObservation
from robocal.rigs.mirror.model import MirrorScene
from robocal.rigs.mirror.scene import DEFAULT_INTRINSICS, perturbed_placements, published_scene

__all__ = ["default_camera", "default_setup", "simulate_observations"]


def default_camera() -> CameraModel:
    """The assumed intrinsics with the patent's distortion (see :mod:`~robocal.rigs.mirror.scene`)."""
    d = DEFAULT_INTRINSICS
    return CameraModel(d["fx"], d["fy"], d["cx"], d["cy"], d["dist"], d["width"], d["height"])


def default_setup(n_placements: int = 1, rng: np.random.Generator | None = None, *,
                  tilt_deg: float = 8.0) -> tuple[CameraModel, MirrorScene]:
    """Camera and the published scene, with ``n_placements - 1`` extra mirror placements.

    Extra placements need ``rng`` (see :func:`~robocal.rigs.mirror.scene.perturbed_placements`;
    ``tilt_deg``: the size of their random tilts, 8 deg by default, 20 deg for the markerless scenes,
    whose accuracy comes from the angles between the mirror normals).
    """
    cam = default_camera()
    scene = published_scene()
    if n_placements > 1:
        if rng is None:
            raise ValueError("default_setup: n_placements > 1 needs an rng")  # programming error
        T = _visible_placements(cam, scene, n_placements, rng, tilt_deg=tilt_deg)
        scene = MirrorScene(scene.T_c_r, T, scene.body_points_r, scene.rectangle)
    return cam, scene


def _visible_placements(cam, scene, k, rng, margin=10.0, tilt_deg=8.0):
    out = [scene.T_c_m[0]]
    while len(out) < k:
        T = perturbed_placements(scene, 2, rng, tilt_deg=tilt_deg)[1]
        try:
            s = MirrorScene(scene.T_c_r, T, scene.body_points_r, scene.rectangle)
        except Exception:  # placement puts the camera or body behind the mirror: draw again
            continue
        uv_m = cam.project(s.markers_c()[0], check=False)
        uv_v = cam.project(s.virtual_points_c()[0], check=False)
        if np.all(cam.in_image(uv_m, margin)) and np.all(cam.in_image(uv_v, margin)):
            out.append(T)
    return np.stack(out)


def simulate_observations(camera: CameraModel, scene: MirrorScene, rng: np.random.Generator, *,
                          sigma_px: float = 0.5, margin_px: float = 0.0) -> list[MirrorObservation]:
    """One :class:`MirrorObservation` per mirror placement of ``scene``.

    Parameters
    ----------
    sigma_px : float
        Std of the isotropic Gaussian noise added to every image coordinate [px].
    margin_px : float
        Body points imaged closer than this to the border are dropped.

    Raises
    ------
    DegenerateGeometryError
        A marker or a reflected point is behind the camera, or a marker is
        outside the image.
    NotEnoughDataError
        Fewer than 4 reflected points fall inside an image.
    """
    obs = []
    markers = scene.markers_c()
    virtual = scene.virtual_points_c()
    for k in range(scene.n_placements):
        if np.any(markers[k, :, 2] <= 0) or np.any(virtual[k, :, 2] <= 0):
            raise DegenerateGeometryError(f"placement {k}: markers or reflected body points are behind the camera")
        uv_m = camera.project(markers[k])
        if not np.all(camera.in_image(uv_m)):
            raise DegenerateGeometryError(f"placement {k}: a mirror marker falls outside the image")
        uv_b = camera.project(virtual[k])
        ids = np.flatnonzero(camera.in_image(uv_b, margin_px))
        if ids.size < 4:
            raise NotEnoughDataError(f"placement {k}: only {ids.size} reflected body points inside the image")
        obs.append(MirrorObservation(
            marker_uv=uv_m + rng.normal(scale=sigma_px, size=uv_m.shape),
            body_uv=uv_b[ids] + rng.normal(scale=sigma_px, size=(ids.size, 2)),
            body_ids=ids,
            name=f"placement {k}",
        ))
    return obs
