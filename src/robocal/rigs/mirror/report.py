"""Result record and HTML report of a mirror calibration.

:func:`result_from_calibration` packs a :class:`MirrorCalibration` into the
shared ``robocal.result/2`` schema, keeping in ``diagnostics`` everything
needed to redraw the report (camera, rectangle, body model, image points,
per-image patent estimates and planar choices); :func:`build_report` draws
from that record alone, so ``robocal mirror report result.json`` needs no
other file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle
from robocal.geometry import euler_from_matrix, invert_transform, rotvec_from_matrix
from robocal.errors import FileFormatError, RobocalError
from robocal.io import CalibrationResult
from robocal.report import Report, new_figure
from robocal.rigs.mirror.calibrate import MirrorCalibration, MirrorObservation, residual_model, _layout
from robocal.rigs.mirror.model import mirror_plane, virtual_transform

__all__ = ["result_from_calibration", "build_report", "draw_image_overlay", "relative_image_paths"]


#: What no check can see; in every result (``diagnostics.unobservable``) and report.
UNOBSERVABLE = ("What no check can see: t_r_c is measured from the origin of the body model (body_points or "
                "body_tags), so an offset of the model by any vector (x, y or z alike) moves t_r_c by that vector "
                "with identical residuals and warnings; a unit error shared by mirror_rectangle and body_points "
                "scales the answer by the same factor; and for (nearly) coplanar body points a model of the wrong "
                "handedness (x sign) fits too (points on one face x = c: the answer moves by 2c along x). "
                "See docs/rigs/mirror.md, 'What the images cannot tell'.")


def result_from_calibration(cal: MirrorCalibration, *, inputs=None, image_paths=None, truth=None) -> CalibrationResult:
    """The shared result record (SI units; ``T_r_c`` is ``robot -> camera``)."""
    est = {
        "T_r_c": cal.T_r_c.tolist(),
        "t_r_c": cal.T_r_c[:3, 3].tolist(),
        "q_r_c": _quat(cal.T_r_c),
        "rotvec_r_c": rotvec_from_matrix(cal.T_r_c[:3, :3]).tolist(),
        "T_c_m": cal.T_c_m.tolist(),
    }
    std = {"t_r_c": cal.std_translation.tolist(), "rotvec_r_c": cal.std_rotation.tolist()}
    units = {"T_r_c": "m", "t_r_c": "m", "q_r_c": "1", "rotvec_r_c": "rad", "T_c_m": "m"}
    m_res, b_res = cal.residuals()
    allres = np.concatenate([m_res.reshape(-1, 2), *b_res])
    singles = []
    for s in cal.singles:
        singles.append({
            "name": None,
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
        })
    for o, d in zip(cal.observations, singles):
        d["name"] = o.name
    diag = {
        "camera": cal.camera.to_dict(),
        "rectangle": {"width": cal.rectangle.width, "height": cal.rectangle.height},
        "body_points_r": cal.body_points_r.tolist(),
        "observations": [o.to_dict() for o in cal.observations],
        "images": dict(image_paths or {}),  # name -> image file, relative to the folder of result.json
        "single_image": singles,
        "cov_rot_t": cal.cov.tolist(),
        "n_images": len(cal.observations),
        "unobservable": UNOBSERVABLE,
    }
    if cal.lsq is not None:
        diag["solver"] = {"iterations": cal.lsq.iterations, "cost_history": cal.lsq.cost_history.tolist(),
                          "rank": cal.lsq.rank, "condition_number": cal.lsq.condition_number,
                          "success": bool(cal.lsq.success), "message": cal.lsq.message}
    if truth is not None:
        diag["truth_T_r_c"] = np.asarray(truth).tolist()
    return CalibrationResult(
        rig="mirror",
        method="patent single-image (seed 002) + joint refinement" if cal.lsq is not None else "patent single-image",
        estimate=est, std=std, units=units,
        residual_rms=float(np.sqrt(np.mean(allres**2))), residual_unit="px",
        warnings=list(cal.warnings), inputs=dict(inputs or {}), diagnostics=diag,
    )


#: What :func:`build_report` reads from a result record: (section, keys).
_REQUIRED = (("estimate", ("T_r_c", "T_c_m")), ("std", ("t_r_c", "rotvec_r_c")),
             ("diagnostics", ("camera", "rectangle", "body_points_r", "observations", "single_image")))


def _check_record(result: CalibrationResult) -> None:
    """One-line error for a record that is not a complete mirror result (e.g. another rig's)."""
    for section, keys in _REQUIRED:
        block = getattr(result, section) or {}
        for key in keys:
            if not isinstance(block, dict) or key not in block:
                raise FileFormatError(f"field '{section}.{key}' is missing: expected a result written by "
                                      f"'robocal mirror calibrate' (rig {result.rig!r})")


def _quat(T):
    from robocal.geometry import quaternion_from_matrix

    return quaternion_from_matrix(np.asarray(T)[:3, :3]).tolist()


def draw_image_overlay(camera: CameraModel, rectangle: MarkerRectangle, body_points_r, obs: MirrorObservation,
                       T_r_c, T_c_m, image=None, ax=None, title: str = ""):
    """Image with detected and reprojected points and the frames m and ri drawn (pure; returns ax)."""
    if ax is None:
        _, ax = new_figure(size=(7.0, 5.4))
    if image is not None:
        ax.imshow(image, cmap="gray", vmin=0, vmax=255)
    else:
        ax.imshow(np.full((camera.height, camera.width), 200, np.uint8), cmap="gray", vmin=0, vmax=255)
    T_c_r = invert_transform(np.asarray(T_r_c))
    n, d = mirror_plane(T_c_m)
    T_c_ri = virtual_transform(T_c_r, n, d)
    ids = np.arange(len(body_points_r)) if obs.body_ids is None else np.asarray(obs.body_ids)
    p_v = (body_points_r[ids] @ T_c_r[:3, :3].T + T_c_r[:3, 3])
    p_v = p_v - 2.0 * (p_v @ n - d)[:, None] * n
    uv_b = camera.project(p_v, check=False)
    uv_m = camera.project_points(rectangle.object_points(), T_c_m, check=False)
    ax.plot(*obs.marker_uv.T, "o", mfc="none", mec="tab:red", ms=9, label="markers (detected)")
    ax.plot(*uv_m.T, "x", color="gold", ms=7, label="markers (reprojected)")
    ax.plot(*obs.body_uv.T, "+", color="tab:blue", ms=8, label="reflected body points (detected)")
    ax.plot(*uv_b.T, "x", color="tab:orange", ms=5, label="reflected body points (reprojected)")
    for T, L, name in ((T_c_m, 0.1, "m"), (T_c_ri, 0.2, "ri")):
        o = camera.project(T[:3, 3][None], check=False)[0]
        for axis, col in zip(range(3), ("r", "g", "b")):
            e = camera.project((T[:3, 3] + L * T[:3, axis])[None], check=False)[0]
            if np.all(np.isfinite([*o, *e])):
                ax.plot([o[0], e[0]], [o[1], e[1]], "-", color=col, lw=2)
        if np.all(np.isfinite(o)):
            ax.annotate(name, o, color="k", fontsize=9, xytext=(4, 4), textcoords="offset points")
    pts = np.vstack([obs.marker_uv, obs.body_uv])
    lo, hi = pts.min(axis=0) - 60, pts.max(axis=0) + 60
    ax.set_xlim(max(lo[0], -0.5), min(hi[0], camera.width - 0.5))
    ax.set_ylim(min(hi[1], camera.height - 0.5), max(lo[1], -0.5))
    ax.set_title(title or obs.name)
    ax.legend(loc="lower left", fontsize=7)
    return ax


def _frames_3d(T_r_c, T_c_m, body_points_r, ax=None):
    """Robot frame r, camera c, mirror(s) m and body points, in r (pure; returns ax)."""
    if ax is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(6.4, 5.0))
        ax = fig.add_subplot(projection="3d")
    T_r_c = np.asarray(T_r_c)
    ax.scatter(*np.asarray(body_points_r).T, s=8, c="tab:blue", label="body points")
    frames = [("r", np.eye(4), 0.2), ("c", T_r_c, 0.15)]
    frames += [(f"m{k}", T_r_c @ T, 0.15) for k, T in enumerate(np.asarray(T_c_m).reshape(-1, 4, 4))]
    for name, T, L in frames:
        for axis, col in zip(range(3), ("r", "g", "b")):
            e = T[:3, 3] + L * T[:3, axis]
            ax.plot([T[0, 3], e[0]], [T[1, 3], e[1]], [T[2, 3], e[2]], color=col)
        ax.text(*T[:3, 3], name)
    ax.set_xlabel("x_r [m]")
    ax.set_ylabel("y_r [m]")
    ax.set_zlabel("z_r [m]")
    ax.set_title("frames in the robot frame r")
    return ax


#: Image overlays drawn in a report (the rest are listed, not drawn: a report stays a few MB).
MAX_OVERLAYS = 4


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


#: Rows of the worst-observations table.
WORST_SHOWN = 5


def _worst_observations(marker_res, body_res, obs, layout) -> list[dict]:
    """The ``WORST_SHOWN`` largest residuals [px], named by image and marker letter / body point row."""
    K = len(obs)
    names = [(obs[k].name, f"marker {'ABCD'[i]}") for k in range(K) for i in range(4)]
    names += [(obs[k].name, f"body point {int(j)}") for k in range(K) for j in layout.ids[k]]
    r = np.vstack([np.asarray(marker_res).reshape(-1, 2), np.asarray(body_res).reshape(-1, 2)])
    norm = np.linalg.norm(r, axis=1)
    return [{"image": names[i][0], "point": names[i][1], "du [px]": r[i, 0], "dv [px]": r[i, 1],
             "|r| [px]": norm[i]} for i in np.argsort(-norm)[:WORST_SHOWN]]


def build_report(result: CalibrationResult, *, title: str = "robocal mirror — camera-to-robot calibration",
                 images=None, base_dir=None) -> Report:
    """HTML report from a result record (see :func:`result_from_calibration`).

    ``images``: optional ``{observation name: image array}`` drawn under the
    overlays; otherwise the files of ``diagnostics.images`` are read, relative
    paths from ``base_dir`` (the folder of result.json; default: the current
    directory).

    Raises :class:`~robocal.errors.FileFormatError` naming the first missing
    field when the record lacks what the report is drawn from.
    """
    _check_record(result)
    d = result.diagnostics
    cam = CameraModel.from_dict(d["camera"])
    rect = MarkerRectangle(d["rectangle"]["width"], d["rectangle"]["height"])
    body = np.asarray(d["body_points_r"], dtype=float)
    obs = [MirrorObservation(np.asarray(o["marker_uv"]), np.asarray(o["body_uv"]),
                             None if o["body_ids"] is None else np.asarray(o["body_ids"], dtype=int), o["name"],
                             marker_sigma_scale=float(o.get("marker_sigma_scale", 1.0)),
                             body_cov=None if o.get("body_cov") is None else np.asarray(o["body_cov"], dtype=float),
                             marker_cov=None if o.get("marker_cov") is None else np.asarray(o["marker_cov"], dtype=float))
           for o in d["observations"]]
    T_r_c = np.asarray(result.estimate["T_r_c"])
    T_c_m = np.asarray(result.estimate["T_c_m"]).reshape(-1, 4, 4)
    rep = Report(title, subtitle=f"{len(obs)} image(s); method: {result.method}")
    s = rep.section("Camera in the robot frame (robot -> camera)")
    rpy = np.degrees(euler_from_matrix("xyz", T_r_c[:3, :3]))
    std_t = np.asarray(result.std["t_r_c"]) * 1e3
    std_r = np.degrees(np.asarray(result.std["rotvec_r_c"]))
    rows = [{"quantity": f"t_r_c {a} [mm]", "value": T_r_c[i, 3] * 1e3, "std": std_t[i]} for i, a in enumerate("xyz")]
    rows += [{"quantity": f"rpy {a} [deg]", "value": rpy[i], "std": std_r[i]} for i, a in enumerate(("roll", "pitch", "yaw"))]
    if "truth_T_r_c" in d:
        Tt = np.asarray(d["truth_T_r_c"])
        e_r = np.degrees(rotvec_from_matrix(T_r_c[:3, :3] @ Tt[:3, :3].T))
        e_t = (T_r_c[:3, 3] - Tt[:3, 3]) * 1e3
        for i, r in enumerate(rows):
            r["error vs truth"] = e_t[i] if i < 3 else e_r[i - 3]
    s.table(rows, digits=4, caption="std: first-order (sampling) uncertainty; rotation std is per axis of the "
                                    "robot-side rotation vector, shown next to roll/pitch/yaw for scale")
    s.text(f"Residual RMS {result.residual_rms:.3g} px over markers and reflected body points.")
    s.text(f"Inputs used: camera {cam.width} x {cam.height} px, fx {cam.fx:.6g}, fy {cam.fy:.6g}, cx {cam.cx:.6g}, "
           f"cy {cam.cy:.6g} px, dist (k1, k2, p1, p2, k3) = ({', '.join(f'{v:.5g}' for v in cam.dist)}); "
           f"mirror rectangle {rect.width * 1e3:.5g} x {rect.height * 1e3:.5g} mm; {len(body)} body points.")
    s.text(UNOBSERVABLE)
    s.diagnostics(result.warnings)
    s2 = rep.section("Per image: the patent's single-image estimate and the planar (IPPE) choice")
    rows = []
    for si in d["single_image"]:
        Ts = np.asarray(si["T_r_c"])
        pc = si["planar_choice"]
        alt = "-"
        if pc.get("ambiguous") and "candidate_T_r_c" in pc:
            Ta = np.asarray(pc["candidate_T_r_c"])[1 - int(pc["chosen"])]
            alt = np.round(Ta[:3, 3] * 1e3, 1).tolist()
        rows.append({"image": si["name"], "t_r_c [mm]": np.round(Ts[:3, 3] * 1e3, 1).tolist(),
                     "marker rms [px]": si["marker_rms_px"], "body rms [px]": si["body_rms_px"],
                     "|Householder - patent|": si["householder_minus_patent"],
                     "IPPE pose": pc["chosen"],
                     "decisive": ("-" if pc.get("ambiguous") is False else
                                  "yes" if pc.get("decisive", True) else "NO (guess)"),
                     "other pose's t_r_c [mm]": alt, "why": pc["reason"]})
    s2.table(rows, digits=4, caption="rms per coordinate (u, v). IPPE returns two poses of the four coplanar "
                                     "markers; pose 0 is the one with the lower marker reprojection error. "
                                     "'decisive' = a test separated them (else the pick is a guess, and "
                                     "'other pose's t_r_c' is the equally likely alternative answer); "
                                     "'-' = both poses coincide, nothing to choose.")
    s3 = rep.section("Images: detected and reprojected points, frames m and ri")
    images = images or {}
    if len(obs) > MAX_OVERLAYS:
        s3.text(f"Overlays for the first {MAX_OVERLAYS} of {len(obs)} images; the per-image table above "
                "covers all of them.")
    for k, o in enumerate(obs[:MAX_OVERLAYS]):
        img = images.get(o.name)
        note = ""
        if img is None and o.name in d.get("images", {}):
            p = Path(d["images"][o.name])
            if not p.is_absolute() and base_dir is not None:
                p = Path(base_dir) / p
            if p.exists():
                from robocal.camera import read_image

                try:
                    img = read_image(p)
                except RobocalError:  # the report still draws the points, on grey
                    img = None
            if img is None:
                note = f" Image file not found or unreadable: {p} (points drawn on grey)."
        fig, ax = new_figure(size=(7.0, 5.4))
        draw_image_overlay(cam, rect, body, o, T_r_c, T_c_m[k], image=img, ax=ax)
        s3.figure(fig, caption=f"{o.name}: circles/plus = detected, crosses = reprojected from the estimate; "
                               f"axes x red, y green, z blue.{note}")
    s4 = rep.section("Geometry")
    ax = _frames_3d(T_r_c, T_c_m, body)
    s4.figure(ax.figure, caption="robot frame r, camera c and mirror frames m_k (in r)")
    layout = _layout(obs, body, rect)
    mk, bd, _, _, _ = residual_model(cam, rect, layout, T_r_c[:3, :3], T_c_m[:, :3, :3])
    p = {"rot_rc": np.zeros(3), "t_rc": T_r_c[:3, 3], "rot_cm": np.zeros((len(obs), 3)), "t_cm": T_c_m[:, :3, 3]}
    fig, ax = new_figure()
    ax.hist(np.concatenate([mk(p).ravel(), bd(p).ravel()]), bins=30, color="tab:gray")
    ax.set_xlabel("reprojection residual [px]")
    ax.set_ylabel("count")
    s4.figure(fig, caption="residuals of markers and reflected body points (u and v)")
    s4.table(_worst_observations(mk(p), bd(p), obs, layout), digits=3,
             caption=f"worst {WORST_SHOWN} observations by residual norm (projected - observed), for finding bad "
                     "points; 'point' is the marker letter or the body_points row")
    if "solver" in d and len(d["solver"]["cost_history"]) > 1:
        fig, ax = new_figure()
        ax.semilogy(d["solver"]["cost_history"], "o-")
        ax.set_xlabel("iteration")
        ax.set_ylabel("cost")
        s4.figure(fig, caption="joint refinement: cost per accepted step")
    return rep


