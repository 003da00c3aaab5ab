"""Pose pairs and their relative motions: pairing, excitation check, pose residuals.

Shared by the closed forms (:mod:`.axxb`, :mod:`.axzb`), the refinement
(:mod:`.refine`) and the plausibility check (:mod:`.plausibility`). Frames as
in :mod:`robocal.handeye`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack as _lapack

from robocal._stats import median
from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.geometry import PoseWithCovariance, matrix_from_rotvec, rotvec_from_matrix, transform_from
from robocal.validation import check_transform

__all__ = ["MIN_ROTATION", "MIN_AXIS_SPREAD", "WEAK_AXIS_SPREAD", "MAX_ALL_PAIRS", "MAX_LONG_PAIRS",
           "LONG_PAIR_ANGLES", "PAIR_MODES", "MotionCheck", "pair_indices", "relative_motions", "check_motions",
           "transform_error", "pose_label", "name_outliers"]

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
#: Tolerance of the pose check (orthonormality and last row).
_POSE_ATOL = 1e-5
# cyclic index shifts: (a x b)_i = a_{i+1} b_{i+2} - a_{i+2} b_{i+1}
_CYC1, _CYC2 = np.array([1, 2, 0]), np.array([2, 0, 1])


def _eigh3(S):
    """``np.linalg.eigh`` of a small symmetric matrix (ascending, lower triangle as NumPy reads it) by LAPACK's
    dsyevd through scipy.linalg.lapack (numpy.linalg's wrapper costs 4x the 3 x 3 problem); NumPy's where
    LAPACK reports a failure (it raises NumPy's error)."""
    w, V, info = _lapack.dsyevd(S, lower=1)
    return (w, V) if info == 0 else np.linalg.eigh(S)


def _check_poses(T, name: str) -> np.ndarray:
    """``T`` as (N, 4, 4) rigid transforms, checked as :func:`robocal.validation.check_transform` does.

    A float64 (N, 4, 4) array is checked here in a few vectorised operations (finite, ``R^T R = I`` to
    :data:`_POSE_ATOL`, det R >= 0, last row) — the generic check costs ~0.13 ms a list, a tenth of a 15-pose
    OpenCV hand-eye call (issue 16); anything else, or a failure, goes to the generic check, which words
    the error."""
    if isinstance(T, np.ndarray) and T.dtype == np.float64 and T.ndim == 3 and T.shape[1:] == (4, 4):
        R = T[:, :3, :3]
        err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(initial=0.0)
        last = np.abs(T[:, 3, :] - (0.0, 0.0, 0.0, 1.0)).max(initial=0.0)
        # err / last are NaN-propagating maxima: a NaN anywhere in R or the last row fails the comparisons;
        # the translations' finiteness is its own check
        # det R >= 0 as the triple product r0 . (r1 x r2) (np.linalg.det's wrapper costs more on 3 x 3s)
        if err <= _POSE_ATOL and last <= _POSE_ATOL and np.isfinite(T[:, :3, 3]).all() and (np.einsum(
                "ni,ni->n", R[:, 0], R[:, 1, _CYC1] * R[:, 2, _CYC2] - R[:, 1, _CYC2] * R[:, 2, _CYC1]) >= 0).all():
            return T
    T = check_transform(T, name, atol=_POSE_ATOL)
    if T.ndim != 3:
        raise ShapeError(f"{name} must have shape (N, 4, 4), got {T.shape}")
    return T


#: ``pairs="auto"`` takes every pair up to this many (n <= 200 poses); beyond, consecutive pairs plus a
#: bounded set of longer ones (:func:`pair_indices`).
MAX_ALL_PAIRS = 20_000
#: At most this many longer pairs ``(i, i + k)``, k >= 2, beside the consecutive ones (``pairs="auto"``).
MAX_LONG_PAIRS = 20_000
#: The gripper rotation (rad) a longer pair must have to be taken: well above the axis noise of small
#: rotations, away from the half-turn where a rotation axis' sign is arbitrary.
LONG_PAIR_ANGLES = (np.deg2rad(10.0), np.deg2rad(150.0))
#: The pair selections (``--pairs``).
PAIR_MODES = ("auto", "consecutive", "all")
#: Working memory of the closed forms per motion (bytes): A, B and their temporaries (tracemalloc peaks on
#: 2e4 motions: 600 B Tsai/Park, 950 B Daniilidis, 1.6 KB Andreff; x2.5 for margin).
BYTES_PER_MOTION = 4096
#: Working memory (bytes) below which the pairs are not checked against the free memory: reading
#: /proc/meminfo costs more than a 15-pose closed form's pairing (issue 16), and a few MB always fit.
_MEMORY_CHECK_FLOOR = 16 * 2**20


def pair_indices(T_base_gripper, pairs: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """The pose pairs ``(i, j)``, ``i < j``, whose relative motions the closed forms use: two int arrays.

    * ``"consecutive"``: ``(i, i + 1)``, n - 1 pairs.
    * ``"all"``: every ``i < j``, n (n - 1) / 2 pairs (refused with a one-line
      :class:`~robocal.errors.ResourceError` when they do not fit in memory).
    * ``"auto"``: all pairs while there are at most :data:`MAX_ALL_PAIRS` (n <= 200); beyond, the
      consecutive pairs plus, for each stride ``k = 2, 4, 8, ... < n``, up to
      ``MAX_LONG_PAIRS / (number of strides)`` pairs ``(i, i + k)`` evenly spaced in ``i``, kept when the
      gripper turns by :data:`LONG_PAIR_ANGLES` (10-150 deg) between them: long motions are well
      conditioned (a consecutive pair of a dense stream turns by a fraction of a degree: its axis is
      noise) and every pose still takes part through its consecutive pairs. At most
      ``n - 1 + MAX_LONG_PAIRS`` pairs: memory linear in n.
    """
    Tg = np.asarray(T_base_gripper, float)
    n = len(Tg)
    if pairs not in PAIR_MODES:
        raise InputError(f"pairs must be one of {', '.join(PAIR_MODES)}, got {pairs!r}")
    if pairs == "all" or (pairs == "auto" and n * (n - 1) // 2 <= MAX_ALL_PAIRS):
        m = n * (n - 1) // 2
        if m * (BYTES_PER_MOTION + 16) > _MEMORY_CHECK_FLOOR:
            from robocal.resources import require_memory

            require_memory(m * (BYTES_PER_MOTION + 16), f"the relative motions of all {m} pairs of {n} "
                           "poses (--pairs all)")
        return _all_pairs(n)
    cons = np.arange(n - 1)
    if pairs == "consecutive":
        return cons, cons + 1
    strides = 2 ** np.arange(1, max(int(np.ceil(np.log2(n))), 1))
    strides = strides[strides < n]
    per = max(MAX_LONG_PAIRS // max(len(strides), 1), 1)
    li = [np.unique(np.linspace(0, n - 1 - k, min(per, n - k)).round().astype(np.intp)) for k in strides]
    lj = [i + k for i, k in zip(li, strides)]
    li, lj = (np.concatenate(li), np.concatenate(lj)) if li else (np.zeros(0, np.intp),) * 2
    R = Tg[:, :3, :3]
    cos = np.clip((np.einsum("nab,nab->n", R[li], R[lj]) - 1) / 2, -1, 1)
    ang = np.arccos(cos)
    keep = (ang >= LONG_PAIR_ANGLES[0]) & (ang <= LONG_PAIR_ANGLES[1])
    return np.concatenate([cons, li[keep]]), np.concatenate([cons + 1, lj[keep]])


@functools.lru_cache(maxsize=32)
def _all_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, 1)``, cached read-only (a calibration's closed forms and checks ask again)."""
    i, j = np.triu_indices(n, 1)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def _inverse(T):
    """Inverses of validated rigid transforms (N, 4, 4): ``[R^T | -R^T t]`` without re-validation."""
    Rt = np.swapaxes(T[:, :3, :3], 1, 2)
    out = np.zeros_like(T)
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -(Rt @ T[:, :3, 3:])[..., 0]
    out[:, 3, 3] = 1.0
    return out


def _motions(Tg, Tc, i, j):
    """``A = Tg[j]^-1 Tg[i]``, ``B = Tc[j] Tc[i]^-1`` for index arrays ``i``, ``j`` (validated poses)."""
    # each pose inverted once, not once per pair it is in (105 pairs of 15 poses)
    return _inverse(Tg)[j] @ Tg[i], Tc[j] @ _inverse(Tc)[i]


def relative_motions(T_base_gripper, T_cam_target, *, pairs: str = "auto"):
    """Relative motions ``(A, B)`` (M, 4, 4) with ``A X = X B`` from absolute poses.

    ``A = T_base_gripper[j]^-1 T_base_gripper[i]``, ``B = T_cam_target[j] T_cam_target[i]^-1``
    for the pairs ``(i, j)`` of :func:`pair_indices` (``"auto"``, ``"consecutive"`` or ``"all"``).
    """
    Tg = _check_poses(T_base_gripper, "T_base_gripper")
    Tc = _check_poses(T_cam_target, "T_cam_target")
    if len(Tg) != len(Tc):
        raise ShapeError(f"T_base_gripper has {len(Tg)} poses but T_cam_target has {len(Tc)}: counts must match")
    if len(Tg) < 3:
        raise NotEnoughDataError(f"hand-eye calibration needs at least 3 poses (2 motions), got {len(Tg)}")
    return _motions(Tg, Tc, *pair_indices(Tg, pairs))


def _axes_angles(R: np.ndarray, rv: np.ndarray | None = None):
    # motions are products of validated poses: the NumPy log map (~20 us) rather than SciPy's Rotation,
    # whose validation and re-orthogonalisation cost ~0.2 ms a call, twice per calibration (issue 16);
    # ``rv``: the rotation vectors when the caller has them already (the closed forms need them too)
    if rv is None:
        from robocal.handeye._lie import log_so3

        rv = log_so3(R)
    ang = np.linalg.norm(rv, axis=-1)
    axes = rv / np.maximum(ang, 1e-300)[..., None]
    return axes, ang


def _angles(R: np.ndarray, rv: np.ndarray | None = None) -> np.ndarray:
    """Rotation angles (rad) of ``R`` (M, 3, 3), from its rotation vectors ``rv`` when given."""
    if rv is None:
        from robocal.handeye._lie import log_so3

        rv = log_so3(R)
    return np.sqrt(np.einsum("ij,ij->i", rv, rv))


_ONE_DEGREE = np.deg2rad(1.0)


def pose_label(k: int, times=None) -> str:
    """``"pose 12"`` or ``"pose 12 (t = 3.400 s)"``: a pose as the user finds it (numbered from 0, the order
    of the file and of the report's per-pose figures)."""
    return f"pose {int(k)}" + ("" if times is None else f" (t = {float(times[int(k)]):.3f} s)")


def _poses_of_pairs(i, j, bad, n: int) -> np.ndarray:
    """The poses behind flagged pairs: those more than half of whose pairs are flagged (one bad pose spoils
    every pair it is in, its partners only one each); failing that, every pose of a flagged pair."""
    used = np.bincount(np.r_[i, j], minlength=n)
    hit = np.bincount(np.r_[i[bad], j[bad]], minlength=n)
    poses = np.flatnonzero(2 * hit > used)
    return poses if poses.size else np.flatnonzero(hit)


def _name_poses(poses, times=None, limit: int = 8) -> str:
    shown = ", ".join(pose_label(k, times) for k in poses[:limit])
    return shown + (f" and {len(poses) - limit} more" if len(poses) > limit else "")


def name_outliers(warnings, times=None, *, what: str) -> list:
    """The solver's ``outliers`` warning with POSES named (one closure observation per pose, so its
    observation numbers are pose numbers) and their times; other warnings unchanged."""
    out = []
    for w in warnings:
        if w.code == "outliers" and w.indices:
            poses = np.asarray(w.indices, int)
            head = w.message.split(":")[0]
            w = Diagnostic("outliers", f"{_name_poses(poses, times)}: the closure {what} of "
                           f"{'this pose' if len(poses) == 1 else 'these poses'} is an outlier ({head})",
                           params=w.params, indices=w.indices)
        out.append(w)
    return out


def check_motions(A, B=None, *, min_rotation: float = MIN_ROTATION, min_axis_spread: float = MIN_AXIS_SPREAD,
                  what: str = "X", pairs=None, times=None, _rotvecs=None) -> MotionCheck:
    """Check that relative motions determine a hand-eye transform.

    ``pairs`` (two index arrays ``(i, j)``, :func:`pair_indices`) and ``times`` (s, per pose) let the
    ``inconsistent_data`` warning name POSE numbers (and times), never motion indices.

    Memory: O(M) for M motions (the axis spread is the 3 x 3 scatter of the axes, not an SVD of the
    M x 3 stack with its M x M left factor).

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
        timestamps, or units); its ``indices`` are the poses to blame.
    """
    A = np.asarray(A, float)
    rvA, rvB = _rotvecs if _rotvecs is not None else (None, None)   # private: the log maps of A and B
    all_axes, ang = _axes_angles(A[:, :3, :3], rvA)
    warns = []
    if ang.max() < min_rotation:
        raise DegenerateGeometryError(
            f"too little rotation: the largest relative rotation is {np.rad2deg(ang.max()):.3g} deg "
            f"(< {np.rad2deg(min_rotation):.3g} deg); the rotation of {what} is not determined, "
            "rotate the sensor about at least two different axes")
    axes = all_axes[ang >= min_rotation]
    if len(axes) >= 2:
        # sign-free spread from the 3 x 3 scatter S = sum a a^T (eigenvalues = squared singular values of
        # the stacked axes); for two axes at angle phi the ratio s2/s1 is tan(phi/2).
        w, V = _eigh3(axes.T @ axes)
        s = np.sqrt(np.maximum(w[::-1], 0.0))
        spread = float(2 * np.arctan(s[1] / s[0]))
        common = V[:, -1]
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
        angB = _angles(np.asarray(B, float)[:, :3, :3], rvB)
        diff = np.abs(ang - angB)
        bad = diff > max(_ONE_DEGREE, 10 * median(diff))
        if bad.any():
            if pairs is not None:
                i, j = (np.asarray(a, np.intp) for a in pairs)
                poses = _poses_of_pairs(i, j, bad, int(max(i.max(), j.max())) + 1)
                msg = (f"{_name_poses(poses, times)}: the robot and the sensor rotate by different angles in "
                       f"the motions to and from {'it' if len(poses) == 1 else 'them'} (worst "
                       f"{np.rad2deg(diff.max()):.3g} deg over {int(bad.sum())} motion(s)): mispaired poses, "
                       "timestamps or an outlier?")
                indices = tuple(int(k) for k in poses)
            else:
                msg = (f"{int(bad.sum())} motion(s) rotate by different angles in the two streams "
                       f"(worst {np.rad2deg(diff.max()):.3g} deg): mispaired poses or timestamps?")
                indices = tuple(int(k) for k in np.flatnonzero(bad))
            warns.append(Diagnostic("inconsistent_data", msg, indices=indices))
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


def _rms(r) -> tuple[float, float]:
    """RMS of the rotation (rad) and translation (m) columns of pose residuals (N, 6) (np.mean's own sums)."""
    r2 = r * r
    n = 3 * len(r)
    return math.sqrt(float(r2[:, :3].sum()) / n), math.sqrt(float(r2[:, 3:].sum()) / n)


def _sigmas(rot_rms: float, trans_rms: float, floor_rot=1e-9, floor_t=1e-12):
    """The refinement's residual scales (rad, m): a closed form's closure RMS (:func:`_rms`), floored (an exact
    closed form has none)."""
    return max(rot_rms, floor_rot), max(trans_rms, floor_t)


_LABELS = ("rx", "ry", "rz", "tx", "ty", "tz")
