"""Outputs of a humanoid calibration: files a robot framework loads, plots, the HTML report.

* ``result.json`` -- shared schema (:meth:`HumanoidCalibration.to_result`);
* ``offsets.yaml`` -- per-joint offset table (deg and rad) and the camera
  mounting correction, the form a robot framework loads;
* ``<robot>_calibrated.urdf`` -- the URDF with the offsets and the camera
  correction folded into the joint origins, limits shifted by the offsets (use
  it with raw sensor angles), and a provenance comment;
* ``report.html`` -- reprojection overlays of a few views, residual
  histograms, per-view RMS, parameter table with uncertainties, the
  identifiability analysis and every warning.

Plot functions are pure: they take ``ax=None`` and return the axes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from robocal.io import CalibrationResult, atomic_write_text
from robocal.report import Report, new_figure
from robocal.rigs.humanoid.calibrate import HumanoidCalibration, _by_view_text

__all__ = [
    "overlay_image",
    "draw_overlay",
    "overlay_picks",
    "plot_residual_histograms",
    "plot_view_rms",
    "plot_cost",
    "offsets_document",
    "build_report",
    "report_from_result",
    "write_outputs",
]


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


def plot_residual_histograms(residuals, ax=None):
    """Histograms of the x and y corner residuals [px] on one axes; returns the axes."""
    if ax is None:
        _, ax = new_figure()
    r = np.asarray(residuals, float).reshape(-1, 2)
    r = r[np.all(np.isfinite(r), axis=1)]  # corners removed at detection have none
    lim = max(float(np.max(np.abs(r), initial=0.0)), 1e-6)
    bins = np.linspace(-lim, lim, 41)
    ax.hist(r[:, 0], bins=bins, alpha=0.6, label=f"x (RMS {np.sqrt(np.mean(r[:, 0] ** 2)):.3f} px)")
    ax.hist(r[:, 1], bins=bins, alpha=0.6, label=f"y (RMS {np.sqrt(np.mean(r[:, 1] ** 2)):.3f} px)")
    ax.set_xlabel("residual (predicted - detected) [px]")
    ax.set_ylabel("corners")
    ax.legend()
    return ax


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
    ax.set_xticklabels([names[i] for i in ticks], rotation=90, fontsize=7)
    ax.set_ylabel("RMS [px]")
    ax.set_title("per-view residual RMS (blue: left board, orange: right board)")
    return ax


def plot_cost(history, ax=None, *, first=None):
    """Cost at each accepted LM iterate (log scale); ``first``: the pass from zero before it.
    Returns the axes."""
    if ax is None:
        _, ax = new_figure(size=(5.0, 3.0))
    k0 = 0
    if first is not None and len(first):
        ax.semilogy(np.arange(len(first)), first, "o-", label="pass 1: from zero, 0.3 px assumed")
        k0 = len(first) - 1
    ax.semilogy(k0 + np.arange(len(history)), history, "s-", label="pass 2: measured corner noise")
    ax.set_xlabel("LM iteration")
    ax.set_ylabel("cost (whitened residuals)")
    ax.legend()
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


def build_report(cal: HumanoidCalibration, *, title: str = "NAO leg and camera calibration", truth=None,
                 n_overlays: int = 4, extra_sections=()) -> Report:
    """The HTML report of one calibration (optionally with the simulation truth)."""
    rep = Report(title, subtitle=f"{cal.data.n_views} views, {len(cal.free)} parameters, seed 001 method")
    lsq = cal.lsq
    s = rep.section("Summary")
    s.table([
        {"quantity": "views used", "value": cal.data.n_views},
        {"quantity": "residual RMS x [px]", "value": float(cal.rms_xy[0])},
        {"quantity": "residual RMS y [px]", "value": float(cal.rms_xy[1])},
        {"quantity": "corner noise used [px]", "value": cal.corner_sigma},
        {"quantity": "joint resolution [deg]", "value": float(np.degrees(cal.joint_resolution))},
        {"quantity": "residual variance / model", "value": float(lsq.residual_variance)},
        {"quantity": "LM iterations (from zero)", "value": cal.first_iterations},
        {"quantity": "LM iterations (measured corner noise)", "value": lsq.iterations if cal.two_pass else "—"},
        {"quantity": "Jacobian rank", "value": "{} of {}".format(*cal.jacobian_rank)},
        {"quantity": "condition number (scaled)", "value": float(lsq.condition_number)},
        {"quantity": "outlier corners (> 3 sigma)", "value": len(cal.outlier_corners)},
        {"quantity": "corners removed at detection", "value": len(cal.missing_corners)},
        {"quantity": "corners removed (--reject-outliers)",
         "value": cal.n_rejected if cal.rejected_corners or cal.rejected_views else "—"},
    ])
    if cal.rejected_corners or cal.rejected_views:
        s.text("Outliers rejected and the calibration re-solved once without them: " + cal.rejection_text()
               + " (view name, corner index in the board's object-point order, row by row). RMS values and "
               "histograms are over the corners used.", cls="warn")
    s.text("Standard deviations are sampling errors under the noise model (corner noise plus joint "
           "quantisation), scaled by the residual variance; they say nothing about model error.")
    s.diagnostics(cal.warnings)
    for msg in cal.messages:
        s.text(msg, cls="warn")
    p = rep.section("Parameters")
    p.table(cal.parameter_rows(truth), caption="estimate and 1-sigma uncertainty; '—' = not identifiable")
    o = rep.section("Per-joint offsets and camera correction")
    o.table([{k: v for k, v in r.items() if k != "offset [rad]"} for r in cal.offsets_table()])
    doc = offsets_document(cal)["camera_correction"]
    o.table([{"correction": k, "value": v} for k, v in doc.items() if k != "frame"],
            caption=f"camera mounting correction in {doc['frame']}")
    i = rep.section("Identifiability")
    i.text(cal.rank_text() + " (column-scaled Jacobian).")
    if cal.unidentifiable:
        i.text("Not determined by these poses (no value reported): " + ", ".join(cal.unidentifiable)
               + f". To fix the null space, {', '.join(cal.held)} was held at its start value and the "
               "others were estimated; the determined parameters do not depend on that choice.", cls="warn")
    i.table([{"parameter a": a, "parameter b": b, "correlation": c} for a, b, c in cal.correlations[:8]],
            caption="strongest correlations")
    r = rep.section("Residuals")
    fig, ax = new_figure(1, 2, size=(11, 3.6))
    plot_residual_histograms(cal.used_residuals, ax=ax[0])
    plot_cost(lsq.cost_history, ax=ax[1], first=cal.first_cost_history)
    r.figure(fig, "corner residual histograms; cost per LM iterate")
    fig, ax = new_figure(size=(9, 3.2))
    plot_view_rms(cal.data.names, cal.data.feet, cal.view_rms, ax=ax)
    r.figure(fig, "per-view residual RMS")
    r.table([{"view": nm, "foot": f, "RMS [px]": float(v)} for nm, f, v in
             zip(cal.data.names, cal.data.feet, cal.view_rms)])
    ov = rep.section("Reprojection overlays")
    for v in overlay_picks(cal.data.feet, cal.view_rms, n_overlays):
        ov.image(overlay_image(cal, v), f"{cal.data.names[v]} ({cal.data.feet[v]} board, RMS "
                                        f"{cal.view_rms[v]:.3f} px): green detected, red reprojected, "
                                        f"yellow residual x20")
    for sec in extra_sections:
        rep.sections.append(sec)
    return rep


def report_from_result(result: CalibrationResult, *, title: str = "NAO leg and camera calibration",
                       n_overlays: int = 4) -> Report:
    """A report rebuilt from a saved ``result.json``: summary, parameter and offset tables,
    identifiability, residual histograms, cost and per-view RMS plots, and reprojection overlays
    of the views whose image files still exist (a grey canvas otherwise, said in the caption).
    A result written before the corners and residuals were saved gets the tables and the
    per-view RMS only."""
    d = result.diagnostics
    rep = Report(title, subtitle=f"from {result.command or 'a saved result'} ({result.created})")
    s = rep.section("Summary")
    nm = d.get("noise_model") or {}
    rank = d.get("rank"), d.get("n_free")
    s.table([
        {"quantity": "views used", "value": d.get("n_views")},
        {"quantity": "residual RMS x [px]", "value": d.get("rms_x_px")},
        {"quantity": "residual RMS y [px]", "value": d.get("rms_y_px")},
        {"quantity": "corner noise used [px]", "value": nm.get("corner_sigma_px")},
        {"quantity": "residual variance / model", "value": nm.get("residual_variance_ratio")},
        {"quantity": "LM iterations (from zero)", "value": d.get("iterations")},
        {"quantity": "LM iterations (measured corner noise)",
         "value": d.get("iterations_reweighted_pass") if d.get("corner_sigma_measured") else "—"},
        {"quantity": "Jacobian rank", "value": f"{rank[0]} of {rank[1]}"},
        {"quantity": "condition number (scaled)", "value": d.get("condition_number")},
        {"quantity": "outlier corners (> 3 sigma)", "value": len(d.get("outlier_corners") or [])},
        {"quantity": "corners removed at detection", "value": len(d.get("missing_corners") or [])},
        {"quantity": "corners removed (--reject-outliers)",
         "value": len(d["rejected_corners"]) if d.get("rejected_corners") or d.get("rejected_views") else "—"},
    ])
    if d.get("rejected_corners") or d.get("rejected_views"):
        s.text("Outliers rejected and the calibration re-solved once without them: "
               + _by_view_text(d.get("rejected_corners") or [], sep=" ")
               + (f"; whole views {d['rejected_views']}" if d.get("rejected_views") else "")
               + " (view name, corner index in the board's object-point order, row by row).", cls="warn")
    s.diagnostics(result.warnings)
    for msg in d.get("messages") or []:
        s.text(msg, cls="warn")
    rows = []
    for k, v in result.estimate.items():
        unit = result.units.get(k)
        f = np.degrees(1.0) if unit == "rad" else 1e3
        sd = result.std.get(k)
        rows.append({"parameter": k, "value": None if v is None else v * f,
                     "std": None if sd is None else sd * f, "unit": "deg" if unit == "rad" else "mm"})
    rep.section("Parameters").table(rows, caption="estimate and 1-sigma uncertainty; '—' = not identifiable")
    if d.get("offsets_table"):
        o = rep.section("Per-joint offsets and camera correction")
        o.table(d["offsets_table"])
        cam = d.get("camera_correction") or {}
        o.table([{"correction": k, "value": None if v is None else v * (np.degrees(1.0) if k in
                  ("roll", "pitch", "yaw") else 1e3), "unit": "deg" if k in ("roll", "pitch", "yaw") else "mm"}
                 for k, v in cam.items()], caption="camera mounting correction")
    i = rep.section("Identifiability")
    i.text(f"Jacobian rank {rank[0]} of {rank[1]} free parameters; condition number "
           f"{d.get('condition_number', float('nan')):.3g}.")
    if d.get("unidentifiable"):
        i.text("Not determined by these poses (no value reported): " + ", ".join(d["unidentifiable"])
               + (f"; gauge held: {', '.join(d['gauge_held'])}" if d.get("gauge_held") else ""), cls="warn")
    corr = d.get("correlations") or []
    if corr:
        i.table([{"parameter a": a, "parameter b": b, "correlation": c} for a, b, c in corr],
                caption="strongest correlations")
    views = d.get("views") or []
    resid = np.asarray(d["residuals_px"], float) if d.get("residuals_px") else None
    sec = rep.section("Residuals")
    if resid is not None and resid.size:
        fig, ax = new_figure(1, 2, size=(11, 3.6))
        used = resid
        if (d.get("rejected_corners") or d.get("rejected_views")) and views:
            names = [v["name"] for v in views]
            keep = np.ones(resid.shape[:2], bool)
            for v, c in d.get("rejected_corners") or []:
                keep[names.index(v), c] = False
            for v in d.get("rejected_views") or []:
                keep[names.index(v)] = False
            used = resid[keep]
        plot_residual_histograms(used, ax=ax[0])
        hist = d.get("cost_history") or []
        first = d.get("cost_history_first_pass")
        plot_cost(np.asarray(hist, float), ax=ax[1],
                  first=np.asarray(first, float) if first and d.get("corner_sigma_measured") else None)
        sec.figure(fig, "corner residual histograms; cost per LM iterate")
    if views:
        fig, ax = new_figure(size=(9, 3.2))
        plot_view_rms([v["name"] for v in views], [v["foot"] for v in views], [v["rms_px"] for v in views], ax=ax)
        sec.figure(fig, "per-view residual RMS")
        sec.table([{"view": v["name"], "foot": v["foot"], "RMS [px]": v["rms_px"]} for v in views])
    if resid is not None and d.get("corners_px") and views:
        det = np.asarray(d["corners_px"], float)
        images = d.get("images") or [None] * len(views)
        size = tuple(d.get("image_size") or (int(np.nanmax(det[..., 0])) + 40, int(np.nanmax(det[..., 1])) + 40))
        ov = rep.section("Reprojection overlays")
        for v in overlay_picks([x["foot"] for x in views], [x["rms_px"] for x in views], n_overlays):
            img = images[v] if images[v] and Path(images[v]).is_file() else None
            if img is not None:
                from robocal.rigs.humanoid.detect import load_image

                img = load_image(img)
            note = "" if img is not None else " (image file not available: grey canvas)"
            ov.image(draw_overlay(img, det[v], det[v] + resid[v], size),
                     f"{views[v]['name']} ({views[v]['foot']} board, RMS {views[v]['rms_px']:.3f} px): green "
                     f"detected, red reprojected, yellow residual x20{note}")
    return rep


def write_outputs(cal: HumanoidCalibration, out_dir, *, inputs=(), command: str | None = None, truth=None,
                  report: Report | None = None, quiet: bool = False) -> list[Path]:
    """Write result.json, report.html, offsets.yaml and the corrected URDF into ``out_dir``."""
    from robocal.cli import write_run
    from robocal.io import hash_inputs

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    hashes = hash_inputs(inputs)
    result = cal.to_result(inputs=hashes, command=command)
    rep = report if report is not None else build_report(cal, truth=truth)
    paths = list(write_run(out_dir, result, rep, quiet=quiet))
    paths.append(atomic_write_text(out_dir / "offsets.yaml",
                                   yaml.safe_dump(offsets_document(cal), sort_keys=False, width=200)))
    urdf = out_dir / f"{cal.model.tree.name}_calibrated.urdf"
    cal.write_urdf(urdf, inputs=hashes)
    paths.append(urdf)
    if not quiet:
        for p in paths[-2:]:
            print(f"wrote {p}")
    return paths
