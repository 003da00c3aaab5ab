"""World-to-projector extrinsic calibration (seed 000, §2.2) and two better solvers.

Data: floor points measured in the world ``^W P_i`` (z = 0) and the same spots
in the projector frame ``^0 P_i = f(theta_i)`` from the joint angles (seed
eq. 6). Unknown: ``R_0_W, t_0_W`` with ``^0P = R ^WP + t`` (seed eq. 1).

Three solvers:

(a) :func:`seed_method` -- the seed's algorithm as published: unit difference
    vectors (eq. 12), a closed-form initial rotation from composed Gibbs
    vectors (eqs. 15-23) and the iterative refinement of eqs. (24)-(29) with
    the Moore-Penrose pseudo-inverse, keeping the cost per iteration (Fig. 4).
(b) :func:`closed_form` -- the maximum-likelihood rigid fit (Umeyama/Kabsch,
    :func:`robocal.geometry.rigid_fit`) for any N >= 3.
(c) :func:`nonlinear` -- least squares on the floor-plane spot error with
    :mod:`robocal.estimation`: yaw and floor translation, optionally
    ``h = H - d1`` and the tilt zero offset; covariance included.

Noise model: the world measurements ``^W P`` (tape, total station) carry
isotropic floor noise ``sigma`` per coordinate; the joint encoders are exact.
Because ``{W}``'s floor (z_W = 0) and the model's floor (z_0 = -H) are both
planes, a rigid transform between them is a rotation about ``z`` plus a
translation: only the yaw, ``t_x``, ``t_y`` are determined by floor points
(``t_z = -H`` by definition of ``{0}``; a roll/pitch of the base would
violate the model's level-floor assumption, seed §2.1).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import (
    ConvergenceError,
    DegenerateGeometryError,
    InconsistentDataError,
    InputError,
    NotEnoughDataError,
    ShapeError,
    UnitError,
)
from robocal.estimation import Problem, solve
from robocal.geometry import (
    compose_gibbs,
    matrix_from_gibbs,
    matrix_from_rotvec,
    rigid_fit,
    rotation_angle,
    rotx,
    roty,
    rotz,
    skew,
)
from robocal.rigs.projector.model import NearSingularityWarning, ProjectorModel, UnreachablePointError
from robocal.validation import check_array

__all__ = [
    "ExtrinsicEstimate",
    "ConsistencyReport",
    "CalibrationRun",
    "check_correspondences",
    "distance_consistency",
    "seed_initial_rotation",
    "seed_method",
    "closed_form",
    "nonlinear",
    "calibrate",
    "yaw_of",
    "floor_pose_jacobian",
    "floor_prediction_columns",
    "rotation_error",
    "beyond_tilt_limit",
]

METHODS = ("seed", "closed_form", "nonlinear")


def yaw_of(R) -> np.ndarray:
    """Rotation angle about ``z`` (rad) of (..., 3, 3) matrices: ``atan2(R10, R00)``."""
    R = np.asarray(R, dtype=float)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


# ----------------------------------------------------------------------- checks
def _as_floor_points(p, name: str, *, z=None) -> np.ndarray:
    p = check_array(p, name)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ShapeError(f"{name} must have shape (N, 2) or (N, 3), got {tuple(p.shape)}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(p.shape[0], 0.0 if z is None else z)])
    return p


def check_correspondences(points_W, points_0, *, min_points: int = 3, rel_tol: float = 1e-6):
    """Validate paired floor points; returns ``(points_W, points_0)`` as (N, 3) float arrays (m).

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
        World floor points (z = 0 when 2 columns are given).
    points_0 : array_like, shape (N, 3)
        The same spots in ``{0}`` (all at ``z_0 = -H``).

    Raises
    ------
    ShapeError, NonFiniteError
        Wrong shapes, NaN/inf.
    NotEnoughDataError
        Fewer than ``min_points`` pairs.
    DegenerateGeometryError
        Duplicated points (named by index) or all points on one line.
    UnitError
        Distances in the two frames differ by a factor typical of mixed units.
    """
    pw = _as_floor_points(points_W, "points_W")
    p0 = check_array(points_0, "points_0")
    if p0.ndim != 2 or p0.shape[1] != 3:
        raise ShapeError(f"points_0 must have shape (N, 3), got {tuple(p0.shape)}")
    if pw.shape[0] != p0.shape[0]:
        raise ShapeError(f"points_W and points_0 must hold the same number of points, got {pw.shape[0]} and "
                         f"{p0.shape[0]}")
    n = pw.shape[0]
    if n < min_points:
        raise NotEnoughDataError(f"extrinsic calibration needs at least {min_points} non-collinear floor points, "
                                 f"got {n}")
    scale = max(np.ptp(pw, axis=0).max(), np.ptp(p0, axis=0).max(), 1e-300)
    for name, p in (("points_W", pw), ("points_0", p0)):
        D = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        iu = np.triu_indices(n, 1)
        dup = D[iu] <= rel_tol * scale
        if np.any(dup):
            k = int(np.flatnonzero(dup)[0])
            raise DegenerateGeometryError(f"{name}: points {iu[0][k]} and {iu[1][k]} coincide (duplicated point)")
        c = p - p.mean(axis=0)
        sv = np.linalg.svd(c, compute_uv=False)
        if sv[1] <= 1e-6 * sv[0]:
            raise DegenerateGeometryError(f"{name}: all {n} points lie on one line (second singular value "
                                          f"{sv[1] / sv[0]:.2g} of the first): the rotation about it is undetermined")
    iu = np.triu_indices(n, 1)
    dW = np.linalg.norm(pw[iu[0]] - pw[iu[1]], axis=1)
    d0 = np.linalg.norm(p0[iu[0]] - p0[iu[1]], axis=1)
    ratio = float(np.median(d0 / dW))
    if not 0.5 < ratio < 2.0:
        raise UnitError(f"pairwise distances in {{0}} are {ratio:.3g} times those in {{W}}: are the two point sets "
                        f"in the same length unit (m, cm, mm)?")
    return pw, p0


@dataclass
class ConsistencyReport:
    """Pairwise-distance check of a rigid correspondence set (before solving).

    A rigid transform preserves distances, so ``|^W P_i - ^W P_j|`` must equal
    ``|^0 P_i - ^0 P_j|`` up to noise. ``pairs`` lists ``(i, j, d_W, d_0,
    d_0 - d_W, relative)`` (m); ``bad_pairs`` those beyond tolerance;
    ``suspects`` the points whose removal explains the bad pairs.
    """

    pairs: list
    bad_pairs: list
    suspects: list
    threshold: str
    warnings: list = field(default_factory=list)
    scale: float | None = None  # relative distance error shared by all pairs, when it explains the bad pairs

    @property
    def consistent(self) -> bool:
        return not self.bad_pairs

    def rows(self) -> list[dict]:
        return [dict(i=i, j=j, d_W=dw, d_0=d0, diff=df, rel=rel, ok=(i, j) not in {(b[0], b[1]) for b in self.bad_pairs})
                for i, j, dw, d0, df, rel in self.pairs]


def distance_consistency(points_W, points_0, *, sigma: float | None = None, n_sigma: float = 4.0,
                         rel_tol: float = 0.02, scale_hint: str = "the model's scale is wrong") -> ConsistencyReport:
    """Compare pairwise distances in ``{W}`` and ``{0}`` and name inconsistent points.

    Threshold per pair: ``n_sigma * sqrt(2) * sigma`` when the world noise
    ``sigma`` (m) is known, else ``rel_tol`` of the distance. Suspects are found
    greedily: the point in most bad pairs is removed until no bad pair is left.

    A model error (``H - d1`` or the tilt offset wrong) scales every ``{0}``
    distance alike, which would make most points "suspects". So with N >= 4,
    when removing one relative scale ``d_0 ~ (1 + s) d_W`` (the median ratio) leaves
    at most a third of the bad pairs, the warning reports the scale ``s`` and
    ``scale_hint`` instead, and names only the points still inconsistent after it.
    """
    pw, p0 = check_correspondences(points_W, points_0)
    n = pw.shape[0]
    iu, ju = np.triu_indices(n, 1)
    dW = np.linalg.norm(pw[iu] - pw[ju], axis=1)
    d0 = np.linalg.norm(p0[iu] - p0[ju], axis=1)
    diff = d0 - dW
    limit = n_sigma * math.sqrt(2.0) * sigma if sigma else rel_tol * dW
    pairs = [(int(i), int(j), float(a), float(b), float(c), float(c / a)) for i, j, a, b, c in zip(iu, ju, dW, d0, diff)]
    bad = [pr for pr, b in zip(pairs, np.abs(diff) > limit) if b]
    threshold = (f"{n_sigma:g} sqrt(2) sigma = {n_sigma * math.sqrt(2) * sigma * 1e3:.3g} mm" if sigma
                 else f"{100 * rel_tol:g} % of the distance")
    scale = None
    blamed = bad
    if n >= 4 and len(bad) >= 3:
        sc = float(np.median(diff / dW))  # the median: one bad point must not drag the scale
        after = [pr for pr, b in zip(pairs, np.abs(diff - sc * dW) > limit) if b]
        if len(after) <= len(bad) / 3:
            scale, blamed = sc, after
    suspects: list[int] = []
    left = [(b[0], b[1]) for b in blamed]
    while left:
        counts = np.bincount(np.array(left).reshape(-1), minlength=n)
        k = int(np.argmax(counts))
        suspects.append(k)
        left = [p for p in left if k not in p]
    warns = []
    if scale is not None:
        warns.append(Diagnostic(
            "inconsistent_data",
            f"pairwise distances in {{0}} are uniformly {100 * scale:+.2f} % of those in {{W}} ({len(bad)} of "
            f"{len(pairs)} pairs beyond {threshold}): a scale error of the model, not of single points: {scale_hint}"
            + (f"; after removing the scale, suspect point(s) {suspects}" if suspects else
               "; after removing the scale every pair agrees"),
            indices=tuple(suspects)))
    elif bad:
        worst = max(bad, key=lambda b: abs(b[5]))
        desc = "; ".join(f"{b[0]}-{b[1]}: {100 * b[5]:+.1f} % ({b[4] * 1e3:+.1f} mm)" for b in bad[:6])
        warns.append(Diagnostic(
            "inconsistent_data",
            f"pairwise distances in {{W}} and {{0}} disagree beyond {threshold} ({desc}); a rigid transform cannot "
            f"fit them: suspect point(s) {suspects} (worst pair {worst[0]}-{worst[1]}, {100 * worst[5]:+.1f} %)",
            indices=tuple(suspects)))
    return ConsistencyReport(pairs, bad, suspects, threshold, warns, scale)


def _spots(model: ProjectorModel, th: np.ndarray) -> np.ndarray:
    """``f(theta)`` (seed eq. 6) of measured spots, without the beyond-the-tilt-limit Python warning:
    :func:`calibrate` reports those points as a ``near_singularity`` diagnostic instead."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        return model.spot(th)


def beyond_tilt_limit(model: ProjectorModel, points_0, what: str) -> Diagnostic | None:
    """A ``near_singularity`` diagnostic naming the calibration spots beyond ``model.tilt_limit``, else None.

    Such a spot was aimed where the head should not go (the tilt limit keeps the
    beam away from the horizon singularity, seed §2.1, where the spot error grows
    as ``1 / cos^2(theta2)``); usually ``tilt_limit`` or the joint angles (their
    unit) are wrong. ``points_0`` (N, 3) in ``{0}`` (m).
    """
    p0 = np.asarray(points_0, dtype=float)
    ok = model.reachable(p0, floor_tol=1e-6 * max(1.0, model.H))
    if np.all(ok):
        return None
    idx = [int(i) for i in np.flatnonzero(~ok)]
    r = np.hypot(p0[idx, 0], p0[idx, 1])
    tilt = np.degrees(np.arctan2(r, model.h))
    return Diagnostic(
        "near_singularity",
        f"{what}: point(s) {idx[:10]}{' ...' if len(idx) > 10 else ''} lie beyond the tilt limit of "
        f"{math.degrees(model.tilt_limit):g} deg (tilt up to {tilt.max():.1f} deg, {r.max():.3g} m from the nadir; "
        f"reachable radius {model.floor_radius:.3g} m): check projector.tilt_limit, the points and the angle unit",
        indices=tuple(idx))


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


def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = np.linalg.norm(v)
    if n == 0:
        raise DegenerateGeometryError(f"seed method: {what} is a zero vector (duplicated point)")
    return v / n


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
    A = np.array([_unit(pw[i] - pw[ref], f"^WP{i} - ^WP{ref}") for i in others])
    B = np.array([_unit(p0[i] - p0[ref], f"^0P{i} - ^0P{ref}") for i in others])
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
    for it in range(1, max_iter + 1):
        delta = alpha * (np.linalg.pinv(J) @ eps)  # eq. 29, Moore-Penrose
        R = rotx(delta[0]) @ roty(delta[1]) @ rotz(delta[2]) @ R  # eq. 24
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


def closed_form(points_W, points_0, *, sigma: float | None = None) -> ExtrinsicEstimate:
    """Maximum-likelihood rigid fit (Umeyama/Kabsch) of ``^WP = R_W_0 ^0P + t_W_0``, N >= 3.

    The noise sits on ``^WP`` (the measured world points), so the fit maps
    the exact model points ``^0P`` onto them (``robocal.geometry.rigid_fit``)
    and is inverted. Standard deviations from
    :func:`robocal.geometry.rigid_fit_covariance` with ``sigma`` (or the
    residual estimate when ``sigma`` is None and N > 3).
    """
    pw, p0 = check_correspondences(points_W, points_0)
    fit = rigid_fit(p0, pw)
    R = fit.R.T
    t = -R @ fit.t
    res = _floor_residuals(pw, p0, R, t)
    n = pw.shape[0]
    # floor residuals have 2 components per point and 3 pose dof
    s = sigma if sigma else (math.sqrt(float(np.sum(res * res)) / (2 * n - 3)) if n > 2 else None)
    std = {"yaw": None, "t_x": None, "t_y": None}
    cov = None
    if s:
        cov = s * s * np.linalg.inv(_pose_information(p0, float(yaw_of(R)), t))
        std = {"yaw": math.sqrt(cov[0, 0]), "t_x": math.sqrt(cov[1, 1]), "t_y": math.sqrt(cov[2, 2])}
    return ExtrinsicEstimate("closed_form", R, t, std, res, _rms(res), np.array([float(np.sum(res * res)) / 2]), 0, [],
                             {"sigma_used": s}, cov, ["yaw", "t_x", "t_y"])


# ---------------------------------------------------------- (c) nonlinear LS
EXTRA_PARAMS = ("h", "pan_offset", "tilt_offset")


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


def nonlinear(points_W, *, theta=None, points_0=None, model: ProjectorModel | None = None, estimate=(),
              sigma: float | None = None, x0: ExtrinsicEstimate | None = None, absolute_sigma: bool = False,
              loss: str = "linear") -> ExtrinsicEstimate:
    """Nonlinear least squares on the floor spot error (robocal.estimation).

    Residual per point: ``^WP_i - [R_0_W^T (f(theta_i) - t_0_W)]_xy`` (m), with
    ``f`` the spot model (seed eq. 6). Parameter blocks: ``R`` (rotation vector,
    only ``rz`` free: see the module docstring), ``t`` (``t_z = -H`` fixed),
    and, with joint angles, ``h = H - d1``, ``pan_offset``, ``tilt_offset`` when
    named in ``estimate``.

    The pan zero offset is **not identifiable** from floor points: turning the
    pan by ``o1`` rotates every spot about the nadir, which a change of yaw and
    ``t`` reproduces exactly. Asking for it yields a ``rank_deficient`` warning
    and ``std = None``.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
    theta : array_like, shape (N, 2), optional
        Joint angles (rad) for each spot; requires ``model``.
    points_0 : array_like, shape (N, 3), optional
        Spots in ``{0}`` when joint angles are not available (then ``estimate``
        must be empty).
    model : ProjectorModel
        Provides ``H, d1`` and offsets (initial values).
    estimate : sequence of {'h', 'pan_offset', 'tilt_offset'}
    sigma : float, optional
        World measurement noise (m); with ``absolute_sigma`` taken as known.
    x0 : ExtrinsicEstimate, optional
        Start (default: the closed form).
    """
    estimate = tuple(estimate)
    unknown = [e for e in estimate if e not in EXTRA_PARAMS]
    if unknown:
        raise InputError(f"estimate: unknown parameter(s) {unknown} (known: {', '.join(EXTRA_PARAMS)})")
    if theta is None:
        if points_0 is None:
            raise InputError("nonlinear: give joint angles theta (with model) or points_0")
        if estimate:
            raise InputError(f"nonlinear: estimating {list(estimate)} needs joint angles, only points_0 were given")
        pw, p0 = check_correspondences(points_W, points_0)
        th = None
        H = float(-np.mean(p0[:, 2]))
        model = ProjectorModel(H=H) if model is None else model
    else:
        if model is None:
            raise InputError("nonlinear: joint angles need a ProjectorModel (H, d1)")
        th = check_array(theta, "theta", shape=("N", 2))
        if th.ndim != 2:
            raise ShapeError(f"theta must have shape (N, 2), got {tuple(th.shape)}")
        p0 = _spots(model, th)
        pw, p0 = check_correspondences(points_W, p0)
    H = model.H
    start = x0 or closed_form(pw, p0, sigma=sigma)
    n = pw.shape[0]
    prob = Problem()
    prob.add_block("R", [0.0, 0.0, start.yaw], fixed=[True, True, False], labels=["rx", "ry", "yaw"], unit="rad")
    prob.add_block("t", [start.t_0_W[0], start.t_0_W[1], -H], fixed=[False, False, True],
                   labels=["t_x", "t_y", "t_z"], unit="m")
    if th is not None:
        prob.add_block("h", [model.h], fixed=["h" not in estimate], labels=["h"], unit="m")
        prob.add_block("offsets", list(model.offsets), fixed=["pan_offset" not in estimate,
                                                               "tilt_offset" not in estimate],
                       labels=["pan_offset", "tilt_offset"], unit="rad")
    target = pw[:, :2]

    def residuals(q):
        c, s = math.cos(q["R"][2]), math.sin(q["R"][2])
        if th is None:
            sp = p0[:, :2]
        else:
            a1 = th[:, 0] + q["offsets"][0]
            a2 = th[:, 1] + q["offsets"][1]
            rho = q["h"][0] * np.tan(a2)
            sp = np.column_stack([rho * np.sin(a1), rho * np.cos(a1)])
        d = sp - q["t"][:2]
        # R_0_W = Rz(yaw) => ^WP_xy = Rz(-yaw) (f - t)_xy
        pred = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        return target - pred

    def jacobian(q):  # residual = target - pred
        if th is None:
            cols = floor_prediction_columns(q["R"][2], q["t"], spots_xy=p0[:, :2])
        else:
            cols = floor_prediction_columns(q["R"][2], q["t"], theta=th, h=q["h"][0], offsets=q["offsets"])
        out = {"R": np.zeros((2 * n, 3)), "t": np.zeros((2 * n, 3))}
        out["R"][:, 2] = -cols["yaw"].reshape(-1)
        out["t"][:, 0], out["t"][:, 1] = -cols["t_x"].reshape(-1), -cols["t_y"].reshape(-1)
        if th is not None:
            out["h"] = -cols["h"].reshape(-1, 1)
            out["offsets"] = -np.stack([cols["pan_offset"], cols["tilt_offset"]], axis=-1).reshape(-1, 2)
        return out

    prob.add_residuals(residuals, name="floor", jacobian=jacobian, residual_dim=2,
                       sigma=sigma if sigma else None)
    # trf, not lm: MINPACK keeps iterating on an exact (zero-residual) fit until max_nfev
    res = solve(prob, method="trf", loss=loss, absolute_sigma=absolute_sigma and bool(sigma))
    if not np.all(np.isfinite(res.x)):
        raise ConvergenceError("nonlinear: the solver returned a non-finite estimate")
    yaw = float(res.params["R"][2])
    R = rotz(yaw)
    t = np.array(res.params["t"], dtype=float)
    resid = res.residuals.reshape(-1, 2)
    std = {"yaw": res.std.get("yaw"), "t_x": res.std.get("t_x"), "t_y": res.std.get("t_y")}
    extra = {}
    if th is not None:
        extra["h"] = float(res.params["h"][0])
        extra["offsets"] = [float(v) for v in res.params["offsets"]]
        for lab in estimate:
            std[lab] = res.std.get(lab)
    return ExtrinsicEstimate("nonlinear", R, t, std, resid, _rms(resid), np.asarray(res.cost_history),
                             res.iterations, list(res.warnings), dict(extra, lsq=res), res.cov, list(res.free_labels))


# --------------------------------------------------------------- the driver
@dataclass
class CalibrationRun:
    """Everything one calibration produced: the consistency check and each method's estimate."""

    points_W: np.ndarray
    points_0: np.ndarray
    theta: np.ndarray | None
    model: ProjectorModel
    consistency: ConsistencyReport
    estimates: dict
    sigma: float | None
    primary: str
    consistency_prefit: ConsistencyReport | None = None
    input_warnings: list = field(default_factory=list)

    @property
    def best(self) -> ExtrinsicEstimate:
        return self.estimates[self.primary]

    @property
    def warnings(self) -> list:
        return list(self.input_warnings) + list(self.consistency.warnings) + [w for w in self.best.warnings]

    def calibrated_model(self, method: str | None = None) -> ProjectorModel:
        """The projector model with the estimated extrinsics (and h / offsets when estimated)."""
        est = self.estimates[method or self.primary]
        m = self.model.with_(R_0_W=est.R_0_W, t_0_W=est.t_0_W)
        if "h" in est.extra:
            m = m.with_(d1=m.H - est.extra["h"], offsets=tuple(est.extra["offsets"]))
        return m


def calibrate(points_W, *, theta=None, points_0=None, model: ProjectorModel | None = None,
              methods=METHODS, estimate=(), sigma: float | None = None, strict: bool = False,
              seed_alpha: float = 0.5, seed_order=None) -> CalibrationRun:
    """Run the consistency check and the chosen solvers on one data set.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
        Measured world floor points (m).
    theta : array_like, shape (N, 2), optional
        Joint angles (rad) that put the spot on each point (then ``model`` is needed).
    points_0 : array_like, shape (N, 3), optional
        The spots in ``{0}``, when given directly (as in the seed's §3).
    model : ProjectorModel, optional
    methods : sequence of {'seed', 'closed_form', 'nonlinear'}
    estimate : extra parameters for the nonlinear solver, see :func:`nonlinear`
    sigma : float, optional
        World measurement noise (m). When given, every standard deviation uses
        it as known (absolute sigma); without it the covariances are scaled by
        the residual variance (needs N > number of parameters / 2).
    seed_alpha, seed_order
        Step factor and point order of :func:`seed_method`.
    strict : bool
        Raise :class:`~robocal.errors.InconsistentDataError` when the distance
        check fails, and :class:`~robocal.rigs.projector.model.UnreachablePointError`
        for spots beyond the tilt limit, instead of warning (``inconsistent_data``,
        ``near_singularity``).

    Returns
    -------
    CalibrationRun
        ``primary`` is the nonlinear estimate when run, else the closed form, else the seed's.
    """
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise InputError(f"methods must be a non-empty subset of {', '.join(METHODS)}, got {list(methods)}")
    if theta is not None:
        if model is None:
            raise InputError("calibrate: joint angles need a projector model (H, d1)")
        th = check_array(theta, "theta", shape=("N", 2))
        if th.ndim != 2:
            raise ShapeError(f"theta must have shape (N, 2), got {tuple(th.shape)}")
        p0 = _spots(model, th)
    elif points_0 is not None:
        th = None
        p0 = check_array(points_0, "points_0")
        if p0.ndim != 2 or p0.shape[-1] != 3:
            raise ShapeError(f"points_0 must have shape (N, 3), got {tuple(p0.shape)}")
        H = float(-np.mean(p0[:, 2]))
        if model is None:
            if not H > 0:
                raise InputError(f"points_0: the floor must be below the projector (z_0 = -H < 0), got mean z {-H:g} m")
            model = ProjectorModel(H=H)
        if np.abs(p0[:, 2] + model.H).max() > 1e-6 * max(1.0, model.H):
            raise InputError(f"points_0: every z must equal -H = {-model.H:g} m (the floor in {{0}}), got "
                             f"{p0[:, 2].tolist()}")
    else:
        raise InputError("calibrate: give joint angles (theta) or projector-frame points (points_0)")
    try:
        pw, p0 = check_correspondences(points_W, p0)
    except UnitError as exc:
        if th is None:
            raise
        # the {0} points come from the joint angles: a wrong angle unit scales the distances too
        raise UnitError(exc.message.rstrip("?") + ", and are the joint angles in their declared angle unit (deg, rad)?",
                        source=exc.source) from None
    if np.abs(pw[:, 2]).max() > 1e-9:
        raise InputError("points_W: world points must lie on the floor (z_W = 0)")
    input_warnings = []
    reach = beyond_tilt_limit(model, p0, "joint_angles" if th is not None else "points_0")
    if reach is not None:
        if strict:
            raise UnreachablePointError(reach.message)
        input_warnings.append(reach)
    estimate = tuple(estimate)
    if estimate and "nonlinear" not in methods:
        raise InputError(f"estimate: {list(estimate)} is estimated only by the 'nonlinear' method, which is not among "
                         f"methods {list(methods)}: add it or drop estimate")
    hint = ("H - d1 or the tilt offset is probably wrong (estimate: [h, tilt_offset] with the nonlinear method)"
            if th is not None else "H or the units of the {0} points are probably wrong")
    cons = distance_consistency(pw, p0, sigma=sigma, scale_hint=hint)
    refine_model = th is not None and any(e in ("h", "tilt_offset") for e in estimate) and "nonlinear" in methods
    # With h or the tilt offset unknown, the nominal f(theta) carries a model error that the
    # distances show too; the check is then repeated with the refined model before judging.
    if strict and not cons.consistent and not refine_model:
        raise InconsistentDataError(cons.warnings[0].message)
    ests = {}
    if "seed" in methods:
        ests["seed"] = seed_method(pw, p0, alpha=seed_alpha, order=seed_order)
    if "closed_form" in methods or "nonlinear" in methods:
        ests["closed_form"] = closed_form(pw, p0, sigma=sigma)
    if "nonlinear" in methods:
        # A stated noise is the measurement sigma: with few points (N = 3, h and the tilt offset free
        # leaves 1 dof) the residual-scaled covariance is far too small, so the stated sigma is used as is.
        ests["nonlinear"] = nonlinear(pw, theta=th, points_0=None if th is not None else p0, model=model,
                                      estimate=estimate, sigma=sigma, x0=ests["closed_form"],
                                      absolute_sigma=sigma is not None)
    if "closed_form" not in methods:
        ests.pop("closed_form", None)
    prefit = cons
    if refine_model and not cons.consistent:
        nl = ests["nonlinear"]
        refined = model.with_(d1=model.H - nl.extra["h"], offsets=tuple(nl.extra["offsets"]))
        cons = distance_consistency(pw, _spots(refined, th), sigma=sigma, scale_hint=hint)
        if strict and not cons.consistent:
            raise InconsistentDataError(cons.warnings[0].message)
    primary = "nonlinear" if "nonlinear" in ests else ("closed_form" if "closed_form" in ests else "seed")
    run = CalibrationRun(pw, p0, th, model, cons, ests, sigma, primary)
    run.consistency_prefit = prefit
    run.input_warnings = input_warnings
    return run


def rotation_error(R_est, R_true) -> np.ndarray:
    """Angle (rad) of ``R_est R_true^T``."""
    return rotation_angle(np.asarray(R_est) @ np.swapaxes(np.asarray(R_true), -1, -2))
