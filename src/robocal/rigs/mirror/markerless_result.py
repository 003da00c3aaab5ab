"""Result record and report of a markerless calibration (:mod:`robocal.rigs.mirror.markerless`, issue 14).

:func:`result_from_markerless` packs a
:class:`~robocal.rigs.mirror.markerless.MarkerlessCalibration` in the rig's
vocabulary: the answer ``T_r_c`` (``robot -> camera``) by
:meth:`~robocal.io.CalibrationResult.add_pose` with its std (left,
robot-side rotation std, as the marker path), the mirror planes (nuisance
parameters) in ``diagnostics.mirror_planes``, the closed form's answer, the
minima of the several starts, the conditioning in words, the solver record
and, for a simulated input, the truth check. :func:`build_markerless_report`
draws the page from that record alone (``diagnostics.markerless`` is true),
so ``robocal report`` rebuilds it.
"""

from __future__ import annotations

import numpy as np

from robocal.camera import CameraModel
from robocal.io import CalibrationResult
from robocal.report import Report, plot_residual_histogram, solver_section, truth_section

__all__ = ["result_from_markerless", "build_markerless_report", "METHOD", "UNOBSERVABLE_MARKERLESS"]

METHOD = "markerless: orthogonality-constraint closed form (Takahashi et al., CVPR 2012) + joint refinement"

#: What no check can see (``diagnostics.unobservable``).
UNOBSERVABLE_MARKERLESS = (
    "What no check can see: t_r_c is measured from the origin of the reference_points model, so an offset of the "
    "model by any vector moves t_r_c by that vector with identical residuals; a unit error of reference_points "
    "scales t_r_c and the mirror distances by the same factor (the images have no scale); a model of the wrong "
    "handedness (x sign) is the mirror image and fits as well whenever the mirror normals can absorb it.")


def _plane_rows(cal) -> list[dict]:
    rows = []
    for j, (o, n, d) in enumerate(zip(cal.observations, cal.normals, cal.distances)):
        std = None if cal.plane_std is None else cal.plane_std[j]
        rows.append({"name": o.name, "normal": np.asarray(n).tolist(), "d": float(d),
                     "std_normal_deg": None if std is None else float(np.degrees(std[0])),
                     "std_d": None if std is None else float(std[1]), "n_points": int(len(o.ids))})
    return rows


def result_from_markerless(cal, *, inputs=None, truth=None, sigma_px=None) -> CalibrationResult:
    """The shared result record of a markerless calibration (SI units; see the module docstring)."""
    from robocal.estimation import truth_check
    from robocal.rigs.mirror.result import TRUTH_NAMES, pose_error, solver_record

    res = np.concatenate(cal.residuals())
    diag = {
        "markerless": True,
        "camera": cal.camera.to_dict(),
        "reference_points_r": cal.points_r.tolist(),
        "observations": [o.to_dict() for o in cal.observations],
        "cov_rot_t": cal.cov.tolist(),
        "mirror_planes": _plane_rows(cal),
        "closed_form_T_r_c": np.asarray(cal.T_r_c_closed_form).tolist(),
        "minima": cal.minima,
        "n_combinations": int(cal.n_combinations),
        "conditioning": cal.conditioning,
        "dropped_poses": list(cal.dropped),
        "n_images": len(cal.observations),
        "sigma_px": None if sigma_px is None else float(sigma_px),
        "unobservable": UNOBSERVABLE_MARKERLESS,
    }
    mixed = getattr(cal, "marker_observations", None)
    if mixed:
        diag["mixed"] = True
        diag["start_label"] = "marker path (start)"
        diag["marker_poses"] = [{"image": o.name, "T_c_m": np.asarray(T).tolist()}
                                for o, T in zip(mixed, cal.T_c_m)]
        diag["marker_observations"] = [o.to_dict() for o in mixed]
    if cal.lsq is not None:
        diag["solver"] = solver_record(cal.lsq)
    if truth is not None:
        truth = np.asarray(truth, dtype=float)
        diag["truth_T_r_c"] = truth.tolist()
        diag["truth_check"] = truth_check(pose_error(cal.T_r_c, truth), cal.cov, names=TRUTH_NAMES).to_dict()
        diag["closed_form_error"] = pose_error(cal.T_r_c_closed_form, truth).tolist()
    method = METHOD if cal.lsq is not None else METHOD.split(" + ")[0]
    if mixed:
        method = (f"mixed: {len(mixed)} mirror pose(s) with markers (patent path) + {len(cal.observations)} "
                  f"markerless, one joint refinement")
    result = CalibrationResult(
        rig="mirror", method=method,
        estimate={}, residual_rms=float(cal.lsq.rms if mixed else np.sqrt(np.mean(res ** 2))), residual_unit="px",
        warnings=list(cal.warnings), inputs=dict(inputs or {}), diagnostics=diag)
    result.add_pose("T_r_c", cal.T_r_c, std_rotation=cal.std_rotation, std_translation=cal.std_translation,
                    parent="robot", child="camera", rotation_std="left")
    return result


def _error_row(name, e) -> dict:
    return {"estimate": name, "rotation error [deg]": float(np.degrees(np.linalg.norm(e[:3]))),
            "translation error [mm]": float(np.linalg.norm(e[3:]) * 1e3)}


def build_markerless_report(result: CalibrationResult, *, base_dir=None, title: str = "") -> Report:
    """HTML report of a markerless result (:func:`result_from_markerless`), from the record alone."""
    from robocal.rigs.mirror.markerless import MarkerlessObservation, markerless_residuals
    from robocal.rigs.mirror.result import pose_error

    d = result.diagnostics
    cam = CameraModel.from_dict(d["camera"])
    P = np.asarray(d["reference_points_r"], dtype=float)
    obs = [MarkerlessObservation(np.asarray(o["uv"], dtype=float), np.asarray(o["ids"], dtype=int), o["name"])
           for o in d["observations"]]
    T_r_c = result.pose("T_r_c").T
    rep = Report(title or "Mirror rig: markerless calibration (camera in the robot frame)",
                 subtitle=f"{len(obs)} mirror pose(s), {len(P)} reference point(s); method: {result.method}")
    s = rep.section("Camera in the robot frame (robot -> camera)")
    s.parameters(result.estimate, result.std, result.units)
    s.text("std: first-order (sampling) uncertainty; rotation std per axis of the rotation vector of a left "
           "(robot-side) perturbation (diagnostics.cov_rot_t).")
    cond = d.get("conditioning") or {}
    if cond.get("text"):
        s.text(f"Conditioning: {cond['text']}.")
    if "truth_T_r_c" in d:
        rows = [_error_row("refined", pose_error(T_r_c, d["truth_T_r_c"]))]
        if "closed_form_error" in d:
            rows.insert(0, _error_row(d.get("start_label", "closed form"), np.asarray(d["closed_form_error"])))
        s.table(rows, digits=4, caption="estimate - simulated truth")
        if "truth_check" in d:
            truth_section(s, d["truth_check"])
    s.text(f"Residual RMS {result.residual_rms:.3g} px over the reflections.")
    s.text(d.get("unobservable", UNOBSERVABLE_MARKERLESS))
    s.diagnostics(result.warnings)
    s2 = rep.section("Mirror planes and the minima of the several starts")
    s2.table([{"pose": r["name"], "normal (camera frame)": np.round(r["normal"], 4).tolist(),
               "d [mm]": r["d"] * 1e3, "normal std [deg]": r["std_normal_deg"],
               "d std [mm]": None if r["std_d"] is None else r["std_d"] * 1e3, "points": r["n_points"]}
              for r in d["mirror_planes"]], digits=4,
             caption="plane n . x = d in the camera frame (n away from the camera): nuisance parameters")
    minima = d.get("minima") or []
    if minima:
        s2.table([{"minimum": k, "cost": m["cost"], "chi-square above best": m.get("delta_chi2"),
                   "rms [px]": m["rms_px"], "starts": m["starts"],
                   "camera from points [m]": m.get("camera_distance_m"),
                   "plausible": "yes" if m.get("plausible", True) else "NO (camera off the robot)",
                   "rotation from best [deg]": m["rotation_from_best_deg"],
                   "translation from best [mm]": m["translation_from_best_mm"]} for k, m in enumerate(minima)],
                 digits=4, caption=f"distinct minima reached from the best closed-form starts "
                                   f"({d.get('n_combinations', 1)} PnP combination(s) scored); a minimum less than 9 "
                                   f"chi-square units above the best is not rejected by the data (warning)")
    if d.get("marker_poses"):
        s2.table([{"image": m["image"], "t_c_m [mm]": np.round(np.asarray(m["T_c_m"])[:3, 3] * 1e3, 1).tolist()}
                  for m in d["marker_poses"]], digits=4,
                 caption="mirror poses with markers (patent path), camera -> mirror, in the same joint problem")
    s3 = rep.section("Residuals and solver")
    r = np.concatenate(markerless_residuals(cam, P, obs, T_r_c, np.asarray([p["normal"] for p in d["mirror_planes"]]),
                                            np.asarray([p["d"] for p in d["mirror_planes"]])))
    sigma = d.get("sigma_px")
    ax = plot_residual_histogram(r.ravel(), unit="px", sigma=result.residual_rms if sigma is None else sigma)
    s3.figure(ax.figure, caption="reprojection residuals of the reflections (u and v), projected - observed")
    if d.get("solver"):
        solver_section(s3, d["solver"], caption="the joint least squares over T_r_c and every mirror plane")
    else:
        s3.text("No refinement (--no-refine): the closed form's answer.")
    return rep
