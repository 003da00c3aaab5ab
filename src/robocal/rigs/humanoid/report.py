"""Outputs of a humanoid calibration: files a robot framework loads, plots, the HTML report.

* ``result.json`` -- shared schema (:meth:`HumanoidCalibration.to_result`);
* ``offsets.yaml`` -- per-joint offset table (deg and rad) and the camera
  mounting correction, the form a robot framework loads;
* ``<robot>_calibrated.urdf`` -- the URDF with the offsets and the camera
  correction folded into the joint origins, limits shifted by the offsets (use
  it with raw sensor angles), and a provenance comment;
* ``report.html`` -- built from the result alone (:func:`build_report`), so
  ``robocal report result.json`` rebuilds the same page: summary, parameter
  and offset tables, the simulation truth check, identifiability, the solver
  record and its two LM passes, residual histograms, per-view RMS and
  reprojection overlays of a few views.

Plot functions are pure: they take ``ax=None`` and return the axes.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from robocal.io import CalibrationResult, atomic_write_text, hash_inputs, write_result
from robocal.report import (Report, new_figure, plot_cost, plot_residual_histogram, solver_section,
                            truth_section)
from robocal.rigs.humanoid.calibration import HumanoidCalibration, parameter_rows, rank_text, rejection_text

__all__ = [
    "overlay_image",
    "draw_overlay",
    "overlay_picks",
    "plot_view_rms",
    "offsets_document",
    "write_offsets",
    "build_report",
    "write_outputs",
]

TITLE = "NAO leg and camera calibration"


def overlay_image(cal: HumanoidCalibration, view: int, *, magnify: float = 20.0) -> np.ndarray:
    """RGB image of one view: detected corners (green), reprojected ones (red), and
    the residual vectors magnified ``magnify`` times (yellow)."""
    det = cal.data.corners[view]
    return draw_overlay(cal.data.images[view], det, det + cal.residuals[view],
                        (cal.model.camera.width, cal.model.camera.height), magnify=magnify)


def draw_overlay(img, det, pred, size, *, magnify: float = 20.0) -> np.ndarray:
    """RGB overlay on ``img`` (array, image path, or None: a grey canvas of ``size`` = (w, h)):
    detected corners ``det`` (green circles), predicted ``pred`` (red crosses), both (N, 2) [px],
    and the residual magnified ``magnify`` times (yellow)."""
    import cv2

    from robocal.rigs.humanoid.detect import load_image

    if img is None:
        img = np.full((size[1], size[0]), 128, np.uint8)
    elif not isinstance(img, np.ndarray):
        img = load_image(img)
    rgb = cv2.cvtColor(np.asarray(img, np.uint8), cv2.COLOR_GRAY2RGB) if np.ndim(img) == 2 else np.array(img)
    for d, p in zip(np.asarray(det, float), np.asarray(pred, float)):
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(p))):
            continue  # a corner removed at detection
        end = d + magnify * (p - d)
        cv2.line(rgb, _pt(d), _pt(end), (240, 200, 0), 1, cv2.LINE_AA)
        cv2.circle(rgb, _pt(d), 4, (0, 200, 0), 1, cv2.LINE_AA)
        cv2.drawMarker(rgb, _pt(p), (230, 0, 0), cv2.MARKER_CROSS, 7, 1, cv2.LINE_AA)
    return rgb


def overlay_picks(feet, rms, n: int) -> list[int]:
    """Views to overlay: the worst of each board first, then the best view, then the next worst."""
    rms = np.asarray(rms, float)
    order = [int(i) for i in np.argsort(-rms)]
    picks = [next(i for i in order if feet[i] == f) for f in dict.fromkeys(feet)]
    picks += [order[-1]] + order
    return list(dict.fromkeys(picks))[:n]


def _pt(p):
    return (int(round(float(p[0]))), int(round(float(p[1]))))


def plot_view_rms(names, feet, rms, ax=None):
    """Bar chart of per-view residual RMS [px], coloured by foot; returns the axes."""
    if ax is None:
        _, ax = new_figure(size=(7.0, 3.2))
    colours = ["C0" if f == "left" else "C1" for f in feet]
    ax.bar(np.arange(len(rms)), rms, color=colours)
    # at most ~40 labelled ticks: with hundreds of views the labels are unreadable and laying them out
    # took seconds (200 views: 8 s of the report's text extents)
    step = max(1, -(-len(rms) // 40))
    ticks = np.arange(0, len(rms), step)
    ax.set_xticks(ticks)
    labels = [str(names[i]) for i in ticks]
    # frames from a recording are named topic@stamp: the shared topic says nothing per bar, and labels
    # that long, rotated, left the axes no height (matplotlib's "axes sizes collapsed to zero")
    shared = os.path.commonprefix(labels) if len(labels) > 1 else ""
    cut = max(shared.rfind("@"), shared.rfind("/")) + 1
    if cut > 0:
        labels = [lb[cut:] for lb in labels]
        ax.set_xlabel(f"view ({shared[:cut]}...)", fontsize=8)
    ax.set_xticklabels([lb if len(lb) <= 24 else "..." + lb[-21:] for lb in labels], rotation=90, fontsize=7)
    ax.set_ylabel("RMS [px]")
    ax.set_title("per-view residual RMS (blue: left board, orange: right board)")
    return ax


def offsets_document(cal: HumanoidCalibration) -> dict:
    """Per-joint offset table and camera correction, units explicit (``offsets.yaml``)."""
    joints = {}
    for r in cal.offsets_table():
        joints[r["joint"]] = {
            "offset_deg": None if r["offset [deg]"] is None else round(r["offset [deg]"], 6),
            "std_deg": None if r["std [deg]"] is None else round(r["std [deg]"], 6),
            "estimated": r["estimated"],
        }
    cam = cal.camera_correction()
    return {
        "description": "q = theta (sensor) + offset; camera: T_head_camera = T_head_camera0 @ Trans(x, y, 0) @ "
                       "Rz(yaw) Ry(pitch) Rx(roll); null = not determined by the data (left at 0 in the URDF)",
        "joint_offsets": joints,
        "camera_correction": {
            "frame": cal.model.camera_link,
            "roll_deg": _deg(cam["roll"]), "pitch_deg": _deg(cam["pitch"]), "yaw_deg": _deg(cam["yaw"]),
            "x_mm": _mm(cam["x"]), "y_mm": _mm(cam["y"]),
        },
    }


def _deg(v):
    return None if v is None else round(float(np.degrees(v)), 6)


def _mm(v):
    return None if v is None else round(float(v) * 1e3, 6)


def build_report(result: CalibrationResult, *, base_dir=None, title: str = TITLE, n_overlays: int = 4) -> Report:
    """The HTML report of one calibration, from its result record alone.

    Summary, parameter table (with the simulated truth and the NEES check when the result has
    them), per-joint offsets and camera correction, identifiability, the solver record with the
    cost of both LM passes, residual histograms and per-view RMS, and reprojection overlays of the
    ``n_overlays`` views :func:`overlay_picks` chooses, drawn on the image files named in the
    result (on a grey canvas, said in the caption, when a file is gone). ``base_dir``: the
    result's folder; image paths in the result are absolute, so it is not needed.
    """
    d = result.diagnostics
    rep = Report(title, subtitle=f"{d.get('n_views')} views, {len(result.estimate)} parameters, seed 001 method")
    nm = d.get("noise_model") or {}
    s = rep.section("Summary")
    s.table([
        {"quantity": "views used", "value": d.get("n_views")},
        {"quantity": "residual RMS x [px]", "value": d.get("rms_x_px")},
        {"quantity": "residual RMS y [px]", "value": d.get("rms_y_px")},
        {"quantity": "corner noise used [px]", "value": nm.get("corner_sigma_px")},
        {"quantity": "joint resolution [deg]", "value": _deg(nm.get("joint_resolution_rad"))},
        {"quantity": "residual variance / model", "value": nm.get("residual_variance_ratio")},
        {"quantity": "LM iterations (from zero)", "value": d.get("iterations")},
        {"quantity": "LM iterations (measured corner noise)",
         "value": d.get("iterations_reweighted_pass") if d.get("corner_sigma_measured") else "—"},
        {"quantity": "Jacobian rank", "value": f"{d.get('rank')} of {d.get('n_free')}"},
        {"quantity": "condition number (scaled)", "value": d.get("condition_number")},
        {"quantity": f"outlier corners (> {d.get('outlier_sigma', 3.0):.3g} sigma)",
         "value": len(d.get("outlier_corners") or [])},
        {"quantity": "corners removed at detection", "value": len(d.get("missing_corners") or [])},
        {"quantity": "corners removed (--reject-outliers)",
         "value": d.get("n_corners_rejected") if d.get("rejected_corners") or d.get("rejected_views") else "—"},
    ])
    if d.get("rejected_corners") or d.get("rejected_views"):
        s.text("Outliers rejected and the calibration re-solved once without them: " + rejection_text(d)
               + " (view name, corner index in the board's object-point order, row by row). RMS values and "
               "histograms are over the corners used.", cls="warn")
    s.text("Standard deviations are sampling errors under the noise model (corner noise plus joint "
           "quantisation), scaled by the residual variance; they say nothing about model error.")
    s.diagnostics(result.warnings)
    for msg in d.get("messages") or []:
        s.text(msg, cls="warn")
    if d.get("truth_check"):
        truth_section(rep.section("Simulation truth"), d["truth_check"])
    rep.section("Parameters").table(parameter_rows(result),
                                    caption="estimate and 1-sigma uncertainty; '—' = not identifiable")
    if d.get("offsets_table"):
        o = rep.section("Per-joint offsets and camera correction")
        o.table(d["offsets_table"])
        cam = d.get("camera_correction") or {}
        o.table([{"correction": k, "value": _deg(v) if k in ("roll", "pitch", "yaw") else _mm(v),
                  "unit": "deg" if k in ("roll", "pitch", "yaw") else "mm"} for k, v in cam.items()],
                caption=f"camera mounting correction in {d.get('camera_frame', 'the camera frame')}")
    i = rep.section("Identifiability")
    i.text(rank_text(d) + " (column-scaled Jacobian).")
    if d.get("unidentifiable"):
        i.text("Not determined by these poses (no value reported): " + ", ".join(d["unidentifiable"])
               + f". To fix the null space, {', '.join(d.get('gauge_held') or [])} was held at its start value "
               "and the others were estimated; the determined parameters do not depend on that choice.",
               cls="warn")
    corr = d.get("correlations") or []
    i.table([{"parameter a": a, "parameter b": b, "correlation": c} for a, b, c in corr[:8]],
            caption="strongest correlations")
    _solver_section(rep.section("Solver"), d)
    _residual_section(rep.section("Residuals"), d)
    _overlay_section(rep, d, n_overlays)
    return rep


def _solver_section(sec, d: dict) -> None:
    """The solver's table (of the final pass) and the cost of every LM pass on one plot."""
    record = dict(d.get("solver") or {})
    if record:  # (a result written before the solver record was kept has only the cost)
        solver_section(sec, record, caption="the final LM pass")
    passes = {}
    if d.get("corner_sigma_measured") and d.get("cost_history_first_pass"):
        passes["pass 1: from zero, 0.3 px assumed"] = _floats(d["cost_history_first_pass"])
        passes["pass 2: measured corner noise"] = _floats(d.get("cost_history") or [])
    else:
        passes["LM from zero" if not d.get("reject_outliers") else "final pass"] = _floats(d.get("cost_history") or [])
    ax = plot_cost(passes)
    sec.figure(ax.figure, "cost per accepted LM step (whitened residuals, log scale)")


def _residual_section(sec, d: dict) -> None:
    views = d.get("views") or []
    if d.get("residuals_px"):
        resid = np.asarray(_floats(d["residuals_px"]), float)
        used = resid[_kept(d, resid.shape[:2])]
        fig, ax = new_figure(1, 2, size=(10, 3.4))
        for k, axis in enumerate("xy"):
            rms = float(np.sqrt(np.mean(used[:, k] ** 2))) if used.size else float("nan")
            plot_residual_histogram(used[:, k], ax=ax[k], sigma=rms, unit="px",
                                    label=f"{axis}: {used.shape[0]} corners, RMS {rms:.3f} px")
            ax[k].set_xlabel(f"{axis} residual (predicted - detected) [px]")
        sec.figure(fig, "corner residual histograms of the corners used, with the Gaussian of their RMS")
    if views:
        fig, ax = new_figure(size=(9, 3.2))
        plot_view_rms([v["name"] for v in views], [v["foot"] for v in views], [v["rms_px"] for v in views], ax=ax)
        sec.figure(fig, "per-view residual RMS")
        sec.table([{"view": v["name"], "foot": v["foot"], "RMS [px]": v["rms_px"]} for v in views])


def _overlay_section(rep: Report, d: dict, n_overlays: int) -> None:
    views = d.get("views") or []
    if not (d.get("residuals_px") and d.get("corners_px") and views):
        return
    from robocal.rigs.humanoid.detect import load_image

    resid = np.asarray(_floats(d["residuals_px"]), float)
    det = np.asarray(_floats(d["corners_px"]), float)
    images = d.get("images") or [None] * len(views)
    size = tuple(d.get("image_size") or (int(np.nanmax(det[..., 0])) + 40, int(np.nanmax(det[..., 1])) + 40))
    ov = rep.section("Reprojection overlays")
    for v in overlay_picks([x["foot"] for x in views], [x["rms_px"] for x in views], n_overlays):
        img = load_image(images[v]) if images[v] and Path(images[v]).is_file() else None
        note = "" if img is not None else " (image file not available: grey canvas)"
        ov.image(draw_overlay(img, det[v], det[v] + resid[v], size),
                 f"{views[v]['name']} ({views[v]['foot']} board, RMS {views[v]['rms_px']:.3f} px): green "
                 f"detected, red reprojected, yellow residual x20{note}")


def _kept(d: dict, shape) -> np.ndarray:
    """Corners (V, N) used in the final solve: present ones less those ``reject_outliers`` removed."""
    keep = np.ones(shape, bool)
    names = [v["name"] for v in d.get("views") or []]
    for v, c in d.get("rejected_corners") or []:
        keep[names.index(v), c] = False
    for v in d.get("rejected_views") or []:
        keep[names.index(v)] = False
    return keep


def _floats(x):
    """A nested list from a result file with ``None`` (JSON's NaN) as NaN."""
    if isinstance(x, (list, tuple)):
        return [_floats(v) for v in x]
    return np.nan if x is None else x


def write_offsets(cal: HumanoidCalibration, out_dir, *, inputs: dict | None = None) -> list[Path]:
    """Write ``offsets.yaml`` and ``<robot>_calibrated.urdf`` into ``out_dir`` (atomically); ``inputs``
    ``{path: sha256}`` for the URDF's provenance comment. Returns the two paths."""
    out_dir = Path(out_dir)
    paths = [atomic_write_text(out_dir / "offsets.yaml",
                               yaml.safe_dump(offsets_document(cal), sort_keys=False, width=200))]
    urdf = out_dir / f"{cal.model.tree.name}_calibrated.urdf"
    cal.write_urdf(urdf, inputs=inputs)
    paths.append(urdf)
    return paths


def write_outputs(cal: HumanoidCalibration, out_dir, *, inputs=(), command: str | None = None, truth=None,
                  report: Report | None = None) -> list[Path]:
    """Write result.json, report.html, offsets.yaml and the corrected URDF into ``out_dir`` (the
    calibrate command's files, for a calibration made from Python). Returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    hashes = hash_inputs(inputs)
    result = cal.to_result(inputs=hashes, command=command, truth=truth)
    rep = report if report is not None else build_report(result, base_dir=out_dir)
    paths = [write_result(out_dir / "result.json", result), rep.write(out_dir / "report.html")]
    return paths + write_offsets(cal, out_dir, inputs=hashes)
