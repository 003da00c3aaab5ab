"""A fleet of cameras of one model (``robocal camera simulate --fleet N``; :func:`robocal.batch.simulate_fleet`).

N copies of ``simulate``'s camera (:func:`robocal.rigs.camera.simulate.default_camera`)
as a production line makes them: each lens focused at the factory and glued,
so the focal length scatters by ``FOCAL_SCATTER`` = 0.3 % (``fx`` and ``fy``
together: the pixel pitch is the sensor's), the principal point by
``CENTRE_PX`` = 2 px per axis (lens-to-sensor alignment; at 640 px wide,
scaled with ``--width``) and the distortion by ``DIST_SCATTER`` (the lens
elements' tolerances). Each camera's data set is ``simulate``'s rendered
session (:func:`robocal.rigs.camera.simulate.simulate_session`). Planted:

* ``fault`` -- one of two lens faults, drawn: the lens **refocused** (the
  glue gave, the focus ring turned), the focal length ``FOCAL_FAULT`` = 5 %
  off (~17 x the fleet's spread), or the lens **decentred** (a drop), the
  principal point ``CENTRE_FAULT_PX`` = 30 px off along x or y (~16 x);
* ``weak`` -- a hurried session: half the views (at least 3), blurred
  (``WEAK_BLUR_FACTOR`` = 2.5 x the blur) and ``WEAK_NOISE_FACTOR`` = 5 x
  the image noise (a dim room): from 6 views at 480 x 360 px the reported
  stds 5-17 x the fleet's in 7 fleets (3x the noise gave 3.1 x once, at
  the report's bar of 3).

The faults' figures are for ``--views 6 --width 480 --height 360``; in
fleets of 10 the report named the faulty lens in every one of 7 seeded
fleets (``t`` 12-37 against a bar of 7), in 4 of 6 fleets of 8
(``bench/bench_fleet_sizes.py``).
"""

from __future__ import annotations

import numpy as np

from robocal.errors import InputError

__all__ = ["fleet_member", "FOCAL_SCATTER", "CENTRE_PX", "DIST_SCATTER", "FOCAL_FAULT", "CENTRE_FAULT_PX",
           "WEAK_BLUR_FACTOR", "WEAK_NOISE_FACTOR"]

#: relative std of the focal length across the fleet
FOCAL_SCATTER = 0.003
#: std of the principal point per axis across the fleet [px, at 640 px wide]
CENTRE_PX = 2.0
#: std of k1, k2, p1, p2, k3 across the fleet (OpenCV's 5 terms)
DIST_SCATTER = (0.004, 0.004, 1e-4, 1e-4, 0.002)
#: the planted faults: the focal length's relative error, the principal point's shift [px, at 640 px wide]
FOCAL_FAULT, CENTRE_FAULT_PX = 0.05, 30.0
#: the weak session's blur and image noise, as multiples of the fleet's (and half the views)
WEAK_BLUR_FACTOR, WEAK_NOISE_FACTOR = 2.5, 5.0


def fleet_member(out_dir, rng: np.random.Generator, *, kind: str | None = None, progress: bool = False,
                 views: int = 12, width: int = 640, height: int = 480, blur: float = 0.7, noise: float = 2.0,
                 lens: str = "pinhole", **options) -> dict:
    """One camera: ``simulate``'s session (images, ``target.yaml``, ``camera_truth.yaml``, ``camera_input.yaml``);
    returns what was planted (``{}`` for a healthy camera; else ``parameter`` as the result names it, ``text``)."""
    import dataclasses

    from robocal.rigs.camera.simulate import default_camera, simulate_session

    if lens != "pinhole":
        raise InputError(f"--fleet: simulates pinhole cameras (OpenCV's 5 terms) only, got --lens {lens}")
    options.pop("seed", None)
    base = default_camera(int(width), int(height))
    s = base.width / 640.0
    f = 1.0 + FOCAL_SCATTER * rng.standard_normal()
    centre = CENTRE_PX * s * rng.standard_normal(2)
    dist = np.asarray(base.dist, float) + np.asarray(DIST_SCATTER) * rng.standard_normal(5)
    planted = {}
    if kind == "fault":
        story, sign = int(rng.integers(2)), float(rng.choice([-1.0, 1.0]))
        if story == 0:
            f *= 1.0 + sign * FOCAL_FAULT
            planted = {"parameter": "fx", "shift": sign * FOCAL_FAULT * base.fx, "unit": "px",
                       "text": f"lens refocused: focal length {sign * 100 * FOCAL_FAULT:+g} %"}
        else:
            axis = int(rng.integers(2))
            centre[axis] += sign * CENTRE_FAULT_PX * s
            planted = {"parameter": "cx" if axis == 0 else "cy", "shift": sign * CENTRE_FAULT_PX * s, "unit": "px",
                       "text": f"lens decentred: principal point {sign * CENTRE_FAULT_PX * s:+g} px in "
                               f"{'x' if axis == 0 else 'y'}"}
    elif kind == "weak":
        views, blur, noise = max(3, int(views) // 2), WEAK_BLUR_FACTOR * blur, WEAK_NOISE_FACTOR * noise
        planted = {"views": views, "text": f"{views} views, blur {blur:g} px, image noise {noise:g} grey levels"}
    cam = dataclasses.replace(base, fx=base.fx * f, fy=base.fy * f, cx=base.cx + centre[0], cy=base.cy + centre[1],
                              dist=dist)
    simulate_session(out_dir, rng, views=views, blur=blur, noise=noise, camera=cam, progress=False, **options)
    return planted
