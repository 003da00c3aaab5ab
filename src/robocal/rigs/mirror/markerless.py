"""Markerless calibration through K >= 3 unknown mirror poses (issue 14; beyond the patent).

Setting (Takahashi, Nobuhara and Matsuyama, "A new mirror-based extrinsic
camera calibration using an orthogonality constraint", CVPR 2012, pp.
1051-1058): reference points ``P_i`` known in the robot frame ``r`` are
never seen directly, only their reflections in a plane mirror with no
markers, put down in K >= 3 unknown poses. Unknowns: ``T_r_c`` (the camera in
the robot frame, as in the rest of the rig) and every mirror plane
``{x : n_j . x = d_j}`` in the camera frame (``n_j`` unit, pointing away from
the camera, ``d_j > 0`` the camera's distance from the plane).

Model
-----
``p_c = R_cr P + t_cr``; its mirror image ``p_v = H_j p_c + 2 d_j n_j`` with
``H_j = I - 2 n_j n_j^T``; the image point ``uv = project(p_v)`` (the
camera's distortion included). Equivalently (docs/rigs/mirror.md, the
compact form) each mirror pose sees the *virtual* frame ``T_c_ri_j`` with
``R_cri_j = H_j R_cr F`` and ``t_cri_j = H_j t_cr + 2 d_j n_j`` where the
reference points have ``ri`` coordinates ``F P = (-x, y, z)``.

Closed-form start (what was chosen and why)
-------------------------------------------
The orthogonality-constraint solution of the CVPR 2012 paper, fed by one
PnP per mirror pose:

1. per pose, ``T_c_ri_j`` by PnP of the reflections with the object set
   ``F P`` (a proper rotation): all up to 4 P3P solutions (``cv2.solveP3P``)
   when a pose sees exactly 3 points, SQPnP refined by LM when it sees more;
2. ``R_cri_i R_cri_j^T = H_i H_j`` (the ``F`` cancels) is a rotation about
   ``m_ij = n_i x n_j`` by twice the angle between the normals; every axis
   ``m_jk`` is orthogonal to ``n_j`` (the orthogonality constraint), so
   ``n_j`` is the null vector of the stacked axes ``m_jk`` (``k != j``),
   weighted by the rotation angles (a small rotation's axis is noisy);
3. ``R_cr = H_j R_cri_j F`` for every ``j``, averaged (nearest rotation to
   the sum);
4. ``t_cr`` and all ``d_j`` from the linear system
   ``(I - 2 n_j n_j^T) t_cr + 2 d_j n_j = t_cri_j`` (3K equations, 3 + K
   unknowns), the paper's "large system of linear equations"; the sign of
   each ``n_j`` is fixed by ``d_j > 0``.

With 3 points each pose has up to 4 PnP solutions, so up to ``4^K``
combinations. The paper selects the combination by the orthogonality
residual; here every combination (up to 256; beyond that, those of the
first three poses, the others' solution then chosen by how well
``R_cri_j F R_cr^T`` is a reflection) gets the closed form and is scored by
its reprojection RMS — the quantity the refinement then minimises, so the
score and the answer agree. The P3P-per-mirror + plane-consensus
alternative of the issue is what steps 2-4 are, with the consensus being
the paper's linear algebra rather than a vote.

Why this one: it is closed form and exact for noise-free data (a test checks
1e-9), needs nothing but the virtual poses, and its failure modes are
explicit (parallel normals: no axis; coplanar normals: no null vector).

Refinement
----------
One nonlinear least-squares problem (:mod:`robocal.estimation`) over
``T_r_c`` (``R_rc = exp(delta) R_rc0`` left perturbation, ``t_rc`` in m,
as :mod:`.joint`) and every plane (``n_j = normalize(n_j0 + B_j a_j)`` with
``B_j`` an orthonormal basis of the tangent plane, ``d_j`` in m) on the
reprojection error of the reflections, analytic Jacobian. Started from the
best few closed-form combinations; the distinct minima reached, their costs
and their spread from the best one are reported (:attr:`MarkerlessCalibration.minima`).
Covariance: ``s^2 (J^T J)^-1`` of the estimation layer (``sigma_px`` given:
absolute). Conditioning: the condition number of the column-scaled Jacobian
and the weakest directions of the pose in words (:func:`conditioning`).

Mixed data (:func:`calibrate_mixed`): poses with markers (the patent's
path, :mod:`.joint`'s residuals, 6 parameters a mirror) and without (3
parameters a plane) in one problem sharing ``T_r_c``; library only (the
input file takes one form or the other).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from robocal.camera import CameraModel
from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.estimation import LSQResult, Problem, solve
from robocal.geometry import (
    invert_transform,
    matrix_from_rotvec,
    project_to_rotation,
    rotvec_from_matrix,
    skew,
    so3_left_jacobian,
    transform_from,
)
from robocal.rigs.mirror.conditioning import conditioning
from robocal.rigs.mirror.model import F_X, PoseCovarianceStd, ri_from_r_points
from robocal.validation import check_array

__all__ = ["MarkerlessObservation", "MarkerlessCalibration", "calibrate_markerless", "closed_form",
           "virtual_pose_candidates", "markerless_residuals", "conditioning", "simulate_markerless",
           "MIN_POSES", "MIN_POINTS", "PARALLEL_NORMALS_DEG"]

#: The problem's minimum: 3 mirror poses (two give one rotation axis, no normal) and 3 points per pose (P3P).
MIN_POSES = 3
MIN_POINTS = 3
#: All normals within this angle of each other [deg] is refused: the rotations H_i H_j (twice the angle
#: between normals) are then a few degrees and their axes, hence the normals, are noise (measured: parallel
#: mirrors seen through 3 points at 0.3 px give 0.9 deg; a usable set of poses differs by 10-30 deg).
PARALLEL_NORMALS_DEG = 2.0
#: Beyond this many PnP combinations only those of the first three poses are enumerated.
MAX_COMBINATIONS = 256
#: Closed-form starts refined (best by reprojection RMS).
N_STARTS = 4


@dataclass
class MarkerlessObservation:
    """One mirror pose: image points ``uv`` (n, 2) [px] of the reflections of reference points ``ids`` (n,)."""

    uv: np.ndarray
    ids: np.ndarray
    name: str = "mirror pose"

    def __post_init__(self):
        self.uv = check_array(self.uv, f"{self.name}: uv", shape=(2,))
        if self.uv.ndim != 2:
            raise ShapeError(f"{self.name}: uv must have shape (n, 2), got {self.uv.shape}")
        ids = np.asarray(self.ids)
        if ids.shape != (len(self.uv),) or (ids.size and not np.issubdtype(ids.dtype, np.integer)):
            raise ShapeError(f"{self.name}: ids must be {len(self.uv)} integers (one per uv row), got {ids.tolist()}")
        if len(set(ids.tolist())) != len(ids):
            raise InputError(f"{self.name}: ids must be unique, got {ids.tolist()}")
        self.ids = ids.astype(int)

    def to_dict(self) -> dict:
        return {"name": self.name, "uv": self.uv.tolist(), "ids": self.ids.tolist()}


class _MarkerlessAnswer(PoseCovarianceStd):
    """What :class:`MarkerlessCalibration` and :class:`~robocal.rigs.mirror.mixed.MixedCalibration` derive from
    their ``cov`` (6, 6) (rotvec left [rad], t [m]) and their markerless poses."""

    def residuals(self) -> list:
        """Reprojection residuals [px] of the markerless poses' reflections, projected - observed."""
        return markerless_residuals(self.camera, self.points_r, self.observations, self.T_r_c, self.normals,
                                    self.distances)


@dataclass
class MarkerlessCalibration(_MarkerlessAnswer):
    """Result of :func:`calibrate_markerless`.

    ``T_r_c`` (4, 4) [m] the answer (camera in the robot frame); ``cov`` (6, 6)
    of ``(rotvec [rad], left; t_rc [m])``; ``normals`` (K, 3), ``distances``
    (K,) [m] the mirror planes in the camera frame with ``plane_std`` (K, 2):
    the normal's angle std [rad] (largest tangent direction) and ``d``'s [m];
    ``T_r_c_closed_form`` the closed form's answer (before refinement);
    ``minima``: one dict per distinct minimum reached from the starts (best
    first: ``cost``, ``delta_chi2`` (twice the cost above the best, in
    noise units), ``rms_px``, ``T_r_c``, ``camera_distance_m`` (from the
    nearest reference point) and ``plausible`` (within max(1 m, 2 x the
    points' span): the camera is on the robot; an implausible minimum is
    never the answer while a plausible one is within 9 chi-square units),
    ``rotation_from_best_deg``,
    ``translation_from_best_mm``, ``starts``); ``conditioning``: see
    :func:`conditioning`; ``dropped``: names of poses left out (< 3 points).
    """

    T_r_c: np.ndarray
    cov: np.ndarray
    normals: np.ndarray
    distances: np.ndarray
    plane_std: np.ndarray | None
    T_r_c_closed_form: np.ndarray
    lsq: LSQResult | None
    minima: list
    conditioning: dict
    warnings: list
    observations: list
    points_r: np.ndarray
    camera: CameraModel
    dropped: list = field(default_factory=list)
    n_combinations: int = 1


def _project_virtual(camera, P_r, T_r_c, n, d):
    T_c_r = invert_transform(T_r_c)
    pc = P_r @ T_c_r[:3, :3].T + T_c_r[:3, 3]
    s = pc @ n - d
    return camera.project(pc - 2.0 * s[:, None] * n, check=False)


def markerless_residuals(camera, points_r, observations, T_r_c, normals, distances) -> list:
    """Per pose ``project(reflection) - uv`` (n_j, 2) [px] for planes ``n . x = d`` in the camera frame."""
    P = np.asarray(points_r, dtype=float)
    return [_project_virtual(camera, P[o.ids], T_r_c, n, d) - o.uv
            for o, n, d in zip(observations, np.asarray(normals), np.asarray(distances))]


# ------------------------------------------------------------------ closed form
def virtual_pose_candidates(camera: CameraModel, points_r, obs: MarkerlessObservation) -> list:
    """``T_c_ri`` candidates (4, 4) of one pose: all P3P solutions (3 points) or the refined SQPnP pose (>= 4)."""
    import cv2

    P = np.ascontiguousarray(ri_from_r_points(np.asarray(points_r, dtype=float)[obs.ids]))
    uv = np.ascontiguousarray(obs.uv, dtype=float)
    K, dist = camera.K, np.asarray(camera.dist, dtype=float)
    out = []
    if len(P) == 3:
        n, rvecs, tvecs = cv2.solveP3P(P, uv, K, dist, flags=cv2.SOLVEPNP_P3P)
        for r, t in zip(rvecs[:n], tvecs[:n]):
            if np.all(np.isfinite(r)) and np.all(np.isfinite(t)):
                out.append(transform_from(matrix_from_rotvec(np.ravel(r)), np.ravel(t)))
    else:
        ok, r, t = cv2.solvePnP(P, uv, K, dist, flags=cv2.SOLVEPNP_SQPNP)
        if ok:
            r, t = cv2.solvePnPRefineLM(P, uv, K, dist, r, t)
            out.append(transform_from(matrix_from_rotvec(np.ravel(r)), np.ravel(t)))
    # a virtual point behind the camera is no solution
    return [T for T in out if np.all((P @ T[:3, :3].T + T[:3, 3])[:, 2] > 0)]


def _normal_angles(T_c_ri) -> np.ndarray:
    """Pairwise angles [rad] between the mirror normals: half the rotation angle of ``R_cri_i R_cri_j^T``."""
    R = np.asarray(T_c_ri)[:, :3, :3]
    rv = rotvec_from_matrix(np.einsum("iab,jcb->ijac", R, R))
    return 0.5 * np.linalg.norm(rv, axis=-1)


def closed_form(T_c_ri) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Takahashi et al. (CVPR 2012): ``(T_r_c, normals (K, 3), d (K,), coplanarity)`` from K >= 3 virtual poses.

    See the module docstring, steps 2-4. ``coplanarity``: the smallest ratio
    of the second to the first singular value of a pose's stacked axes
    ``m_jk`` (0: the normals are coplanar and this pose's normal is not
    determined by the orthogonality constraint).

    Raises
    ------
    DegenerateGeometryError
        All normals parallel within :data:`PARALLEL_NORMALS_DEG`.
    """
    T = np.asarray(T_c_ri, dtype=float)
    K = len(T)
    if K < MIN_POSES:
        raise NotEnoughDataError(f"mirror_poses: need >= {MIN_POSES} mirror poses with >= 3 points each, got {K}")
    R = T[:, :3, :3]
    ang = _normal_angles(T)
    if ang.max() < np.radians(PARALLEL_NORMALS_DEG):
        exc = DegenerateGeometryError(
            f"mirror_poses: all mirror normals are parallel (largest angle between two poses' normals "
            f"{np.degrees(ang.max()):.2f} deg, need >= {PARALLEL_NORMALS_DEG:g} deg, better 10-30 deg): with the "
            f"mirror only shifted, not tilted, the poses give no rotation axis; tilt it differently for each pose")
        exc.angle_deg = float(np.degrees(ang.max()))
        raise exc
    # axis of H_i H_j (= R_cri_i R_cri_j^T) times its angle: n_i x n_j scaled by how well it is determined
    rv = rotvec_from_matrix(np.einsum("iab,jcb->ijac", R, R))  # (K, K, 3)
    normals = np.zeros((K, 3))
    coplanar = 1.0
    for j in range(K):
        A = np.stack([rv[j, k] for k in range(K) if k != j])
        _, s, Vt = np.linalg.svd(A)
        normals[j] = Vt[-1]
        coplanar = min(coplanar, float(s[1] / s[0]) if s[0] > 0 else 0.0)
    H = np.eye(3) - 2.0 * np.einsum("ki,kj->kij", normals, normals)
    R_cr = project_to_rotation(np.sum(H @ R @ F_X, axis=0))
    # (I - 2 n n^T) t + 2 d_j n_j = t_cri_j: 3K equations in (t, d_1..d_K)
    A = np.zeros((3 * K, 3 + K))
    for j in range(K):
        A[3 * j:3 * j + 3, :3] = H[j]
        A[3 * j:3 * j + 3, 3 + j] = 2.0 * normals[j]
    x = np.linalg.lstsq(A, T[:, :3, 3].reshape(-1), rcond=None)[0]
    t_cr, d = x[:3], x[3:].copy()
    flip = d < 0  # H does not see the sign of n; d > 0 fixes it (n away from the camera)
    normals[flip] *= -1.0
    d[flip] *= -1.0
    return invert_transform(transform_from(R_cr, t_cr)), normals, d, coplanar


def _reflection_defect(R_cri, R_cr) -> float:
    """How far ``R_cri F R_cr^T`` is from a symmetric matrix (a reflection is): 0 for the right P3P solution."""
    M = R_cri @ F_X @ R_cr.T
    return float(np.linalg.norm(M - M.T))


def _combinations(cands: list, first_three_only: bool):
    if not first_three_only:
        yield from itertools.product(*[range(len(c)) for c in cands])
        return
    for head in itertools.product(*[range(len(c)) for c in cands[:3]]):
        try:
            T_r_c, *_ = closed_form(np.stack([cands[j][i] for j, i in enumerate(head)]))
        except DegenerateGeometryError:
            continue  # these three poses' normals parallel in this combination: no R_cr to choose the rest by
        R_cr = T_r_c[:3, :3].T
        tail = tuple(int(np.argmin([_reflection_defect(T[:3, :3], R_cr) for T in c])) for c in cands[3:])
        yield head + tail


def _rms(camera, P, observations, T_r_c, n, d) -> float:
    r = np.concatenate(markerless_residuals(camera, P, observations, T_r_c, n, d))
    v = float(np.sqrt(np.mean(r ** 2)))
    return v if np.isfinite(v) else np.inf


# ------------------------------------------------------------------ refinement
def _tangent_basis(n) -> np.ndarray:
    """(K, 3, 2) orthonormal bases of the planes orthogonal to the unit normals ``n`` (K, 3)."""
    out = np.zeros((len(n), 3, 2))
    for k, v in enumerate(n):
        a = np.eye(3)[int(np.argmin(np.abs(v)))]
        b1 = np.cross(v, a)
        b1 /= np.linalg.norm(b1)
        out[k] = np.column_stack([b1, np.cross(v, b1)])
    return out


def _problem(camera, P, observations, T_r_c0, n0, d0, sigma_px):
    K = len(observations)
    R_rc0 = T_r_c0[:3, :3]
    B = _tangent_basis(n0)
    counts = [len(o.ids) for o in observations]
    uv_obs = np.concatenate([o.uv for o in observations])

    def unpack(p):
        R_rc = matrix_from_rotvec(p["rot_rc"]) @ R_rc0
        u = n0 + np.einsum("kij,kj->ki", B, p["plane_a"])
        nu = np.linalg.norm(u, axis=1)
        return R_rc, p["t_rc"], u / nu[:, None], nu, np.asarray(p["plane_d"], dtype=float)

    def geometry(p):
        R_rc, t_rc, n, nu, d = unpack(p)
        q = np.concatenate([P[o.ids] for o in observations]) - t_rc  # (M, 3)
        k = np.repeat(np.arange(K), counts)
        pc = q @ R_rc  # R_rc^T q
        nk = n[k]
        s = np.sum(pc * nk, axis=1) - d[k]
        pv = pc - 2.0 * s[:, None] * nk
        return R_rc, n, nu, k, q, pc, nk, s, pv

    def residual(p):
        *_, pv = geometry(p)
        return camera.project(pv, check=False) - uv_obs

    def jacobian(p):
        R_rc, n, nu, k, q, pc, nk, s, pv = geometry(p)
        M = len(pv)
        _, Jp = camera.project_jacobian(pv, check=False)  # (M, 2, 3)
        H = np.eye(3) - 2.0 * np.einsum("mi,mj->mij", nk, nk)
        Jl = so3_left_jacobian(p["rot_rc"])
        dpc_drot = R_rc.T @ skew(q) @ Jl  # (M, 3, 3)
        JpH = Jp @ H
        dpv_dn = -2.0 * (s[:, None, None] * np.eye(3) + nk[:, :, None] * pc[:, None, :])  # (M, 3, 3)
        # n = u / |u|, u = n0 + B a:  dn/da = (I - n n^T) B / |u|
        dn_da = (np.eye(3) - np.einsum("ki,kj->kij", n, n)) @ B / nu[:, None, None]  # (K, 3, 2)
        ja = np.zeros((M, 2, K, 2))
        jd = np.zeros((M, 2, K))
        rows = np.arange(M)
        ja[rows, :, k] = Jp @ dpv_dn @ dn_da[k]
        jd[rows, :, k] = np.einsum("mij,mj->mi", Jp, 2.0 * nk)
        return {"rot_rc": (JpH @ dpc_drot).reshape(2 * M, 3), "t_rc": (JpH @ -R_rc.T).reshape(2 * M, 3),
                "plane_a": ja.reshape(2 * M, 2 * K), "plane_d": jd.reshape(2 * M, K)}

    prob = Problem()
    prob.add_block("rot_rc", np.zeros(3), labels=["rot_rc_x", "rot_rc_y", "rot_rc_z"], unit="rad", scale=1e-3)
    prob.add_block("t_rc", T_r_c0[:3, 3], labels=["t_rc_x", "t_rc_y", "t_rc_z"], unit="m", scale=1e-3)
    prob.add_block("plane_a", np.zeros((K, 2)), labels=[f"normal{j}_{a}" for j in range(K) for a in "uv"],
                   unit="rad", scale=1e-3)
    prob.add_block("plane_d", np.asarray(d0, dtype=float), labels=[f"d{j}" for j in range(K)], unit="m",
                   scale=1e-3)
    prob.add_residuals(residual, name="reflections", jacobian=jacobian, residual_dim=2,
                       sigma=None if sigma_px is None else float(sigma_px))

    def answer(p):
        R_rc, t_rc, n, _, d = unpack(p)
        return transform_from(R_rc, t_rc), n, d

    return prob, answer, B


# ------------------------------------------------------------------ the API
def _check_inputs(P, observations):
    if P.ndim != 2 or P.shape[1] != 3:
        raise ShapeError(f"reference_points: must have shape (N, 3), got {P.shape}")
    if len(P) < MIN_POINTS:
        raise NotEnoughDataError(f"reference_points: need >= {MIN_POINTS} points (P3P per mirror pose), got {len(P)}")
    for o in observations:
        if o.ids.size and (o.ids.min() < 0 or o.ids.max() >= len(P)):
            raise InputError(f"{o.name}: ids must be rows of reference_points (0..{len(P) - 1}), got "
                             f"{o.ids.tolist()}")


def calibrate_markerless(camera: CameraModel, points_r, observations, *, sigma_px: float | None = None,
                         refine: bool = True, n_starts: int = N_STARTS, accept_implausible: bool = False,
                         declared: dict | None = None, progress: bool = False) -> MarkerlessCalibration:
    """``T_r_c`` and the K mirror planes from reflections of known points, no mirror markers (see module doc).

    Parameters
    ----------
    camera : CameraModel
        Intrinsics and distortion (fixed).
    points_r : array_like, shape (N, 3)
        Reference points in the robot frame [m], N >= 3.
    observations : sequence of MarkerlessObservation
        One per mirror pose, K >= 3 poses with >= 3 points each (a pose that
        sees fewer is dropped with a ``dropped`` warning, counted).
    sigma_px : float, optional
        Pixel noise; given, the covariance takes it as the truth (absolute),
        else the residual variance scales it.
    refine : bool
        Run the joint least squares (else the closed form, with the
        covariance of the refinement's first-order model at it).
    n_starts : int
        Closed-form combinations refined (best reprojection RMS first).
    accept_implausible, declared
        As :func:`robocal.rigs.mirror.calibrate.calibrate`: reference points
        whose span fits no robot (a unit slip) raise
        :class:`~robocal.errors.ImplausibleInputError` naming the unit.

    Raises
    ------
    NotEnoughDataError
        Fewer than 3 points, or fewer than 3 usable mirror poses.
    DegenerateGeometryError
        All mirror normals parallel (named), or no PnP solution in a pose.
    """
    from robocal.rigs.mirror.checks import check_camera
    from robocal.rigs.mirror.slips import check_body_span

    P = check_array(points_r, "reference_points")
    obs_all = list(observations)
    _check_inputs(P, obs_all)
    check_camera(camera)
    warnings = list(check_body_span(P, declared=declared, accept=accept_implausible, field="reference_points"))
    obs = [o for o in obs_all if len(o.ids) >= MIN_POINTS]
    dropped = [o.name for o in obs_all if len(o.ids) < MIN_POINTS]
    if dropped:
        warnings.append(Diagnostic("dropped", f"{len(dropped)} mirror pose(s) see fewer than {MIN_POINTS} reference "
                                              f"points and were left out: {', '.join(dropped)}",
                                   indices=tuple(i for i, o in enumerate(obs_all) if len(o.ids) < MIN_POINTS)))
    if len(obs) < MIN_POSES:
        raise NotEnoughDataError(f"mirror_poses: need >= {MIN_POSES} mirror poses that see >= {MIN_POINTS} reference "
                                 f"points each, got {len(obs)} (of {len(obs_all)})")
    missing = sum(len(P) - len(o.ids) for o in obs)
    if missing:
        warnings.append(Diagnostic("dropped", f"{missing} reflection(s) not seen (a point missing in a pose): "
                                              f"{sum(len(o.ids) for o in obs)} of {len(P) * len(obs)} used"))
    cands = []
    for o in obs:
        c = virtual_pose_candidates(camera, P, o)
        if not c:
            raise DegenerateGeometryError(f"{o.name}: no PnP solution for the reflections (points collinear, or "
                                          f"ids not matching uv)")
        cands.append(c)
    n_comb = int(np.prod([len(c) for c in cands], dtype=float))
    starts = []
    degenerate_error = None
    for combo in _combinations(cands, n_comb > MAX_COMBINATIONS):
        T = np.stack([cands[j][i] for j, i in enumerate(combo)])
        try:
            T_r_c, n, d, copl = closed_form(T)
        except DegenerateGeometryError as exc:
            degenerate_error = exc
            continue
        if np.any(d <= 0):
            continue
        starts.append((_rms(camera, P, obs, T_r_c, n, d), T_r_c, n, d, copl))
    if not starts:
        raise degenerate_error or DegenerateGeometryError(
            "mirror_poses: no combination of the poses' PnP solutions gives mirrors in front of the camera")
    starts.sort(key=lambda s: s[0])
    rms0, T0, n0, d0, copl = starts[0]
    if copl < 0.05:
        warnings.append(Diagnostic("degenerate_geometry",
                                   f"the mirror normals are nearly coplanar (axis ratio {copl:.3f}): the rotation "
                                   f"about their common perpendicular is weakly determined; tilt the mirror about "
                                   f"two different axes between poses", params=("mirror_poses",)))
    if not refine:
        prob, _, _ = _problem(camera, P, obs, T0, n0, d0, sigma_px)
        J = np.asarray(prob.jacobian_at(None, jac="analytic"))
        s2 = 1.0 if sigma_px is not None else rms0 ** 2 * len(J) / max(len(J) - J.shape[1], 1)
        cov = s2 * np.linalg.pinv(J.T @ J)[:6, :6]
        cond = conditioning(cov, T0)
        warnings.append(Diagnostic("weakly_determined", f"closed form only (no refinement): {cond['text']}"))
        return MarkerlessCalibration(T0, cov, n0, d0, None, T0, None, [], cond, warnings, obs, P, camera, dropped,
                                     n_comb)
    results = []
    for i, (rms_s, T_s, n_s, d_s, _) in enumerate(starts[:max(1, int(n_starts))]):
        prob, answer, B = _problem(camera, P, obs, T_s, n_s, d_s, sigma_px)
        try:
            # the best start gets SciPy's full budget; the others 20 steps per parameter: from a wrong P3P
            # combination LM can crawl for a thousand steps (measured: 5 s a calibration), and a start that
            # has not converged by then is no minimum to report
            res = solve(prob, method="lm", absolute_sigma=sigma_px is not None, progress=progress,
                        max_nfev=None if i == 0 else 20 * prob.n_free)
        except (np.linalg.LinAlgError, ValueError):
            continue
        if i > 0 and not res.success:
            continue
        T, n, d = answer(res.params)
        # (n, d) and (-n, -d) are one plane: keep the normal pointing away from the camera
        n, d = n * np.sign(d)[:, None], np.abs(d)
        results.append((res.cost, T, n, d, res, B))
    if not results:
        raise DegenerateGeometryError("mirror_poses: the refinement diverged from every closed-form start")
    results.sort(key=lambda r: r[0])
    # the camera is mounted on the robot: a minimum that puts it far from the reference points is no answer
    # (with 3 points the mirror-image solution often fits as well, 60-90 deg and 10 m away)
    from robocal.rigs.mirror.single import CAMERA_BODY_MAX_M

    limit = max(CAMERA_BODY_MAX_M, 2.0 * float(np.linalg.norm(np.ptp(P, axis=0))))
    s2_of = (lambda r: 1.0) if sigma_px is not None else (lambda r: max(2.0 * r[0] / max(r[4].dof, 1), 1e-300))
    near = [r for r in results if 2.0 * (r[0] - results[0][0]) / s2_of(results[0]) < 9.0
            and _camera_distance(r[1], P) <= limit]
    if near and near[0] is not results[0]:
        results.remove(near[0])
        results.insert(0, near[0])
    cost, T, n, d, res, B = results[0]
    minima = _minima(results, P, limit)
    if not minima[0]["plausible"]:
        from robocal.plausibility import check_slips

        d_cam = minima[0]["camera_distance_m"]
        if degenerate_error is not None and n_comb == 1:
            raise degenerate_error  # the one combination there is has parallel normals
        # with 3 points a combination of wrong P3P solutions can have parallel normals while the right one has
        # not (measured: 1 of 100 scenes tilted by up to 30 deg), or the reverse: name both
        hint = (f"; one combination of the poses' P3P solutions makes all mirror normals parallel "
                f"({getattr(degenerate_error, 'angle_deg', float('nan')):.2f} deg apart): if the mirror was only "
                f"shifted between poses, tilt it differently for each pose" if degenerate_error is not None else "")
        warnings.extend(w for w in [check_slips(
            what="camera's distance from the nearest reference point", residual=d_cam, unit="m", plausible=False,
            threshold=limit, accept=accept_implausible,
            reason=f"the best minimum puts the camera {d_cam:.3g} m from the nearest reference point (limit "
                   f"{limit:.3g} m), but it is mounted on the robot: check that ids match the uv rows, and add mirror "
                   f"poses or points (this geometry is weak: see the conditioning){hint}")] if w is not None)
    cov_full = res.cov
    cov = cov_full[:6, :6]
    K = len(obs)
    plane_std = None
    if np.all(np.isfinite(cov_full)):
        ca = cov_full[6:6 + 2 * K, 6:6 + 2 * K]
        plane_std = np.array([[np.sqrt(np.linalg.eigvalsh(ca[2 * j:2 * j + 2, 2 * j:2 * j + 2]).max()),
                               np.sqrt(cov_full[6 + 2 * K + j, 6 + 2 * K + j])] for j in range(K)])
    cond = conditioning(cov, T, res)
    warnings.extend(res.warnings)
    # a second minimum the data cannot reject: its cost within 9 chi-square units (3 sigma) of the best, and
    # a camera on the robot
    s2 = s2_of(results[0])
    for m in minima:
        m["delta_chi2"] = float(2.0 * (m["cost"] - cost) / s2)
    rivals = [m for m in minima[1:] if m["delta_chi2"] < 9.0 and m["plausible"]]
    if rivals:
        r = rivals[0]
        warnings.append(Diagnostic(
            "degenerate_geometry",
            f"{len(rivals) + 1} minima fit the reflections equally well (chi-square difference "
            f"{r['delta_chi2']:.2g} < 9): the next one differs by {r['rotation_from_best_deg']:.3g} deg / "
            f"{r['translation_from_best_mm']:.3g} mm (diagnostics.minima); add reference points or mirror poses",
            params=("T_r_c",)))
    return MarkerlessCalibration(T, cov, n, d, plane_std, T0, res, minima, cond, warnings, obs, P, camera, dropped,
                                 n_comb)


def _camera_distance(T_r_c, P) -> float:
    return float(np.min(np.linalg.norm(P - np.asarray(T_r_c)[:3, 3], axis=1)))


def _minima(results, P, limit) -> list:
    """Distinct minima (answer first): a result within 1e-3 deg and 1e-3 mm of an earlier one is the same.

    ``plausible``: the camera lies within ``limit`` [m] of the nearest reference point (it is on the robot).
    """
    best = results[0][1]
    out = []
    for cost, T, n, d, res, _ in results:
        dr = float(np.degrees(np.linalg.norm(rotvec_from_matrix(T[:3, :3] @ best[:3, :3].T))))
        dt = float(np.linalg.norm(T[:3, 3] - best[:3, 3]) * 1e3)
        for m in out:
            same_r = np.degrees(np.linalg.norm(rotvec_from_matrix(T[:3, :3] @ np.asarray(m["T_r_c"])[:3, :3].T)))
            if same_r < 1e-3 and np.linalg.norm(T[:3, 3] - np.asarray(m["T_r_c"])[:3, 3]) * 1e3 < 1e-3:
                m["starts"] += 1
                break
        else:
            out.append({"cost": float(cost), "rms_px": float(res.rms), "T_r_c": T.tolist(),
                        "camera_distance_m": _camera_distance(T, P),
                        "plausible": bool(_camera_distance(T, P) <= limit),
                        "rotation_from_best_deg": dr, "translation_from_best_mm": dt, "starts": 1})
    return out


# ------------------------------------------------------------------ simulation
def simulate_markerless(camera: CameraModel, T_c_r, points_r, normals, distances, rng: np.random.Generator, *,
                        sigma_px: float = 0.5) -> list:
    """One :class:`MarkerlessObservation` per plane ``n_j . x = d_j`` (camera frame), Gaussian noise [px].

    Reflections outside the image or behind the camera are left out (a
    point missing in a pose).
    """
    P = np.asarray(points_r, dtype=float)
    T_r_c = invert_transform(np.asarray(T_c_r, dtype=float))
    out = []
    for j, (n, d) in enumerate(zip(np.asarray(normals), np.asarray(distances))):
        pc = P @ T_c_r[:3, :3].T + T_c_r[:3, 3]
        pv = pc - 2.0 * (pc @ n - d)[:, None] * n
        uv = _project_virtual(camera, P, T_r_c, n, d)
        ok = (pv[:, 2] > 0) & camera.in_image(uv)
        ids = np.flatnonzero(ok)
        out.append(MarkerlessObservation(uv[ids] + rng.normal(scale=sigma_px, size=(ids.size, 2)), ids,
                                         f"mirror pose {j}"))
    return out
