"""A fleet of NAO-class humanoids (``robocal humanoid simulate --fleet N``; :func:`robocal.batch.simulate_fleet`).

Every robot is ``simulate``'s: joint, camera and board-mounting offsets
drawn with std ``--offset-scale`` (0.5 deg, the seed's Table 2 magnitudes;
:func:`robocal.rigs.humanoid.simulate.draw_truth`), its own poses, rendered
images. Planted:

* ``fault`` -- one knee or ankle pitch offset moved by 4 deg (a gear that
  slipped a tooth; the calibration refuses offsets beyond 5 deg as
  implausible). That is ~8 x the spread of ``simulate``'s 0.5 deg scatter:
  a fleet of 10 cannot name it surely (with 21 parameters judged its bar is
  ~9 spreads, :mod:`robocal.batch._fleet`); 40 robots can (~5), and so can
  10 robots after a factory calibration (``--offset-scale 0.2``: ~18 x);
* ``weak`` -- a hurried recording: half the views, 3x the blur, 5x the
  image noise: the reported stds ~4x the fleet's (from 8 views per foot;
  ~3.4x from 3, at the fleet report's bar of 3).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["fleet_member", "FAULT_DEG", "FAULT_JOINTS", "WEAK_NOISE_FACTOR", "WEAK_BLUR_FACTOR"]

#: the planted slip [deg]
FAULT_DEG = 4.0
#: the joints a planted slip may hit (pitch joints carry the load: their gears slip)
FAULT_JOINTS = ("LKneePitch", "RKneePitch", "LAnklePitch", "RAnklePitch")
#: the weak recording's image noise and blur, as multiples of the fleet's, and half the views: the stds
#: ~2.8x from the images (the corner detector averages noise well: 10x the noise alone gave ~2x), ~1.4x
#: from the views
WEAK_NOISE_FACTOR, WEAK_BLUR_FACTOR = 5.0, 3.0


def fleet_member(out_dir, rng: np.random.Generator, *, kind: str | None = None, progress: bool = False,
                 views: int = 8, blur: float = 0.8, image_noise: float = 2.0, offset_scale: float = 0.5,
                 tie: bool = False, **_) -> dict:
    """One robot: ``run.yaml``, ``images/``, ``truth.yaml`` as ``simulate`` writes them; returns what was planted."""
    import yaml

    from robocal.io import atomic_write_text
    from robocal.rigs.humanoid.dataset import write_dataset
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.simulate import draw_truth, save_images, simulate_dataset

    model = default_model(tie_hip_yaw_pitch=tie)
    truth = draw_truth(model, rng, joint_deg=offset_scale, camera_deg=offset_scale, board_deg=offset_scale)
    planted = {}
    if kind == "fault":
        joint = FAULT_JOINTS[int(rng.integers(len(FAULT_JOINTS)))]
        shift = float(rng.choice([-1.0, 1.0])) * FAULT_DEG
        truth.params[truth.labels.index(joint)] += math.radians(shift)
        planted = {"parameter": joint, "shift": shift, "unit": "deg", "text": f"{joint} slipped by {shift:+g} deg"}
    elif kind == "weak":
        image_noise, blur = image_noise * WEAK_NOISE_FACTOR, blur * WEAK_BLUR_FACTOR
        views = max(2, int(views) // 2)
        planted = {"image_noise": image_noise, "blur": blur, "views": views,
                   "text": f"a hurried recording: {views} views per foot, out of focus and in a dark room "
                           f"(blur {blur:g} px, image noise {image_noise:g} grey levels)"}
    data = simulate_dataset(model, rng, n_per_foot=int(views), truth=truth, render=True, blur_sigma=blur,
                            image_noise=image_noise, progress=progress)
    out_dir = Path(out_dir)
    paths = save_images(data, out_dir / "images")
    write_dataset(out_dir / "run.yaml", model, data, paths, truth=truth.params)
    atomic_write_text(out_dir / "truth.yaml", yaml.safe_dump(
        {"units": "rad for angles, m for lengths", "truth": truth.as_dict()}, sort_keys=False))
    return planted
