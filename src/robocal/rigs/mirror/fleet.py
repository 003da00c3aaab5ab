"""A fleet of mobile robots of one model (``robocal mirror simulate --fleet N``; :func:`robocal.batch.simulate_fleet`).

Every robot is the patent's published robot (:func:`robocal.rigs.mirror.scene.published_scene`)
with its head camera screwed on slightly differently: ``T_r_c`` scattered
by ``MOUNT_MM`` = 2 mm per axis and ``MOUNT_DEG`` = 0.2 deg per camera axis
(the mount's tolerances). Each robot's data set is ``simulate``'s point
form (:func:`robocal.rigs.mirror.simulate.simulate_observations`): the first
mirror placement where the camera sees it as in the patent, the others
drawn as ``simulate`` draws them. Planted:

* ``fault`` -- a camera knocked in its mount: turned by ``FAULT_DEG`` = 5 deg
  about its x (pitch) or y (pan) axis, its optical centre where it was;
* ``weak`` -- a hurried recording: half the mirror placements (at least
  one) and ``WEAK_NOISE_FACTOR`` = 4x the pixel noise.

The mirror calibration is much less certain than the mount's tolerances:
from 4 placements at ``simulate``'s 0.5 px a rotation std of ~0.7-1.2 deg
and 20-30 mm (the published geometry is poorly conditioned, one
parameter's variance inflation ~1e4), so the fleet's spread is the
calibrations' noise and a 5 deg knock is ~5 of it -- under the ~7 a fleet
of 10 asks for (:mod:`robocal.batch._fleet`): named in 1 of 3 seeded
fleets of 10. Marker and body points found to 0.1 px (``--placements 4
--sigma 0.1``; ~0.15-0.25 deg) name it in every one (``docs/rigs/mirror.md``,
measured).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["fleet_member", "FAULT_DEG", "WEAK_NOISE_FACTOR", "MOUNT_MM", "MOUNT_DEG"]

#: the camera mount's tolerances: std of T_r_c's translation [mm] and rotation [deg] per axis across the fleet
MOUNT_MM, MOUNT_DEG = 2.0, 0.2
#: the planted knock [deg]
FAULT_DEG = 5.0
#: the weak recording's pixel noise, as a multiple of the fleet's (and half the placements)
WEAK_NOISE_FACTOR = 4.0


def fleet_member(out_dir, rng: np.random.Generator, *, kind: str | None = None, progress: bool = False,
                 placements: int = 1, sigma_px: float = 0.5, images: bool = False, markerless: bool = False,
                 **_) -> dict:
    """One robot: ``mirror_input.yaml`` as ``simulate`` writes it (point form, with its truth); returns what was
    planted (``{}`` for a healthy robot; else ``parameter`` as the result names it, ``shift`` [deg], ``text``)."""
    if images or markerless:
        raise InputError("--fleet: simulates the point form only (mirror markers and body points); "
                         "leave out --images and --markerless")
    k, sigma = int(placements), float(sigma_px)
    if k < 1 or not np.isfinite(sigma) or sigma < 0:
        raise InputError(f"--placements >= 1 and --sigma >= 0, got {placements} and {sigma_px}")
    import yaml

    from robocal.batch import knocked, scattered_mount
    from robocal.geometry import invert_transform
    from robocal.rigs.mirror.files import write_input
    from robocal.rigs.mirror.model import MirrorScene
    from robocal.rigs.mirror.scene import published_scene
    from robocal.rigs.mirror.simulate import _visible_placements, default_camera, simulate_observations
    from robocal.rigs.mirror.workflow import INPUT_NAME, _truth_block

    published = published_scene()
    # the mount's tolerances, in the camera's own axes and the body's
    T_r_c = scattered_mount(invert_transform(published.T_c_r), rng, MOUNT_MM, MOUNT_DEG, own_axes=True)
    planted = {}
    if kind == "fault":
        T_r_c, shift, axis = knocked(T_r_c, rng, FAULT_DEG)
        planted = {"parameter": "T_r_c.rotvec", "shift": shift, "unit": "deg",
                   "text": f"camera knocked in its mount: turned {shift:+g} deg about its {'xy'[axis]} axis "
                           f"({'pitch' if axis == 0 else 'pan'})"}
    elif kind == "weak":
        k, sigma = max(1, k // 2), WEAK_NOISE_FACTOR * sigma
        planted = {"placements": k, "sigma_px": sigma,
                   "text": f"{k} mirror placement(s) with {WEAK_NOISE_FACTOR:g}x the pixel noise ({sigma:g} px)"}
    cam = default_camera()
    # the first mirror where the operator puts it for the camera to see it (the patent's place in the camera's
    # frame), the others drawn about it as simulate draws them (visible markers and reflected body)
    scene = MirrorScene(invert_transform(T_r_c), published.T_c_m[:1], published.body_points_r, published.rectangle)
    if k > 1:
        scene = MirrorScene(scene.T_c_r, _visible_placements(cam, scene, k, rng), scene.body_points_r, scene.rectangle)
    obs = simulate_observations(cam, scene, rng, sigma_px=sigma)
    path = write_input(Path(out_dir) / INPUT_NAME, cam, scene.rectangle, scene.body_points_r, obs,
                       sigma_px=sigma if sigma > 0 else None,
                       comment=f"robocal mirror simulate --fleet: one robot of a simulated fleet, {k} placement(s), "
                               f"{sigma:g} px noise")
    with open(path, "a", encoding="utf-8") as fh:  # ground truth, for the report only
        fh.write(yaml.safe_dump({"truth": _truth_block(scene.T_r_c)}, default_flow_style=None))
    return planted
