"""Classic hand-eye solvers: AX = XB (eye-in-hand) and AX = ZB (robot-world).

Frames and names (see ``docs/conventions.md``: ``T_a_b`` maps b into a):

* eye-in-hand, absolute poses: ``T_base_gripper[i]`` from the robot and
  ``T_cam_target[i]`` from the sensor; unknown ``X = T_gripper_cam`` and the
  fixed target ``Y = T_base_target = T_base_gripper[i] X T_cam_target[i]``.
  These are OpenCV's ``R/t_gripper2base``, ``R/t_target2cam`` and
  ``R/t_cam2gripper`` (``cv2.calibrateHandEye``).
* relative motions: for a pair (i, j), ``A = T_base_gripper[j]^-1 T_base_gripper[i]``
  (gripper motion) and ``B = T_cam_target[j] T_cam_target[i]^-1`` (sensor
  motion) satisfy ``A X = X B``.
* robot-world: ``A[i] X = Z B[i]`` with ``A = T_cam_world``,
  ``B = T_gripper_base``, ``X = T_world_base`` and ``Z = T_cam_gripper``
  (``cv2.calibrateRobotWorldHandEye``'s ``world2cam``, ``base2gripper``,
  ``base2world``, ``gripper2cam``).

Closed-form rotation solvers: Tsai-Lenz (modified Rodrigues vectors),
Park-Martin (log map / orthogonal Procrustes), Horaud-Dornaika (unit
quaternions, eigenvector), Andreff (Kronecker null space), Daniilidis (dual
quaternions, rotation and translation together); Shah (Kronecker) for AX = ZB.
Every solver can be followed by a nonlinear refinement on all poses
(:mod:`robocal.estimation`), which gives the covariance.

Degenerate motion sets are refused, never answered with an identity: if every
relative rotation is below ``min_rotation``, or all rotation axes are parallel
(planar motion of a mobile robot, seed 002; a single revolute joint), a
:class:`~robocal.errors.DegenerateGeometryError` names the undetermined part
(rotation about the common axis from rotations alone, translation along it).

References
----------
R. Tsai, R. Lenz, IEEE T-RA 5(3), 1989. F. Park, B. Martin, IEEE T-RA 10(5),
1994. R. Horaud, F. Dornaika, IJRR 14(3), 1995. N. Andreff, R. Horaud,
B. Espiau, 3DIM 1999. K. Daniilidis, IJRR 18(3), 1999. M. Shah, J. Mech. Rob.
5(3), 2013.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.estimation import Problem, solve
from robocal.geometry import (
    invert_transform,
    matrix_from_quaternion,
    matrix_from_rotvec,
    project_to_rotation,
    rotation_angle,
    rotvec_from_matrix,
    skew,
    transform_from,
)
from robocal.validation import check_array, check_transform

__all__ = [
    "AXXB_METHODS",
    "invert_with_covariance",
    "HandEyeResult",
    "RobotWorldResult",
    "MotionCheck",
    "relative_motions",
    "check_motions",
    "solve_ax_xb",
    "calibrate_hand_eye",
    "calibrate_robot_world",
    "transform_error",
    "judge_poses",
    "closure_residuals",
]

AXXB_METHODS = ("tsai", "park", "horaud", "andreff", "daniilidis")
#: Default smallest useful relative rotation (rad): below it the axis is noise.
MIN_ROTATION = np.deg2rad(2.0)
#: Default smallest spread between rotation axes (rad) before the set is called parallel.
MIN_AXIS_SPREAD = np.deg2rad(2.0)
#: Axis spread (rad) below which the result is flagged as weakly determined.
WEAK_AXIS_SPREAD = np.deg2rad(10.0)

# Plausibility of the pose lists (:func:`judge_poses`). The closure T_base_gripper X T_cam_target = Y
# turns a rotation error d into a translation error of about d times the lever (the target's distance
# from the camera plus the camera's from the gripper), so with consistent data the translation RMS is
# about the rotation RMS times the lever (the shipped example: ratio 1.1). A unit slip on one list's
# translations breaks that (target in mm: ratio 28, gripper in mm: 2.8e4); a translation-only noise
# source can too, hence the absolute floor below which no translation residual is judged.
#: translation residual / (rotation residual x lever) above which the translations are implausible
TRANS_ROT_RATIO_MAX = 10.0
#: translation residual (m) below which the translations are never judged implausible
TRANS_FLOOR = 0.01
#: rotation residual (rad) above which pose inversions / quaternion orders are tried (0.17 deg:
#: the example has 0.72 mrad; an inverted list 11 mrad, scalar-first quaternions 10.5 mrad)
ROT_TRY = 3e-3
#: a camera farther from the gripper than this many times the robot's reach is implausible
REACH_FACTOR = 10.0


# ----------------------------------------------------------------------------- results
@dataclass
class HandEyeResult:
    """Outcome of an AX = XB calibration.

    Attributes
    ----------
    X : ndarray, shape (4, 4)
        ``T_gripper_cam`` (metres).
    method : str
        Closed-form solver used (``+refine`` when refined).
    Y : ndarray, shape (4, 4) or None
        ``T_base_target`` when absolute poses were given.
    cov : ndarray, shape (6, 6) or None
        Covariance of ``(rx, ry, rz, tx, ty, tz)`` of X (left rotation-vector
        perturbation in rad, translation in m); only after refinement.
    std : dict
        ``{"rx": .., ..., "tz": ..}`` (None where not identifiable).
    rot_rms, trans_rms : float
        RMS of the rotation (rad) and translation (m) residuals.
    n_motions : int
    warnings : list of Diagnostic
    lsq : LSQResult or None
    """

    X: np.ndarray
    method: str
    Y: np.ndarray | None = None
    cov: np.ndarray | None = None
    std: dict = field(default_factory=dict)
    rot_rms: float = float("nan")
    trans_rms: float = float("nan")
    n_motions: int = 0
    warnings: list = field(default_factory=list)
    lsq: object = None


@dataclass
class RobotWorldResult:
    """Outcome of an AX = ZB calibration: ``X = T_world_base``, ``Z = T_cam_gripper``.

    ``cov`` (12, 12) orders X's ``(rx, ry, rz, tx, ty, tz)`` then Z's.
    """

    X: np.ndarray
    Z: np.ndarray
    method: str
    cov: np.ndarray | None = None
    std: dict = field(default_factory=dict)
    rot_rms: float = float("nan")
    trans_rms: float = float("nan")
    warnings: list = field(default_factory=list)
    lsq: object = None


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


# ----------------------------------------------------------------------------- rotation solvers
def _quat_from_rotvec(v):
    """Scalar-first quaternions from rotation vectors, *without* sign canonicalisation."""
    th = np.linalg.norm(v, axis=-1)
    k = v / np.maximum(th, 1e-300)[..., None]
    return np.concatenate([np.cos(th / 2)[..., None], np.sin(th / 2)[..., None] * k], axis=-1)


def _aligned_rotvecs(RA, RB):
    """Rotation vectors of A and B whose axes correspond (alpha_i ~ R_X beta_i).

    Near a half-turn the axis sign of a rotation vector is arbitrary, so A's
    and B's may disagree; every closed form below then breaks. A first Park
    estimate from the motions below 0.8 pi fixes each sign: where
    ``alpha . R0 beta < 0`` beta is replaced by the same rotation written as
    ``(theta - 2 pi) k``.
    """
    alpha = rotvec_from_matrix(RA)
    beta = rotvec_from_matrix(RB)
    th = np.linalg.norm(beta, axis=-1)
    safe = th < 0.8 * np.pi
    use = safe if safe.sum() >= 2 else np.ones_like(safe)
    R0 = _rot_park(alpha[use], beta[use])
    flip = np.einsum("ni,ij,nj->n", alpha, R0, beta) < 0
    beta[flip] = beta[flip] * ((th[flip] - 2 * np.pi) / np.maximum(th[flip], 1e-300))[:, None]
    return alpha, beta


def _rot_tsai(alpha, beta):
    """Tsai-Lenz: modified Rodrigues vectors P = 2 sin(theta/2) k; skew(Pa+Pb) P' = Pb - Pa."""
    Pa = 2 * _quat_from_rotvec(alpha)[:, 1:]
    Pb = 2 * _quat_from_rotvec(beta)[:, 1:]
    M = skew(Pa + Pb).reshape(-1, 3)
    Pp, *_ = np.linalg.lstsq(M, (Pb - Pa).reshape(-1), rcond=None)
    Px = 2 * Pp / np.sqrt(1 + Pp @ Pp)
    n2 = Px @ Px
    return (1 - n2 / 2) * np.eye(3) + 0.5 * (np.outer(Px, Px) + np.sqrt(4 - n2) * skew(Px))


def _rot_park(alpha, beta):
    """Park-Martin: M = sum beta_i alpha_i^T, R = (M^T M)^-1/2 M^T (log-map Procrustes)."""
    M = beta.T @ alpha  # sum_i beta_i alpha_i^T
    w, V = np.linalg.eigh(M.T @ M)
    return project_to_rotation(V @ np.diag(1 / np.sqrt(np.maximum(w, 1e-300))) @ V.T @ M.T)


def _qleft(q):
    w, x, y, z = q
    return np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]])


def _qright(q):
    w, x, y, z = q
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]])


def _matrix_from_wxyz(q):
    return matrix_from_quaternion(np.r_[q[1:], q[0]])


def _rot_horaud(alpha, beta):
    """Horaud-Dornaika: q_A q_X = q_X q_B, smallest eigenvector of sum (L(q_A) - R(q_B))^T (...)."""
    S = np.zeros((4, 4))
    for a, b in zip(_quat_from_rotvec(alpha), _quat_from_rotvec(beta)):
        Mi = _qleft(a) - _qright(b)
        S += Mi.T @ Mi
    return _matrix_from_wxyz(np.linalg.eigh(S)[1][:, 0])


def _rot_andreff(RA, RB):
    """Andreff: (R_A (x) I - I (x) R_B^T) vec(R_X) = 0 (row-major vec), null vector -> SO(3)."""
    K = np.concatenate([np.kron(a, np.eye(3)) - np.kron(np.eye(3), b.T) for a, b in zip(RA, RB)])
    v = np.linalg.svd(K, full_matrices=False)[2][-1]
    Rx = v.reshape(3, 3)
    Rx *= np.sign(np.linalg.det(Rx)) / abs(np.linalg.det(Rx)) ** (1 / 3)
    return project_to_rotation(Rx)


def _translation(RA, tA, RB_tB_rot, Rx):
    """(R_A - I) t_X = R_X t_B - t_A stacked, least squares with a rank check."""
    tB = RB_tB_rot
    M = (RA - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,nj->ni", Rx, tB) - tA).reshape(-1)
    s = np.linalg.svd(M, compute_uv=False)
    if s[-1] < 1e-6 * s[0]:
        v = np.linalg.svd(M, full_matrices=False)[2][-1]
        raise DegenerateGeometryError(
            f"the translation of X along {np.round(v, 3).tolist()} is undetermined (rotation axes parallel)")
    t, *_ = np.linalg.lstsq(M, rhs, rcond=None)
    return t


def _daniilidis(A, B):
    """Daniilidis: dual quaternions, SVD of the 6M x 8 system, two-vector null-space combination."""
    alpha, beta = _aligned_rotvecs(A[:, :3, :3], B[:, :3, :3])

    def dual(T, rv):
        q = _quat_from_rotvec(rv)
        t = np.concatenate([np.zeros((len(T), 1)), T[:, :3, 3]], axis=1)
        qd = 0.5 * np.array([_qleft(ti) @ qi for ti, qi in zip(t, q)])
        return q, qd

    qa, qda = dual(A, alpha)
    qb, qdb = dual(B, beta)
    rows = []
    for a, ad, b, bd in zip(qa, qda, qb, qdb):
        S = np.zeros((6, 8))
        S[:3, 0] = a[1:] - b[1:]
        S[:3, 1:4] = skew(a[1:] + b[1:])
        S[3:, 0] = ad[1:] - bd[1:]
        S[3:, 1:4] = skew(ad[1:] + bd[1:])
        S[3:, 4] = a[1:] - b[1:]
        S[3:, 5:8] = skew(a[1:] + b[1:])
        rows.append(S)
    Vt = np.linalg.svd(np.concatenate(rows), full_matrices=False)[2]
    u1, v1 = Vt[-2, :4], Vt[-2, 4:]
    u2, v2 = Vt[-1, :4], Vt[-1, 4:]
    a_, b_, c_ = u1 @ v1, u1 @ v2 + u2 @ v1, u2 @ v2
    if abs(a_) < 1e-14:
        roots = np.array([-c_ / b_]) if abs(b_) > 1e-14 else np.array([0.0])
    else:
        disc = b_ * b_ - 4 * a_ * c_
        if disc < 0:
            disc = 0.0  # noise only: the exact system has real roots
        roots = (-b_ + np.array([1.0, -1.0]) * np.sqrt(disc)) / (2 * a_)
    vals = roots**2 * (u1 @ u1) + 2 * roots * (u1 @ u2) + u2 @ u2
    k = int(np.argmax(vals))
    l2 = 1 / np.sqrt(vals[k])
    l1 = roots[k] * l2
    q = l1 * u1 + l2 * u2
    qd = l1 * v1 + l2 * v2
    R = _matrix_from_wxyz(q)
    qc = q * np.array([1, -1, -1, -1])
    t = 2 * (_qleft(qd) @ qc)[1:]
    return R, t


_ROT = {"tsai": _rot_tsai, "park": _rot_park, "horaud": _rot_horaud}


def _check_method(method: str) -> str:
    m = str(method).lower().replace("-", "").replace("_", "")
    alias = {"tsailenz": "tsai", "parkmartin": "park", "horauddornaika": "horaud"}
    m = alias.get(m, m)
    if m not in AXXB_METHODS:
        raise InputError(f"method must be one of {', '.join(AXXB_METHODS)}, got {method!r}")
    return m


def solve_ax_xb(A, B, method: str = "tsai", *, min_rotation: float = MIN_ROTATION,
                min_axis_spread: float = MIN_AXIS_SPREAD) -> tuple[np.ndarray, MotionCheck]:
    """Closed-form solution of ``A_i X = X B_i``.

    Parameters
    ----------
    A, B : array_like, shape (M, 4, 4)
        Paired relative motions (metres), M >= 2 with non-parallel rotation axes.
    method : {'tsai', 'park', 'horaud', 'andreff', 'daniilidis'}

    Returns
    -------
    X : ndarray, shape (4, 4)
    check : MotionCheck
    """
    m = _check_method(method)
    A = _check_poses(A, "A")
    B = _check_poses(B, "B")
    if len(A) != len(B):
        raise ShapeError(f"A has {len(A)} motions but B has {len(B)}: counts must match")
    if len(A) < 2:
        raise NotEnoughDataError(f"AX = XB needs at least 2 motions, got {len(A)}")
    chk = check_motions(A, B, min_rotation=min_rotation, min_axis_spread=min_axis_spread)
    if m == "daniilidis":
        R, t = _daniilidis(A, B)
    else:
        if m == "andreff":
            R = _rot_andreff(A[:, :3, :3], B[:, :3, :3])
        else:
            R = _ROT[m](*_aligned_rotvecs(A[:, :3, :3], B[:, :3, :3]))
        t = _translation(A[:, :3, :3], A[:, :3, 3], B[:, :3, 3], R)
    return transform_from(R, t), chk


# ----------------------------------------------------------------------------- plausibility
def closure_residuals(T_base_gripper, T_cam_target, method: str = "tsai", *, pairs: str = "consecutive"):
    """Closed-form X and the RMS closure residuals ``(rot_rms rad, trans_rms m, X)`` of two pose lists.

    ``Y`` is the mean of ``T_base_gripper[i] X T_cam_target[i]`` (the fixed target); the residuals are
    each pose's deviation from it (rotation vector, translation).
    """
    Tg, Tc = np.asarray(T_base_gripper, float), np.asarray(T_cam_target, float)
    A, B = relative_motions(Tg, Tc, pairs=pairs)
    try:
        X, _ = solve_ax_xb(A, B, method)
    except DegenerateGeometryError:
        if pairs == "all":
            raise
        # consecutive motions about one axis can still span several with all pairs
        X, _ = solve_ax_xb(*relative_motions(Tg, Tc, pairs="all"), method)
    Yall = Tg @ X @ Tc
    Y = transform_from(project_to_rotation(np.mean(Yall[:, :3, :3], axis=0)), Yall[:, :3, 3].mean(axis=0))
    r = _pose_residual(Yall, Y[None])
    return float(np.sqrt(np.mean(r[:, :3] ** 2))), float(np.sqrt(np.mean(r[:, 3:] ** 2))), X


def _translations_plausible(Tg, Tc, rot_rms, trans_rms, X) -> tuple[bool, str]:
    lever = float(np.sqrt(np.mean(np.sum(Tc[:, :3, 3] ** 2, axis=1)))) + float(np.linalg.norm(X[:3, 3]))
    reach = max(float(np.max(np.linalg.norm(Tg[:, :3, 3], axis=1))), 0.2)
    tx = float(np.linalg.norm(X[:3, 3]))
    if tx > max(2.0, REACH_FACTOR * reach):
        return False, (f"the camera comes out {tx:.3g} m from the gripper, more than {REACH_FACTOR:g} x the "
                       f"gripper's largest distance from the base ({reach:.3g} m)")
    if trans_rms > TRANS_FLOOR and trans_rms > TRANS_ROT_RATIO_MAX * rot_rms * lever:
        return False, (f"the translation residual {1e3 * trans_rms:.3g} mm is {trans_rms / max(rot_rms * lever, 1e-300):.3g} x "
                       f"what the rotation residual {1e3 * rot_rms:.3g} mrad gives over the {lever:.3g} m lever "
                       f"(consistent poses: about 1, plausible <= {TRANS_ROT_RATIO_MAX:g})")
    return True, ""


def _quat_scalar_first(T):
    """The rotations a file meant when its qx, qy, qz, qw columns held w, x, y, z."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()        # what was read, scalar-last (x', y', z', w')
    out = np.array(T, float, copy=True)
    out[:, :3, :3] = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    return out


def judge_poses(T_base_gripper, T_cam_target, *, names=("T_base_gripper", "T_cam_target"),
                method: str = "tsai", accept: bool = False, source: str | None = None) -> list:
    """Judge two pose lists before calibration; name the slip when they are implausible.

    Two cheap figures of the closed-form closure (:func:`closure_residuals`, consecutive pairs):

    * **rotation residual**: above :data:`ROT_TRY` the lists are tried inverted (``T_a_b`` given as
      ``T_b_a``) and with scalar-first quaternions; one that lowers the residual 5 x is named.
    * **translations**: the translation residual against the rotation residual times the lever
      (:data:`TRANS_ROT_RATIO_MAX`, above :data:`TRANS_FLOOR`), and ``|t_gripper_cam|`` against the
      robot's reach (:data:`REACH_FACTOR`); when implausible, each list's translations are tried
      /1000 and x1000 (mm <-> m).

    Parameters
    ----------
    T_base_gripper, T_cam_target : array_like, shape (N, 4, 4)
        As read (metres).
    names : (str, str)
        The two lists' files, for the message.
    accept : bool
        ``--accept-implausible``: a warning instead of :class:`~robocal.errors.ImplausibleInputError`.

    Returns
    -------
    list of Diagnostic
        Empty when plausible; one ``implausible_input`` warning when accepted.
    """
    from robocal.plausibility import Slip, check_slips

    Tg, Tc = np.asarray(T_base_gripper, float), np.asarray(T_cam_target, float)
    rot, trans, X = closure_residuals(Tg, Tc, method)
    out = []
    gname, tname = names

    def rot_of(a, b):
        return 1e3 * closure_residuals(a, b, method)[0]

    if rot > ROT_TRY:
        rslips = [
            Slip("target_poses_inverted", f"the poses of {tname} look inverted (T_target_cam given as T_cam_target)",
                 "with them inverted", lambda: rot_of(Tg, invert_transform(Tc))),
            Slip("gripper_poses_inverted", f"the poses of {gname} look inverted (T_gripper_base given as "
                 "T_base_gripper)", "with them inverted", lambda: rot_of(invert_transform(Tg), Tc)),
            Slip("target_quaternion_scalar_first", f"the quaternions of {tname} look scalar-first (w, x, y, z), "
                 "not scalar-last", "with (w, x, y, z) read", lambda: rot_of(Tg, _quat_scalar_first(Tc))),
            Slip("gripper_quaternion_scalar_first", f"the quaternions of {gname} look scalar-first (w, x, y, z), "
                 "not scalar-last", "with (w, x, y, z) read", lambda: rot_of(_quat_scalar_first(Tg), Tc)),
        ]
        # on a poorly excited set (small rotations about few axes) several may explain the data about
        # equally: the best is named, the others within 10 % listed, rather than a guess
        from dataclasses import replace as _replace

        from robocal.plausibility import try_slips

        trial = try_slips(rslips, 1e3 * rot, unit="mrad")
        if trial.best is not None:
            also = [n for n, v in trial.tried if v is not None and n != trial.best.name
                    and v <= 1.1 * trial.best_value]
            describe = trial.best.describe if not also else \
                f"{trial.best.describe} (or, as well explained by these motions: {', '.join(also)})"
            named = _replace(trial, best=_replace(trial.best, describe=describe))
            d = check_slips(what="rotation residual", residual=1e3 * rot, unit="mrad", plausible=False,
                            reason="", trial=named, accept=accept, source=source)
            out.append(d)
            return out
    ok, reason = _translations_plausible(Tg, Tc, rot, trans, X)
    if ok:
        return out

    def trans_of(a, b):
        # scaling both lists alike keeps them consistent, so the undone slip must also give physical
        # sizes: a gripper within 2 cm..20 m of the base, a target 5 mm..100 m from the camera
        reach = float(np.max(np.linalg.norm(a[:, :3, 3], axis=1)))
        dist = float(np.median(np.linalg.norm(b[:, :3, 3], axis=1)))
        if not (0.02 <= reach <= 20.0 and 0.005 <= dist <= 100.0):
            return np.nan
        r, t, x = closure_residuals(a, b, method)
        return 1e3 * t if _translations_plausible(a, b, r, t, x)[0] else np.nan

    def scaled(T, k):
        T = np.array(T, float, copy=True)
        T[:, :3, 3] *= k
        return T

    tslips = [
        Slip("target_mm_as_m", f"x, y, z of {tname} look like mm, not m", "with /1000",
             lambda: trans_of(Tg, scaled(Tc, 1e-3))),
        Slip("gripper_mm_as_m", f"x, y, z of {gname} look like mm, not m", "with /1000",
             lambda: trans_of(scaled(Tg, 1e-3), Tc)),
        Slip("both_mm_as_m", f"x, y, z of {gname} and {tname} look like mm, not m", "with /1000",
             lambda: trans_of(scaled(Tg, 1e-3), scaled(Tc, 1e-3))),
        Slip("target_m_as_mm", f"x, y, z of {tname} look like m, not mm", "with x1000",
             lambda: trans_of(Tg, scaled(Tc, 1e3))),
        Slip("gripper_m_as_mm", f"x, y, z of {gname} look like m, not mm", "with x1000",
             lambda: trans_of(scaled(Tg, 1e3), Tc)),
    ]
    d = check_slips(what="translation residual", residual=1e3 * trans, unit="mm", plausible=False, reason=reason,
                    slips=tslips, accept=accept, source=source)
    out.append(d)
    return out


# ----------------------------------------------------------------------------- refinement
def transform_error(T_est, T_true) -> tuple[float, float]:
    """Rotation (rad) and translation (m) error of an estimate: angle of ``R_est R_true^T`` and ``|t_est - t_true|``."""
    T_est, T_true = np.asarray(T_est, float), np.asarray(T_true, float)
    return (float(rotation_angle(T_est[:3, :3] @ T_true[:3, :3].T)),
            float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3])))


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


def _std_dict(res, prefix: str) -> dict:
    return {k: res.std.get(f"{prefix}.{k}") for k in _LABELS}


def calibrate_hand_eye(T_base_gripper, T_cam_target, method: str = "tsai", *, refine: bool = True,
                       pairs: str = "all", min_rotation: float = MIN_ROTATION,
                       min_axis_spread: float = MIN_AXIS_SPREAD, accept_implausible: bool = False,
                       names=("T_base_gripper", "T_cam_target")) -> HandEyeResult:
    """Eye-in-hand calibration ``X = T_gripper_cam`` from absolute poses.

    Parameters
    ----------
    T_base_gripper : array_like, shape (N, 4, 4)
        Robot poses (forward kinematics), metres.
    T_cam_target : array_like, shape (N, 4, 4)
        Poses of a fixed target measured by the sensor, metres.
    method : str
        Closed-form solver, see :data:`AXXB_METHODS`.
    refine : bool
        Refine X and ``Y = T_base_target`` jointly by least squares on the
        per-pose closure ``T_base_gripper[i] X T_cam_target[i] = Y``
        (rotation and translation residuals weighted by their RMS after the
        closed form), which gives the covariance of X.
    pairs : {'all', 'consecutive'}
        Relative motions used by the closed form ('all': every pair up to 200 poses, beyond that
        the pairs ``(i, i + 2^k)``, see :data:`MAX_ALL_PAIRS`).
    accept_implausible : bool
        Go on (with an ``implausible_input`` warning) when :func:`judge_poses` finds the lists
        implausible; by default that raises :class:`~robocal.errors.ImplausibleInputError`.
    names : (str, str)
        The two lists' files, for the plausibility message.

    Returns
    -------
    HandEyeResult
    """
    Tg = _check_poses(T_base_gripper, "T_base_gripper")
    Tc = _check_poses(T_cam_target, "T_cam_target")
    A, B = relative_motions(Tg, Tc, pairs=pairs)
    m = _check_method(method)
    X0, chk = solve_ax_xb(A, B, m, min_rotation=min_rotation, min_axis_spread=min_axis_spread)
    warnings = judge_poses(Tg, Tc, names=names, accept=accept_implausible) + list(chk.warnings)
    Yall = Tg @ X0 @ Tc
    Y0 = transform_from(project_to_rotation(np.mean(Yall[:, :3, :3], axis=0)), Yall[:, :3, 3].mean(axis=0))
    r0 = _pose_residual(Yall, Y0[None])
    out = HandEyeResult(X=X0, method=m, Y=Y0, rot_rms=float(np.sqrt(np.mean(r0[:, :3] ** 2))),
                        trans_rms=float(np.sqrt(np.mean(r0[:, 3:] ** 2))), n_motions=len(A), warnings=warnings)
    if not refine:
        return out
    sr, st = _sigmas(r0)

    def fun(p):
        X = _perturbed(X0, np.r_[p["X"][:3], p["X"][3:]])
        Y = _perturbed(Y0, p["Y"])
        return _pose_residual(Tg @ X @ Tc, Y[None])

    prob = Problem()
    prob.add_block("X", np.r_[0, 0, 0, X0[:3, 3]], labels=[f"X.{k}" for k in _LABELS],
                   unit=["rad"] * 3 + ["m"] * 3)
    prob.add_block("Y", np.r_[0, 0, 0, Y0[:3, 3]], labels=[f"Y.{k}" for k in _LABELS],
                   unit=["rad"] * 3 + ["m"] * 3)
    prob.add_residuals(fun, name="closure", residual_dim=6, sigma=[sr] * 3 + [st] * 3)
    res = solve(prob, method="lm")
    X = _perturbed(X0, res.params["X"])
    Y = _perturbed(Y0, res.params["Y"])
    r = _pose_residual(Tg @ X @ Tc, Y[None])
    idx = [res.free_labels.index(f"X.{k}") for k in _LABELS]
    return HandEyeResult(X=X, method=f"{m}+refine", Y=Y, cov=res.cov[np.ix_(idx, idx)], std=_std_dict(res, "X"),
                         rot_rms=float(np.sqrt(np.mean(r[:, :3] ** 2))),
                         trans_rms=float(np.sqrt(np.mean(r[:, 3:] ** 2))), n_motions=len(A),
                         warnings=warnings + list(res.warnings), lsq=res)


def _rw_rotation(RA, RB):
    """Shah: (R_A (x) I) vec R_X - (I (x) R_B^T) vec R_Z = 0, null vector of the 9N x 18 system."""
    K = np.concatenate([np.hstack([np.kron(a, np.eye(3)), -np.kron(np.eye(3), b.T)]) for a, b in zip(RA, RB)])
    _, s, Vt = np.linalg.svd(K, full_matrices=False)
    if s[-2] < 1e-6 * s[0]:
        raise DegenerateGeometryError(
            "AX = ZB: the rotations do not determine X and Z (null space of dimension > 1); "
            "use poses whose relative rotations are about at least two different axes")
    v = Vt[-1]
    Rx, Rz = v[:9].reshape(3, 3), v[9:].reshape(3, 3)
    d = np.linalg.det(Rx)
    scale = np.sign(d) / abs(d) ** (1 / 3)
    return project_to_rotation(Rx * scale), project_to_rotation(Rz * scale)


def invert_with_covariance(T, cov):
    """``T^-1`` and its covariance (6, 6), first order, from ``cov`` (6, 6) of ``T``.

    Both covariances are over ``(rx, ry, rz, tx, ty, tz)``: the rotation vector
    of ``R_perturbed R^T`` (rad) and the translation (m), the convention of
    :class:`RobotWorldResult` and :class:`HandEyeResult`. With ``T = (R, t)``
    and ``T^-1 = (R^T, -R^T t)``: ``d omega_inv = -R^T d omega``,
    ``d t_inv = -R^T [t]x d omega - R^T d t``.
    """
    T = check_transform(T, "T")
    cov = check_array(cov, "cov", shape=(6, 6))
    R, t = T[:3, :3], T[:3, 3]
    G = np.zeros((6, 6))
    G[:3, :3] = -R.T
    G[3:, :3] = -R.T @ skew(t)
    G[3:, 3:] = -R.T
    return invert_transform(T), G @ cov @ G.T


def calibrate_robot_world(T_cam_world, T_gripper_base, *, refine: bool = True,
                          min_rotation: float = MIN_ROTATION,
                          min_axis_spread: float = MIN_AXIS_SPREAD, accept_implausible: bool = False,
                          names=("T_base_gripper", "T_cam_world")) -> RobotWorldResult:
    """Robot-world / hand-eye ``A_i X = Z B_i`` (Shah's closed form, optional refinement).

    Parameters
    ----------
    T_cam_world : array_like, shape (N, 4, 4)
        ``A``: the world (target) frame seen by the camera, metres.
    T_gripper_base : array_like, shape (N, 4, 4)
        ``B``: the inverse of the robot's forward kinematics.
    accept_implausible, names
        As in :func:`calibrate_hand_eye` (the lists are judged as ``T_base_gripper = B^-1`` and
        ``T_cam_target = A``, by :func:`judge_poses`); ``names``: the robot's and the camera's files.

    Returns
    -------
    RobotWorldResult
        ``X = T_world_base``, ``Z = T_cam_gripper``.
    """
    TA = _check_poses(T_cam_world, "T_cam_world")
    TB = _check_poses(T_gripper_base, "T_gripper_base")
    if len(TA) != len(TB):
        raise ShapeError(f"T_cam_world has {len(TA)} poses but T_gripper_base has {len(TB)}: counts must match")
    if len(TA) < 3:
        raise NotEnoughDataError(f"AX = ZB needs at least 3 poses, got {len(TA)}")
    # excitation: relative motions of the gripper (B_j^-1 B_i is a gripper motion in its own frame)
    i, j = np.array(_pair_indices(len(TB), "all")).T
    chk = check_motions(TB[j] @ invert_transform(TB[i]), min_rotation=min_rotation,
                        min_axis_spread=min_axis_spread, what="X and Z")
    judged = judge_poses(invert_transform(TB), TA, names=names, accept=accept_implausible)
    Rx, Rz = _rw_rotation(TA[:, :3, :3], TB[:, :3, :3])
    M = np.concatenate([np.hstack([a, -np.eye(3)]) for a in TA[:, :3, :3]])
    rhs = (np.einsum("ij,nj->ni", Rz, TB[:, :3, 3]) - TA[:, :3, 3]).reshape(-1)
    sol, *_ = np.linalg.lstsq(M, rhs, rcond=None)
    X0, Z0 = transform_from(Rx, sol[:3]), transform_from(Rz, sol[3:])
    r0 = _pose_residual(TA @ X0, Z0 @ TB)
    warnings = judged + list(chk.warnings)
    out = RobotWorldResult(X=X0, Z=Z0, method="shah", rot_rms=float(np.sqrt(np.mean(r0[:, :3] ** 2))),
                           trans_rms=float(np.sqrt(np.mean(r0[:, 3:] ** 2))), warnings=warnings)
    if not refine:
        return out
    sr, st = _sigmas(r0)

    def fun(p):
        return _pose_residual(TA @ _perturbed(X0, p["X"]), _perturbed(Z0, p["Z"]) @ TB)

    prob = Problem()
    prob.add_block("X", np.r_[0, 0, 0, X0[:3, 3]], labels=[f"X.{k}" for k in _LABELS])
    prob.add_block("Z", np.r_[0, 0, 0, Z0[:3, 3]], labels=[f"Z.{k}" for k in _LABELS])
    prob.add_residuals(fun, name="closure", residual_dim=6, sigma=[sr] * 3 + [st] * 3)
    res = solve(prob, method="lm")
    X, Z = _perturbed(X0, res.params["X"]), _perturbed(Z0, res.params["Z"])
    r = _pose_residual(TA @ X, Z @ TB)
    std = {f"X.{k}": res.std.get(f"X.{k}") for k in _LABELS} | {f"Z.{k}": res.std.get(f"Z.{k}") for k in _LABELS}
    return RobotWorldResult(X=X, Z=Z, method="shah+refine", cov=res.cov, std=std,
                            rot_rms=float(np.sqrt(np.mean(r[:, :3] ** 2))),
                            trans_rms=float(np.sqrt(np.mean(r[:, 3:] ** 2))), warnings=warnings + list(res.warnings),
                            lsq=res)
