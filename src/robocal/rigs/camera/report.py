"""HTML report of an intrinsic calibration, drawn from its result record alone.

:func:`build_report` reads the :class:`~robocal.io.CalibrationResult` written
by :func:`robocal.rigs.camera.workflow.to_result` (and, when they are still
there, the images it names, relative to the result's folder), so that
``robocal camera report`` and ``robocal report`` rebuild the page
``robocal camera calibrate`` wrote. mrcal's habits: the projection
uncertainty over the image and where the corners fell, side by side (an
empty image corner is extrapolated distortion), residual vectors on the
image, the correlation of the intrinsics.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError
from robocal.io import CalibrationResult
from robocal.report import Report, new_figure, plot_residual_histogram, solver_section, truth_section

__all__ = ["build_report"]

_REQUIRED = ("camera", "model", "labels", "free", "cov", "views", "target", "image_size", "rejected")
#: A residual of 3 sigma is drawn this fraction of the image width long (sub-pixel residuals on a full image).
ARROW_LENGTH = 0.05


def _check_record(result: CalibrationResult) -> None:
    if result.rig != "camera":
        raise FileFormatError(f"a result of rig {result.rig!r}, not 'camera'")
    for key in _REQUIRED:
        if key not in (result.diagnostics or {}):
            raise FileFormatError(f"field 'diagnostics.{key}' is missing: expected a result written by "
                                  "'robocal camera calibrate'")


def _maps(section, cal) -> None:
    from robocal.camera import coverage, projection_uncertainty

    cam = cal.camera
    step = max(cam.width, cam.height) / 40.0
    pu = projection_uncertainty(cal, grid_step_px=step)
    fixed = projection_uncertainty(cal, grid_step_px=step, compensate_rotation=False)
    ue, ve, counts = coverage(cal, cell_px=max(cam.width, cam.height) / 16.0)
    fig, axes = new_figure(1, 2, size=(11.0, 4.2))
    ax = axes[0]
    cs = ax.contourf(pu.u, pu.v, pu.std, levels=12, cmap="viridis")
    fig.colorbar(cs, ax=ax, label="std of the projection [px]")
    ax.set_title("projection uncertainty (up to a camera rotation)")
    ax2 = axes[1]
    m = ax2.pcolormesh(ue, ve, counts, cmap="magma")
    fig.colorbar(m, ax=ax2, label="corners per cell")
    ax2.set_title(f"coverage: {sum(len(v) for v in cal.views)} corners")
    for a in axes:
        a.set_xlim(-0.5, cam.width - 0.5)
        a.set_ylim(cam.height - 0.5, -0.5)
        a.set_aspect("equal")
        a.set_xlabel("u [px]")
        a.set_ylabel("v [px]")
    finite = pu.std[np.isfinite(pu.std)]
    cx, cy = cam.cx, cam.cy
    at = (np.argmin(np.abs(pu.v - cy)), np.argmin(np.abs(pu.u - cx)))
    empty = int(np.sum(counts == 0))
    section.figure(fig, caption=(
        f"left: where a ray lands is known to {pu.std[at]:.3g} px at the image centre and {finite.max():.3g} px "
        f"at worst (mean {finite.mean():.3g} px), from the intrinsics' covariance, up to the small camera rotation "
        f"every pose estimated with this camera absorbs (mrcal's compensating rotation); with the ray held fixed "
        f"in the camera frame (the optical axis as a reference) it is {fixed.std[at]:.3g} px at the centre and "
        f"{np.nanmax(fixed.std):.3g} px at worst. Right: corners per cell, {empty} of {counts.size} cells empty "
        f"(where the distortion is extrapolated, the left map grows)."))


def _residual_vectors(section, cal, base_dir) -> None:
    import cv2

    cam = cal.camera
    fig, ax = new_figure(size=(7.5, 7.5 * cam.height / cam.width + 0.6))
    worst = max(cal.view_rms, key=cal.view_rms.get)
    img = None
    # the view names are the images' paths relative to the result's folder: drawn over when still there
    p = Path(base_dir if base_dir is not None else ".") / worst
    if p.is_file():
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
    if img is not None and img.shape[::-1] == (cam.width, cam.height):
        ax.imshow(img, cmap="gray", alpha=0.5)
    gain = ARROW_LENGTH * cam.width / (3.0 * max(cal.sigma_px, 1e-6))
    for v in cal.views:
        q, r = v.image_points, cal.residuals[v.name]
        colour = "C3" if v.name == worst else "C0"
        # image v runs down; quiver's "xy" angles follow the data axes, which are inverted below
        ax.quiver(q[:, 0], q[:, 1], r[:, 0], r[:, 1], color=colour, angles="xy", scale_units="xy",
                  scale=1.0 / gain, width=0.002)
    ax.set_xlim(-0.5, cam.width - 0.5)
    ax.set_ylim(cam.height - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u [px]")
    ax.set_ylabel("v [px]")
    section.figure(fig, caption=(f"residuals (observed - projected) of every corner used, drawn {gain:.0f}x; "
                                 f"red: the worst view, {worst} ({cal.view_rms[worst]:.3f} px RMS)"
                                 + (", over its image" if img is not None else "")
                                 + ". A pattern (a swirl, arrows pointing out at the edges) is a model the "
                                   "data disagree with; noise looks like noise."))


def _views_table(section, cal, d) -> None:
    rows = []
    for v in cal.views:
        T = cal.poses[v.name]
        tilt = np.degrees(np.arccos(np.clip(abs(T[2, 2]), 0.0, 1.0)))  # board normal against the optical axis
        rows.append({"image": v.name, "corners": len(v), "RMS [px]": cal.view_rms[v.name],
                     "noise [px]": cal.view_sigma.get(v.name),
                     "distance [m]": float(np.linalg.norm(T[:3, 3])), "tilt [deg]": float(tilt),
                     "blur [px]": d.get("blur_px", {}).get(v.name)})
    section.table(rows, ["image", "corners", "RMS [px]", "noise [px]", "distance [m]", "tilt [deg]", "blur [px]"],
                  digits=4, caption="views used: the pixel noise each view is weighted by (one pooled level unless "
                                    "the views' levels differ), distance of the board origin, angle between the "
                                    "board normal and the optical axis (tilted views determine the focal length), "
                                    "edge blur")
    rej = d.get("rejected") or {}
    if rej:
        section.table([{"image": n, "why not used": r} for n, r in rej.items()], ["image", "why not used"],
                      caption=f"{len(rej)} image(s) not used")
    if d.get("outliers"):
        section.text("corners removed as outliers (image # corner id): "
                     + ", ".join(f"{n}#{i}" for n, i in d["outliers"]))
    for note in d.get("detection_notes") or ():
        section.text(note)
    fig, ax = new_figure(size=(8.0, 3.0))
    names = [v.name for v in cal.views]
    ax.bar(range(len(names)), [cal.view_rms[n] for n in names], color="C0")
    ax.axhline(cal.sigma_px, color="C3", lw=1, label=f"noise {cal.sigma_px:.3f} px")
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels([Path(n).stem for n in names], rotation=90, fontsize=7)
    ax.set_ylabel("RMS [px]")
    ax.legend(fontsize=8)
    section.figure(fig, caption="reprojection RMS per view")


def _correlation(section, cal) -> None:
    free = [i for i, lab in enumerate(cal.labels) if lab in cal.free]
    C = cal.cov[np.ix_(free, free)]
    s = np.sqrt(np.diag(C))
    with np.errstate(invalid="ignore", divide="ignore"):
        R = C / np.outer(s, s)
    names = [cal.labels[i] for i in free]
    rows = [{"": a, **{b: (None if not np.isfinite(R[i, j]) else round(float(R[i, j]), 3))
                       for j, b in enumerate(names)}} for i, a in enumerate(names)]
    section.table(rows, ["", *names], digits=3,
                  caption="correlation of the intrinsics; |r| > 0.99 between two terms: the data cannot tell "
                          "them apart (a weakly_determined warning names them)")


def _distortion(section, cam) -> None:
    u = np.linspace(0, cam.width - 1, 48)
    v = np.linspace(0, cam.height - 1, 36)
    uu, vv = np.meshgrid(u, v)
    xy = cam.undistort_points(np.stack([uu, vv], axis=-1))
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy]]) if hasattr(cam, "fx") else cam.K[:2]
    ideal = xy @ K[:, :2].T + K[:, 2]
    shift = np.linalg.norm(np.stack([uu, vv], axis=-1) - ideal, axis=-1)
    fig, ax = new_figure(size=(6.4, 4.6))
    cs = ax.contourf(uu, vv, shift, levels=12, cmap="cividis")
    fig.colorbar(cs, ax=ax, label="|distorted - pinhole| [px]")
    ax.set_xlim(-0.5, cam.width - 0.5)
    ax.set_ylim(cam.height - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_title("distortion: how far a pixel is from where a pinhole camera puts it")
    section.figure(fig, caption=f"largest shift {np.nanmax(shift):.1f} px")


def build_report(result: CalibrationResult, *, base_dir=None, title: str | None = None) -> Report:
    """The report of a camera-rig result (from the result alone; images drawn where still present)."""
    from robocal.rigs.camera.workflow import CAMERA_FILES, calibration_from_result

    _check_record(result)
    d = result.diagnostics
    cal = calibration_from_result(result)
    cam = cal.camera
    w, h = d["image_size"]
    rep = Report(title or "robocal camera: intrinsic calibration",
                 subtitle=f"{d['target']['describe']} in {len(cal.views)} of {d.get('n_images', len(cal.views))} "
                          f"images of {w} x {h} px; model {cal.model}")
    s = rep.section("Intrinsics")
    s.parameters(result.estimate, result.std, result.units)
    s.text(f"reprojection RMS {cal.rms:.4f} px over {sum(len(v) for v in cal.views)} corners; pixel noise "
           f"estimated {cal.sigma_px:.4f} px (the std above are scaled by it); cv2.calibrateCamera's start "
           f"{cal.opencv_rms:.4f} px (its RMS definition).")
    s.diagnostics(result.warnings)
    _maps(rep.section("Projection uncertainty and coverage"), cal)
    r = rep.section("Residuals")
    _residual_vectors(r, cal, base_dir)
    ax = plot_residual_histogram(np.concatenate([cal.residuals[v.name] for v in cal.views]), sigma=cal.sigma_px,
                                 unit="px")
    r.figure(ax.figure, caption="residual components (u and v) of every corner used")
    _views_table(rep.section("Views"), cal, d)
    _distortion(rep.section("Distortion"), cam)
    _correlation(rep.section("Correlation of the intrinsics"), cal)
    solver_section(rep.section("Solver"), d.get("solver") or {},
                   caption="joint least squares over the intrinsics and every view's pose")
    if d.get("truth_note"):
        rep.section("Check against the simulated truth").text(d["truth_note"])
    if d.get("truth_check"):
        t = rep.section("Check against the simulated truth")
        truth_section(t, d["truth_check"])
    o = rep.section("Camera files")
    o.text("The camera is written beside result.json as " + ", ".join(
        f"{n} ({f})" for n, f in CAMERA_FILES.items()) + ". Every camera rig reads any of them: "
        "`camera: {file: camera.yaml}` in its input file.")
    o.text(f"Target: {d['target']['describe']} (from {d['target']['source']}).")
    return rep
