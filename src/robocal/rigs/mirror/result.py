"""The result record of a mirror calibration (schema ``robocal.result/2``, ``docs/results.md``).

:func:`result_from_calibration` packs a :class:`~robocal.rigs.mirror.calibrate.MirrorCalibration`:

* the answer, ``T_r_c`` (``robot -> camera``: the camera pose in the robot
  frame), written by :meth:`~robocal.io.CalibrationResult.add_pose` with its
  std; the rotation std is that of a *left* (robot-side) perturbation
  ``R_r_c = Exp(d) R_hat``, the side the covariance of the joint problem uses
  (:mod:`robocal.rigs.mirror.joint`);
* the mirror poses ``T_c_m_k``, one per placement, are nuisance parameters
  (the mirror is put down anywhere for each image): kept in
  ``diagnostics.mirror_poses`` with their std, not in ``estimate``;
* in ``diagnostics`` everything the report is drawn from (camera, rectangle,
  body model, image points, per-image patent estimates and planar choices,
  the solver record, the truth check of a simulated input), so that
  ``robocal report result.json`` rebuilds the page without any other file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from robocal.geometry import PoseWithCovariance
from robocal.io import CalibrationResult

__all__ = ["result_from_calibration", "relative_image_paths", "pose_error", "solver_record", "upgraded",
           "UNOBSERVABLE", "TRUTH_NAMES", "SOLVER_FIELDS"]

#: What no check can see; in every result (``diagnostics.unobservable``) and report.
UNOBSERVABLE = ("What no check can see: t_r_c is measured from the origin of the body model (body_points or "
                "body_tags), so an offset of the model by any vector (x, y or z alike) moves t_r_c by that vector "
                "with identical residuals and warnings; a unit error shared by mirror_rectangle and body_points "
                "scales the answer by the same factor; and for (nearly) coplanar body points a model of the wrong "
                "handedness (x sign) fits too (points on one face x = c: the answer moves by 2c along x). "
                "See docs/rigs/mirror.md, 'What the images cannot tell'.")

#: Names of the six pose parameters in ``diagnostics.truth_check.z`` (order of ``diagnostics.cov_rot_t``).
TRUTH_NAMES = ("T_r_c rotvec x", "T_r_c rotvec y", "T_r_c rotvec z",
               "T_r_c translation x", "T_r_c translation y", "T_r_c translation z")

#: The fields of :meth:`robocal.estimation.LSQResult.to_dict` kept in ``diagnostics.solver`` (:func:`solver_record`): what
#: :func:`robocal.report.solver_section` shows (the covariance and residuals of all 6 + 6K parameters
#: would make the file grow with the square of the placements).
SOLVER_FIELDS = ("method", "loss", "status", "message", "success", "iterations", "nfev", "cost", "cost_history",
                 "rms", "rank", "free_labels", "condition_number", "outlier_sigma", "absolute_sigma")


def pose_error(T_est, T_true) -> np.ndarray:
    """``[rotvec(R_est R_true^T) [rad], t_est - t_true [m]]`` (6,): the error on the covariance's (left) side."""
    return PoseWithCovariance(np.asarray(T_est, dtype=float).reshape(4, 4)).error_to(
        np.asarray(T_true, dtype=float).reshape(4, 4)).vector


def relative_image_paths(image_paths: dict, base_dir) -> dict:
    """``{name: path}`` with each path relative to ``base_dir`` (the folder of result.json).

    Relative paths keep a run portable: moving the output folder together with
    the inputs keeps the report's images. Paths that cannot be made relative
    (another drive) stay absolute.
    """
    out = {}
    for name, p in (image_paths or {}).items():
        try:
            out[name] = os.path.relpath(Path(p).resolve(), Path(base_dir).resolve())
        except ValueError:
            out[name] = str(Path(p).resolve())
    return out


def _plain(v):
    """JSON value as :meth:`robocal.estimation.LSQResult.to_dict` writes it (NaN -> None, inf -> "inf")."""
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return None if np.isnan(v) else ("inf" if v == np.inf else "-inf" if v == -np.inf else v)
    return v


def solver_record(lsq) -> dict:
    """The fields ``SOLVER_FIELDS`` of an :class:`~robocal.estimation.LSQResult`, JSON-ready."""
    return {k: _plain(getattr(lsq, k)) for k in SOLVER_FIELDS}


def _single_record(s, name: str) -> dict:
    return {
        "name": name,
        "T_r_c": s.T_r_c.tolist(),
        "T_c_m": s.T_c_m.tolist(),
        "T_c_ri": s.steps.T_c_ri.tolist(),
        "T_m_ri": s.steps.T_m_ri.tolist(),
        "T_om_r": s.steps.T_om_r.tolist(),
        "T_m_r": s.steps.T_m_r.tolist(),
        "householder_minus_patent": float(np.abs(s.T_c_r_householder - s.steps.T_c_r).max()),
        "planar_choice": s.choice.to_dict(),
        # per coordinate (u and v), as residual_rms
        "marker_rms_px": float(np.sqrt(np.mean(s.marker_residuals**2))),
        "body_rms_px": float(np.sqrt(np.mean(s.body_residuals**2))),
    }


def _mirror_poses(cal) -> list[dict]:
    out = []
    for k, (o, T) in enumerate(zip(cal.observations, cal.T_c_m)):
        std = None if cal.mirror_std is None else np.asarray(cal.mirror_std[k], dtype=float)
        out.append({"image": o.name, "T_c_m": np.asarray(T).tolist(),
                    "std_rotvec": None if std is None else std[:3].tolist(),
                    "std_translation": None if std is None else std[3:].tolist()})
    return out


def result_from_calibration(cal, *, inputs=None, image_paths=None, truth=None, sigma_px=None) -> CalibrationResult:
    """The shared result record of a :class:`~robocal.rigs.mirror.calibrate.MirrorCalibration` (SI units).

    ``image_paths``: ``{image name: file}`` relative to the folder the result
    is written to (:func:`relative_image_paths`); ``truth``: the simulated
    ``T_r_c`` (4, 4), checked by NEES against the reported covariance
    (:func:`robocal.estimation.truth_check`, ``diagnostics.truth_check``);
    ``sigma_px``: the pixel noise the input declared (None: estimated).
    """
    from robocal.estimation import truth_check

    m_res, b_res = cal.residuals()
    allres = np.concatenate([m_res.reshape(-1, 2), *b_res])
    diag = {
        "camera": cal.camera.to_dict(),
        "rectangle": {"width": cal.rectangle.width, "height": cal.rectangle.height},
        "body_points_r": cal.body_points_r.tolist(),
        "observations": [o.to_dict() for o in cal.observations],
        "images": dict(image_paths or {}),  # name -> image file, relative to the folder of result.json
        "single_image": [_single_record(s, o.name) for s, o in zip(cal.singles, cal.observations)],
        # covariance of (rotvec [rad], left perturbation; translation [m]) of T_r_c
        "cov_rot_t": cal.cov.tolist(),
        "mirror_poses": _mirror_poses(cal),
        "n_images": len(cal.observations),
        "sigma_px": None if sigma_px is None else float(sigma_px),
        "unobservable": UNOBSERVABLE,
    }
    if cal.lsq is not None:
        diag["solver"] = solver_record(cal.lsq)
    if truth is not None:
        truth = np.asarray(truth, dtype=float)
        diag["truth_T_r_c"] = truth.tolist()
        diag["truth_check"] = truth_check(pose_error(cal.T_r_c, truth), cal.cov, names=TRUTH_NAMES).to_dict()
    result = CalibrationResult(
        rig="mirror",
        method="patent single-image (seed 002) + joint refinement" if cal.lsq is not None else "patent single-image",
        estimate={}, residual_rms=float(np.sqrt(np.mean(allres**2))), residual_unit="px",
        warnings=list(cal.warnings), inputs=dict(inputs or {}), diagnostics=diag,
    )
    result.add_pose("T_r_c", cal.T_r_c, std_rotation=cal.std_rotation, std_translation=cal.std_translation,
                    parent="robot", child="camera", rotation_std="left")
    return result


def upgraded(result: CalibrationResult) -> CalibrationResult:
    """A mirror result written before schema 2 in this module's vocabulary (others unchanged).

    Those files had ``estimate.T_r_c`` (4x4), ``t_r_c``, ``q_r_c``,
    ``rotvec_r_c`` and ``T_c_m`` (K x 4 x 4), with std under ``t_r_c`` and
    ``rotvec_r_c`` (the same left-perturbation std): the report of an old run
    can still be rebuilt. The mirror poses then have no std.
    """
    import copy

    est = result.estimate or {}
    if "T_r_c.rotation" in est or np.shape(est.get("T_r_c")) != (4, 4):
        return result
    new = copy.deepcopy(result)
    new.estimate = {k: v for k, v in est.items() if k not in ("T_r_c", "t_r_c", "q_r_c", "rotvec_r_c", "T_c_m")}
    for k in ("T_r_c", "t_r_c", "q_r_c", "rotvec_r_c", "T_c_m"):
        new.units.pop(k, None)
    std_r, std_t = new.std.pop("rotvec_r_c", None), new.std.pop("t_r_c", None)
    new.add_pose("T_r_c", np.asarray(est["T_r_c"], dtype=float), std_rotation=std_r, std_translation=std_t,
                 parent="robot", child="camera", rotation_std="left")
    names = [o.get("name", f"image {k}") for k, o in enumerate(new.diagnostics.get("observations") or [])]
    stack = np.asarray(est.get("T_c_m", []), dtype=float).reshape(-1, 4, 4)
    new.diagnostics.setdefault("mirror_poses", [
        {"image": names[k] if k < len(names) else f"image {k}", "T_c_m": T.tolist(), "std_rotvec": None,
         "std_translation": None} for k, T in enumerate(stack)])
    return new
