"""The extrinsic estimate and its closed-form solvers (seed 000 eqs. 1, 12-29; Umeyama/Kabsch).

:class:`ExtrinsicEstimate` is what every solver returns. :func:`seed_method`
is the seed's algorithm as published (unit difference vectors, eq. 12; the
Gibbs-vector initial rotation, eqs. 15-23; the iterative refinement, eqs.
24-29); :func:`closed_form` the maximum-likelihood rigid fit for any N >= 3,
with its covariance from the floor-pose Fisher information
(:func:`floor_pose_jacobian`) or, under per-point floor covariances
(:func:`floor_covariance`, world plus encoder noise), the sandwich.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError
from robocal.geometry import (compose_gibbs, matrix_from_angle, matrix_from_gibbs, matrix_from_rotvec, rigid_fit,
                              rotation_angle, skew)
from robocal.rigs.projector.consistency import LARGE_N, check_correspondences
from robocal.rigs.projector.model import ProjectorModel
from robocal.validation import check_array

__all__ = ["ExtrinsicEstimate", "yaw_of", "seed_initial_rotation", "seed_method", "closed_form", "floor_pose_jacobian",
           "floor_prediction_columns", "floor_covariance", "rotation_error"]


def yaw_of(R) -> np.ndarray:
    """Rotation angle about ``z`` (rad) of (..., 3, 3) matrices: ``atan2(R10, R00)``."""
    R = np.asarray(R, dtype=float)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


# ------------------------------------------------------------------ estimates
@dataclass
class ExtrinsicEstimate:
    """One solver's estimate of ``^0P = R_0_W ^WP + t_0_W``.

    Attributes
    ----------
    method : str
        ``'seed'``, ``'closed_form'`` or ``'nonlinear'``.
    R_0_W : ndarray, shape (3, 3)
    t_0_W : ndarray, shape (3,)
        Metres.
    std : dict
        Standard deviations: ``yaw`` (rad), ``t_x``, ``t_y`` (m), and any extra
        parameter; ``None`` where not available or not identifiable.
    residuals : ndarray, shape (N, 2)
        Floor residuals ``^WP_measured - ^WP_predicted`` (m).
    rms : float
        RMS of the residual vectors (m).
    cost_history : ndarray
        The solver's cost per iteration (seed: ``eps^T eps`` of eq. 27).
    iterations : int
    warnings : list of Diagnostic
    extra : dict
        Method-specific values (seed: ``R_init``; nonlinear: ``h``, offsets, ...).
    cov : ndarray or None
        Covariance of the free parameters ``labels``.
    labels : list of str
    """

    method: str
    R_0_W: np.ndarray
    t_0_W: np.ndarray
    std: dict
    residuals: np.ndarray
    rms: float
    cost_history: np.ndarray
    iterations: int
    warnings: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    cov: np.ndarray | None = None
    labels: list = field(default_factory=list)

    @property
    def yaw(self) -> float:
        """Rotation of ``R_0_W`` about ``z`` (rad)."""
        return float(yaw_of(self.R_0_W))

    @property
    def T_0_W(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R_0_W
        T[:3, 3] = self.t_0_W
        return T


def _floor_residuals(pw, p0, R, t) -> np.ndarray:
    pred = (p0 - t) @ R  # R^T (p0 - t)
    return (pw - pred)[:, :2]


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(res * res, axis=-1))))


# ------------------------------------------------------------- (a) the seed
def _gibbs(axis: np.ndarray, angle: float) -> np.ndarray:
    """Gibbs vector ``tan(angle/2) k`` (seed, text before eq. 19)."""
    if abs(angle) >= math.pi - 1e-12:
        raise DegenerateGeometryError("seed method: a difference vector is reversed between {W} and {0} "
                                      "(rotation by pi): its Gibbs vector is infinite")
    return math.tan(angle / 2.0) * axis


def _align(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float]:
    """Axis ``u x v / |u x v|`` and angle ``arccos(u^T v)`` of the rotation taking u to v."""
    w = np.cross(u, v)
    n = np.linalg.norm(w)
    ang = math.acos(min(1.0, max(-1.0, float(u @ v))))
    if n < 1e-15:  # already aligned: any axis, zero angle (seed assumes u x v != 0)
        return np.array([0.0, 0.0, 1.0]), 0.0 if ang < 1.0 else ang
    return w / n, ang


def _units(v: np.ndarray, what: str, others, ref) -> np.ndarray:
    """Rows of ``v`` normalised (eq. 12), naming the first zero one (a duplicated point)."""
    nv = np.linalg.norm(v, axis=1)
    if np.any(nv == 0):
        k = int(np.flatnonzero(nv == 0)[0])
        raise DegenerateGeometryError(f"seed method: {what}{others[k]} - {what}{ref} is a zero vector (duplicated point)")
    return v / nv[:, None]


def seed_initial_rotation(a, b, c, d) -> np.ndarray:
    """Closed-form rotation with ``R c = d`` and ``R a`` closest to ``b`` (seed eqs. 15-23).

    ``m = r(c x d, acos c.d) (x) r(-a x b, acos a.b)`` (eq. 20, Gibbs
    composition of eq. 19); ``tan(theta2/2) = (d x b + (d x m) x b)^+ (b x m)``
    (eq. 22 with the vector pseudo-inverse ``u^+ = u^T / |u|^2``);
    ``R = R(d, theta2) R(c x d, acos c.d)`` (eq. 23). Exact when the two vector
    pairs are consistent, an approximation otherwise.
    """
    a, b, c, d = (np.asarray(v, dtype=float) for v in (a, b, c, d))
    k_ab, ang_ab = _align(a, b)
    k_cd, ang_cd = _align(c, d)
    r_cd = _gibbs(k_cd, ang_cd)
    m = compose_gibbs(r_cd, _gibbs(-k_ab, ang_ab))  # eq. 20
    u = np.cross(d, b) + np.cross(np.cross(d, m), b)  # eq. 22, left factor
    v = np.cross(b, m)
    uu = float(u @ u)
    tau2 = float(u @ v) / uu if uu > 1e-24 else 0.0  # eq. 23: pseudo-inverse of a vector
    return matrix_from_rotvec(2.0 * math.atan(tau2) * d) @ matrix_from_gibbs(r_cd)


def seed_method(points_W, points_0, *, alpha: float = 0.5, eps0: float = 1e-12, max_iter: int = 500,
                order=None) -> ExtrinsicEstimate:
    """The seed's extrinsic calibration, as published (seed 000 eqs. 12-29).

    1. Unit difference vectors to the reference point (eq. 12): for N = 3 with
       the reference last, ``a = unit(^WP1 - ^WP3)``, ``b = unit(^0P1 - ^0P3)``,
       ``c = unit(^WP2 - ^WP3)``, ``d = unit(^0P2 - ^0P3)``, so ``R a = b``,
       ``R c = d`` (eq. 13). For N > 3 every other point gives one more pair
       (a direct generalisation; the seed uses three points).
    2. Initial ``R`` from the first two pairs, :func:`seed_initial_rotation`.
    3. Iterate ``R <- Rx(dx) Ry(dy) Rz(dz) R`` (eq. 24) with
       ``[dx, dy, dz] = alpha J^+ eps`` (eq. 29), ``J = -[[b^]x; [d^]x]``
       (eq. 26), ``eps = Y - Y^``. The seed writes ``J^T (J J^T)^-1``, but J is
       (3(N-1) x 3) and ``J J^T`` is singular; the Moore-Penrose pseudo-inverse
       ``(J^T J)^-1 J^T`` is what makes ``L' < 0`` (eq. 27). Stop when
       ``|eps_{k+1} - eps_k| < eps0``.
    4. The paper does not say how ``t`` is obtained; its published ``t`` is
       ``^0P - R ^WP`` at the reference point, used here.

    Parameters
    ----------
    points_W, points_0 : array_like, shape (N, 3)
        Paired points (m); see :func:`check_correspondences`.
    alpha : float
        Step factor of eq. (29) (the seed gives no value).
    eps0 : float
        Stopping threshold of Step 3.
    max_iter : int
    order : sequence of int, optional
        The points in the roles ``P_1, P_2, ..., P_N`` of eq. (12): the last is
        the reference every difference is taken to, the first two give the
        eq.-(23) initial value. Default: as given.

    Returns
    -------
    ExtrinsicEstimate
        ``cost_history`` holds ``eps^T eps`` before each step (the seed's Fig. 4);
        ``extra['R_init']`` the eq.-23 rotation.
    """
    pw, p0 = check_correspondences(points_W, points_0)
    n = pw.shape[0]
    if not 0 < alpha <= 1:
        raise InputError(f"alpha must be in (0, 1], got {alpha!r}")
    order = list(range(n)) if order is None else [int(i) for i in order]
    if sorted(order) != list(range(n)):
        raise InputError(f"seed order must be a permutation of 0..{n - 1}, got {order}")
    ref = order[-1]
    others = order[:-1]
    A = _units(pw[others] - pw[ref], "^WP", others, ref)
    B = _units(p0[others] - p0[ref], "^0P", others, ref)
    R = seed_initial_rotation(A[0], B[0], A[1], B[1])
    R_init = R.copy()
    Y = B.reshape(-1)

    def step(R):
        Yh = A @ R.T
        eps = Y - Yh.reshape(-1)
        J = -skew(Yh).reshape(-1, 3)  # eq. 26: -[[b^]x; [d^]x; ...]
        return eps, J

    eps, J = step(R)
    costs = [float(eps @ eps)]
    converged = False
    it = 0
    from robocal.progress import progress

    for it in progress(range(1, max_iter + 1), desc="seed method, eq. (29)", enabled=n > LARGE_N):
        # eq. 29, Moore-Penrose: J^+ = (J^T J)^+ J^T exactly, a 3 x 3 pseudo-inverse instead of a (3N x 3) SVD
        delta = alpha * (np.linalg.pinv(J.T @ J) @ (J.T @ eps))
        R = (matrix_from_angle("x", delta[0]) @ matrix_from_angle("y", delta[1])  # eq. 24
             @ matrix_from_angle("z", delta[2]) @ R)
        eps_new, J = step(R)
        costs.append(float(eps_new @ eps_new))
        if np.linalg.norm(eps_new - eps) < eps0:
            eps = eps_new
            converged = True
            break
        eps = eps_new
    t = p0[ref] - R @ pw[ref]
    res = _floor_residuals(pw, p0, R, t)
    warns = []
    if not converged:
        warns.append(Diagnostic("not_converged", f"seed method: |eps_(k+1) - eps_k| >= {eps0:g} after {max_iter} "
                                                 f"iterations (alpha = {alpha:g})"))
    return ExtrinsicEstimate("seed", R, t, {"yaw": None, "t_x": None, "t_y": None}, res, _rms(res), np.array(costs),
                             it, warns, {"R_init": R_init, "alpha": alpha, "order": order, "converged": converged,
                                         "seed_cost": costs[-1]})


# ----------------------------------------------------------- (b) closed form
def floor_pose_jacobian(points_0, yaw: float, t_0_W) -> np.ndarray:
    """Jacobian (2N, 3) of the floor residuals ``^WP - Rz(-yaw)(^0P - t)_xy`` w.r.t. (yaw, t_x, t_y).

    With isotropic world noise ``sigma``, ``sigma^2 (J^T J)^-1`` is the
    Cramér-Rao bound of the floor pose (:func:`robocal.estimation.fisher_bound`).
    """
    p0 = check_array(points_0, "points_0", shape=("N", 3))
    c, s = math.cos(yaw), math.sin(yaw)
    d = p0[:, :2] - np.asarray(t_0_W, dtype=float)[:2]
    J = np.zeros((p0.shape[0], 2, 3))
    J[:, 0, 0] = s * d[:, 0] - c * d[:, 1]
    J[:, 1, 0] = c * d[:, 0] + s * d[:, 1]
    J[:, 0, 1], J[:, 0, 2] = c, s
    J[:, 1, 1], J[:, 1, 2] = -s, c
    return J.reshape(-1, 3)


def _pose_information(p0, yaw, t) -> np.ndarray:
    J = floor_pose_jacobian(p0, yaw, t)
    return J.T @ J


def closed_form(points_W, points_0, *, sigma: float | None = None, cov=None) -> ExtrinsicEstimate:
    """Maximum-likelihood rigid fit (Umeyama/Kabsch) of ``^WP = R_W_0 ^0P + t_W_0``, N >= 3.

    The noise sits on ``^WP`` (the measured world points), so the fit maps
    the exact model points ``^0P`` onto them (``robocal.geometry.rigid_fit``)
    and is inverted. Standard deviations from the floor-pose Fisher information
    with ``sigma`` (or the residual estimate when ``sigma`` is None and N > 3).
    With per-point floor covariances ``cov`` (N, 2, 2, m^2: world noise plus the
    joint noise mapped to the floor, :func:`floor_covariance`) the unweighted fit
    is no longer the ML estimate, and its covariance is the sandwich
    ``(J^T J)^-1 J^T Sigma J (J^T J)^-1``.
    """
    pw, p0 = check_correspondences(points_W, points_0, unit_check=False)
    fit = rigid_fit(p0, pw)
    R = fit.R.T
    t = -R @ fit.t
    res = _floor_residuals(pw, p0, R, t)
    n = pw.shape[0]
    # floor residuals have 2 components per point and 3 pose dof
    s = sigma if sigma else (math.sqrt(float(np.sum(res * res)) / (2 * n - 3)) if n > 2 else None)
    std = {"yaw": None, "t_x": None, "t_y": None}
    cov_p = None
    if s:
        J = floor_pose_jacobian(p0, float(yaw_of(R)), t)
        Ninv = np.linalg.inv(J.T @ J)
        if cov is not None and sigma:
            Jb = J.reshape(n, 2, 3)
            meat = np.einsum("nai,nab,nbj->ij", Jb, cov, Jb)
            cov_p = Ninv @ meat @ Ninv
        else:
            cov_p = s * s * Ninv
        std = {"yaw": math.sqrt(cov_p[0, 0]), "t_x": math.sqrt(cov_p[1, 1]), "t_y": math.sqrt(cov_p[2, 2])}
    return ExtrinsicEstimate("closed_form", R, t, std, res, _rms(res), np.array([float(np.sum(res * res)) / 2]), 0, [],
                             {"sigma_used": s}, cov_p, ["yaw", "t_x", "t_y"])


def floor_covariance(model: ProjectorModel, theta, yaw: float = 0.0, *, sigma: float = 0.0,
                     joint_noise=(0.0, 0.0)) -> np.ndarray:
    """Covariance (N, 2, 2, m^2) of each floor residual ``^WP_i - Rz(-yaw) f_xy(theta_i)``.

    ``sigma^2 I + J_theta diag(joint_noise^2) J_theta^T`` (issue 19): isotropic
    world noise ``sigma`` (m) plus the encoder noise ``joint_noise`` (pan, tilt,
    rad) mapped to the floor by the spot model's joint Jacobian (seed eqs. 6, 9,
    rotated into ``{W}``). The tilt part, ``h / cos^2(tilt)`` along the radius,
    grows fast with the tilt; the pan part, ``h tan(tilt)`` across it. With
    ``yaw = 0`` the covariance is that of ``f_xy`` in ``{0}``.
    """
    th = np.asarray(theta, dtype=float)
    jn = np.asarray(joint_noise, dtype=float)
    cols = floor_prediction_columns(yaw, np.zeros(2), theta=th, h=model.h, offsets=model.offsets)
    a, b = cols["pan_offset"], cols["tilt_offset"]  # d pred / d theta1, d theta2 (the offsets add to theta)
    C = (jn[0] ** 2) * a[:, :, None] * a[:, None, :] + (jn[1] ** 2) * b[:, :, None] * b[:, None, :]
    C[:, 0, 0] += sigma * sigma
    C[:, 1, 1] += sigma * sigma
    return C


def _whitener(C: np.ndarray) -> np.ndarray:
    """``L^-1`` (N, 2, 2) with ``C = L L^T``: ``L^-1 r`` has unit covariance."""
    return np.linalg.inv(np.linalg.cholesky(C))


def floor_prediction_columns(yaw: float, t_xy, *, spots_xy=None, theta=None, h: float | None = None,
                             offsets=(0.0, 0.0)) -> dict:
    """``d pred / d p`` (M, 2) per parameter of the floor prediction ``pred = Rz(-yaw) (f - t)_xy`` (seed eqs. 1, 6).

    Either the spots ``f_xy`` (M, 2) in {0} are given (columns ``yaw``, ``t_x``,
    ``t_y``), or joint angles ``theta`` (M, 2) with ``h`` and ``offsets``: then
    ``f = h tan(a2) (sin a1, cos a1)`` with ``a = theta + offsets`` (seed eq. 6)
    and the columns ``h``, ``pan_offset``, ``tilt_offset`` are added. One source
    for the residual Jacobian of :func:`nonlinear` and the error map's
    propagation (:func:`robocal.rigs.projector.evaluate.floor_prediction_jacobian`).
    """
    c, s = math.cos(yaw), math.sin(yaw)
    cols = {}
    if theta is not None:
        a1 = theta[:, 0] + offsets[0]
        a2 = theta[:, 1] + offsets[1]
        ta, s1, c1 = np.tan(a2), np.sin(a1), np.cos(a1)
        rho = h * ta
        spots_xy = np.column_stack([rho * s1, rho * c1])

        def rot(v):  # Rz(-yaw) applied to floor vectors
            return np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]])

        cols["h"] = rot(np.column_stack([ta * s1, ta * c1]))
        cols["pan_offset"] = rot(np.column_stack([rho * c1, -rho * s1]))
        cols["tilt_offset"] = rot((h / np.cos(a2) ** 2)[:, None] * np.column_stack([s1, c1]))
    d = np.asarray(spots_xy, dtype=float) - np.asarray(t_xy, dtype=float)[:2]
    cols["yaw"] = np.column_stack([-s * d[:, 0] + c * d[:, 1], -c * d[:, 0] - s * d[:, 1]])
    cols["t_x"] = np.tile([-c, s], (len(d), 1))
    cols["t_y"] = np.tile([-s, -c], (len(d), 1))
    return cols



def rotation_error(R_est, R_true) -> np.ndarray:
    """Angle (rad) of ``R_est R_true^T``."""
    return rotation_angle(np.asarray(R_est) @ np.swapaxes(np.asarray(R_true), -1, -2))
