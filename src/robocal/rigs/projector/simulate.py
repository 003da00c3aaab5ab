"""Simulated projector rigs with known ground truth (seed 000 §3 as the default room).

The operator jogs the projector until the spot sits on a floor point, reads
the joint encoders (exact, or with ``theta_sigma``) and measures the spot in
the world with a tape / total station (isotropic floor noise ``sigma``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError, NotEnoughDataError
from robocal.geometry import matrix_from_angle
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.published import SEED_A_T, SEED_B_R, SEED_B_T, SEED_H

__all__ = ["Scenario", "default_truth", "default_nominal", "seed_room_projectors", "simulate_calibration",
           "sample_floor_points"]


def default_truth(name: str = "A") -> ProjectorModel:
    """Projector A of the seed's room: H = 2.90 m, yaw 2.40 deg, t = (2.40, -0.90, -2.90) m,
    with a pan-tilt head of d1 = 0.12 m, d2 = 0.05 m and a small tilt zero offset (0.3 deg)."""
    return ProjectorModel(H=SEED_H, d1=0.12, d2=0.05, offsets=(0.0, math.radians(0.3)),
                          tilt_limit=math.radians(75.0), R_0_W=matrix_from_angle("z", math.radians(2.4047)),
                          t_0_W=SEED_A_T, name=name)


def default_nominal(truth: ProjectorModel) -> ProjectorModel:
    """What the user believes before calibration: drawing values (d1 off by 1 cm), zero offsets, no extrinsics."""
    return ProjectorModel(H=truth.H, d1=truth.d1 + 0.01, d2=truth.d2, tilt_limit=truth.tilt_limit,
                          rate_limits=truth.rate_limits, name=truth.name)


def seed_room_projectors() -> list[ProjectorModel]:
    """Projectors A and B with the seed's published extrinsics (ideal heads)."""
    a = ProjectorModel(H=SEED_H, d1=0.12, d2=0.05, tilt_limit=math.radians(75.0),
                       R_0_W=matrix_from_angle("z", math.radians(2.4047)), t_0_W=SEED_A_T, name="A")
    yaw_b = math.atan2(SEED_B_R[1, 0], SEED_B_R[0, 0])
    b = ProjectorModel(H=SEED_H, d1=0.12, d2=0.05, tilt_limit=math.radians(75.0), R_0_W=matrix_from_angle("z", yaw_b),
                       t_0_W=SEED_B_T, name="B")
    return [a, b]


@dataclass
class Scenario:
    """One simulated calibration data set.

    Attributes
    ----------
    truth : ProjectorModel
        The real projector (with its true extrinsics).
    nominal : ProjectorModel
        The user's model before calibration (no extrinsics).
    points_W_true : ndarray, shape (N, 3)
        Where the spots really are (m).
    points_W : ndarray, shape (N, 3)
        The measured world points (m), ``z = 0``.
    theta : ndarray, shape (N, 2)
        Joint angles read at each point (rad).
    sigma : float
        World measurement noise per coordinate (m).
    """

    truth: ProjectorModel
    nominal: ProjectorModel
    points_W_true: np.ndarray
    points_W: np.ndarray
    theta: np.ndarray
    sigma: float
    theta_sigma: float = 0.0


def sample_floor_points(truth: ProjectorModel, n: int, rng: np.random.Generator, *, min_tilt: float = 0.1,
                        fill: float = 0.8) -> np.ndarray:
    """``n`` world floor points (n, 3) spread over the reachable disc, away from the nadir.

    Points are drawn uniformly over the annulus ``min_tilt <= tilt <= fill *
    tilt_limit`` (rad) around the nadir, with a well-spread layout (stratified in angle).
    """
    if n < 1:
        raise NotEnoughDataError(f"n_points must be >= 1, got {n}")
    r_min = truth.h * math.tan(min_tilt)
    r_max = truth.h * math.tan(fill * truth.tilt_limit)
    if r_max <= r_min:
        raise InputError("sample_floor_points: the annulus is empty (min_tilt too large for the tilt limit)")
    ang = (np.arange(n) + rng.uniform(0, 1, n)) * (2 * math.pi / n)
    rad = np.sqrt(rng.uniform(r_min**2, r_max**2, n))
    p0 = np.column_stack([rad * np.sin(ang), rad * np.cos(ang), np.full(n, -truth.H)])
    return truth.to_world(p0) * [1, 1, 0]


def simulate_calibration(rng: np.random.Generator, *, truth: ProjectorModel | None = None,
                         nominal: ProjectorModel | None = None, n_points: int = 6, sigma: float = 0.005,
                         theta_sigma: float = 0.0, points_W=None) -> Scenario:
    """Simulate one calibration: floor points, exact joint angles, noisy world measurements.

    Parameters
    ----------
    rng : numpy.random.Generator
    truth, nominal : ProjectorModel, optional
        Default :func:`default_truth` and :func:`default_nominal`.
    n_points : int
        Number of floor points (ignored when ``points_W`` is given).
    sigma : float
        World measurement noise per coordinate (m).
    theta_sigma : float
        Encoder noise (rad) added to the recorded joint angles.
    points_W : array_like, shape (N, 2) or (N, 3), optional
        A fixed design (true spot positions); else :func:`sample_floor_points`.
    """
    truth = default_truth() if truth is None else truth
    nominal = default_nominal(truth) if nominal is None else nominal
    if sigma < 0 or theta_sigma < 0:
        raise InputError(f"noise levels must be >= 0, got sigma={sigma!r}, theta_sigma={theta_sigma!r}")
    if points_W is None:
        pw = sample_floor_points(truth, n_points, rng)
    else:
        pw = np.asarray(points_W, dtype=float)
        if pw.ndim == 2 and pw.shape[1] == 2:
            pw = np.column_stack([pw, np.zeros(len(pw))])
    theta = truth.ik_world(pw)
    if theta_sigma:
        theta = theta + rng.normal(0.0, theta_sigma, theta.shape)
    meas = pw.copy()
    meas[:, :2] += rng.normal(0.0, sigma, (len(pw), 2))
    return Scenario(truth, nominal, pw, meas, theta, sigma, theta_sigma)
