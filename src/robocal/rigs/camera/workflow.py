"""The camera rig's steps of the rig contract (:mod:`robocal.workflow`): library functions, no argparse.

``simulate_files`` -> :func:`robocal.rigs.camera.files.load_input` (images ->
target detections) -> ``calibrate_input`` (:func:`robocal.camera.calibrate_intrinsics`
+ the plausibility of the target's scale) -> ``to_result`` ->
:func:`robocal.rigs.camera.report.build_report`, ``write_outputs`` (the camera
as OpenCV, ROS and JSON files), ``summary`` and ``demo``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.io import CalibrationResult, hash_inputs
from robocal.workflow import DemoContext, DemoOutcome

__all__ = ["simulate_files", "calibrate_input", "to_result", "write_outputs", "summary", "demo", "CameraRun",
           "camera_from_result", "calibration_from_result", "check_target_scale", "CAMERA_FILES",
           "BOARD_SIZE_RANGE_M"]

#: The camera files ``calibrate`` writes beside ``result.json``: name -> format of :func:`robocal.camera.write_camera`.
CAMERA_FILES = {"camera.yaml": "opencv", "camera_info.yaml": "ros", "camera.json": "json"}
#: Plausible physical size (largest extent) of a calibration target [m]: from a 3 mm micro target to a 5 m
#: wall board. A board outside it with an otherwise good fit is a length in the wrong unit (the fit of a planar
#: target is blind to its scale: every distance scales with it, the pixels do not change).
BOARD_SIZE_RANGE_M = (3e-3, 5.0)


def simulate_files(out_dir, rng: np.random.Generator, *, progress: bool = False, **options) -> list[Path]:
    """The ``simulate`` step: :func:`robocal.rigs.camera.simulate.simulate_session`; returns the files written."""
    from robocal.rigs.camera.simulate import simulate_session

    s = simulate_session(out_dir, rng, progress=progress, **options)
    return [s.session, s.target_file, s.truth_file, Path(out_dir) / "images"]


@dataclass
class CameraRun:
    """What ``calibrate_input`` hands ``to_result``: the calibration, the input's rejections, the checks."""

    calibration: object
    base_dir: Path
    warnings: list = field(default_factory=list)


def _board_size(target) -> float:
    pts = target.object_points()
    return float(np.max(np.ptp(pts[:, :2], axis=0)))


def _declared_unit(target_file) -> str | None:
    """The length unit the target file declared for its sizes (``None``: plain numbers, read as m)."""
    if target_file is None:
        return None
    from robocal.io import load_document

    doc = load_document(target_file)
    for key in ("square", "marker"):
        raw = doc.data.get(key)
        if isinstance(raw, dict) and isinstance(raw.get("unit"), str):
            return raw["unit"]
        if raw is not None:
            return doc.units.get("length", "m")
    return None


def _length_text(x: float) -> str:
    return f"{x * 1e3:.3g} mm" if x < 1.0 else f"{x:.3g} m"


def check_target_scale(target, *, target_source: str, declared: str | None, accept: bool = False):
    """Judge the target's physical size; name the unit slip when it is implausible.

    The reprojection residual of a planar target does not depend on its scale
    (board and distances scale together), so no residual can tell a wrong
    unit: the figure judged is the board's size against
    :data:`BOARD_SIZE_RANGE_M`, and the slip named is the other length unit
    (:data:`robocal.plausibility.LENGTH_UNITS`) that brings it into the range
    (``square: {value: 25, unit: m}`` makes a 225 m board; read as mm it is
    0.225 m). Returns ``None``, or an ``implausible_input`` :class:`Diagnostic`
    with ``accept``; raises :class:`ImplausibleInputError` otherwise.
    """
    from robocal.errors import ImplausibleInputError
    from robocal.plausibility import IMPLAUSIBLE_CODE, LENGTH_UNITS

    lo, hi = BOARD_SIZE_RANGE_M
    size = _board_size(target)
    if lo <= size <= hi:
        return None
    key = "square" if target.kind != "aruco_grid" else "marker"
    declared = declared if declared in LENGTH_UNITS else "m"
    msg = (f"the {target.describe()} would be {_length_text(size)} across; a calibration target is "
           f"{_length_text(lo)}-{_length_text(hi)}")
    # the other units that bring the board into the range; of two (25 "m" as cm: 2 m, as mm: 0.2 m) the one
    # nearer a typical printed target (0.3 m) is named
    fits = [(abs(np.log(size * f / LENGTH_UNITS[declared] / 0.3)), u, size * f / LENGTH_UNITS[declared])
            for u, f in LENGTH_UNITS.items() if u != declared and lo <= size * f / LENGTH_UNITS[declared] <= hi]
    slip = None
    if fits:
        _, unit, fixed = min(fits)
        slip = f"{key}_{unit}_as_{declared}"
        msg = f"`{key}` looks like {unit}, not {declared}: {msg}; read as {unit} it is {_length_text(fixed)}"
    if accept:
        return Diagnostic(IMPLAUSIBLE_CODE, f"accepted with --accept-implausible: {msg}",
                          params=(slip,) if slip else ())
    raise ImplausibleInputError(f"{msg} (fix the unit in the target file, or pass --accept-implausible to go on "
                                "with it as given)", source=f"{target_source}: {key}", slip=slip)


def _detection_warnings(inp) -> list[Diagnostic]:
    dets = inp.detections
    out = []
    rejected = dets.rejected
    if rejected:
        text = "; ".join(f"{Path(n).name}: {r}" for n, r in list(rejected.items())[:12])
        more = f"; ... {len(rejected) - 12} more in the report" if len(rejected) > 12 else ""
        out.append(Diagnostic("views_rejected", f"{len(rejected)} of {len(inp.images)} image(s) not used: {text}{more}",
                              params=tuple(rejected)))
    for note in dets.notes:
        code = note.split(":", 1)[0].strip() or "detection"
        out.append(Diagnostic(f"target_{code}", note))
    return out


def calibrate_input(inp, *, out_dir=None, progress: bool = False, accept_implausible: bool = False,
                    model: str = "opencv5", fix=(), max_outliers: int | None = None, min_corners: int | None = None,
                    noise: str = "per_view", **_) -> CameraRun:
    """Calibrate the intrinsics from a loaded input (:func:`robocal.rigs.camera.files.load_input`).

    ``model``/``fix``/``max_outliers``/``min_corners``/``noise``: of
    :func:`robocal.camera.calibrate_intrinsics` (CLI ``--model``, ``--fix``,
    ...). The target's scale is judged first (:func:`check_target_scale`).
    """
    from robocal.camera import MIN_CORNERS_PER_VIEW, calibrate_intrinsics

    warnings = _detection_warnings(inp)
    diag = check_target_scale(inp.target, target_source=inp.target_source, declared=_declared_unit(inp.target_file),
                              accept=accept_implausible)
    if diag is not None:
        warnings.append(diag)
    views = inp.detections.target_views()
    cal = calibrate_intrinsics(views, inp.image_size, model=model, fix=tuple(fix or ()), max_outliers=max_outliers,
                               min_corners=MIN_CORNERS_PER_VIEW if min_corners is None else int(min_corners),
                               noise=noise)
    return CameraRun(cal, Path(out_dir) if out_dir is not None else Path.cwd(), warnings)


def _rel(path, base: Path) -> str:
    """An image file's path relative to ``base``; a name that is no file (a recording's ``topic@stamp``) as is."""
    if not Path(path).is_file():
        return str(path)
    try:
        return Path(os.path.relpath(Path(path).resolve(), Path(base).resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return str(path)


def _target_record(inp) -> dict:
    from robocal.rigs.camera.simulate import target_mapping

    return {"mapping": target_mapping(inp.target), "describe": inp.target.describe(), "source": inp.target_source}


def _truth_record(cal, truth) -> dict:
    """``truth`` (the true camera and its values in ``cal.labels`` order) and ``truth_check`` (NEES), or a
    ``truth_note`` when the truth is of another kind than the model fitted (its terms mean other things)."""
    from robocal.camera import FisheyeCamera
    from robocal.estimation import truth_check

    if isinstance(truth, FisheyeCamera) != (cal.model == "fisheye"):
        kind = "a fisheye" if isinstance(truth, FisheyeCamera) else "a pinhole"
        return {"truth_note": f"the true camera is {kind} camera, the model fitted is {cal.model}: not compared"}
    n = len(cal.labels)
    tv = np.array([truth.fx, truth.fy, truth.cx, truth.cy, *np.asarray(truth.dist, dtype=float)])
    tv = np.concatenate([tv, np.zeros(max(0, n - tv.size))])[:n]  # terms the truth lacks are zero in it
    free = [i for i, lab in enumerate(cal.labels) if lab in cal.free]
    check = truth_check((cal.values - tv)[free], cal.cov[np.ix_(free, free)], names=[cal.labels[i] for i in free])
    return {"truth": {"camera": truth.to_dict(), "values": tv.tolist()}, "truth_check": check.to_dict()}


def to_result(run: CameraRun, inp) -> CalibrationResult:
    """The result record: intrinsics with std and covariance, per-view poses and residuals, rejected views."""
    cal = run.calibration
    base = run.base_dir
    est, std, units = {}, {}, {}
    for i, lab in enumerate(cal.labels):
        est[lab] = float(cal.values[i])
        std[lab] = cal.std[lab]
        units[lab] = "px" if i < 4 else "1"
    views = {}
    for v in cal.views:
        # keyed by the image's path relative to the result's folder: the report finds the image there
        views[_rel(v.name, base)] = {
            "T_cam_board": np.round(cal.poses[v.name], 12).tolist(),
            "pose_std": np.asarray(cal.pose_std[v.name]).tolist(), "rms_px": cal.view_rms[v.name],
            "sigma_px": float(cal.view_sigma.get(v.name, cal.sigma_px)),
            "ids": v.ids.tolist(), "image_points": np.round(v.image_points, 5).tolist(),
            "residuals": np.round(cal.residuals[v.name], 6).tolist(),
        }
    lsq = cal.lsq.to_dict() if cal.lsq is not None else {}
    solver = {k: lsq[k] for k in ("method", "loss", "message", "status", "iterations", "nfev", "cost_history", "cost",
                                  "rms", "rank", "free_labels", "condition_number", "outlier_sigma") if k in lsq}
    diag = {
        "camera": cal.camera.to_dict(), "model": cal.model, "labels": list(cal.labels), "free": list(cal.free),
        "cov": cal.cov, "sigma_px": cal.sigma_px, "opencv_rms_px": cal.opencv_rms,
        "image_size": list(inp.image_size), "target": _target_record(inp), "views": views,
        "outliers": [[_rel(n, base), int(i)] for n, i in cal.outliers],
        "dropped": [_rel(n, base) for n in cal.dropped],
        "rejected": {_rel(n, base): r for n, r in inp.detections.rejected.items()},
        "detection_notes": list(inp.detections.notes),
        "blur_px": {_rel(d.name, base): d.blur_px for d in inp.detections.detections},
        "n_images": len(inp.images), "solver": solver,
    }
    if inp.truth is not None:
        diag.update(_truth_record(cal, inp.truth))
    inputs = hash_inputs([p for p in (inp.source, inp.target_file, inp.truth_file) if p is not None]
                         + [p for p in inp.images if Path(p).is_file()])
    return CalibrationResult(
        rig="camera", method=f"joint least squares over intrinsics ({cal.model}) and view poses, started from "
                             "cv2.calibrateCamera",
        estimate=est, std=std, units=units, residual_rms=cal.rms, residual_unit="px",
        warnings=[*run.warnings, *cal.warnings], inputs=inputs, diagnostics=diag)


def camera_from_result(result: CalibrationResult):
    """The estimated camera of a camera-rig result (:class:`CameraModel` or :class:`FisheyeCamera`)."""
    from robocal.camera import camera_from_mapping

    return camera_from_mapping(result.diagnostics["camera"], "result.json: diagnostics.camera")


def calibration_from_result(result: CalibrationResult):
    """The :class:`robocal.camera.IntrinsicCalibration` a result was written from (views rebuilt from their ids).

    What the report needs to redraw the uncertainty and coverage maps
    (:func:`robocal.camera.projection_uncertainty`, :func:`robocal.camera.coverage`);
    ``lsq`` is not kept (``None``).
    """
    from robocal.camera import IntrinsicCalibration, TargetView, target_from_document
    from robocal.io import Document

    d = result.diagnostics
    target = target_from_document(Document(d["target"]["mapping"], "result.json: diagnostics.target.mapping"))
    views, poses, pose_std, residuals, view_rms, view_sigma = [], {}, {}, {}, {}, {}
    for name, v in d["views"].items():
        ids = np.asarray(v["ids"], dtype=int)
        views.append(TargetView(name, target.object_points(ids), np.asarray(v["image_points"], float), ids))
        poses[name] = np.asarray(v["T_cam_board"], float)
        pose_std[name] = np.asarray(v["pose_std"], float)
        residuals[name] = np.asarray(v["residuals"], float).reshape(-1, 2)
        view_rms[name] = float(v["rms_px"])
        view_sigma[name] = float(v.get("sigma_px", d["sigma_px"]))
    labels = tuple(d["labels"])
    values = np.array([result.estimate[k] for k in labels], dtype=float)
    cov = np.array([[np.nan if c is None else c for c in row] for row in d["cov"]], dtype=float)
    return IntrinsicCalibration(
        camera=camera_from_result(result), model=d["model"], labels=labels, values=values, cov=cov,
        std=dict(result.std), free=tuple(d["free"]), poses=poses, pose_std=pose_std, views=views,
        residuals=residuals, view_rms=view_rms, rms=float(result.residual_rms), sigma_px=float(d["sigma_px"]),
        opencv_rms=float(d["opencv_rms_px"]), outliers=[tuple(o) for o in d["outliers"]],
        dropped=list(d["dropped"]), warnings=list(result.warnings), lsq=None, view_sigma=view_sigma)


def write_outputs(result: CalibrationResult, out_dir) -> list[Path]:
    """The ``write_outputs`` step: the camera as ``camera.yaml`` (OpenCV FileStorage), ``camera_info.yaml``
    (ROS ``camera_calibration_parsers``) and ``camera.json``; every camera rig reads each of them
    (``camera: {file: ...}``)."""
    from robocal.camera import write_camera

    cam = camera_from_result(result)
    return [write_camera(Path(out_dir) / name, cam, format=fmt) for name, fmt in CAMERA_FILES.items()]


def summary(result: CalibrationResult) -> str:
    """The lines printed after ``robocal camera calibrate``: the intrinsics with std, the RMS, the views used."""
    e, s = result.estimate, result.std
    d = result.diagnostics

    def pm(k, digits=2):
        sd = s.get(k)
        return f"{e[k]:.{digits}f} +- {sd:.{digits}f}" if sd is not None else f"{e[k]:.{digits}f} (undetermined)"

    dist = ", ".join(f"{k} {e[k]:+.4g}" for k in d["labels"][4:] if k in d["free"])
    used = len(d["views"])
    lines = [f"fx {pm('fx')}, fy {pm('fy')}, cx {pm('cx')}, cy {pm('cy')} px; {dist}",
             f"{used} of {d['n_images']} image(s) used, reprojection RMS {result.residual_rms:.3f} px "
             f"(noise {d['sigma_px']:.3f} px); {len(result.warnings)} warning(s)"]
    if d.get("rejected"):
        why = [f"{Path(n).name} ({r.split(':')[0]})" for n, r in d["rejected"].items()]
        lines.append("not used: " + ", ".join(why))
    return "\n".join(lines)


def demo(ctx: DemoContext) -> DemoOutcome:
    """Render 15 views (plus a defocused and a duplicate shot) -> detect -> calibrate -> check against the truth.

    Passes when the intrinsics' errors are consistent with their reported
    covariance (NEES, :func:`robocal.estimation.truth_check`) and both
    defective views were named and skipped.
    """
    from robocal.rigs.camera.files import load_input
    from robocal.rigs.camera.report import build_report
    from robocal.rigs.camera.simulate import simulate_session

    out = Path(ctx.out_dir)
    t0 = time.perf_counter()
    sim = simulate_session(out / "session", ctx.rng, views=15, defects=True, progress=ctx.progress)
    inp = load_input(sim.session, progress=ctx.progress)
    run = calibrate_input(inp, out_dir=out)
    result = to_result(run, inp)
    report = build_report(result, base_dir=out, title="camera demo: 15 rendered views of a 9x6 chessboard, "
                                                      "+ a defocused and a duplicate shot")
    check = result.diagnostics["truth_check"]
    rejected = set(result.diagnostics["rejected"])
    expected = {_rel(sim.session.parent / "images" / n, out) for n in sim.defects}
    named = expected <= rejected
    e, t = result.estimate, sim.camera
    summary_ = {
        "views used": f"{len(result.diagnostics['views'])} of {result.diagnostics['n_images']}",
        "fx error": f"{e['fx'] - t.fx:+.2f} px (std {result.std['fx']:.2f})",
        "cx error": f"{e['cx'] - t.cx:+.2f} px (std {result.std['cx']:.2f})",
        "reprojection RMS": f"{result.residual_rms:.3f} px",
        "NEES": f"{check['nees']:.2f} (limit {check['threshold']:.1f})",
        "defects named": "yes" if named else f"no: {sorted(expected - rejected)}",
        "time": f"{time.perf_counter() - t0:.1f} s",
    }
    return DemoOutcome(summary=summary_, passed=bool(check["passed"] and named), sections=list(report.sections),
                       result=result)
