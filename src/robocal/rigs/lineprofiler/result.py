"""A line-profiler calibration as a result file: the pose vocabulary plus what its report draws.

``T_E_L`` (laser frame L -> end effector E, the hand-eye X) is written with
:meth:`robocal.io.CalibrationResult.add_pose` (std of the rotation as a left
rotation vector, rad: the convention of :func:`.refine.refine_sphere` and
:func:`.mct.mct_covariance`); a translation component the poses do not
determine is ``null`` (value and std), never a silent 0. The report
(:func:`robocal.rigs.lineprofiler.report.build_report`) is rebuilt from the
result alone, so ``diagnostics`` holds what it draws, binned where the data
are large (a residual histogram, not 10^6 residuals).
"""

from __future__ import annotations

import numpy as np

from robocal.io import CalibrationResult

__all__ = ["result_from", "histogram", "solver_record"]

#: The fields of :meth:`robocal.estimation.LSQResult.to_dict` the report's solver section shows
#: (the full record holds every residual and the covariance: 0.7 MB for the example's 7351 points).
SOLVER_FIELDS = ("method", "loss", "message", "status", "iterations", "nfev", "cost_history", "cost", "rms",
                 "rank", "free_labels", "condition_number", "outlier_sigma")
#: Bins of the residual histograms kept in a result
HIST_BINS = 60

_FRAMES = {"parent": "end effector E", "child": "laser L"}


def solver_record(lsq) -> dict:
    """The solver's record for :func:`robocal.report.solver_section`: :data:`SOLVER_FIELDS` of ``lsq.to_dict()``."""
    if lsq is None:
        return {}
    d = lsq.to_dict()
    return {k: d[k] for k in SOLVER_FIELDS if k in d}


def histogram(values, *, bins: int = HIST_BINS) -> dict:
    """``{"edges", "counts", "n"}`` of the finite ``values`` (same unit as the values)."""
    v = np.asarray(values, float).reshape(-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"edges": [], "counts": [], "n": 0}
    counts, edges = np.histogram(v, bins=bins)
    return {"edges": edges.tolist(), "counts": counts.tolist(), "n": int(v.size)}


def _finite_or_none(v):
    return [float(x) if np.isfinite(x) else None for x in np.asarray(v, float).ravel()]


def _blank(values, undetermined, labels):
    """``values`` with None where the label is undetermined (a value the data do not fix)."""
    return [None if lab in undetermined else float(v) for v, lab in zip(values, labels)]


def result_from(cal, inputs=None) -> CalibrationResult:
    """The :class:`~robocal.io.CalibrationResult` of a :class:`~.calibrate.SphereCalibration` or
    :class:`~.calibrate.MCTCalibration` (``inputs``: content hashes of the files read)."""
    from robocal.rigs.lineprofiler.calibrate import MCTCalibration

    if isinstance(cal, MCTCalibration):
        return _mct_result(cal, inputs)
    f, g = cal.fpdp, cal.refined
    und = set(g.undetermined)
    tlab = ("X.tx", "X.ty", "X.tz")
    res = CalibrationResult(rig="lineprofiler", method="fpdp+geometric", estimate={}, std={}, units={},
                            residual_rms=g.rms, residual_unit="m",
                            warnings=list(f.warnings) + list(g.warnings), inputs=inputs or {})
    res.add_pose("T_E_L", g.X, std_rotation=[g.std[f"X.r{c}"] for c in "xyz"],
                 std_translation=[g.std[k] for k in tlab], **_FRAMES)
    res.estimate["T_E_L.translation"] = _blank(g.X[:3, 3], und, tlab)
    res.estimate["sphere_centre"] = _blank(g.Q, und, ("Q.x", "Q.y", "Q.z"))
    res.std["sphere_centre"] = [g.std[f"Q.{c}"] for c in "xyz"]
    res.units["sphere_centre"] = "m"
    # FPDP's linear estimate, the refinement's start: no std of its own
    res.add_pose("fpdp.T_E_L", f.X, **_FRAMES)
    res.estimate["fpdp.T_E_L.translation"] = _blank(f.X[:3, 3], und, tlab)
    res.diagnostics = {
        "frames": "T_E_L: laser frame L -> end-effector frame E (hand-eye X); fpdp.T_E_L: FPDP's linear "
                  "estimate (seed eqs. 3-4), the refinement's start",
        "undetermined": sorted(und), "fpdp_rank": f.rank, "fpdp_unknowns": f.n_unknowns,
        "fpdp_rms_m": f.rms, "n_profiles_used": int(len(f.used)), "n_points": g.n_points,
        "noise_sigma_m": g.sigma, "signs": f.signs.tolist(),
        "joint_noise_modelled": g.dq is not None,
        **({"joint_corrections": g.dq.tolist(),
            "joint_corrections_unit": "per joint: m (prismatic) or rad (revolute), per used profile"}
           if g.dq is not None else {}),
        "residual_histogram_m": histogram(g.residuals),
        "per_profile_rms_m": np.asarray(g.per_profile_rms, float).tolist(),
        "circle_cuts": [{"profile": int(c.index), "x_c_m": float(c.centre[0]), "z_c_m": float(c.centre[1]),
                         "r_c_m": float(c.radius), "side": int(sg), "points": int(c.n_points)}
                        for c, sg in zip(f.cuts, f.signs)],
        "solver": solver_record(g.lsq),
    }
    return res


def _mct_result(cal, inputs=None) -> CalibrationResult:
    from robocal.rigs.lineprofiler.mct import _X_LABELS

    r = cal.mct
    undetermined = [lab for lab, v in zip(_X_LABELS, r.X_std) if not np.isfinite(v)]
    terms = {k: {"T_E_L.rotvec": _finite_or_none(v[:3]), "T_E_L.translation": _finite_or_none(v[3:])}
             for k, v in r.cov_terms.items()}
    res = CalibrationResult(rig="lineprofiler", method="mct", estimate={}, std={}, units={},
                            residual_rms=r.scan_rms, residual_unit="m", warnings=list(r.warnings),
                            inputs=inputs or {})
    res.add_pose("T_E_L", r.X, std_rotation=_finite_or_none(r.X_std[:3]),
                 std_translation=_finite_or_none(r.X_std[3:]), **_FRAMES)
    # the intermediate frames of seed eqs. 6-12, at the scan's reference pose: derived, no std of their own
    for name, T, parent, child in (("T_T_L", r.T_T_L, "laser tracker T", "laser L"),
                                   ("T_T_E", r.T_T_E, "laser tracker T", "end effector E"),
                                   ("T_T_B", r.T_T_B, "laser tracker T", "block corner B"),
                                   ("T_L_B", r.T_L_B, "laser L", "block corner B")):
        res.add_pose(name, T, parent=parent, child=child)
    res.estimate["P3_direction_L"] = np.asarray(r.u_L, float).tolist()
    res.units["P3_direction_L"] = "1"
    diag = {
        "frames": "T_E_L: laser frame L -> end-effector frame E (hand-eye X); T: laser tracker; "
                  "B: block corner; all at the scan's reference pose",
        "undetermined": undetermined,
        "covariance": {"labels": list(_X_LABELS),
                       "rotation": "rotation vector of R_perturbed R^T (rad)",
                       "matrix": [_finite_or_none(row) for row in r.X_cov],
                       "std_by_source": terms},
        "tracker_sigma_m": r.tracker_sigma, "height_sigma_m": r.height_sigma,
        "arm_dh_sigma": {"length_m": r.dh_sigma[0], "angle_rad": r.dh_sigma[1]},
        "encoder_sigma_m": r.encoder_sigma,
        "fit_rms_m": {"arc": r.arc_rms, "line": r.line_rms, "block_faces": r.block_rms,
                      "block_scan": r.scan_rms},
        "n_scan_points": r.n_scan_points,
    }
    if r.scan_residuals is not None:
        radius = np.linalg.norm(np.asarray(cal.data.arc_T) - r.O_A, axis=1)
        diag["scan_residual_histogram_m"] = histogram(r.scan_residuals)
        diag["arc"] = {"R2_rad": np.asarray(cal.data.q_arc, float)[:, -2].tolist(),
                       "radius_deviation_m": (radius - radius.mean()).tolist()}
    res.diagnostics = diag
    return res
