"""A fleet of projector heads (``robocal projector simulate --fleet N``; :func:`robocal.batch.simulate_fleet`).

The same pan-tilt head, built N times and mounted in N copies of the seed's
room (projector A's place): what differs between the robots is what the
line and the fitter leave -- the link offset ``d1`` (+-1 mm, machining),
the tilt encoder's zero (0.3 +- 0.1 deg) and the mounting (yaw +-0.1 deg,
+-5 mm on the ceiling). Everyone starts from the same drawing (the nominal
head, :func:`robocal.rigs.projector.simulate.default_nominal` of the
undisturbed head).

Planted: ``fault`` -- the tilt encoder's zero slipped by 3 deg (inside the
calibration's +-5 deg ``tilt_offset_limit``): ~20 x the fleet's spread with
30 floor points (``--points 30``; a tilt offset std of ~0.12 deg), but only
~7 x with ``simulate``'s default 8 (~0.35 deg; h and the tilt offset are
nearly confounded there), too few for a fleet of 10 to name it surely; ``weak`` -- the floor points
measured with 5x the noise (a tape measure instead of the total station).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

__all__ = ["fleet_member", "FAULT_DEG", "WEAK_NOISE_FACTOR"]

#: the planted slip of the tilt encoder's zero [deg]
FAULT_DEG = 3.0
#: the planted weak recording's world noise, as a multiple of the fleet's
WEAK_NOISE_FACTOR = 5.0


def fleet_member(out_dir, rng: np.random.Generator, *, kind: str | None = None, progress: bool = False,
                 points: int = 8, noise: float = 5.0, theta_noise: float = 0.0, seed=None, **_) -> dict:
    """One head of the fleet: ``out_dir/projector.yaml`` as ``simulate`` writes it; returns what was planted."""
    import yaml

    from robocal.io import atomic_write_text
    from robocal.geometry import matrix_from_angle
    from robocal.rigs.projector.simulate import default_nominal, default_truth, simulate_calibration
    from robocal.rigs.projector.workflow import scenario_document

    drawing = default_truth()
    yaw = math.atan2(drawing.R_0_W[1, 0], drawing.R_0_W[0, 0]) + math.radians(0.1) * rng.standard_normal()
    t = np.asarray(drawing.t_0_W, float) + np.r_[5e-3 * rng.standard_normal(2), 0.0]
    tilt_zero = drawing.offsets[1] + math.radians(0.1) * rng.standard_normal()
    planted = {}
    if kind == "fault":
        tilt_zero += math.radians(FAULT_DEG)
        planted = {"parameter": "offsets.1", "shift": FAULT_DEG, "unit": "deg",
                   "text": f"tilt encoder zero slipped by {FAULT_DEG:+g} deg"}
    elif kind == "weak":
        noise *= WEAK_NOISE_FACTOR
        planted = {"noise_mm": noise, "text": f"floor points measured with {WEAK_NOISE_FACTOR:g}x the noise ({noise:g} mm)"}
    truth = dataclasses.replace(drawing, d1=drawing.d1 + 1e-3 * rng.standard_normal(), offsets=(0.0, tilt_zero),
                                R_0_W=matrix_from_angle("z", yaw), t_0_W=t)
    sc = simulate_calibration(rng, truth=truth, nominal=default_nominal(drawing), n_points=int(points),
                              sigma=noise * 1e-3, theta_sigma=math.radians(theta_noise))
    doc = scenario_document(sc)
    atomic_write_text(Path(out_dir) / "projector.yaml",
                      "# robocal projector simulate --fleet: one head of a simulated fleet\n"
                      + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120))
    return planted
