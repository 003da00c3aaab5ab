"""Pose pairs and their relative motions: pairing, excitation check, pose residuals.

Shared by the closed forms (:mod:`.axxb`, :mod:`.axzb`), the refinement
(:mod:`.refine`) and the plausibility check (:mod:`.plausibility`). Frames as
in :mod:`robocal.handeye`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.geometry import (PoseWithCovariance, invert_transform, matrix_from_rotvec, rotvec_from_matrix,
                              transform_from)
from robocal.validation import check_transform

__all__ = ["MIN_ROTATION", "MIN_AXIS_SPREAD", "WEAK_AXIS_SPREAD", "MAX_ALL_PAIRS", "MotionCheck",
           "relative_motions", "check_motions", "transform_error"]

#: Default smallest useful relative rotation (rad): below it the axis is noise.
MIN_ROTATION = np.deg2rad(2.0)
#: Default smallest spread between rotation axes (rad) before the set is called parallel.
MIN_AXIS_SPREAD = np.deg2rad(2.0)
#: Axis spread (rad) below which the result is flagged as weakly determined.
WEAK_AXIS_SPREAD = np.deg2rad(10.0)


@dataclass(frozen=True)
class MotionCheck:
    """Excitation of a motion set: relative rotation angles (rad), axis spread (rad)."""

    angles: np.ndarray
    axis_spread: float
    common_axis: np.ndarray | None
    warnings: tuple = ()


# ----------------------------------------------------------------------------- helpers
def _check_poses(T, name: str) -> np.ndarray:
    T = check_transform(T, name, atol=1e-5)
    if T.ndim != 3:
        raise ShapeError(f"{name} must have shape (N, 4, 4), got {T.shape}")
    return T


#: Most relative motions "all" pairs gives (n <= 200 poses); beyond, "all" takes the pairs (i, i + k) for
#: strides k = 1, 2, 4, ... < n: O(n log n) motions instead of n^2 / 2 (10^4 poses: 1.3e5 instead of
#: 5e7 motions, 6.4 GB of 4x4 matrices), every pose still in motions of every scale.
MAX_ALL_PAIRS = 20_000


def _pair_indices(n: int, pairs: str) -> list[tuple[int, int]]:
    if pairs == "all" and n * (n - 1) // 2 > MAX_ALL_PAIRS:
        out, k = [], 1
        while k < n:
            out += [(i, i + k) for i in range(n - k)]
            k *= 2
        return out
    if pairs == "all":
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    if pairs == "consecutive":
        return [(i, i + 1) for i in range(n - 1)]
    raise InputError(f"pairs must be 'all' or 'consecutive', got {pairs!r}")


def relative_motions(T_base_gripper, T_cam_target, *, pairs: str = "all"):
    """Relative motions ``(A, B)`` (M, 4, 4) with ``A X = X B`` from absolute poses.

    ``A = T_base_gripper[j]^-1 T_base_gripper[i]``, ``B = T_cam_target[j] T_cam_target[i]^-1``
    for the pairs ``(i, j)`` (all ``i < j`` up to :data:`MAX_ALL_PAIRS` of them, else strides of powers
    of two; or consecutive ones).
    """
    Tg = _check_poses(T_base_gripper, "T_base_gripper")
    Tc = _check_poses(T_cam_target, "T_cam_target")
    if len(Tg) != len(Tc):
        raise ShapeError(f"T_base_gripper has {len(Tg)} poses but T_cam_target has {len(Tc)}: counts must match")
    if len(Tg) < 3:
        raise NotEnoughDataError(f"hand-eye calibration needs at least 3 poses (2 motions), got {len(Tg)}")
    idx = _pair_indices(len(Tg), pairs)
    i, j = np.array(idx).T
    A = invert_transform(Tg[j]) @ Tg[i]
    B = Tc[j] @ invert_transform(Tc[i])
    return A, B


def _axes_angles(R: np.ndarray):
    rv = rotvec_from_matrix(R)
    ang = np.linalg.norm(rv, axis=-1)
    axes = rv / np.maximum(ang, 1e-300)[..., None]
    return axes, ang


def check_motions(A, B=None, *, min_rotation: float = MIN_ROTATION, min_axis_spread: float = MIN_AXIS_SPREAD,
                  what: str = "X") -> MotionCheck:
    """Check that relative motions determine a hand-eye transform.

    Raises
    ------
    DegenerateGeometryError
        Every relative rotation is below ``min_rotation`` (too little rotation),
        or the rotation axes are parallel within ``min_axis_spread``: then the
        rotations fix only two of X's three rotation parameters and X's
        translation along the common axis is not determined at all.

    Returns
    -------
    MotionCheck
        With a ``weakly_determined`` diagnostic when the spread is below 10 deg
        and an ``inconsistent_data`` one when |angle(A_i) - angle(B_i)| is
        large (the pair is not a rigid motion of one body: wrong pairing,
        timestamps, or units).
    """
    A = np.asarray(A, float)
    _, ang = _axes_angles(A[:, :3, :3])
    warns = []
    if ang.max() < min_rotation:
        raise DegenerateGeometryError(
            f"too little rotation: the largest relative rotation is {np.rad2deg(ang.max()):.3g} deg "
            f"(< {np.rad2deg(min_rotation):.3g} deg); the rotation of {what} is not determined, "
            "rotate the sensor about at least two different axes")
    axes, _ = _axes_angles(A[ang >= min_rotation, :3, :3])
    if len(axes) >= 2:
        # sign-free spread: singular values of the stacked axes; for two axes at
        # angle phi the ratio s2/s1 is tan(phi/2).
        s = np.linalg.svd(axes, compute_uv=False)
        spread = float(2 * np.arctan(s[1] / s[0]))
        common = np.linalg.svd(axes, full_matrices=False)[2][0]
    else:
        spread, common = 0.0, axes[0]
    if spread < min_axis_spread:
        raise DegenerateGeometryError(
            f"all relative rotations are about parallel axes (spread {np.rad2deg(spread):.3g} deg < "
            f"{np.rad2deg(min_axis_spread):.3g} deg, common axis {np.round(common, 3).tolist()} in the gripper "
            f"frame): the translation of {what} along that axis is undetermined and its rotation about it is "
            "fixed only through the translations; add a rotation about a second axis")
    if spread < WEAK_AXIS_SPREAD:
        warns.append(Diagnostic("weakly_determined",
                                f"rotation axes span only {np.rad2deg(spread):.3g} deg: {what} is weakly determined",
                                params=("rx", "ry", "rz", "tx", "ty", "tz")))
    if B is not None:
        _, angB = _axes_angles(np.asarray(B, float)[:, :3, :3])
        diff = np.abs(ang - angB)
        bad = np.flatnonzero(diff > max(np.deg2rad(1.0), 10 * np.median(diff)))
        if bad.size:
            warns.append(Diagnostic("inconsistent_data",
                                    f"{bad.size} motion pair(s) rotate by different angles in the two streams "
                                    f"(worst {np.rad2deg(diff.max()):.3g} deg): mispaired poses or timestamps?",
                                    indices=tuple(int(k) for k in bad)))
    return MotionCheck(ang, spread, None if spread >= min_axis_spread else common, tuple(warns))



def transform_error(T_est, T_true) -> tuple[float, float]:
    """Rotation (rad) and translation (m) error of an estimate: angle of ``R_est R_true^T`` and ``|t_est - t_true|``.

    :meth:`robocal.geometry.PoseWithCovariance.error_to`'s first two fields (kept for its callers).
    """
    err = PoseWithCovariance(T_est).error_to(T_true)
    return float(err.rotation), float(err.translation)


def _perturbed(T0, x):
    return transform_from(matrix_from_rotvec(x[:3]) @ T0[:3, :3], x[3:6])


def _pose_residual(T_a, T_b):
    """(n, 6): rotation vector of R_a R_b^T (rad) and t_a - t_b (m)."""
    Rerr = T_a[..., :3, :3] @ np.swapaxes(T_b[..., :3, :3], -1, -2)
    return np.concatenate([rotvec_from_matrix(Rerr), T_a[..., :3, 3] - T_b[..., :3, 3]], axis=-1)


def _sigmas(r: np.ndarray, floor_rot=1e-9, floor_t=1e-12):
    sr = max(float(np.sqrt(np.mean(r[:, :3] ** 2))), floor_rot)
    st = max(float(np.sqrt(np.mean(r[:, 3:] ** 2))), floor_t)
    return sr, st


_LABELS = ("rx", "ry", "rz", "tx", "ty", "tz")
