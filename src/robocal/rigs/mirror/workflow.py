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
from robocal.rigs.mirror.files import MirrorInput, load_input, write_input
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


def simulate_files(out_dir, rng: np.random.Generator | None = None, *, placements: int = 1, sigma_px: float = 0.5,
                   images: bool = False, seed: int = 0, progress: bool = False) -> list[Path]:
    """Write ``mirror_input.yaml`` (and PNG images with ``images=True``) for the published scene.

    ``rng``: the run's random generator (default: ``np.random.default_rng(seed)``).
    The file carries a ``truth`` section (``R_r_c``, ``t_r_c`` in mm) that
    ``calibrate`` uses to check the answer (``diagnostics.truth_check``).
    """
    import cv2

    from robocal.rigs.mirror.render import default_body_tags, detect_mirror_image, render_mirror_image

    if int(placements) < 1:
        raise InputError(f"placements: must be >= 1, got {placements}")
    if not np.isfinite(sigma_px) or sigma_px < 0:
        raise InputError(f"sigma_px: must be >= 0, got {sigma_px}")
    out_dir = Path(out_dir)
    rng = np.random.default_rng(seed) if rng is None else rng
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


@dataclass
class MirrorRun:
    """What ``calibrate_input`` hands ``to_result``: the calibration and the folder the result goes to.

    ``base_dir`` makes the image paths of the result relative to the result
    file (:func:`~robocal.rigs.mirror.result.relative_image_paths`).
    """

    calibration: MirrorCalibration
    base_dir: Path


def calibrate_input(inp: MirrorInput, *, out_dir=None, progress: bool = False, accept_implausible: bool = False,
                    no_refine: bool = False, **_) -> MirrorRun:
    """Calibrate from a loaded input (:func:`~robocal.rigs.mirror.files.load_input`).

    ``no_refine``: the patent's single-image estimates only, averaged over the
    images (CLI ``--no-refine``). ``out_dir``: the folder the result will be
    written to (default: the current directory). ``accept_implausible``: see
    :func:`robocal.rigs.mirror.calibrate.calibrate`.
    """
    cal = calibrate(inp.camera, inp.rectangle, inp.body_points_r, inp.observations, sigma_px=inp.sigma_px,
                    refine=not no_refine, progress=progress, accept_implausible=accept_implausible,
                    declared=inp.declared)
    return MirrorRun(cal, Path(out_dir) if out_dir is not None else Path.cwd())


def to_result(run: MirrorRun, inp: MirrorInput) -> CalibrationResult:
    """The result record (:func:`~robocal.rigs.mirror.result.result_from_calibration`) with the inputs' hashes."""
    inputs = hash_inputs([inp.source, *([inp.camera_file] if inp.camera_file else []), *inp.image_paths.values()])
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
    return f"{text}\n{line}" if line else text


def _error_text(e) -> str:
    return f"{np.linalg.norm(e[3:]) * 1e3:.1f} mm / {np.degrees(np.linalg.norm(e[:3])):.2f} deg"


def demo(ctx: DemoContext) -> DemoOutcome:
    """Simulate -> calibrate -> check on the published scene (points, 4 placements) and one rendered image.

    Passes when both answers are consistent with their reported covariance
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
    summary_ = {
        "1 image error": _error_text(e1),
        "4 placements error": _error_text(e4),
        "4 placements std": f"{np.linalg.norm(joint.std_translation) * 1e3:.1f} mm / "
                            f"{np.degrees(np.linalg.norm(joint.std_rotation)):.2f} deg",
        "4 placements NEES": f"{check4['nees']:.2f} (limit {check4['threshold']:.1f})",
        "ArUco image error": f"{np.linalg.norm(e_img[3:]) * 1e3:.1f} mm",
        "ArUco image NEES": f"{check_img['nees']:.2f} (limit {check_img['threshold']:.1f})",
        "time": f"{time.perf_counter() - t0:.1f} s",
    }
    passed = bool(check4["passed"] and check_img["passed"])
    return DemoOutcome(summary=summary_, passed=passed, sections=list(report.sections), result=result)
