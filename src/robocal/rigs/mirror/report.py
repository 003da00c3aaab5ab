"""HTML report of a mirror calibration, drawn from its result record alone.

:func:`build_report` reads only the :class:`~robocal.io.CalibrationResult`
(:mod:`robocal.rigs.mirror.result` puts everything it needs into
``diagnostics``) and the image files named in ``diagnostics.images``, relative
to the result's folder: ``robocal mirror report`` and ``robocal report``
rebuild the page ``robocal mirror calibrate`` wrote. The residual histogram,
the solver table with its cost plot and the truth check are the core's
(:mod:`robocal.report`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle
from robocal.errors import FileFormatError, RobocalError
from robocal.geometry import euler_from_matrix, invert_transform
from robocal.io import CalibrationResult
from robocal.report import Report, new_figure, plot_residual_histogram, solver_section, truth_section
from robocal.rigs.mirror.joint import _layout, residual_model
from robocal.rigs.mirror.model import mirror_plane, virtual_transform
from robocal.rigs.mirror.observation import MirrorObservation
from robocal.rigs.mirror.result import (  # noqa: F401  (re-exported: their former home)
    UNOBSERVABLE,
    pose_error,
    relative_image_paths,
    result_from_calibration,
    upgraded,
)

__all__ = ["build_report", "draw_image_overlay", "relative_image_paths", "result_from_calibration"]


#: What :func:`build_report` reads from a result record: (section, keys).
_REQUIRED = (("estimate", ("T_r_c.rotation", "T_r_c.translation")), ("std", ("T_r_c.rotvec", "T_r_c.translation")),
             ("diagnostics", ("camera", "rectangle", "body_points_r", "observations", "single_image",
                              "mirror_poses")))


def _check_record(result: CalibrationResult) -> None:
    """One-line error for a record that is not a complete mirror result (e.g. another rig's)."""
    if result.rig != "mirror":
        raise FileFormatError(f"a result of rig {result.rig!r}, not 'mirror'")
    for section, keys in _REQUIRED:
        block = getattr(result, section) or {}
        for key in keys:
            if not isinstance(block, dict) or key not in block:
                raise FileFormatError(f"field '{section}.{key}' is missing: expected a result written by "
                                      f"'robocal mirror calibrate' (rig {result.rig!r})")


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
    if ax is None:  # not through pyplot, which keeps every figure open until closed
        _, ax = new_figure(size=(6.4, 5.0), subplot_kw={"projection": "3d"})
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




#: Title of a calibration's report.
TITLE = "robocal mirror — camera-to-robot calibration"


def _observations(d: dict) -> list:
    return [MirrorObservation(np.asarray(o["marker_uv"]), np.asarray(o["body_uv"]),
                              None if o["body_ids"] is None else np.asarray(o["body_ids"], dtype=int), o["name"],
                              marker_sigma_scale=float(o.get("marker_sigma_scale", 1.0)),
                              body_cov=None if o.get("body_cov") is None else np.asarray(o["body_cov"], dtype=float),
                              marker_cov=None if o.get("marker_cov") is None else np.asarray(o["marker_cov"],
                                                                                            dtype=float))
            for o in d["observations"]]


def _image_of(d: dict, name: str, base_dir) -> tuple[np.ndarray | None, str]:
    """The image file of observation ``name`` (``diagnostics.images``, relative to ``base_dir``) and a note."""
    if name not in d.get("images", {}):
        return None, ""
    p = Path(d["images"][name])
    if not p.is_absolute() and base_dir is not None:
        p = Path(base_dir) / p
    img = None
    if p.exists():
        from robocal.camera import read_image

        try:
            img = read_image(p)
        except RobocalError:  # the report still draws the points, on grey
            img = None
    return img, ("" if img is not None else f" Image file not found or unreadable: {p} (points drawn on grey).")


def _pose_section(rep: Report, result: CalibrationResult, cam, rect, n_body: int) -> None:
    d = result.diagnostics
    T_r_c = result.pose("T_r_c").T
    s = rep.section("Camera in the robot frame (robot -> camera)")
    s.parameters(result.estimate, result.std, result.units)
    s.text("std: first-order (sampling) uncertainty. The rotation std is per axis of the rotation vector d of a "
           "left (robot-side) perturbation, R_r_c = Exp(d) R_hat, the side the covariance "
           "(diagnostics.cov_rot_t) uses.")
    rpy = np.degrees(euler_from_matrix("xyz", T_r_c[:3, :3]))
    s.table([{"roll [deg]": rpy[0], "pitch [deg]": rpy[1], "yaw [deg]": rpy[2]}], digits=5,
            caption="the same rotation as roll, pitch, yaw (fixed axes x, y, z), for reading")
    if "truth_T_r_c" in d:
        e = pose_error(T_r_c, d["truth_T_r_c"])
        s.table([{"error": f"translation {a} [mm]", "value": e[3 + i] * 1e3} for i, a in enumerate("xyz")]
                + [{"error": f"rotation vector {a} [deg]", "value": np.degrees(e[i])} for i, a in enumerate("xyz")],
                digits=4, caption="estimate - simulated truth (rotation: rotvec(R_hat R_true^T), left)")
        if "truth_check" in d:
            truth_section(s, d["truth_check"])
    s.text(f"Residual RMS {result.residual_rms:.3g} px over markers and reflected body points.")
    s.text(f"Inputs used: camera {cam.width} x {cam.height} px, fx {cam.fx:.6g}, fy {cam.fy:.6g}, cx {cam.cx:.6g}, "
           f"cy {cam.cy:.6g} px, dist (k1, k2, p1, p2, k3) = ({', '.join(f'{v:.5g}' for v in cam.dist)}); "
           f"mirror rectangle {rect.width * 1e3:.5g} x {rect.height * 1e3:.5g} mm; {n_body} body points.")
    s.text(d.get("unobservable", UNOBSERVABLE))
    s.diagnostics(result.warnings)


def _single_image_section(rep: Report, d: dict) -> None:
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


def _mirror_pose_rows(d: dict) -> list[dict]:
    from robocal.geometry import rotvec_from_matrix

    rows = []
    for m in d["mirror_poses"]:
        T = np.asarray(m["T_c_m"], dtype=float)
        rv = np.degrees(rotvec_from_matrix(T[:3, :3]))
        st = m.get("std_translation")
        sr = m.get("std_rotvec")
        rows.append({"image": m["image"], "t_c_m [mm]": np.round(T[:3, 3] * 1e3, 1).tolist(),
                     "std [mm]": "-" if st is None else np.round(np.asarray(st) * 1e3, 2).tolist(),
                     "rotation vector [deg]": np.round(rv, 2).tolist(),
                     "std [deg]": "-" if sr is None else np.round(np.degrees(np.asarray(sr)), 3).tolist()})
    return rows


def build_report(result: CalibrationResult, *, base_dir=None, title: str = TITLE) -> Report:
    """HTML report from a result record (:func:`~robocal.rigs.mirror.result.result_from_calibration`).

    ``base_dir``: the folder of result.json; the image files of
    ``diagnostics.images`` are read relative to it (default: the current
    directory). Raises :class:`~robocal.errors.FileFormatError` naming the
    first missing field when the record lacks what the report is drawn from.
    A result written before schema 2 (bare ``T_r_c``, ``T_c_m``) is read too
    (:func:`~robocal.rigs.mirror.result.upgraded`).
    """
    if result.rig == "mirror" and (result.diagnostics or {}).get("markerless"):
        from robocal.rigs.mirror.markerless_result import build_markerless_report

        return build_markerless_report(result, base_dir=base_dir)
    result = upgraded(result)
    _check_record(result)
    d = result.diagnostics
    cam = CameraModel.from_dict(d["camera"])
    rect = MarkerRectangle(d["rectangle"]["width"], d["rectangle"]["height"])
    body = np.asarray(d["body_points_r"], dtype=float)
    obs = _observations(d)
    T_r_c = result.pose("T_r_c").T
    T_c_m = np.asarray([m["T_c_m"] for m in d["mirror_poses"]], dtype=float).reshape(-1, 4, 4)
    rep = Report(title, subtitle=f"{len(obs)} image(s); method: {result.method}")
    _pose_section(rep, result, cam, rect, len(body))
    _single_image_section(rep, d)
    s3 = rep.section("Images: detected and reprojected points, frames m and ri")
    if len(obs) > MAX_OVERLAYS:
        s3.text(f"Overlays for the first {MAX_OVERLAYS} of {len(obs)} images; the per-image table above "
                "covers all of them.")
    for k, o in enumerate(obs[:MAX_OVERLAYS]):
        img, note = _image_of(d, o.name, base_dir)
        fig, ax = new_figure(size=(7.0, 5.4))
        draw_image_overlay(cam, rect, body, o, T_r_c, T_c_m[k], image=img, ax=ax)
        s3.figure(fig, caption=f"{o.name}: circles/plus = detected, crosses = reprojected from the estimate; "
                               f"axes x red, y green, z blue.{note}")
    s4 = rep.section("Geometry and residuals")
    ax = _frames_3d(T_r_c, T_c_m, body)
    s4.figure(ax.figure, caption="robot frame r, camera c and mirror frames m_k (in r)")
    s4.table(_mirror_pose_rows(d), digits=4,
             caption="mirror (marker frame) pose per image, camera -> mirror: nuisance parameters of the joint "
                     "problem; std from its covariance (rotation: left, camera-side perturbation), '-' without "
                     "the joint refinement")
    layout = _layout(obs, body, rect)
    mk, bd, _, _, _ = residual_model(cam, rect, layout, T_r_c[:3, :3], T_c_m[:, :3, :3])
    p = {"rot_rc": np.zeros(3), "t_rc": T_r_c[:3, 3], "rot_cm": np.zeros((len(obs), 3)), "t_cm": T_c_m[:, :3, 3]}
    r_m, r_b = mk(p), bd(p)
    sigma = d.get("sigma_px")
    ax = plot_residual_histogram(np.concatenate([r_m.ravel(), r_b.ravel()]), unit="px",
                                 sigma=result.residual_rms if sigma is None else sigma)
    s4.figure(ax.figure, caption="residuals of markers and reflected body points (u and v), projected - observed; "
                                 "the curve: the declared sigma_px, else the residual RMS")
    s4.table(_worst_observations(r_m, r_b, obs, layout), digits=3,
             caption=f"worst {WORST_SHOWN} observations by residual norm (projected - observed), for finding bad "
                     "points; 'point' is the marker letter or the body_points row")
    s5 = rep.section("Joint refinement: solver")
    if d.get("solver"):
        solver_section(s5, d["solver"], caption="the joint least squares over T_r_c and every mirror pose")
    else:
        s5.text("No joint refinement (--no-refine): the answer is the average of the single-image estimates.")
    return rep
