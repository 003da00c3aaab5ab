"""The mirror rig's steps of the rig contract (:mod:`robocal.workflow`): library functions, no argparse.

``simulate_files`` -> ``load_input`` -> ``calibrate_input`` -> ``to_result``
-> :func:`robocal.rigs.mirror.report.build_report`, plus ``summary`` (the
lines printed after ``robocal mirror calibrate``) and ``demo``. The core
(:mod:`robocal.cli._workflow`) runs them; :mod:`robocal.rigs.mirror.cli`
only declares them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from robocal.errors import InputError
from robocal.io import CalibrationResult, hash_inputs
from robocal.rigs.mirror.calibrate import MirrorCalibration, calibrate
from robocal.rigs.mirror.files import MarkerlessInput, MirrorInput, load_input, write_input, write_markerless_input
from robocal.rigs.mirror.model import MirrorScene
from robocal.rigs.mirror.result import pose_error, relative_image_paths, result_from_calibration
from robocal.rigs.mirror.simulate import default_setup, simulate_observations
from robocal.workflow import DemoContext, DemoOutcome

__all__ = ["simulate_files", "load_input", "calibrate_input", "to_result", "summary", "planar_summary", "demo",
           "MirrorRun", "INPUT_NAME"]

#: The input file ``simulate`` writes (``Workflow.simulated_inputs``).
INPUT_NAME = "mirror_input.yaml"


def _truth_block(T_r_c) -> dict:
    T = np.asarray(T_r_c)
    return {"R_r_c": np.round(T[:3, :3], 12).tolist(), "t_r_c": np.round(T[:3, 3] * 1e3, 9).tolist()}


#: Tilt size [deg] of the simulated markerless mirror poses: the accuracy comes from the angles between the
#: normals (at the patent path's 8 deg, 3 poses of the published scene are often nearly degenerate).
MARKERLESS_TILT_DEG = 30.0


def spread_subset(P, k: int) -> np.ndarray:
    """Row indices of ``k`` well-spread points of ``P`` (farthest-point order from row 0), sorted."""
    P = np.asarray(P, dtype=float)
    idx = [0]
    dist = np.linalg.norm(P - P[0], axis=1)
    while len(idx) < min(int(k), len(P)):
        idx.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(P - P[idx[-1]], axis=1))
    return np.sort(np.array(idx))


def markerless_setup(mirrors: int, rng: np.random.Generator, *, points: int = 20):
    """``(camera, scene, points_r)``: the published scene with ``mirrors`` poses tilted by up to
    :data:`MARKERLESS_TILT_DEG`, and ``points`` of its body points as the reference points."""
    cam, scene = default_setup(mirrors, rng, tilt_deg=MARKERLESS_TILT_DEG)
    return cam, scene, scene.body_points_r[spread_subset(scene.body_points_r, points)]


def simulate_files(out_dir, rng: np.random.Generator | None = None, *, placements: int = 1, sigma_px: float = 0.5,
                   images: bool = False, markerless: bool = False, mirrors: int = 3, points: int = 20,
                   seed: int = 0, progress: bool = False) -> list[Path]:
    """Write ``mirror_input.yaml`` (and PNG images with ``images=True``) for the published scene.

    ``rng``: the run's random generator (default: ``np.random.default_rng(seed)``).
    The file carries a ``truth`` section (``R_r_c``, ``t_r_c`` in mm) that
    ``calibrate`` uses to check the answer (``diagnostics.truth_check``).
    ``markerless``: the markerless form instead (no marker rectangle,
    ``mirrors`` poses tilted by up to :data:`MARKERLESS_TILT_DEG`, ``points``
    well-spread body points as reference points; ``placements`` unused).
    """
    import cv2

    from robocal.rigs.mirror.render import default_body_tags, detect_mirror_image, render_mirror_image

    if int(placements) < 1:
        raise InputError(f"placements: must be >= 1, got {placements}")
    if not np.isfinite(sigma_px) or sigma_px < 0:
        raise InputError(f"sigma_px: must be >= 0, got {sigma_px}")
    out_dir = Path(out_dir)
    rng = np.random.default_rng(seed) if rng is None else rng
    if markerless:
        from robocal.rigs.mirror.markerless import MIN_POINTS, MIN_POSES, simulate_markerless

        if images:
            return _simulate_markerless_images(out_dir, rng, int(mirrors))
        if int(mirrors) < MIN_POSES or int(points) < MIN_POINTS:
            raise InputError(f"--mirrors and --points: need >= {MIN_POSES} mirror poses and >= {MIN_POINTS} points, "
                             f"got {mirrors} and {points}")
        cam, scene, P = markerless_setup(int(mirrors), rng, points=int(points))
        n, d = scene.planes()
        obs = simulate_markerless(cam, scene.T_c_r, P, n, d, rng, sigma_px=sigma_px)
        path = write_markerless_input(out_dir / INPUT_NAME, cam, P, obs, sigma_px=sigma_px if sigma_px > 0 else None,
                                      comment=f"robocal mirror simulate --markerless: {mirrors} mirror poses, "
                                              f"{len(P)} reference points, {sigma_px} px noise")
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(yaml.safe_dump({"truth": _truth_block(scene.T_r_c)}, default_flow_style=None))
        return [path]
    cam, scene = default_setup(placements, rng)
    written = []
    if images:
        tags = default_body_tags()
        scene = MirrorScene(scene.T_c_r, scene.T_c_m, tags.body_points_r(), scene.rectangle)
        files = {}
        obs = []
        for k in range(scene.n_placements):
            img = render_mirror_image(cam, scene, tags, placement=k, rng=rng)
            name = f"placement_{k}.png"
            cv2.imwrite(str(out_dir / name), img)
            written.append(out_dir / name)
            files[k] = name
            obs.append(detect_mirror_image(img, cam, tags, name=f"placement {k}", rectangle=scene.rectangle))
        path = write_input(out_dir / INPUT_NAME, cam, scene.rectangle, None, obs, tags=tags, image_files=files,
                           comment="robocal mirror simulate --images: rendered images, ArUco tags on the body")
    else:
        obs = simulate_observations(cam, scene, rng, sigma_px=sigma_px)
        # sigma_px: 0 is no noise model calibrate can use (it must be > 0): leave it out, so the noise
        # level is estimated from the residuals
        path = write_input(out_dir / INPUT_NAME, cam, scene.rectangle, scene.body_points_r, obs,
                           sigma_px=sigma_px if sigma_px > 0 else None,
                           comment=f"robocal mirror simulate: {placements} placement(s), {sigma_px} px noise")
    with open(path, "a", encoding="utf-8") as fh:  # ground truth, for the report only
        fh.write(yaml.safe_dump({"truth": _truth_block(scene.T_r_c)}, default_flow_style=None))
    written.append(path)
    return written


#: The reference target of ``simulate --markerless --images``: a 5 x 7 chessboard (inner corners, 40 mm squares)
#: on the body's front face (x_r = 0.46 m), upright, facing forward (target z = -x_r, x = y_r, y = -z_r).
SIM_TARGET = {"rows": 5, "cols": 7, "square_mm": 40.0,
              "R_r_t": [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]], "t_r_t_mm": [460.0, -120.0, 270.0]}


def _simulate_markerless_images(out_dir: Path, rng: np.random.Generator, mirrors: int) -> list[Path]:
    """``simulate --markerless --images``: a chessboard on the body seen in ``mirrors`` mirror poses, rendered
    (:func:`~robocal.rigs.mirror.mirrored_target.render_mirrored_target`, 0.6 px blur, grey noise 2)."""
    import cv2

    from robocal.camera import ChessboardTarget
    from robocal.geometry import transform_from
    from robocal.io import atomic_write_text
    from robocal.rigs.mirror.mirrored_target import render_mirrored_target

    cam, scene, _ = markerless_setup(int(mirrors), rng)
    target = ChessboardTarget(SIM_TARGET["rows"], SIM_TARGET["cols"], SIM_TARGET["square_mm"] / 1e3)
    T_r_t = transform_from(np.array(SIM_TARGET["R_r_t"]), np.array(SIM_TARGET["t_r_t_mm"]) / 1e3)
    n, d = scene.planes()
    written, poses = [], []
    for j in range(len(n)):
        img = render_mirrored_target(cam, target, scene.T_c_r @ T_r_t, n[j], d[j], rng, blur_sigma=0.6,
                                     noise_sigma=2.0)
        name = f"mirror_pose_{j}.png"
        cv2.imwrite(str(out_dir / name), img)
        written.append(out_dir / name)
        poses.append({"name": f"mirror pose {j}", "image": name})
    cam_d = cam.to_dict()
    cam_d.pop("units", None)
    cam_d.pop("model", None)
    doc = {"units": {"length": "mm", "pixel": "px"}, "camera": cam_d,
           "reference_target": {"chessboard": {"rows": target.rows, "cols": target.cols,
                                               "square": SIM_TARGET["square_mm"]},
                                "R_r_t": SIM_TARGET["R_r_t"], "t_r_t": SIM_TARGET["t_r_t_mm"]},
           "mirror_poses": poses, "truth": _truth_block(scene.T_r_c)}
    path = out_dir / INPUT_NAME
    atomic_write_text(path, f"# robocal mirror simulate --markerless --images: a chessboard on the body seen in "
                            f"{mirrors} mirror poses (no mirror markers)\n"
                      + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    written.append(path)
    return written


@dataclass
class MirrorRun:
    """What ``calibrate_input`` hands ``to_result``: the calibration and the folder the result goes to.

    ``base_dir`` makes the image paths of the result relative to the result
    file (:func:`~robocal.rigs.mirror.result.relative_image_paths`).
    """

    calibration: MirrorCalibration  # or a MarkerlessCalibration (markerless input)
    base_dir: Path


def calibrate_input(inp: MirrorInput, *, out_dir=None, progress: bool = False, accept_implausible: bool = False,
                    no_refine: bool = False, **_) -> MirrorRun:
    """Calibrate from a loaded input (:func:`~robocal.rigs.mirror.files.load_input`).

    ``no_refine``: the patent's single-image estimates only, averaged over the
    images (CLI ``--no-refine``). ``out_dir``: the folder the result will be
    written to (default: the current directory). ``accept_implausible``: see
    :func:`robocal.rigs.mirror.calibrate.calibrate`.
    """
    if isinstance(inp, MarkerlessInput):
        from robocal.rigs.mirror.markerless import calibrate_markerless

        cal = calibrate_markerless(inp.camera, inp.points_r, inp.observations, sigma_px=inp.sigma_px,
                                   refine=not no_refine, accept_implausible=accept_implausible,
                                   declared=inp.declared, progress=progress)
        return MirrorRun(cal, Path(out_dir) if out_dir is not None else Path.cwd())
    if inp.markerless_poses:  # mixed data: poses with markers and without, one joint problem
        from robocal.rigs.mirror.mixed import calibrate_mixed

        cal = calibrate_mixed(inp.camera, inp.rectangle, inp.body_points_r, inp.observations, inp.markerless_poses,
                              sigma_px=inp.sigma_px, accept_implausible=accept_implausible)
        return MirrorRun(cal, Path(out_dir) if out_dir is not None else Path.cwd())
    cal = calibrate(inp.camera, inp.rectangle, inp.body_points_r, inp.observations, sigma_px=inp.sigma_px,
                    refine=not no_refine, progress=progress, accept_implausible=accept_implausible,
                    declared=inp.declared)
    return MirrorRun(cal, Path(out_dir) if out_dir is not None else Path.cwd())


def to_result(run: MirrorRun, inp: MirrorInput) -> CalibrationResult:
    """The result record (:func:`~robocal.rigs.mirror.result.result_from_calibration`) with the inputs' hashes."""
    inputs = hash_inputs([inp.source, *([inp.camera_file] if inp.camera_file else []), *inp.image_paths.values()])
    if isinstance(inp, MarkerlessInput) or getattr(inp, "markerless_poses", None):
        from robocal.rigs.mirror.markerless_result import result_from_markerless

        return result_from_markerless(run.calibration, inputs=inputs, truth=inp.truth, sigma_px=inp.sigma_px)
    return result_from_calibration(run.calibration, inputs=inputs,
                                   image_paths=relative_image_paths(inp.image_paths, run.base_dir),
                                   truth=inp.truth, sigma_px=inp.sigma_px)


def planar_summary(result: CalibrationResult) -> str:
    """One line on the marker planar ambiguity ('' when no image had two distinct poses)."""
    singles = result.diagnostics.get("single_image") or []
    amb = [s for s in singles if s["planar_choice"].get("ambiguous")]
    if not amb:
        return ""
    guessed = [s["name"] for s in amb if not s["planar_choice"].get("decisive", True)]
    text = (f"planar choice: {len(amb)} of {len(singles)} image(s) had two marker poses; "
            f"{len(amb) - len(guessed)} decided by a test")
    if guessed:
        text += f", {len(guessed)} guessed ({', '.join(guessed)})"
    return text + "; reasons and the other pose's answer in report.html"


def summary(result: CalibrationResult) -> str:
    """The lines printed after ``robocal mirror calibrate``: ``t_r_c`` with its std, the rotation std, the planar choice."""
    pose = result.pose("T_r_c")
    t = pose.T[:3, 3] * 1e3
    s = pose.std_translation * 1e3
    text = (f"t_r_c = [{t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}] mm  (std {s[0]:.1f}, {s[1]:.1f}, {s[2]:.1f} mm); "
            f"rotation std {np.degrees(pose.std_rotation).max():.3g} deg")
    line = planar_summary(result)
    cond = (result.diagnostics.get("conditioning") or {}).get("text")
    if cond:  # markerless: the conditioning in words
        line = f"{line}\n" if line else ""
        line += f"conditioning: {cond}"
    return f"{text}\n{line}" if line else text


def _error_text(e) -> str:
    return f"{np.linalg.norm(e[3:]) * 1e3:.1f} mm / {np.degrees(np.linalg.norm(e[:3])):.2f} deg"


def demo(ctx: DemoContext) -> DemoOutcome:
    """Simulate -> calibrate -> check on the published scene (points, 4 placements), one rendered image, and the
    markerless method next to the patent's on 4 mirror poses tilted by up to 30 deg.

    Passes when the three answers are consistent with their reported covariance
    (:func:`robocal.estimation.truth_check`, NEES over the 6 pose parameters).
    """
    import cv2

    from robocal.rigs.mirror.render import default_body_tags, detect_mirror_image, render_mirror_image
    from robocal.rigs.mirror.report import build_report

    out_dir = Path(ctx.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = ctx.rng
    t0 = time.perf_counter()
    cam, scene = default_setup(4, rng)
    obs = simulate_observations(cam, scene, rng, sigma_px=0.5)
    single = calibrate(cam, scene.rectangle, scene.body_points_r, obs[:1], sigma_px=0.5)
    joint = calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    e1 = pose_error(single.T_r_c, scene.T_r_c)
    e4 = pose_error(joint.T_r_c, scene.T_r_c)
    result = result_from_calibration(joint, truth=scene.T_r_c, sigma_px=0.5)
    report = build_report(result, base_dir=out_dir, title="mirror demo: published scene, 4 mirror placements, 0.5 px")
    # the image path: one rendered image, ArUco tags on the body found in the flipped image
    tags = default_body_tags()
    scene_tags = MirrorScene(scene.T_c_r, scene.T_c_m[:1], tags.body_points_r(), scene.rectangle)
    img = render_mirror_image(cam, scene_tags, tags, rng=rng)
    cv2.imwrite(str(out_dir / "rendered_image.png"), img)
    obs_img = detect_mirror_image(img, cam, tags, name="rendered image", rectangle=scene.rectangle)
    cal_img = calibrate(cam, scene.rectangle, scene_tags.body_points_r, [obs_img])
    e_img = pose_error(cal_img.T_r_c, scene.T_r_c)
    res_img = result_from_calibration(cal_img, truth=scene.T_r_c, image_paths={"rendered image": "rendered_image.png"})
    rep_img = build_report(res_img, base_dir=out_dir)
    check4, check_img = result.diagnostics["truth_check"], res_img.diagnostics["truth_check"]
    sec = report.section("ArUco path: one rendered image")
    sec.text(f"{len(obs_img.body_ids) // 4} of {len(tags.ids)} body tags found in the flipped image; "
             f"error {np.linalg.norm(e_img[3:]) * 1e3:.1f} mm / {np.degrees(np.linalg.norm(e_img[:3])):.2f} deg "
             f"(reported std {np.linalg.norm(cal_img.std_translation) * 1e3:.1f} mm); NEES {check_img['nees']:.2f} "
             f"over {check_img['dof']} parameters, limit {check_img['threshold']:.1f}.")
    for s in rep_img.sections:
        if s.title.startswith("Images"):
            report.extend([s], prefix="ArUco")
    report.write(out_dir / "report.html")
    # markerless (issue 14) next to the patent's method on the same 4 mirror poses, tilted by up to 30 deg
    from robocal.rigs.mirror.markerless import calibrate_markerless, simulate_markerless
    from robocal.rigs.mirror.markerless_result import result_from_markerless

    cam_ml, scene_ml, P_ml = markerless_setup(4, rng)
    n_ml, d_ml = scene_ml.planes()
    cal_ml = calibrate_markerless(cam_ml, P_ml, simulate_markerless(cam_ml, scene_ml.T_c_r, P_ml, n_ml, d_ml, rng,
                                                                    sigma_px=0.5), sigma_px=0.5)
    cal_pat = calibrate(cam_ml, scene_ml.rectangle, P_ml, simulate_observations(cam_ml, scene_ml, rng, sigma_px=0.5),
                        sigma_px=0.5)
    res_ml = result_from_markerless(cal_ml, truth=scene_ml.T_r_c, sigma_px=0.5)
    check_ml = res_ml.diagnostics["truth_check"]
    e_ml, e_cf = pose_error(cal_ml.T_r_c, scene_ml.T_r_c), pose_error(cal_ml.T_r_c_closed_form, scene_ml.T_r_c)
    e_pat = pose_error(cal_pat.T_r_c, scene_ml.T_r_c)
    sec = report.section("Markerless (no mirror markers) next to the patent's method, same 4 mirror poses")
    sec.table([{"method": name, "error": _error_text(e), "reported std": std}
               for name, e, std in (
                   ("markerless closed form (Takahashi et al. 2012)", e_cf, "-"),
                   ("markerless refined", e_ml, f"{np.linalg.norm(cal_ml.std_translation) * 1e3:.1f} mm / "
                                                f"{np.degrees(np.linalg.norm(cal_ml.std_rotation)):.2f} deg"),
                   ("patent + joint (markers)", e_pat, f"{np.linalg.norm(cal_pat.std_translation) * 1e3:.1f} mm / "
                                                       f"{np.degrees(np.linalg.norm(cal_pat.std_rotation)):.2f} deg"))],
              caption=f"{len(P_ml)} body points, 0.5 px; markerless NEES {check_ml['nees']:.2f} (limit "
                      f"{check_ml['threshold']:.1f}). Conditioning: {cal_ml.conditioning['text']}")
    summary_ = {
        "1 image error": _error_text(e1),
        "4 placements error": _error_text(e4),
        "4 placements std": f"{np.linalg.norm(joint.std_translation) * 1e3:.1f} mm / "
                            f"{np.degrees(np.linalg.norm(joint.std_rotation)):.2f} deg",
        "4 placements NEES": f"{check4['nees']:.2f} (limit {check4['threshold']:.1f})",
        "ArUco image error": f"{np.linalg.norm(e_img[3:]) * 1e3:.1f} mm",
        "ArUco image NEES": f"{check_img['nees']:.2f} (limit {check_img['threshold']:.1f})",
        "markerless 4 poses error": f"{_error_text(e_ml)} (closed form {_error_text(e_cf)}; patent on the same "
                                    f"poses {_error_text(e_pat)})",
        "markerless NEES": f"{check_ml['nees']:.2f} (limit {check_ml['threshold']:.1f})",
        "time": f"{time.perf_counter() - t0:.1f} s",
    }
    passed = bool(check4["passed"] and check_img["passed"] and check_ml["passed"])
    return DemoOutcome(summary=summary_, passed=passed, sections=list(report.sections), result=result)
