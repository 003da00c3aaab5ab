"""Mirror poses with markers (the patent's path, :mod:`.joint`) and without (:mod:`.markerless`) in one problem.

Split from :mod:`robocal.rigs.mirror.markerless` (issue 14's "mixed data"):
the marker poses' residuals of the joint model and the markerless reflections
share ``T_r_c``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.camera import CameraModel
from robocal.errors import NotEnoughDataError
from robocal.estimation import LSQResult, solve
from robocal.rigs.mirror.markerless import (MIN_POINTS, _MarkerlessAnswer, _problem, _reflection_defect,
                                            calibrate_markerless, conditioning, virtual_pose_candidates)
from robocal.rigs.mirror.model import F_X
from robocal.validation import check_array

__all__ = ["MixedCalibration", "calibrate_mixed"]


@dataclass
class MixedCalibration(_MarkerlessAnswer):
    """Result of :func:`calibrate_mixed`: ``T_r_c`` (4, 4) [m] and its ``cov`` (6, 6) (rotvec left [rad], t [m]),
    the marker poses ``T_c_m`` (K_m, 4, 4), the markerless planes ``normals`` (K_n, 3) / ``distances`` (K_n,),
    the solver's ``lsq``, ``conditioning`` (:func:`conditioning`) and ``warnings``."""

    T_r_c: np.ndarray
    cov: np.ndarray
    T_c_m: np.ndarray
    normals: np.ndarray
    distances: np.ndarray
    lsq: LSQResult
    conditioning: dict
    warnings: list
    observations: list = field(default_factory=list)  # the markerless poses
    marker_observations: list = field(default_factory=list)
    points_r: np.ndarray | None = None
    camera: CameraModel | None = None
    #: the start: the marker path's estimate (or the markerless closed form without marker poses)
    T_r_c_closed_form: np.ndarray | None = None
    plane_std: np.ndarray | None = None
    minima: list = field(default_factory=list)
    n_combinations: int = 1
    dropped: list = field(default_factory=list)


def _plane_given_pose(T_c_ri_candidates, T_r_c) -> tuple[np.ndarray, float]:
    """The plane ``(n, d)`` that makes one of a pose's virtual poses consistent with ``T_r_c`` (the candidate
    whose ``R_cri F R_cr^T`` is closest to a reflection)."""
    R_cr = T_r_c[:3, :3].T
    t_cr = -R_cr @ T_r_c[:3, 3]
    T = min(T_c_ri_candidates, key=lambda c: _reflection_defect(c[:3, :3], R_cr))
    M = T[:3, :3] @ F_X @ R_cr.T
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    n = V[:, 0]  # H = I - 2 n n^T: eigenvalue -1 along n
    d = 0.5 * float(n @ (T[:3, 3] - (np.eye(3) - 2.0 * np.outer(n, n)) @ t_cr))
    return (n, d) if d > 0 else (-n, -d)


def calibrate_mixed(camera: CameraModel, rectangle, points_r, marker_observations, markerless_observations, *,
                    sigma_px: float | None = None, accept_implausible: bool = False) -> MixedCalibration:
    """Mirror poses with markers (the patent's, :mod:`.joint`) and without (this module) in one joint problem.

    ``points_r`` (N, 3) [m] are both the marker path's body points and the
    markerless reference points (``MirrorObservation.body_ids`` and
    ``MarkerlessObservation.ids`` index them). Unknowns: ``T_r_c``, each
    marker pose ``T_c_m`` (6 parameters, :func:`~robocal.rigs.mirror.joint.residual_model`'s
    residuals on markers and reflections) and each markerless plane (3
    parameters, this module's residuals); the blocks ``rot_rc``, ``t_rc`` are
    shared. Start: the marker path's estimate (:func:`~robocal.rigs.mirror.calibrate.calibrate`)
    when there are marker poses, each markerless plane then from its
    virtual pose given that ``T_r_c``; else :func:`calibrate_markerless`.
    """
    from robocal.rigs.mirror.calibrate import calibrate
    from robocal.rigs.mirror.joint import _labels, _layout, residual_model

    P = check_array(points_r, "body_points")
    mk, ml = list(marker_observations), list(markerless_observations)
    if not mk:
        c = calibrate_markerless(camera, P, ml, sigma_px=sigma_px, accept_implausible=accept_implausible)
        T0, n0, d0, T_c_m0, warnings = c.T_r_c, c.normals, c.distances, np.zeros((0, 4, 4)), list(c.warnings)
    else:
        c = calibrate(camera, rectangle, P, mk, sigma_px=sigma_px, accept_implausible=accept_implausible)
        T0, T_c_m0, warnings = c.T_r_c, c.T_c_m, list(c.warnings)
        planes = []
        for o in ml:
            if len(o.ids) < MIN_POINTS:
                raise NotEnoughDataError(f"{o.name}: needs >= {MIN_POINTS} points, got {len(o.ids)}")
            planes.append(_plane_given_pose(virtual_pose_candidates(camera, P, o), T0))
        n0 = np.array([p[0] for p in planes]).reshape(-1, 3)
        d0 = np.array([p[1] for p in planes])
    if not ml:
        raise NotEnoughDataError("markerless_observations: none given; use robocal.rigs.mirror.calibrate")
    prob, answer, _ = _problem(camera, P, ml, T0, n0, d0, sigma_px)
    sig = None if sigma_px is None else float(sigma_px)
    if mk:
        layout = _layout(mk, P, rectangle)
        markers, body, mjac, bjac, poses = residual_model(camera, rectangle, layout, T0[:3, :3], T_c_m0[:, :3, :3])
        lab = _labels(layout.K)
        prob.add_block("rot_cm", np.zeros((layout.K, 3)), labels=lab["rot_cm"], unit="rad", scale=1e-3)
        prob.add_block("t_cm", T_c_m0[:, :3, 3], labels=lab["t_cm"], unit="m", scale=1e-3)
        # the joint model's rot_rc / t_rc are this problem's (same left perturbation of the same R_rc0)
        prob.add_residuals(markers, name="markers", jacobian=mjac, residual_dim=2, sigma=sig)
        prob.add_residuals(body, name="body", jacobian=bjac, residual_dim=2, sigma=sig)
    res = solve(prob, method="lm", absolute_sigma=sigma_px is not None)
    T, n, d = answer(res.params)
    n, d = n * np.sign(d)[:, None], np.abs(d)
    T_c_m = poses(res.params)[1] if mk else np.zeros((0, 4, 4))
    cov = res.cov[:6, :6]
    warnings.extend(res.warnings)
    return MixedCalibration(T, cov, T_c_m, n, d, res, conditioning(cov, T, res), warnings, ml, mk, P, camera, T0)
