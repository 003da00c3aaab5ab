"""Robot-world / hand-eye AX = ZB: Shah's closed form and the joint refinement of X and Z.

``A_i X = Z B_i`` with ``A = T_cam_world``, ``B = T_gripper_base``,
``X = T_world_base``, ``Z = T_cam_gripper``. Reference: M. Shah, "Solving the
robot-world/hand-eye calibration problem using the Kronecker product",
J. Mechanisms Robotics 5(3), 2013.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import DegenerateGeometryError, NotEnoughDataError, ShapeError
from robocal.estimation import Problem, solve
from robocal.geometry import PoseWithCovariance, invert_transform, project_to_rotation, transform_from
from robocal.handeye._lie import left_jacobian, left_jacobian_inverse, log_so3, skew3
from robocal.handeye.motions import (_LABELS, MIN_AXIS_SPREAD, MIN_ROTATION, _check_poses, _rms, _sigmas,
                                     check_motions, name_outliers, pair_indices)
from robocal.handeye.refine import _perturb
from robocal.handeye.plausibility import judge_poses

__all__ = ["RobotWorldResult", "calibrate_robot_world"]


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

    @property
    def X_pose(self) -> PoseWithCovariance:
        """``X = T_world_base`` with its 6x6 block of :attr:`cov` (left side; none before refinement)."""
        return PoseWithCovariance(self.X, None if self.cov is None else np.asarray(self.cov)[:6, :6])

    @property
    def Z_pose(self) -> PoseWithCovariance:
        """``Z = T_cam_gripper`` with its 6x6 block of :attr:`cov` (the X-Z correlation is in :attr:`cov`)."""
        return PoseWithCovariance(self.Z, None if self.cov is None else np.asarray(self.cov)[6:, 6:])



def _rw_rotation(RA, RB):
    """Shah: (R_A (x) I) vec R_X - (I (x) R_B^T) vec R_Z = 0, null vector of the 9N x 18 system."""
    I3 = np.eye(3)
    # kron(R_A, I)[3i+k, 3j+l] = R_A[i, j] d_kl and kron(I, R_B^T)[3i+k, 3j+l] = d_ij R_B[l, k], for all poses at once
    K = np.concatenate([np.einsum("nij,kl->nikjl", RA, I3).reshape(-1, 9, 9),
                        -np.einsum("ij,nlk->nikjl", I3, RB).reshape(-1, 9, 9)], axis=2).reshape(-1, 18)
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



def _rw_predicted(TB, X, Z):
    """``A`` predicted by ``Z B X^-1``: rotations (N, 3, 3) and translations (N, 3)."""
    Rp = Z[:3, :3] @ TB[:, :3, :3] @ X[:3, :3].T
    return Rp, Z[:3, 3] + TB[:, :3, 3] @ Z[:3, :3].T - Rp @ X[:3, 3]


def _rw_residual(TA, TB, X, Z):
    """(N, 6) residual of ``A X = Z B`` in the camera's own terms: the measured ``A`` against ``Z B X^-1``,
    ``log(R_A R_pred^T)`` (rad) and ``t_A - t_pred`` (m).

    The camera's pose error (a rotation d left of ``R_A``, a translation error added to ``t_A``) then enters
    the two parts separately, as the weighting by ``(sr, st)`` assumes. The form ``t(A X) - t(Z B)`` (before
    2026-11-27) carried ``[R_A t_X]x d`` into the translation residual too, 0.65 mm per mrad at the bench's
    0.65 m: correlated parts weighted as independent, errors above Shah's closed form and a NEES of 1.27.
    """
    Rp, tp = _rw_predicted(TB, X, Z)
    return np.concatenate([log_so3(TA[:, :3, :3] @ np.swapaxes(Rp, 1, 2)), TA[:, :3, 3] - tp], axis=1)


def _rw_jacobian(TA, TB, X, Z, e, wx, wz):
    """d(residual)/d(X's and Z's parameters), (N, 6, 12): X's columns then Z's (rx, ry, rz, tx, ty, tz).

    With ``R_X = exp(w_X) R_X0``, ``R_Z = exp(w_Z) R_Z0`` (:func:`~.refine._perturb`), ``E = R_A R_X R_B^T R_Z^T``
    and ``R_p = R_Z R_B R_X^T``: ``de/dw_X = J_l(e)^-1 R_A J_l(w_X)``, ``de/dw_Z = -J_l(e)^-T J_l(w_Z)`` (the
    derivation of :func:`~.refine._closure_jacobian`); the translation ``t_A - t_Z - R_Z (t_B - R_B R_X^T t_X)``
    gives ``R_p [t_X]x J_l(w_X)`` (w_X), ``R_p`` (t_X), ``-[R_Z (R_B R_X^T t_X - t_B)]x J_l(w_Z)`` (w_Z) and
    ``-I`` (t_Z).
    """
    RA = TA[:, :3, :3]
    Rp, _ = _rw_predicted(TB, X, Z)
    Jinv = left_jacobian_inverse(e)
    JlX, JlZ = left_jacobian(wx), left_jacobian(wz)
    q = TB[:, :3, :3] @ (X[:3, :3].T @ X[:3, 3]) - TB[:, :3, 3]
    J = np.zeros((len(TA), 6, 12))
    J[:, :3, :3] = Jinv @ (RA @ JlX)
    J[:, 3:, :3] = Rp @ (skew3(X[:3, 3]) @ JlX)
    J[:, 3:, 3:6] = Rp
    J[:, :3, 6:9] = -np.swapaxes(Jinv, 1, 2) @ JlZ
    J[:, 3:, 6:9] = -skew3(q @ Z[:3, :3].T) @ JlZ
    J[:, 3:, 9:] = -np.eye(3)
    return J


def _refine_robot_world(TA, TB, X0, Z0, sr: float, st: float, *, jac: str = "analytic"):
    """Least squares on ``A X = Z B`` (:func:`_rw_residual`) from Shah's ``(X0, Z0)`` (the warm start):
    ``(Problem, LSQResult)``.

    Blocks ``X``, ``Z`` as in :func:`~.refine._refine_closure`; ``jac="2-point"``: finite differences (the
    tests' reference for the analytic Jacobian).
    """
    cache = {}

    def fun(p):
        X, Z = _perturb(X0, p["X"]), _perturb(Z0, p["Z"])
        r = _rw_residual(TA, TB, X, Z)
        cache["key"], cache["XZ"], cache["e"] = (p["X"].tobytes(), p["Z"].tobytes()), (X, Z), r[:, :3]
        return r

    def jacobian(p):
        if cache.get("key") != (p["X"].tobytes(), p["Z"].tobytes()):
            fun(p)
        return _rw_jacobian(TA, TB, *cache["XZ"], cache["e"], p["X"][:3], p["Z"][:3])

    prob = Problem()
    prob.add_block("X", np.r_[0, 0, 0, X0[:3, 3]], labels=[f"X.{k}" for k in _LABELS])
    prob.add_block("Z", np.r_[0, 0, 0, Z0[:3, 3]], labels=[f"Z.{k}" for k in _LABELS])
    prob.add_residuals(fun, name="closure", residual_dim=6, sigma=[sr] * 3 + [st] * 3,
                       jacobian=jacobian if jac == "analytic" else None)
    return prob, solve(prob, method="lm", jac=jac)


def calibrate_robot_world(T_cam_world, T_gripper_base, *, refine: bool = True, pairs: str = "auto", times=None,
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
    refine : bool
        Refine X and Z jointly from Shah's closed form by least squares on each measured ``A`` against
        ``Z B X^-1`` (:func:`_rw_residual`: rotation and translation residuals weighted by their RMS, the
        camera's pose error), which gives their covariance.
    pairs : {'auto', 'consecutive', 'all'}
        The gripper motions of the excitation check (:func:`~robocal.handeye.motions.pair_indices`).
    times : array_like, shape (N,), optional
        The poses' times (s), only to name poses in warnings.
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
    i, j = pair_indices(TB, pairs)
    chk = check_motions(TB[j] @ invert_transform(TB[i]), min_rotation=min_rotation,
                        min_axis_spread=min_axis_spread, what="X and Z")
    judged = judge_poses(invert_transform(TB), TA, names=names, accept=accept_implausible, times=times)
    Rx, Rz = _rw_rotation(TA[:, :3, :3], TB[:, :3, :3])
    M = np.concatenate([TA[:, :3, :3], np.broadcast_to(-np.eye(3), (len(TA), 3, 3))], axis=2).reshape(-1, 6)
    rhs = (np.einsum("ij,nj->ni", Rz, TB[:, :3, 3]) - TA[:, :3, 3]).reshape(-1)
    sol, *_ = np.linalg.lstsq(M, rhs, rcond=None)
    X0, Z0 = transform_from(Rx, sol[:3]), transform_from(Rz, sol[3:])
    rot0, trans0 = _rms(_rw_residual(TA, TB, X0, Z0))
    warnings = judged + list(chk.warnings)
    out = RobotWorldResult(X=X0, Z=Z0, method="shah", rot_rms=rot0, trans_rms=trans0, warnings=warnings)
    if not refine:
        return out
    sr, st = _sigmas(rot0, trans0)

    _, res = _refine_robot_world(TA, TB, X0, Z0, sr, st)
    X, Z = _perturb(X0, res.params["X"]), _perturb(Z0, res.params["Z"])
    rot, trans = _rms(_rw_residual(TA, TB, X, Z))
    std = {f"X.{k}": res.std.get(f"X.{k}") for k in _LABELS} | {f"Z.{k}": res.std.get(f"Z.{k}") for k in _LABELS}
    return RobotWorldResult(X=X, Z=Z, method="shah+refine", cov=res.cov, std=std,
                            rot_rms=rot, trans_rms=trans,
                            warnings=warnings + name_outliers(res.warnings, times, what="A X = Z B"),
                            lsq=res)
