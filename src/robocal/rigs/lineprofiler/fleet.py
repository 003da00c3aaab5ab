"""A fleet of arms with a line-laser profiler (``robocal lineprofiler simulate --fleet N``).

The same cell built N times: the profiler is mounted on the flange by the
same bracket, so the hand-eye transform ``X = T_E_L`` differs between the
robots only by the bracket's tolerances (0.3 mm, 0.1 deg std about
:func:`robocal.rigs.lineprofiler.model.default_hand_eye`). Each robot's
data set is ``simulate``'s FPDP sphere scan (``fpdp_input.yaml`` +
``fpdp_profiles.csv``; :func:`robocal.rigs.lineprofiler.simulate.simulate_fpdp`).
Planted:

* ``fault`` -- a profiler knocked in its bracket: ``X`` turned by 2 deg
  about one of frame E's axes, ~20 x the fleet's spread (0.1 deg);
* ``weak`` -- a scan with 5x the profiler noise (a dusty sphere, stray light).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

__all__ = ["fleet_member", "FAULT_DEG", "WEAK_NOISE_FACTOR", "MOUNT_MM", "MOUNT_DEG"]

#: the bracket's tolerances: std of the hand-eye translation [mm] and rotation [deg] across the fleet
MOUNT_MM, MOUNT_DEG = 0.3, 0.1
#: the planted knock [deg]
FAULT_DEG = 2.0
#: the weak recording's profiler noise, as a multiple of the fleet's
WEAK_NOISE_FACTOR = 5.0


def fleet_member(out_dir, rng: np.random.Generator, *, kind: str | None = None, progress: bool = False,
                 poses: int = 16, noise_free: bool = False, seed=None, **_) -> dict:
    """One robot: ``fpdp_input.yaml`` + ``fpdp_profiles.csv`` as ``simulate`` writes them; returns what was planted."""
    from robocal.batch import knocked, scattered_mount
    from robocal.geometry import rotvec_from_matrix
    from robocal.io import atomic_write_text
    from robocal.rigs.lineprofiler.io import write_profiles_csv
    from robocal.rigs.lineprofiler.model import LineProfilerRig, ProfilerModel, default_hand_eye
    from robocal.rigs.lineprofiler.simulate import simulate_fpdp

    X = scattered_mount(default_hand_eye(), rng, MOUNT_MM, MOUNT_DEG)
    profiler = ProfilerModel()
    planted = {}
    if kind == "fault":
        X, shift, axis = knocked(X, rng, FAULT_DEG, axes=3, own_axes=False)
        # the result's rotation vector of X: a turn about E's axis moves a mix of its components
        planted = {"parameter": "T_E_L.rotvec", "shift": shift, "unit": "deg",
                   "text": f"profiler knocked in its bracket: X turned {shift:+g} deg about its {'xyz'[axis]} axis"}
    elif kind == "weak":
        profiler = dataclasses.replace(profiler, sigma_x=WEAK_NOISE_FACTOR * profiler.sigma_x,
                                       sigma_z=WEAK_NOISE_FACTOR * profiler.sigma_z)
        planted = {"text": f"scanned with {WEAK_NOISE_FACTOR:g}x the profiler noise"}
    rig = LineProfilerRig(X=X, profiler=profiler)
    d, _ = simulate_fpdp(rig, rng, n_poses=int(poses), noise=not noise_free)
    out = Path(out_dir)
    write_profiles_csv(out / "fpdp_profiles.csv", d.profiles, d.q, angle_joints=(1,))
    atomic_write_text(out / "fpdp_input.yaml", (
        "# robocal lineprofiler simulate --fleet: one robot of a simulated fleet\nunits: {length: mm}\n"
        f"sphere_radius: {1e3 * d.sphere_radius:.4f}\narm: p1r2p3\nprofiles: fpdp_profiles.csv\nsign: auto\n"
        f"# truth: T_E_L translation [m] = {np.round(X[:3, 3], 6).tolist()}, "
        f"rotation vector [deg] = {np.round(np.degrees(rotvec_from_matrix(X[:3, :3])), 4).tolist()}\n"))
    return planted

