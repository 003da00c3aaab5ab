"""Perspective-n-point: object pose from 3D-2D correspondences, via OpenCV.

``solve_pnp`` (general, SQPnP + Levenberg–Marquardt refinement),
``solve_pnp_planar`` (IPPE: both solutions of the planar ambiguity, each
refined) and ``pnp_covariance`` (first-order covariance of the pose from the
analytic projection Jacobian).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from robocal.camera._model import CameraModel
from robocal.errors import ConvergenceError, DegenerateGeometryError, InputError, NotEnoughDataError
from robocal.validation import check_array, check_points, check_transform

__all__ = [
    "PnPSolution",
    "PnPCandidates",
    "solve_pnp",
    "solve_pnp_planar",
    "pnp_covariance",
    "pnp_jacobian",
    "reprojection_residuals",
]

# OpenCV 5's solvePnPRefineLM (the new LevMarq) reads eps differently from 4's: at 1e-12 it stops
# ~3e-9 rad / 1e-6 px short of the optimum of noise-free data (4.x: 1e-16), and two candidates
# that refine to one pose then look like two. At 1e-15 both majors reach < 1e-12 in the same
# time (noisy data: the same answer to the last bit as eps = 0, where 4.x runs all 100 iterations).
_REFINE_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-15)
#: Relative thickness below which points count as coplanar / collinear.
_PLANAR_RTOL = 1e-6


@dataclass(frozen=True)
class PnPSolution:
    """A PnP pose with its reprojection residuals.

    Attributes
    ----------
    T_cam_obj : ndarray, shape (4, 4)
        Maps object-frame points into the camera frame [m].
    rms_px : float
        ``sqrt(mean_i |r_i|^2)`` [px] (OpenCV's ``calibrateCamera`` definition:
        per point, not per coordinate).
    residuals : ndarray, shape (N, 2)
        ``uv_observed - uv_projected`` [px].
    """

    T_cam_obj: np.ndarray
    rms_px: float
    residuals: np.ndarray

    @property
    def rms(self) -> float:
        """Alias of :attr:`rms_px`."""
        return self.rms_px

    @property
    def rvec(self) -> np.ndarray:
        """OpenCV rotation vector of ``R_cam_obj`` [rad], shape (3,)."""
        return cv2.Rodrigues(np.ascontiguousarray(self.T_cam_obj[:3, :3]))[0].reshape(3)

    @property
    def tvec(self) -> np.ndarray:
        """``t_cam_obj`` [m], shape (3,)."""
        return self.T_cam_obj[:3, 3].copy()


class PnPCandidates(tuple):
    """The planar-PnP solutions, best (lowest RMS) first; a tuple of :class:`PnPSolution`.

    ``ambiguity = rms_best / rms_second`` in [0, 1]: near 0 the choice is
    clear, near 1 the two poses explain the data equally well (a small or
    distant target seen nearly frontally) and the pose should not be trusted
    without other information. ``error_ratio = rms_second / rms_best`` is its
    inverse (inf for noise-free data).
    """

    @property
    def best(self) -> PnPSolution:
        return self[0]

    @property
    def ambiguity(self) -> float:
        if len(self) < 2:
            return 0.0
        if self[1].rms_px == 0.0:
            return 1.0
        return float(self[0].rms_px / self[1].rms_px)

    @property
    def error_ratio(self) -> float:
        if len(self) < 2:
            return float("inf")
        if self[0].rms_px == 0.0:
            return float("inf") if self[1].rms_px > 0 else 1.0
        return float(self[1].rms_px / self[0].rms_px)


def _transform(rvec, tvec) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, dtype=float).reshape(3)
    return T


def _rvec_tvec(T: np.ndarray):
    return cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))[0].reshape(3, 1), T[:3, 3].reshape(3, 1).copy()


def _check_camera(camera) -> CameraModel:
    if not isinstance(camera, CameraModel):
        raise InputError(f"camera must be a robocal.camera.CameraModel, got {type(camera).__name__}")
    return camera


def _check_inputs(camera, p_obj, uv, min_count: int):
    _check_camera(camera)
    p = check_points(p_obj, "p_obj", dim=3)
    q = check_points(uv, "uv", dim=2)
    if p.shape[0] != q.shape[0]:
        raise InputError(f"p_obj and uv must have the same number of points, got {p.shape[0]} and {q.shape[0]}")
    if p.shape[0] < min_count:
        raise NotEnoughDataError(f"PnP needs at least {min_count} points, got {p.shape[0]}")
    # coincident or collinear image points determine no pose; OpenCV's answer to
    # them is an assertion (SQPnP), a NaN pose or "behind the camera" (IPPE)
    sv = np.linalg.svd(q - q.mean(axis=0), compute_uv=False)
    if sv[0] < 1e-6 or sv[1] <= 1e-9 * sv[0]:
        what = "coincide" if sv[0] < 1e-6 else "are collinear"
        raise DegenerateGeometryError(f"uv: the {q.shape[0]} image points {what}; the pose is not determined")
    # OpenCV rejects strided views (e.g. uv[:, ::-1] or a column slice)
    return np.ascontiguousarray(p), np.ascontiguousarray(q)


def _opencv(fn, *args, **kw):
    """Call an OpenCV solver; its assertion errors on degenerate data become a named error."""
    try:
        return fn(*args, **kw)
    except cv2.error as exc:
        first = str(exc).strip().splitlines()[-1] if str(exc).strip() else repr(exc)
        raise DegenerateGeometryError(f"OpenCV could not solve this PnP problem: {first}") from None


def reprojection_residuals(camera: CameraModel, p_obj, uv, T_cam_obj) -> np.ndarray:
    """``uv - camera.project_points(p_obj, T_cam_obj)``, shape (N, 2) [px]."""
    return np.asarray(uv, dtype=float) - camera.project_points(p_obj, T_cam_obj)


def _solution(camera, p, q, T) -> PnPSolution:
    p_cam = p @ T[:3, :3].T + T[:3, 3]
    if np.any(p_cam[:, 2] <= 0):
        raise ConvergenceError(
            f"PnP pose puts points behind the camera (indices {np.flatnonzero(p_cam[:, 2] <= 0)[:8].tolist()}); "
            "check the correspondences"
        )
    r = q - camera.project(p_cam)
    return PnPSolution(T, float(np.sqrt(np.mean(np.sum(r * r, axis=1)))), r)


def _refine(camera, p, q, rvec, tvec):
    """OpenCV's Levenberg-Marquardt, then SciPy's (MINPACK) to convergence.

    OpenCV's LM stops where its own termination test says, and 4.x and 5.x
    differ: on noise-free data 5.x stops 3e-9 rad short where 4.x reaches
    1e-16, and 4.x can stop with a gradient far from zero (the second IPPE
    pose of a small, distant rectangle: |J^T r| = 6 px^2/rad at 0.42 px RMS,
    where a true LM run goes on to the first pose's minimum, 0.33 px). Which
    poses a caller sees then depended on the OpenCV version. MINPACK's LM
    with the analytic Jacobian (:func:`pnp_jacobian`) from OpenCV's answer
    takes a few evaluations when that answer is converged, and makes the
    result the minimum robocal asks for on every OpenCV.
    """
    from scipy.optimize import least_squares

    rvec, tvec = _opencv(
        cv2.solvePnPRefineLM, p.reshape(-1, 1, 3), q.reshape(-1, 1, 2), camera.K, camera.dist, rvec.copy(),
        tvec.copy(), _REFINE_CRITERIA
    )
    cache = {}

    def both(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            uv, J = pnp_jacobian(camera, p, _transform(x[:3], x[3:]))
            cache[key] = ((uv - q).ravel(), J.reshape(-1, 6))
        return cache[key]

    x0 = np.concatenate([rvec.ravel(), tvec.ravel()])
    try:
        f0 = both(x0)[0]  # OpenCV's answer, the first evaluation of the solve too (cached)
        sol = least_squares(lambda x: both(x)[0], x0, jac=lambda x: both(x)[1], method="lm", x_scale="jac",
                            xtol=_POLISH_TOL, ftol=_POLISH_TOL, gtol=_POLISH_TOL, max_nfev=_POLISH_MAX_NFEV)
    except (DegenerateGeometryError, InputError, ValueError):
        return rvec, tvec  # a step put points behind the camera, or too few residuals: keep OpenCV's
    if not np.all(np.isfinite(sol.x)) or not sol.cost <= 0.5 * f0 @ f0:
        return rvec, tvec
    return sol.x[:3].reshape(3, 1), sol.x[3:].reshape(3, 1)


#: MINPACK tolerances (relative) and evaluation budget of :func:`_refine`: converged to the last bits.
_POLISH_TOL = 1e-15
_POLISH_MAX_NFEV = 200


def _plane_basis(p: np.ndarray):
    """Centroid, singular values and principal axes of a point set."""
    c = p.mean(axis=0)
    _, s, Vt = np.linalg.svd(p - c, full_matrices=False)
    return c, s, Vt


def solve_pnp(camera: CameraModel, p_obj, uv, *, refine: bool = True) -> PnPSolution:
    """Pose of an object from N >= 4 point correspondences (general 3D or planar points).

    SQPnP (``cv2.SOLVEPNP_SQPNP``, globally optimal for the algebraic error)
    then Levenberg–Marquardt on the reprojection error
    (``cv2.solvePnPRefineLM``) unless ``refine=False``.

    Parameters
    ----------
    camera : CameraModel
    p_obj : array_like, shape (N, 3)
        Object-frame points [m].
    uv : array_like, shape (N, 2)
        Observed pixels (OpenCV pixel-centre convention) [px].

    Raises
    ------
    NotEnoughDataError
        Fewer than 4 points.
    DegenerateGeometryError
        All points (nearly) collinear or coincident.
    ConvergenceError
        OpenCV found no pose, or the pose puts points behind the camera.
    """
    p, q = _check_inputs(camera, p_obj, uv, 4)
    _, s, _ = _plane_basis(p)
    if s[0] == 0.0 or s[1] <= _PLANAR_RTOL * s[0]:
        raise DegenerateGeometryError(
            f"p_obj: points are collinear or coincident (singular values {s.tolist()}); the pose is not determined"
        )
    ok, rvec, tvec = _opencv(
        cv2.solvePnP, p.reshape(-1, 1, 3), q.reshape(-1, 1, 2), camera.K, camera.dist, flags=cv2.SOLVEPNP_SQPNP
    )
    if not ok:
        raise ConvergenceError("cv2.solvePnP (SQPnP) found no pose")
    if refine:
        rvec, tvec = _refine(camera, p, q, rvec, tvec)
    return _solution(camera, p, q, _transform(rvec, tvec))


def solve_pnp_planar(camera: CameraModel, p_obj, uv, *, refine: bool = True) -> PnPCandidates:
    """Both IPPE poses of a planar target, each refined, best first.

    A planar target seen by a camera has two poses that fit the image nearly
    equally when the target is small or far (the "flip" ambiguity). This
    returns both (``cv2.solvePnPGeneric`` with ``SOLVEPNP_IPPE``), each
    refined by Levenberg–Marquardt, sorted by reprojection RMS; the result's
    ``ambiguity`` (rms_best / rms_second) says how clear the choice is.

    Parameters
    ----------
    p_obj : array_like, shape (N, 3)
        Coplanar object points [m], N >= 4. Points with ``z = 0`` are used as
        they are; any other plane is found (SVD), the points moved to a plane
        frame, and the poses returned for the original object frame.
    uv : array_like, shape (N, 2) [px]

    Raises
    ------
    DegenerateGeometryError
        Points not coplanar (relative thickness > 1e-6) or collinear.
    """
    p, q = _check_inputs(camera, p_obj, uv, 4)
    c, s, Vt = _plane_basis(p)
    if s[0] == 0.0 or s[1] <= _PLANAR_RTOL * s[0]:
        raise DegenerateGeometryError(f"p_obj: points are collinear or coincident (singular values {s.tolist()})")
    if s[2] > _PLANAR_RTOL * s[0]:
        raise DegenerateGeometryError(
            f"p_obj: points must be coplanar for planar PnP, got out-of-plane spread {s[2]:.3g} "
            f"against in-plane {s[0]:.3g} (use solve_pnp)"
        )
    if np.all(p[:, 2] == 0.0):
        T_obj_plane = np.eye(4)
        p_plane = p
    else:
        R = Vt.copy()
        if np.linalg.det(R) < 0:
            R[2] *= -1.0
        T_obj_plane = np.eye(4)
        T_obj_plane[:3, :3] = R.T
        T_obj_plane[:3, 3] = c
        p_plane = (p - c) @ R.T
        p_plane[:, 2] = 0.0
    n, rvecs, tvecs, _ = _opencv(
        cv2.solvePnPGeneric, p_plane.reshape(-1, 1, 3), q.reshape(-1, 1, 2), camera.K, camera.dist,
        flags=cv2.SOLVEPNP_IPPE
    )
    if n == 0:
        raise ConvergenceError("cv2.solvePnPGeneric (IPPE) found no pose")
    T_plane_obj = np.linalg.inv(T_obj_plane)
    sols = []
    for rvec, tvec in zip(rvecs, tvecs):
        if refine:
            rvec, tvec = _refine(camera, p_plane, q, rvec, tvec)
        T = _transform(rvec, tvec) @ T_plane_obj
        T[3] = (0.0, 0.0, 0.0, 1.0)
        try:
            sols.append(_solution(camera, p, q, T))
        except ConvergenceError:
            continue
    if not sols:
        raise ConvergenceError("planar PnP: every IPPE pose puts points behind the camera")
    return PnPCandidates(_order_candidates(sols))


#: Two planar-PnP candidates whose RMS differ by less than this fraction (plus _TIE_ABS_PX) are a tie:
#: both refinements stop at ~1e-9 relative parameter precision, which moves an RMS by ~1e-12
#: relative, so a real difference is orders of magnitude above it and no pixel noise can tell
#: the two apart below it.
_TIE_RTOL = 1e-6
_TIE_ABS_PX = 1e-9


def _order_candidates(sols: list) -> list:
    """Best RMS first; a near-tie is broken by robocal, not by the order OpenCV returns the poses in.

    OpenCV 4 and 5 return IPPE's two poses in different orders, and when both fit
    equally (noise-free data, a frontal target) a plain sort by RMS kept that
    order or flipped on the last bits. Ties are ordered by the rotation angle of
    ``R_cam_obj`` (smaller first: the less tilted pose), then by ``t_cam_obj``.
    """
    sols = sorted(sols, key=lambda sol: sol.rms_px)
    if len(sols) == 2:
        a, b = sols
        if b.rms_px - a.rms_px <= _TIE_RTOL * b.rms_px + _TIE_ABS_PX:
            sols.sort(key=lambda sol: (round(float(np.linalg.norm(sol.rvec)), 9), *np.round(sol.tvec, 12)))
    return sols


def pnp_jacobian(camera: CameraModel, p_obj, T_cam_obj) -> tuple[np.ndarray, np.ndarray]:
    """Pixels and their derivative w.r.t. the pose parameters ``(rvec, t)``.

    ``rvec`` is OpenCV's rotation vector of ``R_cam_obj`` (Rodrigues, [rad]),
    ``t = t_cam_obj`` [m]; the derivative of R w.r.t. rvec is
    ``cv2.Rodrigues``'s analytic one, chained with
    :meth:`CameraModel.project_jacobian`.

    Returns
    -------
    uv : ndarray, shape (N, 2) [px]
    J : ndarray, shape (N, 2, 6)
        Columns: ``d uv / d (rvec_x, rvec_y, rvec_z, t_x, t_y, t_z)``.
    """
    _check_camera(camera)
    p = check_points(p_obj, "p_obj", dim=3)
    T = check_transform(T_cam_obj, "T_cam_obj")
    rvec, _ = _rvec_tvec(T)
    R, dR = cv2.Rodrigues(rvec)  # dR: (3, 9), row k = d vec(R) / d rvec_k (row-major)
    p_cam = p @ R.T + T[:3, 3]
    uv, Jp = camera.project_jacobian(p_cam)
    dpdr = np.einsum("kij,nj->nik", dR.reshape(3, 3, 3), p)  # (N, 3, 3): d p_cam / d rvec
    J = np.concatenate([Jp @ dpdr, Jp], axis=2)
    return uv, J


def pnp_covariance(camera: CameraModel, p_obj, T_cam_obj, sigma_px: float) -> np.ndarray:
    """First-order covariance of the PnP pose ``(rvec, t)``, shape (6, 6).

    For independent isotropic pixel noise of standard deviation ``sigma_px``
    on every coordinate, ``cov = sigma^2 (J^T J)^-1`` with ``J`` from
    :func:`pnp_jacobian` (rvec [rad] = OpenCV rotation vector of
    ``R_cam_obj``, t = ``t_cam_obj`` [m]). This is the Cramér–Rao bound of
    the reprojection-error estimate, and its covariance to first order.

    Raises
    ------
    DegenerateGeometryError
        The pose is not determined by these points (J^T J singular).
    """
    sigma = float(check_array(sigma_px, "sigma_px"))
    if not sigma > 0:
        raise InputError(f"sigma_px must be > 0 [px], got {sigma!r}")
    _, J = pnp_jacobian(camera, p_obj, T_cam_obj)
    J = J.reshape(-1, 6)
    if J.shape[0] < 6:
        raise NotEnoughDataError(f"pnp_covariance needs at least 3 points, got {J.shape[0] // 2}")
    JtJ = J.T @ J
    w = np.linalg.eigvalsh(JtJ)
    if w[0] <= 1e-12 * w[-1]:
        raise DegenerateGeometryError(
            f"pose not determined by these points (J^T J eigenvalues {w[0]:.3g} .. {w[-1]:.3g})"
        )
    cov = sigma * sigma * np.linalg.inv(JtJ)
    return 0.5 * (cov + cov.T)
