"""AX = XB refined: X and the fixed target Y by least squares on every pose, with their covariance.

The closed form (:mod:`.axxb`) starts a :class:`robocal.estimation.Problem` on
the per-pose closure ``T_base_gripper[i] X T_cam_target[i] = Y`` (rotation and
translation residuals weighted by the closed form's RMS), solved by
:func:`robocal.estimation.solve` with an analytic Jacobian (:func:`_closure_jacobian`,
checked against finite differences in tests/handeye/test_handeye_refine.py) from the
closed form (the warm start: MINPACK's LM stops after 2-3 steps);
:func:`invert_with_covariance` carries a pose's covariance through its inverse (first order).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError, NotEnoughDataError, ShapeError
from robocal.estimation import Problem, solve
from robocal.geometry import PoseWithCovariance, invert_transform
from robocal.handeye._lie import _I3, exp_so3, left_jacobian, left_jacobian_inverse, log_so3, skew3
from robocal.handeye.axxb import _check_method, _nearest_rotation, _solve_checked
from robocal.handeye.motions import (_LABELS, MIN_AXIS_SPREAD, MIN_ROTATION, _check_poses, _motions, _rms, _sigmas,
                                     name_outliers, pair_indices)
from robocal.handeye.plausibility import _judge_checked
from robocal.validation import check_array, check_transform

__all__ = ["SETUPS", "HandEyeResult", "calibrate_hand_eye", "invert_with_covariance"]

#: The two set-ups: the names of X and Y (``T_parent_child``) and their frames.
#: eye-in-hand: a camera on the gripper views a fixed target, ``T_base_gripper X T_cam_target = Y``;
#: eye-to-hand: a fixed camera views a target on the gripper, ``T_base_gripper^-1 X T_cam_target = Y``.
SETUPS = {
    "eye-in-hand": {"X": ("T_gripper_cam", "gripper", "camera"), "Y": ("T_base_target", "robot base", "target")},
    "eye-to-hand": {"X": ("T_base_cam", "robot base", "camera"), "Y": ("T_gripper_target", "gripper", "target")},
}


@dataclass
class HandEyeResult:
    """Outcome of an AX = XB calibration.

    Attributes
    ----------
    X : ndarray, shape (4, 4)
        ``T_gripper_cam`` (eye-in-hand) or ``T_base_cam`` (eye-to-hand), metres.
    method : str
        Closed-form solver used (``+refine`` when refined).
    Y : ndarray, shape (4, 4) or None
        The target's pose: ``T_base_target`` (eye-in-hand) or ``T_gripper_target`` (eye-to-hand).
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
    setup: str = "eye-in-hand"

    @property
    def names(self) -> tuple[str, str]:
        """The names of X and Y in this set-up (:data:`SETUPS`): ``("T_gripper_cam", "T_base_target")`` or
        ``("T_base_cam", "T_gripper_target")``."""
        return SETUPS[self.setup]["X"][0], SETUPS[self.setup]["Y"][0]

    @property
    def X_pose(self) -> PoseWithCovariance:
        """``X`` with its covariance (left side; none before refinement): inverse, error to a truth, result."""
        return PoseWithCovariance(self.X, self.cov)


def _std_dict(res, prefix: str) -> dict:
    return {k: res.std.get(f"{prefix}.{k}") for k in _LABELS}


def _perturb(T0, x):
    """``[exp(x[:3]) R0 | x[3:]]``: the refinement's parametrisation (left rotation vector, rad; translation, m)."""
    T = np.zeros((4, 4))
    T[:3, :3] = exp_so3(x[:3]) @ T0[:3, :3]
    T[:3, 3] = x[3:6]
    T[3, 3] = 1.0
    return T


def _closure(Tg, Tc, X, Y):
    """Per-pose closure of ``Tg X Tc = Y``: ``C = Tg X Tc`` (N, 4, 4) and its residual (N, 6) against Y:
    ``e = log(R_C R_Y^T)`` (rad) and ``t_C - t_Y`` (m), :func:`~.motions._pose_residual`'s convention."""
    C = Tg @ X @ Tc
    return C, _closure_residual(C, Y)


def _closure_residual(C, Y):
    """:func:`_closure`'s residual (N, 6) of the products ``C`` (N, 4, 4) against ``Y``."""
    r = np.empty((len(C), 6))
    r[:, :3] = log_so3(C[:, :3, :3] @ Y[:3, :3].T)
    r[:, 3:] = C[:, :3, 3] - Y[:3, 3]
    return r


def _closure_jacobian(Tg, Tc, X, e, wx, wy, _const=None):
    """d(closure residual)/d(X's and Y's parameters), (N, 6, 12): columns X's then Y's (rx, ry, rz, tx, ty, tz).

    With ``R_X = exp(w_X) R_X0`` and ``R_Y = exp(w_Y) R_Y0`` (:func:`_perturb`), ``E = R_g R_X R_c R_Y^T``
    and ``e = log E``: ``exp(w + d) = exp(J_l(w) d) exp(w)`` moves ``E`` to ``exp(R_g J_l(w_X) d) E``
    and to ``E exp(-J_l(w_Y) d)``, so ``de/dw_X = J_l(e)^-1 R_g J_l(w_X)`` and
    ``de/dw_Y = -J_l(e)^-T J_l(w_Y)``; the translation ``t_C = R_g (R_X t_c + t_X) + t_g`` gives
    ``dt/dw_X = -R_g [R_X t_c]x J_l(w_X)``, ``dt/dt_X = R_g``, ``dt/dt_Y = -I``.

    ``_const``: ``(R_g, t_c, J0)`` precomputed by :func:`_closure_constants` (the refinement evaluates
    this at every step on the same poses).
    """
    Rg, tc, J0 = _closure_constants(Tg, Tc) if _const is None else _const
    Jinv = left_jacobian_inverse(e)
    J = J0.copy()                          # the constant blocks dt/dt_X = R_g and dt/dt_Y = -I in place
    JlX = left_jacobian(wx)
    RgJ = Rg @ JlX
    J[:, :3, :3] = Jinv @ RgJ
    # R_g [u]x = [R_g u]x R_g: the rotation block's R_g J_l(w_X) serves the translation block too
    J[:, 3:, :3] = -skew3(np.einsum("nij,nj->ni", Rg, tc @ X[:3, :3].T)) @ RgJ
    J[:, :3, 6:9] = -np.swapaxes(Jinv, 1, 2) @ left_jacobian(wy)
    return J


def _closure_constants(Tg, Tc):
    """What :func:`_closure_jacobian` takes from the poses alone: ``R_g`` and ``t_c`` (contiguous) and the
    Jacobian's constant part (N, 6, 12)."""
    Rg = np.ascontiguousarray(Tg[:, :3, :3])
    J0 = np.zeros((len(Tg), 6, 12))
    J0[:, 3:, 3:6] = Rg
    J0[:, 3:, 9:] = -_I3
    return Rg, np.ascontiguousarray(Tc[:, :3, 3]), J0


_X_LABELS, _Y_LABELS = tuple(f"X.{k}" for k in _LABELS), tuple(f"Y.{k}" for k in _LABELS)
_UNITS = ("rad",) * 3 + ("m",) * 3
_ZERO3 = np.zeros(3)


def _refine_closure(Tg, Tc, X0, Y0, w, sr: float, st: float, *, jac: str = "analytic", r0=None):
    """Least squares on the closure ``Tg[i] X Tc[i] = Y`` from the closed form ``(X0, Y0)``: the LSQResult.

    Blocks ``X`` and ``Y``: ``(w, t)``, the left rotation vector from ``X0`` / ``Y0`` (rad) and the translation
    (m), so the start (the warm start: ``(0, t0)``) is the closed form itself. Residuals per pose times ``w``
    (N, 6), weighted by ``sigma = (sr, sr, sr, st, st, st)``. ``jac="analytic"`` (:func:`_closure_jacobian`)
    or ``"2-point"`` (finite differences, the path before the analytic Jacobian; kept for the tests).
    ``r0``: the closure residual (N, 6) at the start, when the caller has it (the solver's first evaluation).
    """
    cache = {}
    wj = w[:, :, None]
    const = _closure_constants(Tg, Tc)
    unit = bool(np.all(w == 1.0))          # unit weights (no pose_sigmas): the products by w are identities
    x0X, x0Y = np.concatenate((_ZERO3, X0[:3, 3])), np.concatenate((_ZERO3, Y0[:3, 3]))
    if r0 is not None:
        # the start is the closed form itself, whose closure the caller has: the Problem's first evaluation
        # (and the Jacobian there) reuse it instead of a second product and log map of every pose
        cache["key"], cache["X"], cache["e"], cache["r"] = (x0X.tobytes(), x0Y.tobytes()), X0, r0[:, :3], r0

    def fun(p):
        key = (p["X"].tobytes(), p["Y"].tobytes())
        if cache.get("key") != key:
            X, Y = _perturb(X0, p["X"]), _perturb(Y0, p["Y"])
            _, r = _closure(Tg, Tc, X, Y)
            cache["key"], cache["X"], cache["e"], cache["r"] = key, X, r[:, :3], r
        return cache["r"].copy() if unit else cache["r"] * w

    def jacobian(p):
        # the solver asks for the Jacobian right after the residuals at the same point: reuse X and e
        if cache.get("key") != (p["X"].tobytes(), p["Y"].tobytes()):
            fun(p)
        J = _closure_jacobian(Tg, Tc, cache["X"], cache["e"], p["X"][:3], p["Y"][:3], const)
        return J if unit else J * wj

    prob = Problem()
    prob.add_block("X", x0X, labels=_X_LABELS, unit=_UNITS)
    prob.add_block("Y", x0Y, labels=_Y_LABELS, unit=_UNITS)
    prob.add_residuals(fun, name="closure", residual_dim=6, sigma=np.array([sr, sr, sr, st, st, st]),
                       jacobian=jacobian if jac == "analytic" else None)
    return prob, solve(prob, method="lm", jac=jac)


def calibrate_hand_eye(T_base_gripper, T_cam_target, method: str = "tsai", *, refine: bool = True,
                       pairs: str = "auto", times=None, setup: str = "eye-in-hand", pose_sigmas=None,
                       min_rotation: float = MIN_ROTATION,
                       min_axis_spread: float = MIN_AXIS_SPREAD, accept_implausible: bool = False,
                       names=("T_base_gripper", "T_cam_target")) -> HandEyeResult:
    """Hand-eye calibration from absolute poses: ``X = T_gripper_cam`` (eye-in-hand) or ``T_base_cam``
    (eye-to-hand).

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
    pairs : {'auto', 'consecutive', 'all'}
        Relative motions used by the closed form (:func:`~robocal.handeye.motions.pair_indices`; 'auto':
        every pair up to 200 poses, beyond that the consecutive ones and a bounded set of
        well-conditioned longer ones: memory linear in the number of poses).
    times : array_like, shape (N,), optional
        The poses' times (s), only to name poses in warnings.
    setup : {'eye-in-hand', 'eye-to-hand'}
        Eye-in-hand: the camera on the gripper, the target fixed; ``X = T_gripper_cam``,
        ``Y = T_base_target``. Eye-to-hand: the camera fixed, the target on the gripper; the same
        closure with the robot poses inverted, ``T_gripper_base[i] X T_cam_target[i] = Y``, gives
        ``X = T_base_cam`` and ``Y = T_gripper_target`` (:data:`SETUPS`).
    pose_sigmas : array_like, shape (N, 2), optional
        Per-pose std of ``T_cam_target``: rotation [rad] and translation [m] (e.g. from the images,
        :func:`robocal.handeye.images.view_poses`). The refinement then weights pose i's closure by
        ``1 / sigma_i`` relative to the others, with the translation std
        ``sqrt(s_t^2 + (|t_cam_target| s_rot)^2)`` (a rotation error moves the target by its distance);
        the overall scale still comes from the residuals.
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
    if setup not in SETUPS:
        raise InputError(f"setup must be one of {', '.join(SETUPS)}, got {setup!r}")
    if setup == "eye-to-hand":
        Tg = invert_transform(Tg)
    if len(Tg) != len(Tc):
        raise ShapeError(f"T_base_gripper has {len(Tg)} poses but T_cam_target has {len(Tc)}: counts must match")
    if len(Tg) < 3:
        raise NotEnoughDataError(f"hand-eye calibration needs at least 3 poses (2 motions), got {len(Tg)}")
    m = _check_method(method)
    ij = pair_indices(Tg, pairs)
    A, B = _motions(Tg, Tc, *ij)
    X0, chk = _solve_checked(A, B, m, min_rotation=min_rotation, min_axis_spread=min_axis_spread, pairs=ij,
                             times=times)
    del A, B                                    # the refinement works on the poses
    Yall = Tg @ X0 @ Tc
    Y0 = np.eye(4)
    Y0[:3, :3], Y0[:3, 3] = _nearest_rotation(Yall[:, :3, :3].mean(axis=0)), Yall[:, :3, 3].mean(axis=0)
    r0 = _closure_residual(Yall, Y0)
    rot0, trans0 = _rms(r0)
    # the lists are validated above: the plausibility check (judge_poses) takes them as they are, and this
    # closed form's closure figures (plausible ones need no closed form of the check's own)
    warnings = _judge_checked(Tg, Tc, names=names, accept=accept_implausible, times=times,
                              closed_form=(rot0, trans0, X0)) + list(chk.warnings)
    out = HandEyeResult(X=X0, method=m, Y=Y0, rot_rms=rot0, trans_rms=trans0, n_motions=len(ij[0]),
                        warnings=warnings, setup=setup)
    if not refine:
        return out
    sr, st = _sigmas(rot0, trans0)

    w = np.ones((len(Tc), 6))
    if pose_sigmas is not None:
        ps = np.asarray(pose_sigmas, float)
        if ps.shape != (len(Tc), 2) or not np.all(np.isfinite(ps) & (ps > 0)):
            raise ShapeError(f"pose_sigmas must be (N, 2) = ({len(Tc)}, 2) positive finite stds, got shape {ps.shape}")
        s_rot = ps[:, 0]
        s_t = np.hypot(ps[:, 1], np.linalg.norm(Tc[:, :3, 3], axis=1) * ps[:, 0])
        # relative weights (median 1): the overall noise scale is still estimated from the residuals
        w[:, :3] = (np.median(s_rot) / s_rot)[:, None]
        w[:, 3:] = (np.median(s_t) / s_t)[:, None]

    _, res = _refine_closure(Tg, Tc, X0, Y0, w, sr, st, r0=r0)
    X, Y = _perturb(X0, res.params["X"]), _perturb(Y0, res.params["Y"])
    # the closure at the solution: the solver's raw residuals (r * w) without the weights
    rot, trans = _rms(res.residuals.reshape(-1, 6) / w)
    idx = [res.free_labels.index(lab) for lab in _X_LABELS]
    cov = res.cov[:6, :6].copy() if idx == [0, 1, 2, 3, 4, 5] else res.cov[np.ix_(idx, idx)]
    return HandEyeResult(X=X, method=f"{m}+refine", Y=Y, cov=cov, std=_std_dict(res, "X"),
                         rot_rms=rot, trans_rms=trans, n_motions=len(ij[0]),
                         warnings=warnings + name_outliers(res.warnings, times, what="T_base_gripper X "
                                                           "T_cam_target = Y"), lsq=res, setup=setup)



def invert_with_covariance(T, cov):
    """``T^-1`` and its covariance (6, 6), first order, from ``cov`` (6, 6) of ``T``.

    Both covariances are over ``(rx, ry, rz, tx, ty, tz)``: the rotation vector
    of ``R_perturbed R^T`` (rad) and the translation (m), the convention of
    :class:`RobotWorldResult` and :class:`HandEyeResult`. Kept for its callers:
    :meth:`robocal.geometry.PoseWithCovariance.inverse` (left side) does it.
    """
    inv = PoseWithCovariance(check_transform(T, "T"), check_array(cov, "cov", shape=(6, 6))).inverse()
    return inv.T, inv.cov
