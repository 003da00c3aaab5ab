"""Intrinsic calibration: one joint least-squares problem over the intrinsics and every view's pose.

The measurement model is OpenCV's (``cv2.projectPoints``): a planar target's
corners ``P_j`` (target frame, metres) seen in view ``i`` at pose
``T_cam_obj_i = (R(r_i), t_i)`` land at

.. math::

    q_{ij} = \\pi(K, d;\\; R(r_i) P_j + t_i) + e_{ij}, \\qquad e_{ij} \\sim N(0, \\sigma_i^2 I_2)

with ``pi`` the pinhole + Brown-Conrady projection of
:class:`~robocal.camera.CameraModel` and ``sigma_i`` the pixel noise of view
``i`` (its focus, distance and exposure set it; estimated from its residuals,
see ``_view_noise``, or one ``sigma`` for all with ``noise="pooled"``). The
estimate minimises ``sum ||q - pi||^2 / sigma_i^2`` over ``(fx, fy, cx, cy,
k1, k2, p1, p2, k3)`` and every ``(r_i, t_i)`` (Zhang, "A flexible new technique for camera calibration",
IEEE PAMI 22(11), 2000, sec. 3.3), started from ``cv2.calibrateCamera`` on
the same corners. Each view's residuals depend only on the intrinsics and
its own pose (one residual term per view), so the Jacobian is block sparse;
its analytic derivatives are OpenCV's (``cv2.projectPoints``' ``jacobian``).
The covariance, outliers and identifiability are those of
:func:`robocal.estimation.solve` (a corner is an outlier against its own
view's noise); corner outliers are removed one at a time and the problem
refitted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.camera._model import CameraModel
from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.validation import check_array

__all__ = [
    "TargetView",
    "IntrinsicCalibration",
    "calibrate_intrinsics",
    "projection_uncertainty",
    "ProjectionUncertainty",
    "coverage",
    "simulate_target_views",
    "INTRINSIC_MODELS",
    "MIN_CORNERS_PER_VIEW",
    "MIN_VIEWS",
    "CORRELATION_LIMIT",
]

#: Models :func:`calibrate_intrinsics` fits, with the intrinsic labels each estimates (OpenCV order).
INTRINSIC_MODELS = {
    "opencv4": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "opencv5": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"),
    "opencv8": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "opencv12": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4"),
    "fisheye": ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"),
}
#: A view needs this many corners: 6 pose parameters plus a share of the intrinsics from 2 residuals per corner.
MIN_CORNERS_PER_VIEW = 6
#: Fewer usable views than this cannot separate focal length from board distance (Zhang 2000, sec. 3.1).
MIN_VIEWS = 3
#: Intrinsics correlated beyond this are named ``weakly_determined`` (one is nearly a function of the other).
CORRELATION_LIMIT = 0.99
#: Residual evaluations of one solve (see _fit).
MAX_NFEV = 100
#: Beyond this many free parameters (~100 views) the joint problem is solved with a sparse Jacobian.
SPARSE_ABOVE_PARAMS = 620
#: Fits that re-estimate the views' noise levels (noise="per_view"); from a fitted start they settle in 2-3.
REWEIGHT_ROUNDS = 4
#: The views' noise levels have settled when none changes by more than this fraction.
REWEIGHT_TOL = 0.02
#: Views whose noise levels pass Cochran's homogeneity test at this level share the pooled one (_view_noise).
HOMOGENEITY_P = 0.05
#: How the pixel noise is modelled: one level for all corners, or one per view.
NOISE_MODELS = ("per_view", "pooled")
_DIST_LABELS = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4")


def _is_fisheye(labels) -> bool:
    return "p1" not in labels


def _model_labels(model: str) -> tuple:
    """Labels of the intrinsics block: opencv4 is opencv5 with k3 held at 0 (a CameraModel has >= 5 terms)."""
    return INTRINSIC_MODELS["opencv5" if model == "opencv4" else model]


@dataclass(frozen=True, eq=False)
class TargetView:
    """The corners of a calibration target found in one image.

    Attributes
    ----------
    name : str
        The view's name (usually the image file), used in every message.
    object_points : ndarray, shape (N, 3)
        Corners in the target frame [m] (a planar target has ``z = 0``).
    image_points : ndarray, shape (N, 2)
        Where they were detected [px] (OpenCV pixel-centre convention).
    ids : ndarray of int, shape (N,)
        Corner ids on the target (default ``0..N-1``), used to name outliers.
    """

    name: str
    object_points: np.ndarray
    image_points: np.ndarray
    ids: np.ndarray | None = None

    def __post_init__(self):
        p = check_array(self.object_points, f"view '{self.name}': object_points", shape=(None, 3))
        q = check_array(self.image_points, f"view '{self.name}': image_points", shape=(None, 2))
        if p.shape[0] != q.shape[0]:
            raise InputError(f"view '{self.name}': {p.shape[0]} object points but {q.shape[0]} image points")
        ids = np.arange(p.shape[0]) if self.ids is None else np.asarray(self.ids).reshape(-1)
        if ids.shape[0] != p.shape[0] or not np.issubdtype(ids.dtype, np.integer):
            raise InputError(f"view '{self.name}': ids must be {p.shape[0]} integers, got {ids.shape[0]} of "
                             f"dtype {ids.dtype}")
        for name, v in (("object_points", p), ("image_points", q), ("ids", ids.astype(int))):
            v = np.array(v, dtype=float if name != "ids" else int)
            v.flags.writeable = False
            object.__setattr__(self, name, v)
        object.__setattr__(self, "name", str(self.name))

    def __len__(self) -> int:
        return self.object_points.shape[0]

    def subset(self, keep) -> "TargetView":
        """The view with only the corners selected by ``keep`` (mask or indices)."""
        return TargetView(self.name, self.object_points[keep], self.image_points[keep], self.ids[keep])


@dataclass(eq=False)
class IntrinsicCalibration:
    """Result of :func:`calibrate_intrinsics`.

    Attributes
    ----------
    camera : CameraModel or FisheyeCamera
        The estimate.
    model : str
        Key of :data:`INTRINSIC_MODELS`.
    labels : tuple of str
        ``fx, fy, cx, cy, k1, k2, p1, p2, k3[, k4, k5, k6[, s1..s4]]``: the
        order of ``values`` and ``cov`` (n = 9, 12 or 16 by model).
    values : ndarray, shape (n,)
    cov : ndarray, shape (n, n)
        Covariance of the intrinsics [px^2, px, 1] (rows/columns of fixed
        terms zero, NaN for unidentifiable ones), scaled by the residual
        variance (the pixel noise is estimated from the fit: per view, see
        ``view_sigma``).
    std : dict of str to float or None
        Of every label (0 for fixed terms, None where not identifiable).
    free : tuple of str
        The labels estimated (the rest held at their start value).
    poses : dict of str to ndarray (4, 4)
        ``T_cam_obj`` of every used view, by view name.
    pose_std : dict of str to ndarray (6,)
        Std of ``(rx, ry, rz)`` [rad] (rotation vector) and ``(tx, ty, tz)`` [m].
    views : list of TargetView
        The views used, with the corners used (outliers removed).
    residuals : dict of str to ndarray (N, 2)
        ``observed - projected`` [px] of the corners used, by view.
    view_rms : dict of str to float
        RMS [px] of each used view's residual components.
    rms : float
        RMS [px] of every used residual component.
    sigma_px : float
        Pixel noise estimated from the fit, ``sqrt(sum r^2 / (m - n))`` over
        every residual component (pooled over the views).
    opencv_rms : float
        RMS [px] of ``cv2.calibrateCamera``'s start on the same corners
        (``sqrt(sum r^2 / N)`` of corners, OpenCV's definition).
    outliers : list of (str, int)
        ``(view name, corner id)`` removed, in order of removal.
    dropped : list of str
        Views skipped (too few usable corners).
    warnings : list of Diagnostic
    lsq : LSQResult
        The final solve (cost history, Jacobian analysis, ...).
    view_sigma : dict of str to float
        The pixel noise [px] of each used view's corners, their weight in the
        fit (``noise="per_view"``; all ``sigma_px`` with ``noise="pooled"``).
    """

    camera: CameraModel
    model: str
    labels: tuple
    values: np.ndarray
    cov: np.ndarray
    std: dict
    free: tuple
    poses: dict
    pose_std: dict
    views: list
    residuals: dict
    view_rms: dict
    rms: float
    sigma_px: float
    opencv_rms: float
    outliers: list = field(default_factory=list)
    dropped: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    lsq: object = None
    view_sigma: dict = field(default_factory=dict)

    @property
    def std_array(self) -> np.ndarray:
        """Std of ``values`` in ``labels`` order (NaN where not identifiable)."""
        return np.array([np.nan if self.std[k] is None else self.std[k] for k in self.labels])

    def warning_codes(self) -> list[str]:
        return [w.code for w in self.warnings]

    def to_dict(self) -> dict:
        """JSON-safe summary: camera, model, intrinsics with std and covariance, per-view pose and RMS, warnings."""
        from robocal.estimation._result import _json

        return _json({
            "camera": self.camera.to_dict(), "model": self.model, "labels": list(self.labels),
            "values": self.values, "std": dict(self.std), "cov": self.cov, "free": list(self.free),
            "rms_px": self.rms, "sigma_px": self.sigma_px, "opencv_rms_px": self.opencv_rms,
            "views": {n: {"T_cam_obj": self.poses[n], "pose_std": self.pose_std[n], "rms_px": self.view_rms[n],
                          "sigma_px": self.view_sigma.get(n, self.sigma_px),
                          "corners": int(self.residuals[n].shape[0])} for n in self.poses},
            "outliers": [[n, int(i)] for n, i in self.outliers], "dropped": list(self.dropped),
            "warnings": [w.to_dict() for w in self.warnings],
        })


def _check_views(views) -> list[TargetView]:
    if not isinstance(views, (list, tuple)) or not views:
        raise InputError(f"views must be a non-empty list of TargetView, got {type(views).__name__}")
    out = []
    for i, v in enumerate(views):
        if not isinstance(v, TargetView):
            raise InputError(f"views[{i}] must be a TargetView, got {type(v).__name__}")
        out.append(v)
    names = [v.name for v in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"view names must be unique (they name outliers and poses), repeated: {dup}")
    return out


def _rodrigues(rvec) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))[0]


def _project_view(intr, pose, obj, *, jacobian: bool = False, fisheye: bool = False):
    """``cv2.projectPoints`` of one view; ``intr`` the 9 intrinsics, ``pose`` (rvec, tvec)."""
    import cv2

    K = np.array([[intr[0], 0.0, intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
    if fisheye:
        uv, J = cv2.fisheye.projectPoints(obj.reshape(-1, 1, 3), pose[:3].copy(), pose[3:].copy(), K,
                                          intr[4:].copy())
        uv = uv.reshape(-1, 2)
        # cv2.fisheye's columns: (fx, fy), (cx, cy), k(4), rvec(3), tvec(3), skew
        return uv if not jacobian else (uv, J[:, 0:8], J[:, 8:14])
    uv, J = cv2.projectPoints(obj.reshape(-1, 1, 3), pose[:3].copy(), pose[3:].copy(), K, intr[4:].copy())
    uv = uv.reshape(-1, 2)
    if not jacobian:
        return uv
    # cv2's columns: rvec(3), tvec(3), (fx, fy), (cx, cy), dist(n); rows interleaved u0, v0, u1, ...
    return uv, J[:, 6:6 + intr.size], J[:, 0:6]


def _fit(views, x0, poses0, fixed, labels, *, outlier_sigma, sigmas=None):
    from robocal.estimation import Problem, solve

    prob = Problem()
    fish = _is_fisheye(labels)
    prob.add_block("intrinsics", x0, fixed=fixed, labels=list(labels), unit=["px"] * 4 + [None] * (len(labels) - 4))
    for v, p0 in zip(views, poses0):
        prob.add_block(f"pose:{v.name}", p0,
                       labels=[f"{v.name}.{k}" for k in ("rx", "ry", "rz", "tx", "ty", "tz")],
                       unit=["rad"] * 3 + ["m"] * 3)

        def fun(params, v=v):
            return v.image_points - _project_view(params["intrinsics"], params[f"pose:{v.name}"], v.object_points,
                                                  fisheye=fish)

        def jac(params, v=v):
            _, Ji, Jp = _project_view(params["intrinsics"], params[f"pose:{v.name}"], v.object_points,
                                      jacobian=True, fisheye=fish)
            return {"intrinsics": -Ji, f"pose:{v.name}": -Jp}

        prob.add_residuals(fun, name=v.name, blocks=["intrinsics", f"pose:{v.name}"], jacobian=jac,
                           residual_dim=2, sigma=None if sigmas is None else sigmas[v.name])
    # x_scale='jac': pixels, radians and metres differ by orders of magnitude; let the Jacobian balance them.
    # weak_vif: the principal point trades against every view's rotation (variance inflation 1e4-1e5 on a
    # good set of 15 views), so the generic 1e4 would fire on every calibration; _overparameterisation
    # names what matters for a camera model (std > value, correlation > CORRELATION_LIMIT).
    # The block structure is declared above either way. SciPy's sparse path (LSMR, inexact steps) crawls
    # near the optimum at tight tolerances (measured: 9900 evaluations after one corner was removed), so up
    # to SPARSE_ABOVE_PARAMS (~100 views; J 2N x n, ~50 MB) MINPACK's dense LM solves it exactly, and 3-20x
    # faster than dense 'trf', whose SVD per step suffers most from BLAS threads on a shared CPU.
    n = x0.size + 6 * len(views)
    sparse = n > SPARSE_ABOVE_PARAMS
    # max_nfev: from cv2's start a well-posed model converges in 2-10 steps; an over-parameterised one
    # (rational terms on a mild lens) crawls along its degenerate valley for 10^4 evaluations at these
    # tolerances (~0.1 s each at 30 views, mostly the estimation layer's Jacobian assembly). Stopping is
    # reported (not_converged next to rank_deficient); LM only accepts steps that lower the cost, so the
    # result is never worse than cv2's start.
    return prob, solve(prob, method="trf" if sparse else "lm", x_scale="jac", outlier_sigma=outlier_sigma,
                       ftol=1e-12, xtol=1e-12, gtol=1e-12, weak_vif=1e7, sparse=sparse, max_nfev=MAX_NFEV)


def _view_noise(res, views, n_intr: int) -> dict:
    """Each view's pixel noise [px]: its residual variance, robust to outliers, shrunk to the pooled one.

    A view's corners share its distance, tilt, focus and exposure, so their
    noise differs between views (rendered views with blur 0.5-1.6 px and
    1.5-6 grey levels: per-view corner RMS 0.024-0.062 px, 10-90 %) while
    within a view it is nearly constant. View ``i`` with ``m_i`` residual
    components has ``s_i^2 = sum r^2 / (m_i - p_i)``, ``p_i = 6 + n_intr m_i /
    m`` its share of the fitted parameters (its pose, and the intrinsics in
    proportion to its residuals), after the 3-sigma clipping of
    :func:`robocal.estimation.solve` corrected for the truncation (so a gross
    outlier neither inflates its view's noise nor hides behind it); ``s^2``
    likewise over all views. Each ratio ``z_i = s_i^2 / s^2`` scatters by
    ``2 / dof_i`` from sampling alone. When ``Q = sum (z_i - 1)^2 dof_i / 2``
    is within chi-square(n_views - 1)'s ``1 - HOMOGENEITY_P`` quantile
    (Cochran, Biometrics 10, 1954) the views are taken to share one level,
    the pooled one. Otherwise the true spread ``tau^2`` is what the
    observed scatter has beyond that (method of moments, DerSimonian & Laird,
    Controlled Clinical Trials 7, 1986), and each view keeps the share
    ``lambda_i = tau^2 / (tau^2 + 2 / dof_i)`` of its deviation:
    ``s_i^2 <- s^2 (1 + lambda_i (z_i - 1))``. Views of equal noise thus get
    (nearly) equal weights, the fit of one noise level, instead of weights
    that carry their own sampling noise into the estimate.
    """
    from scipy import special

    from robocal.estimation._solve import _clipped_variance  # the solver's own robust noise estimate

    m = 2 * sum(len(v) for v in views)
    q = {v.name: np.sum(res.obs_residuals(v.name) ** 2, axis=1) for v in views}
    q_all = np.concatenate(list(q.values()))
    pooled = _clipped_variance(q_all, np.full(q_all.size, 2), m, n_intr + 6 * len(views), 3.0)
    if not pooled > 0:
        return {v.name: 1.0 for v in views}  # noise-free data: any weights give the same exact fit
    z, dof = [], []
    for v in views:
        mi = 2 * len(v)
        p = 6 + n_intr * mi / m
        dof.append(max(mi - p, 1.0))
        z.append(_clipped_variance(q[v.name], np.full(len(v), 2), mi, p, 3.0) / pooled)
    z, samp = np.array(z), 2.0 / np.array(dof)
    # Cochran's homogeneity test first: views whose levels scatter no more than sampling allows (5 % level)
    # keep the pooled one exactly; a spread estimated > 0 by chance would only add the weights' noise
    if np.sum((z - 1.0) ** 2 / samp) <= special.chdtri(len(views) - 1, HOMOGENEITY_P):
        return {v.name: float(np.sqrt(pooled)) for v in views}
    tau2 = max(float(np.mean((z - 1.0) ** 2 - samp)), 0.0)
    lam = tau2 / (tau2 + samp)
    s2 = pooled * np.maximum(1.0 + lam * (z - 1.0), 1e-6)
    return {v.name: float(np.sqrt(x)) for v, x in zip(views, s2)}


def _opencv_start(views, image_size, fixed, labels):
    import cv2

    if _is_fisheye(labels):
        return _fisheye_start(views, image_size, fixed, labels)
    n = len(labels) - 4
    flags = (cv2.CALIB_RATIONAL_MODEL if n >= 8 else 0) | (cv2.CALIB_THIN_PRISM_MODEL if n >= 12 else 0)
    fixed = dict(zip(labels, fixed))
    for lab in ("k1", "k2", "k3", "k4", "k5", "k6"):
        if fixed.get(lab):
            flags |= getattr(cv2, f"CALIB_FIX_{lab.upper()}")
    if fixed["p1"] and fixed["p2"]:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if n >= 12 and all(fixed[f"s{i}"] for i in range(1, 5)):
        flags |= cv2.CALIB_FIX_S1_S2_S3_S4
    obj = [v.object_points.astype(np.float32) for v in views]
    img = [v.image_points.astype(np.float32) for v in views]
    try:
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, tuple(int(s) for s in image_size), None, None,
                                                         flags=flags)
    except cv2.error as exc:
        raise NotEnoughDataError(f"cv2.calibrateCamera could not initialise the calibration from "
                                 f"{len(views)} views: {str(exc).strip().splitlines()[-1]}") from None
    d = np.zeros(n)
    dist = np.asarray(dist, dtype=float).reshape(-1)
    d[:min(n, dist.size)] = dist[:n]
    x0 = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d])
    x0[list(fixed.values())] = 0.0  # only distortion terms can be fixed: they start (and stay) at 0
    poses = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in zip(rvecs, tvecs)]
    return float(rms), x0, poses


def fisheye_flag(name: str) -> int:
    """``cv2.fisheye.calibrate``'s flag ``name``: in ``cv2.fisheye`` on OpenCV 4, in ``cv2`` on OpenCV 5.

    OpenCV 5 moved the fisheye flags into the common calibration namespace
    with other values (``CALIB_FIX_SKEW``: 8 in 4.x, 1 << 25 in 5.0).
    """
    import cv2

    return int(getattr(cv2.fisheye, name, None) if hasattr(cv2.fisheye, name) else getattr(cv2, name))


def _fisheye_start(views, image_size, fixed, labels):
    import cv2

    flags = fisheye_flag("CALIB_RECOMPUTE_EXTRINSIC") | fisheye_flag("CALIB_FIX_SKEW")
    for i, lab in enumerate(labels[4:]):
        if fixed[4 + i]:
            flags |= fisheye_flag(f"CALIB_FIX_{lab.upper()}")
    obj = [v.object_points.reshape(1, -1, 3).astype(np.float64) for v in views]
    img = [v.image_points.reshape(1, -1, 2).astype(np.float64) for v in views]
    try:
        rms, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
            obj, img, tuple(int(s) for s in image_size), None, None, flags=flags,
            criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-10))
    except cv2.error as exc:
        raise NotEnoughDataError(f"cv2.fisheye.calibrate could not initialise the calibration from "
                                 f"{len(views)} views: {str(exc).strip().splitlines()[-1]}") from None
    x0 = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *np.ravel(D)[:4]])
    x0[np.asarray(fixed)] = 0.0
    poses = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in zip(rvecs, tvecs)]
    return float(rms), x0, poses


def calibrate_intrinsics(views, image_size, *, model: str = "opencv5", fix=(), max_outliers: int | None = None,
                         outlier_sigma: float | None = None,
                         min_corners: int = MIN_CORNERS_PER_VIEW, noise: str = "per_view") -> IntrinsicCalibration:
    """Estimate a camera's intrinsics and distortion from target views (joint least squares).

    Parameters
    ----------
    views : list of TargetView
        Corners per image (target frame [m] and pixels [px]); names unique.
    image_size : (int, int)
        ``(width, height)`` [px], OpenCV's ``imageSize`` order.
    model : str
        ``'opencv5'`` (``k1, k2, p1, p2, k3``, default), ``'opencv4'``
        (``k3 = 0``), ``'opencv8'`` (+ rational ``k4, k5, k6``) or
        ``'opencv12'`` (+ thin prism ``s1..s4``), or ``'fisheye'`` (OpenCV's
        ``cv2.fisheye`` equidistant model, ``k1..k4``, started from
        ``cv2.fisheye.calibrate``; ``camera`` is then a
        :class:`~robocal.camera.FisheyeCamera`); see :data:`INTRINSIC_MODELS`.
        (OpenCV's 14-term tilted model is not implemented.)
    fix : iterable of str
        Distortion terms of the model held at zero (e.g. ``("k3",)``).
    max_outliers : int, optional
        Corners that may be removed (default: 5 % of all corners).
    outlier_sigma : float, optional
        Threshold [sigma] beyond which the worst corner is removed; default
        :func:`robocal.estimation.outlier_sigma` of the number of corners
        (Bonferroni: 1 % chance of removing any corner of a clean data set).
    min_corners : int
        Views with fewer usable corners are skipped (named in ``dropped``).
    noise : {"per_view", "pooled"}
        ``"per_view"`` (default): each view's corners have their own noise
        level, estimated from its residuals (see ``_view_noise``) and used as
        the weight of its corners (iteratively reweighted least squares), in
        the outlier test and in the covariance: a defocused or distant view
        neither dilutes the sharp ones nor has its normal corners removed as
        outliers. ``"pooled"``: one noise level for every corner (Zhang 2000,
        OpenCV, mrcal).

    Returns
    -------
    IntrinsicCalibration
        Warnings: ``dropped`` (views skipped), ``outliers`` (corners removed,
        by view and corner id), ``weakly_determined`` (a distortion term
        whose std exceeds its magnitude, or two intrinsics correlated beyond
        :data:`CORRELATION_LIMIT`: the model has more terms than the data
        determine), and the solver's own (``rank_deficient``, ...).

    Raises
    ------
    NotEnoughDataError
        Fewer than :data:`MIN_VIEWS` usable views.
    InputError
        Unknown model or term, bad views.
    """
    from robocal.estimation import outlier_sigma as bonferroni

    if model not in INTRINSIC_MODELS:
        raise InputError(f"model must be one of {', '.join(INTRINSIC_MODELS)}, got {model!r}")
    if noise not in NOISE_MODELS:
        raise InputError(f"noise must be one of {', '.join(NOISE_MODELS)}, got {noise!r}")
    size = check_array(image_size, "image_size", shape=(2,))
    if not np.all(size >= 1) or not np.all(size == np.round(size)):
        raise InputError(f"image_size must be (width, height), integers >= 1 [px], got {size.tolist()}")
    width, height = (int(s) for s in size)
    fix = tuple(fix)
    labels = _model_labels(model)
    bad = [f for f in fix if f not in labels[4:]]
    if bad:
        raise InputError(f"fix: unknown distortion terms {bad}; the terms of model {model!r} are "
                         f"{', '.join(labels[4:])}")
    fixed = np.array([lab not in INTRINSIC_MODELS[model] or lab in fix for lab in labels])
    views = _check_views(views)
    for v in views:
        q = v.image_points
        # 1 px beyond the pixel edges: sub-pixel refinement may push a corner on the border slightly out
        out = (q[:, 0] < -1.5) | (q[:, 1] < -1.5) | (q[:, 0] > width + 0.5) | (q[:, 1] > height + 0.5)
        if np.any(out):
            raise InputError(f"view '{v.name}': corner(s) at {q[out][0].round(1).tolist()} px lie outside the "
                             f"{width} x {height} px image_size: an image of another size, or width and height "
                             "swapped (cv2's imageSize is (width, height))")
    warnings: list[Diagnostic] = []

    dropped = [v.name for v in views if len(v) < min_corners]
    used = [v for v in views if len(v) >= min_corners]

    def _need_views():
        if len(used) < MIN_VIEWS:
            raise NotEnoughDataError(f"{len(used)} usable views (with >= {min_corners} corners), at least "
                                     f"{MIN_VIEWS} are needed; skipped: {dropped}")

    _need_views()
    cv_rms, x0, poses0 = _opencv_start(used, (width, height), fixed, labels)
    n_corners = sum(len(v) for v in used)
    if max_outliers is None:
        max_outliers = int(0.05 * n_corners)
    thr_sigma = bonferroni(n_corners) if outlier_sigma is None else float(outlier_sigma)

    outliers: list[tuple[str, int]] = []
    n_intr = int(np.sum(~fixed))
    sig = None  # per-view noise [px] by view name (noise="per_view"), None: one pooled noise level

    def refit(sig):
        return _fit(used, res.params["intrinsics"], [res.params[f"pose:{v.name}"] for v in used], fixed, labels,
                    outlier_sigma=thr_sigma, sigmas=sig)

    prob, res = _fit(used, x0, poses0, fixed, labels, outlier_sigma=thr_sigma)
    while True:
        if noise == "per_view":
            # reweight until the views' noise levels settle (2-3 fits from a fitted start: each converges in a
            # few evaluations), so that the outlier test below judges a corner against its own view's noise
            for _ in range(REWEIGHT_ROUNDS):
                new = _view_noise(res, used, n_intr)
                if sig is None and len(set(new.values())) == 1:
                    sig = new  # one level for all views: the unweighted fit is already the fit with these weights
                    break
                settled = sig is not None and all(abs(new[k] / sig[k] - 1.0) < REWEIGHT_TOL for k in new)
                if settled:
                    break
                sig = new
                prob, res = refit(sig)
        if not res.outliers.size or len(outliers) >= max_outliers:
            break
        worst = int(res.outliers[np.argmax(res.observation_scores[res.outliers])])
        vname, k = res.locate_observation(worst)
        vi = next(i for i, v in enumerate(used) if v.name == vname)
        outliers.append((vname, int(used[vi].ids[k])))
        keep = np.ones(len(used[vi]), bool)
        keep[k] = False
        used[vi] = used[vi].subset(keep)
        if len(used[vi]) < min_corners:
            dropped.append(vname)
            del used[vi]
            _need_views()
        if sig is not None:
            sig = {v.name: sig[v.name] for v in used}
        prob, res = refit(sig)

    if dropped:
        warnings.append(Diagnostic("dropped", f"{len(dropped)} view(s) skipped with fewer than {min_corners} "
                                   f"usable corners: {', '.join(dropped)}", params=tuple(dropped)))
    if outliers:
        txt = ", ".join(f"{n}#{i}" for n, i in outliers)
        warnings.append(Diagnostic("outliers", f"{len(outliers)} corner(s) removed beyond {thr_sigma:.2f} sigma "
                                   f"(view#corner id): {txt}", params=tuple(sorted({n for n, _ in outliers}))))
    # the solver's own warnings, less its outlier list: what was left is below max_outliers' budget or named above
    warnings += [w for w in res.warnings if w.code != "outliers"]
    if res.outliers.size:
        names = [f"{res.locate_observation(int(i))[0]}#{i}" for i in res.outliers[:8]]
        warnings.append(Diagnostic("outliers", f"{res.outliers.size} corner(s) still beyond {thr_sigma:.2f} sigma "
                                   f"after removing max_outliers = {max_outliers}: {names}",
                                   indices=tuple(int(i) for i in res.outliers)))

    intr = np.asarray(res.params["intrinsics"], dtype=float)
    free = tuple(lab for lab, f in zip(labels, fixed) if not f)
    idx = [res.free_labels.index(lab) for lab in free]
    cov = np.zeros((len(labels), len(labels)))
    sub = res.cov[np.ix_(idx, idx)]
    fi = [i for i, f in enumerate(fixed) if not f]
    cov[np.ix_(fi, fi)] = sub
    std = {lab: (0.0 if fixed[i] else res.std[lab]) for i, lab in enumerate(labels)}
    warnings += _overparameterisation(labels, free, intr, std, cov)

    if _is_fisheye(labels):
        from robocal.camera._fisheye import FisheyeCamera

        camera = FisheyeCamera(intr[0], intr[1], intr[2], intr[3], intr[4:], width, height)
    else:
        camera = CameraModel(intr[0], intr[1], intr[2], intr[3], intr[4:], width, height)
    poses, pose_std, residuals, view_rms = {}, {}, {}, {}
    for v in used:
        p = res.params[f"pose:{v.name}"]
        T = np.eye(4)
        T[:3, :3] = _rodrigues(p[:3])
        T[:3, 3] = p[3:]
        poses[v.name] = T
        pose_std[v.name] = res.block_std(f"pose:{v.name}")
        r = res.obs_residuals(v.name)
        residuals[v.name] = r
        view_rms[v.name] = float(np.sqrt(np.mean(r ** 2)))
    all_r = np.concatenate([r.ravel() for r in residuals.values()])
    sigma_px = float(np.sqrt(np.sum(all_r ** 2) / res.dof)) if res.dof > 0 else float("nan")
    return IntrinsicCalibration(
        camera=camera, model=model, labels=labels, values=intr, cov=cov, std=std, free=free, poses=poses,
        pose_std=pose_std, views=used, residuals=residuals, view_rms=view_rms,
        rms=float(np.sqrt(np.mean(all_r ** 2))), sigma_px=sigma_px, opencv_rms=cv_rms, outliers=outliers,
        dropped=dropped, warnings=warnings, lsq=res,
        view_sigma=dict(sig) if sig is not None else {n: sigma_px for n in poses})


def _overparameterisation(labels, free, values, std, cov) -> list:
    out = []
    weak = [lab for lab in free if lab in _DIST_LABELS and std[lab] is not None
            and std[lab] > abs(values[labels.index(lab)])]
    if weak:
        txt = ", ".join(f"{lab} = {values[labels.index(lab)]:.3g} +- {std[lab]:.2g}" for lab in weak)
        out.append(Diagnostic("weakly_determined", f"distortion term(s) with std above their magnitude: {txt}; "
                              "the data do not determine them: fix them (fix=...) or use a smaller model",
                              params=tuple(weak)))
    d = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(d, d)
    pairs = []
    for a in range(len(labels)):
        for b in range(a + 1, len(labels)):
            if labels[a] in free and labels[b] in free and abs(corr[a, b]) > CORRELATION_LIMIT:
                pairs.append((labels[a], labels[b], float(corr[a, b])))
    if pairs:
        txt = ", ".join(f"{a}/{b} {c:+.4f}" for a, b, c in pairs)
        out.append(Diagnostic("weakly_determined", f"intrinsics correlated beyond {CORRELATION_LIMIT}: {txt}; the "
                              "views do not separate them (tilt the board more, fill the corners of the image) "
                              "or the model has more terms than the data determine",
                              params=tuple(sorted({x for a, b, _ in pairs for x in (a, b)}))))
    return out


# the maps drawn from a calibration and the simulated views, in their own module (re-exported here)
from robocal.camera._calibration_maps import (ProjectionUncertainty, coverage, projection_uncertainty,  # noqa: E402
                                              simulate_target_views)
