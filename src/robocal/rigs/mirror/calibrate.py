"""Camera-to-robot calibration from images of a plane mirror (seed 002): the API.

Two estimators:

* :func:`calibrate_single` (:mod:`.single`) — the patent's method on one
  image: planar PnP of the four mirror markers (both IPPE solutions, one
  chosen with the body points, see :func:`choose_planar_solution`), PnP of
  the reflected body points with the x-flipped object set, and the
  composition of :func:`~robocal.rigs.mirror.model.patent_compose` (eqs.
  [1]-[7]).
* :func:`calibrate` — beyond the patent: one nonlinear least-squares problem
  (:mod:`.joint`) over ``T_r_c`` and every mirror pose ``T_c_m_k`` of K images
  (mirror placements), on the reprojection error of the markers and of the
  reflected body points, started from the single-image estimates; covariance
  from the estimation layer; the images' agreement checked by
  :mod:`.consistency`.

For one image the joint problem splits into the two PnPs (``T_c_ri`` is a
re-parametrisation of ``T_c_r`` for a fixed mirror), so both estimators agree
and the joint problem's covariance is the first-order covariance of the
patent's estimate.

Parametrisation (all results): ``T_r_c`` (camera in the robot frame; the
patent's ``(R_rc, T_rc)``); rotation uncertainty is that of the rotation
vector ``delta`` in ``R_rc = exp(delta) R_rc_ref`` (left, robot-side
perturbation, as ``docs/conventions.md``), in radians; translation in metres.
The mirror poses ``T_c_m_k`` likewise, with ``R_cm = exp(delta) R_cm_ref``
(left, camera side).

The observation types (:mod:`.observation`), the single-image method
(:mod:`.single`), the joint problem (:mod:`.joint`) and the consistency checks
(:mod:`.consistency`) are re-exported here, where tests, benchmarks and the
docs import them from.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle
from robocal.errors import NotEnoughDataError, ShapeError
from robocal.estimation import LSQResult, solve
from robocal.geometry import invert_transform, matrix_from_rotvec, rotvec_from_matrix
from robocal.rigs.mirror.checks import (
    camera_warnings,
    check_camera,
    handedness_warnings,
    marker_fit_warnings,
    rectangle_warnings,
)
from robocal.rigs.mirror.consistency import _consensus_choice, _consistency_warnings, _name_outliers
from robocal.rigs.mirror.model import PoseCovarianceStd
from robocal.rigs.mirror.joint import (  # noqa: F401  (re-exported)
    _checked_body_cov,
    _labels,
    _layout,
    _Layout,
    _problem,
    _two_component_covariance,
    predicted_covariance,
    residual_model,
)
from robocal.rigs.mirror.observation import (  # noqa: F401  (re-exported)
    OUTSIDE_IMAGE_FRACTION,
    OUTSIDE_IMAGE_MIN_PX,
    MirrorObservation,
    check_in_image,
    check_observation,
)
from robocal.rigs.mirror.single import (  # noqa: F401  (re-exported)
    BODY_EXTENT_RANGE_M,
    CAMERA_BODY_MAX_M,
    CHI2_P_MIN,
    FLAT_RATIO,
    MIN_GOOD_POINTS,
    PARALLEL_DEG,
    PlanarChoice,
    SingleImageResult,
    _single_warnings,
    calibrate_single,
    choose_planar_solution,
    geometry_warnings,
    plausibility_warnings,
)
from robocal.validation import check_array

__all__ = [
    "MirrorObservation",
    "PlanarChoice",
    "SingleImageResult",
    "MirrorCalibration",
    "check_observation",
    "check_camera",
    "check_in_image",
    "camera_warnings",
    "choose_planar_solution",
    "calibrate_single",
    "calibrate",
    "geometry_warnings",
    "plausibility_warnings",
    "handedness_warnings",
    "marker_fit_warnings",
    "rectangle_warnings",
    "residual_model",
    "predicted_covariance",
]


@dataclass
class MirrorCalibration(PoseCovarianceStd):
    """Result of :func:`calibrate` (K images, joint refinement).

    Attributes
    ----------
    T_r_c : ndarray, shape (4, 4)
        Camera pose in the robot frame (the answer; ``robot -> camera``).
    T_c_m : ndarray, shape (K, 4, 4)
        Mirror (marker) pose in each image.
    cov : ndarray, shape (6, 6)
        Covariance of ``(rot_rc [rad], t_rc [m])`` (rotation as a left perturbation).
    singles : list of SingleImageResult
        The patent's estimate from each image alone.
    lsq : LSQResult or None
        The joint problem's solution (None with ``refine=False``).
    warnings : list of Diagnostic
    noise_components : ndarray, shape (2,) or None
        With per-tag covariances (ArUco path) and sigma estimated: the two
        noise variances ``(s1^2, s2^2)`` [px^2] of the edge-fit part and of
        the independent-corner part (:func:`_two_component_covariance`;
        ``s2^2 = 0`` when they could not be separated).
    mirror_std : ndarray, shape (K, 6) or None
        Standard deviations of each mirror pose ``(rot_cm [rad], t_cm [m])``
        from the joint covariance (rotation as a left, camera-side
        perturbation); None without the joint refinement. The mirror poses
        are nuisance parameters (one per placement).
    """

    T_r_c: np.ndarray
    T_c_m: np.ndarray
    cov: np.ndarray
    singles: list
    lsq: LSQResult | None
    warnings: list
    observations: list
    rectangle: MarkerRectangle
    body_points_r: np.ndarray
    camera: CameraModel
    noise_components: np.ndarray | None = None
    mirror_std: np.ndarray | None = None

    @property
    def T_c_r(self) -> np.ndarray:
        return invert_transform(self.T_r_c)

    def residuals(self):
        """``(marker (K, 4, 2), body list of (N_k, 2))`` reprojection residuals [px], projected - observed."""
        layout = _layout(self.observations, self.body_points_r, self.rectangle)
        markers, body, _, _, _ = residual_model(self.camera, self.rectangle, layout, self.T_r_c[:3, :3],
                                                self.T_c_m[:, :3, :3])
        p = {"rot_rc": np.zeros(3), "t_rc": self.T_r_c[:3, 3], "rot_cm": np.zeros((layout.K, 3)),
             "t_cm": self.T_c_m[:, :3, 3]}
        b = body(p)
        splits = np.cumsum([len(i) for i in layout.ids])[:-1]
        return markers(p).reshape(layout.K, 4, 2), np.split(b, splits)


def calibrate(camera: CameraModel, rectangle: MarkerRectangle, body_points_r, observations, *,
              sigma_px: float | None = None, refine: bool = True, progress: bool = False,
              accept_implausible: bool = False, declared: dict | None = None) -> MirrorCalibration:
    """Calibrate ``T_r_c`` from K >= 1 mirror images (joint refinement).

    Parameters
    ----------
    camera, rectangle, body_points_r
        As :func:`calibrate_single`.
    observations : sequence of MirrorObservation
        One per image / mirror placement; the camera must not move on the body
        between them.
    sigma_px : float, optional
        Pixel noise; when given the covariance uses it as the true noise,
        otherwise the residual variance scales it.
    refine : bool
        Run the joint least squares (else: average of the single-image
        estimates, with the covariance of that average, ``sum(C_k) / K^2``
        from each image's :func:`predicted_covariance` ``C_k``).
    accept_implausible : bool
        Body points or rectangle in an implausible unit, a camera estimated far from the body it is
        mounted on, or a mirrored body model (:mod:`robocal.rigs.mirror.slips`) are an
        :class:`~robocal.errors.ImplausibleInputError` naming the slip; with this, an
        ``implausible_input`` warning and the answer for the data as given (CLI ``--accept-implausible``).
    declared : dict, optional
        Units ``mirror_rectangle`` and ``body_points`` were written in
        (:func:`robocal.rigs.mirror.slips.declared_units`), to name a slip in the file's units.
    """
    obs_list = list(observations)
    if not obs_list:
        raise NotEnoughDataError("observations: need at least one image")
    names = [o.name for o in obs_list]
    if len(set(names)) != len(names):
        obs_list = [dataclasses.replace(o, name=f"{o.name} #{i}", warnings=list(o.warnings))
                    for i, o in enumerate(obs_list)]
    P_all = check_array(body_points_r, "body_points_r")
    if P_all.ndim != 2 or P_all.shape[1] != 3:
        raise ShapeError(f"body_points_r must have shape (N, 3), got {P_all.shape}")
    check_camera(camera)
    from robocal.rigs.mirror.slips import check_answer, check_body_span

    # before any PnP: a body model 1000x too small makes OpenCV's SQPnP fail with an assertion
    slip_warnings = check_body_span(P_all, declared=declared, accept=accept_implausible)
    singles = [calibrate_single(camera, rectangle, P_all, o, sigma_px=sigma_px) for o in obs_list]
    singles = _consensus_choice(singles, camera, rectangle, P_all, obs_list, sigma_px)
    if not slip_warnings:
        slip_warnings = check_answer(camera, rectangle, P_all, obs_list, singles, sigma_px=sigma_px,
                                     declared=declared, accept=accept_implausible)
    warnings = slip_warnings + camera_warnings(camera) + rectangle_warnings(rectangle)
    warnings += [w for o in obs_list for w in o.warnings]
    warnings += [w for s in singles for w in s.warnings]
    T_c_m0 = np.stack([s.T_c_m for s in singles])
    # start from the first image's estimate, rotation-averaged over the images
    T_r_c0 = singles[0].T_r_c.copy()
    if len(singles) > 1:
        dev = np.mean([rotvec_from_matrix(s.T_r_c[:3, :3] @ T_r_c0[:3, :3].T) for s in singles], axis=0)
        T_r_c0[:3, :3] = matrix_from_rotvec(dev) @ T_r_c0[:3, :3]
        T_r_c0[:3, 3] = np.mean([s.T_r_c[:3, 3] for s in singles], axis=0)
    layout = _layout(obs_list, P_all, rectangle)
    if not refine:
        # The answer is the mean of K independent single-image estimates, so its first-order
        # covariance is sum(C_k) / K^2 — not the joint ML covariance, which is up to ~2x smaller
        # in variance because the joint fit weights the images by their information.
        cov = np.zeros((6, 6))
        for s, o in zip(singles, obs_list):
            sig = sigma_px if sigma_px is not None else s.sigma_px
            cov += predicted_covariance(camera, rectangle, P_all, s.T_r_c, s.T_c_m, [o], sig)
        cov /= len(singles) ** 2
        return MirrorCalibration(T_r_c0, T_c_m0, cov, singles, None, warnings, obs_list, rectangle, P_all, camera)
    n_obs = 4 * layout.K + sum(len(i) for i in layout.ids)
    # The joint solve holds a dense Jacobian of 2 n_obs rows by 6 + 6K columns (each placement adds a
    # mirror pose): memory grows with K^2 and the solver's SVD time with K^3. About 8 copies of it
    # live at the peak (measured: 0.74 GB resident at K = 200 placements x 20 points).
    from robocal.resources import require_memory

    require_memory(8 * 8.0 * 2 * n_obs * (6 + 6 * layout.K),
                   f"the joint solve of {layout.K} mirror placements ({n_obs} points; dense, grows with the "
                   f"square of the placements)")
    prob, poses, whitened = _problem(camera, rectangle, layout, T_r_c0, T_c_m0, sigma_px)
    # outlier threshold: solve's default, Bonferroni over the n_obs observations (robocal.estimation.outlier_sigma)
    res = solve(prob, method="lm", absolute_sigma=sigma_px is not None, progress=progress)
    T_r_c, T_c_m = poses(res.params)
    full, components = res.cov, None
    if layout.correlated and sigma_px is None:
        full, components = _two_component_covariance(prob, whitened, res)
    cov = full[:6, :6]
    warnings.extend(_name_outliers(w, layout, obs_list) for w in res.warnings)
    if len(singles) > 1:
        warnings.extend(_consistency_warnings(camera, rectangle, P_all, singles, obs_list, T_r_c, sigma_px))
    return MirrorCalibration(T_r_c, T_c_m, cov, singles, res, warnings, obs_list, rectangle, P_all, camera,
                             components, _mirror_std(full, layout.K))


def _mirror_std(cov, K: int) -> np.ndarray:
    """``(K, 6)`` std of ``(rot_cm_k, t_cm_k)`` from the joint covariance (order of :func:`predicted_covariance`)."""
    var = np.diag(np.asarray(cov, dtype=float))
    rot = var[6:6 + 3 * K].reshape(K, 3)
    t = var[6 + 3 * K:6 + 6 * K].reshape(K, 3)
    return np.sqrt(np.concatenate([rot, t], axis=1))
