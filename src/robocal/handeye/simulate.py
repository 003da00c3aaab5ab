"""Simulated eye-in-hand pose lists: a camera on the gripper viewing a fixed target from varied directions.

Frames as in :mod:`robocal.handeye` (``docs/handeye.md``): ``X = T_gripper_cam``,
``Y = T_base_target``, ``T_cam_target[i] = X^-1 T_base_gripper[i]^-1 Y``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError
from robocal.geometry import invert_transform, matrix_from_rotvec, transform_from

__all__ = ["HandEyeSimulation", "default_hand_eye", "simulate_eye_in_hand", "simulate_eye_to_hand"]


def default_hand_eye() -> np.ndarray:
    """The truth ``X = T_gripper_cam`` of the simulations and of ``examples/lineprofiler/*_poses.csv``: the camera's
    optical axis along the gripper's y, a few degrees off, mounted (35, 60, 120) mm from the flange."""
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    return transform_from(matrix_from_rotvec(np.deg2rad([1.5, -2.0, 3.0])) @ R0, [0.035, 0.060, 0.120])


@dataclass(frozen=True)
class HandEyeSimulation:
    """Simulated poses (N, 4, 4) with their truth ``X``, ``Y`` (eye-in-hand: ``T_gripper_cam``,
    ``T_base_target``; eye-to-hand: ``T_base_cam``, ``T_gripper_target``) and the sensor noise (rad, m; 0
    when noise-free)."""

    T_base_gripper: np.ndarray
    T_cam_target: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    sigma_rotation: float
    sigma_translation: float


def simulate_eye_in_hand(rng: np.random.Generator, n_poses: int = 16, *, X=None, distance=(0.30, 0.45),
                         max_tilt: float = np.deg2rad(35.0), max_roll: float = 0.6, noise: bool = True,
                         sigma_rotation: float = 1e-3, sigma_translation: float = 0.2e-3) -> HandEyeSimulation:
    """``n_poses`` views of a target lying on a table 0.6 m in front of the robot base.

    Each camera centre is drawn at ``distance`` (m) from the target centre, tilted up to ``max_tilt`` (rad)
    from the table's normal in a uniformly drawn direction; its optical axis (camera z) points at the target
    and it is rolled about that axis by up to ``max_roll`` (rad), so the relative rotations turn about
    every axis (AX = XB needs two non-parallel ones). ``T_base_gripper = T_base_cam X^-1``. With ``noise``,
    each ``T_cam_target`` gets a left rotation error of ``sigma_rotation`` (rad) per axis and a translation
    error of ``sigma_translation`` (m) per axis, the pose noise of a calibrated camera on a target
    ~0.4 m away.
    """
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if n_poses < 3:
        raise InputError(f"n_poses must be at least 3 (2 motions), got {n_poses}")
    X = default_hand_eye() if X is None else np.asarray(X, float)
    Y = transform_from(np.eye(3), [0.6, 0.0, 0.0])
    n = int(n_poses)
    d = rng.uniform(*distance, n)
    tilt = max_tilt * np.sqrt(rng.uniform(0.0, 1.0, n))        # uniform over the spherical cap's area
    az = rng.uniform(-np.pi, np.pi, n)
    roll = rng.uniform(-max_roll, max_roll, n)
    up = np.column_stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    centre = Y[:3, 3] + d[:, None] * up
    z = -up                                                     # optical axis towards the target
    x = np.cross(np.array([0.0, 1.0, 0.0]), z)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    R_base_cam = np.stack([x, np.cross(z, x), z], axis=-1) @ matrix_from_rotvec(roll[:, None] * [0.0, 0.0, 1.0])
    T_base_cam = transform_from(R_base_cam, centre)
    Tg = T_base_cam @ invert_transform(X)
    Tc = invert_transform(T_base_cam) @ Y
    sr, st = (sigma_rotation, sigma_translation) if noise else (0.0, 0.0)
    if noise:
        Tc = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * sr) @ Tc[:, :3, :3],
                            Tc[:, :3, 3] + rng.normal(size=(n, 3)) * st)
    return HandEyeSimulation(Tg, Tc, X, Y, float(sr), float(st))


def simulate_eye_to_hand(rng: np.random.Generator, n_poses: int = 16, *, noise: bool = True,
                         sigma_rotation: float = 1e-3, sigma_translation: float = 0.2e-3) -> HandEyeSimulation:
    """``n_poses`` views of a target held by the gripper, from a camera fixed 1 m above the robot base.

    The views (camera-target geometry) are those of :func:`simulate_eye_in_hand`; the truth is
    ``X = T_base_cam`` (the camera at (0.6, 0, 1.0) m looking down) and ``Y = T_gripper_target`` (the
    target 0.1 m out of the flange along its z, turned 90 deg about it), and
    ``T_base_gripper[i] = X T_cam_target[i] Y^-1`` (noise-free); each ``T_cam_target`` gets the sensor
    noise of :func:`simulate_eye_in_hand`.
    """
    views = simulate_eye_in_hand(rng, n_poses, noise=False)
    X = transform_from(np.diag([1.0, -1.0, -1.0]) @ matrix_from_rotvec([0.02, -0.03, 0.4]), [0.6, 0.0, 1.0])
    Y = transform_from(matrix_from_rotvec([0.0, 0.0, np.pi / 2]), [0.0, 0.0, 0.1])
    Tc = views.T_cam_target
    Tg = X @ Tc @ invert_transform(Y)
    sr, st = (sigma_rotation, sigma_translation) if noise else (0.0, 0.0)
    n = len(Tc)
    if noise:
        Tc = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * sr) @ Tc[:, :3, :3],
                            Tc[:, :3, 3] + rng.normal(size=(n, 3)) * st)
    return HandEyeSimulation(Tg, Tc, X, Y, float(sr), float(st))
