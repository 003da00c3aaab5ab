"""A fleet of eye-in-hand cells (``robocal handeye simulate --fleet N``; :func:`robocal.batch.simulate_fleet`).

The same cell built N times: a camera screwed to each robot's flange by the
same bracket, so the hand-eye transform ``X = T_gripper_cam`` differs between
the robots only by the bracket's tolerances (``MOUNT_MM`` = 0.5 mm and
``MOUNT_DEG`` = 0.1 deg std per axis about
:func:`robocal.handeye.simulate.default_hand_eye`); the target lies in the
same fixture in every cell (``T_base_target`` as ``simulate``'s). Each
robot's data set is ``simulate``'s two pose lists
(:func:`robocal.handeye.simulate.simulate_eye_in_hand`: 1 mrad / 0.2 mm pose
noise). Planted:

* ``fault`` -- a camera knocked on its mount: ``X`` turned by
  ``FAULT_DEG`` = 3 deg about the camera's x or y axis (its optical centre
  stays), ~30 x the fleet's spread (0.1 deg; a calibration from 16 poses is
  good to ~0.03 deg);
* ``weak`` -- a hurried recording: a third of the poses (at least 4) and
  ``WEAK_NOISE_FACTOR`` = 5x the pose noise (a blurred, distant target):
  reported stds ~9-12x the fleet's from 16 poses (the report's bar is 3).

Only the eye-in-hand set-up: ``robocal batch handeye`` calibrates a fleet's
manifest with ``calibrate``'s default ``--setup eye-in-hand`` (the manifest
:func:`robocal.batch.simulate_fleet` writes carries no options).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["fleet_member", "FAULT_DEG", "WEAK_NOISE_FACTOR", "MOUNT_MM", "MOUNT_DEG"]

#: the bracket's tolerances: std of the hand-eye translation [mm] and rotation [deg] per axis across the fleet
MOUNT_MM, MOUNT_DEG = 0.5, 0.1
#: the planted knock [deg]
FAULT_DEG = 3.0
#: the weak recording's pose noise, as a multiple of the fleet's (and a third of the poses)
WEAK_NOISE_FACTOR = 5.0


def fleet_member(out_dir, rng: np.random.Generator, *, kind: str | None = None, progress: bool = False,
                 poses: int = 16, noise_free: bool = False, setup: str = "eye-in-hand", **_) -> dict:
    """One cell: ``gripper_poses.csv``, ``target_poses.csv`` and ``truth.yaml`` as ``simulate`` writes them.

    Returns what was planted (``{}`` for a healthy cell; else ``parameter``
    as the result names it, ``shift`` [deg], ``text``).
    """
    from robocal.batch import knocked, scattered_mount
    from robocal.geometry import rotvec_from_matrix
    from robocal.handeye.simulate import default_hand_eye, simulate_eye_in_hand
    from robocal.io import atomic_write_text, write_poses

    if setup != "eye-in-hand":
        raise InputError(f"--fleet: simulates eye-in-hand cells only (the fleet's manifest calibrates with the "
                         f"default --setup), got --setup {setup}")
    n = int(poses)
    X = scattered_mount(default_hand_eye(), rng, MOUNT_MM, MOUNT_DEG)
    sr, st = 1e-3, 0.2e-3  # simulate_eye_in_hand's defaults: a calibrated camera on a target ~0.4 m away
    planted = {}
    if kind == "fault":
        # about the camera's own x or y axis: the lens turned, its centre where it was
        X, shift, axis = knocked(X, rng, FAULT_DEG)
        planted = {"parameter": "T_gripper_cam.rotvec", "shift": shift, "unit": "deg",
                   "text": f"camera knocked on its mount: turned {shift:+g} deg about its {'xy'[axis]} axis"}
    elif kind == "weak":
        n = max(4, n // 3)
        sr, st = WEAK_NOISE_FACTOR * sr, WEAK_NOISE_FACTOR * st
        planted = {"poses": n, "text": f"{n} poses with {WEAK_NOISE_FACTOR:g}x the pose noise"}
    sim = simulate_eye_in_hand(rng, n, X=X, noise=not noise_free, sigma_rotation=sr, sigma_translation=st)
    out = Path(out_dir)
    t = np.arange(n) * 0.1
    write_poses(out / "gripper_poses.csv", sim.T_base_gripper, t)
    write_poses(out / "target_poses.csv", sim.T_cam_target, t)

    def pose(T):
        return "{rotation: %s, translation: %s}" % (np.round(T[:3, :3], 12).tolist(), np.round(T[:3, 3], 12).tolist())
    atomic_write_text(out / "truth.yaml", (
        "# robocal handeye simulate --fleet: one cell of a simulated fleet; ground truth (m), not an input\n"
        f"setup: eye-in-hand\nT_gripper_cam: {pose(sim.X)}\nT_base_target: {pose(sim.Y)}\n"
        f"# T_gripper_cam rotation vector [deg] = "
        f"{np.round(np.degrees(rotvec_from_matrix(sim.X[:3, :3])), 4).tolist()}\n"
        f"noise: {{rotation_rad: {sim.sigma_rotation}, translation_m: {sim.sigma_translation}}}\n"))
    return planted
