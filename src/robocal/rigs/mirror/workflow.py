"""End-to-end workflows behind the CLI and the demo (library functions, no argparse)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import yaml

from robocal.errors import InputError, RobocalError
from robocal.io import hash_inputs, load_document
from robocal.rigs.mirror.calibrate import MirrorCalibration, calibrate
from robocal.rigs.mirror.files import load_input, write_input
from robocal.rigs.mirror.model import MirrorScene
from robocal.rigs.mirror.montecarlo import pose_error
from robocal.rigs.mirror.render import default_body_tags, detect_mirror_image, render_mirror_image
from robocal.rigs.mirror.report import build_report, relative_image_paths, result_from_calibration
from robocal.rigs.mirror.simulate import default_setup, simulate_observations

__all__ = ["simulate_files", "calibrate_file", "planar_summary", "demo"]

INPUT_NAME = "mirror_input.yaml"


def _truth_block(T_r_c) -> dict:
    T = np.asarray(T_r_c)
    return {"R_r_c": np.round(T[:3, :3], 12).tolist(), "t_r_c": np.round(T[:3, 3] * 1e3, 9).tolist()}


def simulate_files(out_dir, *, placements: int = 1, sigma_px: float = 0.5, seed: int = 0,
                   images: bool = False) -> list[Path]:
    """Write ``mirror_input.yaml`` (and PNG images with ``images=True``) for the published scene.

    The file carries a ``truth`` section (``R_r_c``, ``t_r_c`` in mm) that
    ``calibrate`` uses to report errors.
    """
    import cv2

    if int(placements) < 1:
        raise InputError(f"placements: must be >= 1, got {placements}")
    if not np.isfinite(sigma_px) or sigma_px < 0:
        raise InputError(f"sigma_px: must be >= 0, got {sigma_px}")
    out_dir = Path(out_dir)
    rng = np.random.default_rng(seed)
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


def _read_truth(path) -> np.ndarray | None:
    doc = load_document(path)
    if "truth" not in doc:
        return None
    t = doc.sub("truth")
    T = np.eye(4)
    T[:3, :3] = t.array("R_r_c", shape=(3, 3))
    T[:3, 3] = t.array("t_r_c", kind="length", shape=(3,))
    return T


def planar_summary(cal: MirrorCalibration) -> str:
    """One line on the marker planar ambiguity for stdout ('' when no image had two distinct poses)."""
    amb = [s for s in cal.singles if s.choice.ambiguous]
    if not amb:
        return ""
    guessed = [o.name for s, o in zip(cal.singles, cal.observations)
               if s.choice.ambiguous and not s.choice.decisive]
    text = (f"planar choice: {len(amb)} of {len(cal.singles)} image(s) had two marker poses; "
            f"{len(amb) - len(guessed)} decided by a test")
    if guessed:
        text += f", {len(guessed)} guessed ({', '.join(guessed)})"
    return text + "; reasons and the other pose's answer in report.html"


def calibrate_file(path, *, refine: bool = True, progress: bool = False, out_dir=None,
                   accept_implausible: bool = False):
    """Calibrate from an input file: ``(MirrorCalibration, CalibrationResult, Report)``.

    ``out_dir``: folder the result will be written to; image paths are then
    stored relative to it (else relative to the current directory).
    ``accept_implausible``: see :func:`robocal.rigs.mirror.calibrate.calibrate`.
    """
    inp = load_input(path)
    try:
        cal = calibrate(inp.camera, inp.rectangle, inp.body_points_r, inp.observations, sigma_px=inp.sigma_px,
                        refine=refine, progress=progress, accept_implausible=accept_implausible,
                        declared=inp.declared)
    except RobocalError as exc:  # the library names the image and field; the user also needs the file
        raise (exc if exc.source else exc.with_source(str(path))) from None
    truth = _read_truth(path)
    inputs = hash_inputs([path, *([inp.camera_file] if inp.camera_file else []), *inp.image_paths.values()])
    base = Path(out_dir) if out_dir is not None else Path.cwd()
    result = result_from_calibration(cal, inputs=inputs, image_paths=relative_image_paths(inp.image_paths, base),
                                     truth=truth)
    return cal, result, build_report(result, base_dir=base)


def demo(out_dir, rng: np.random.Generator, *, progress: bool = False):
    """Simulate -> calibrate -> check on the published scene (points, 4 placements) and one rendered image."""
    from robocal.cli import DemoOutcome

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cam, scene = default_setup(4, rng)
    obs = simulate_observations(cam, scene, rng, sigma_px=0.5)
    single = calibrate(cam, scene.rectangle, scene.body_points_r, obs[:1], sigma_px=0.5)
    joint: MirrorCalibration = calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    e1 = pose_error(single.T_r_c, scene.T_r_c)
    e4 = pose_error(joint.T_r_c, scene.T_r_c)
    # 3-sigma check per component against the reported covariance
    z = np.abs(e4) / np.sqrt(np.diag(joint.cov))
    passed = bool(np.all(z < 3.5))
    result = result_from_calibration(joint, truth=scene.T_r_c)
    report = build_report(result, title="mirror demo: published scene, 4 mirror placements, 0.5 px")
    # the image path: one rendered image, ArUco tags on the body found in the flipped image
    tags = default_body_tags()
    scene_tags = MirrorScene(scene.T_c_r, scene.T_c_m[:1], tags.body_points_r(), scene.rectangle)
    img = render_mirror_image(cam, scene_tags, tags, rng=rng)
    obs_img = detect_mirror_image(img, cam, tags, name="rendered image", rectangle=scene.rectangle)
    cal_img = calibrate(cam, scene.rectangle, scene_tags.body_points_r, [obs_img])
    e_img = pose_error(cal_img.T_r_c, scene.T_r_c)
    z_img = np.abs(e_img) / np.sqrt(np.diag(cal_img.cov))
    passed = passed and bool(np.all(z_img < 4.0))
    res_img = result_from_calibration(cal_img, truth=scene.T_r_c)
    rep_img = build_report(res_img, images={"rendered image": img})
    sec = report.section("ArUco path: one rendered image")
    sec.text(f"{len(obs_img.body_ids) // 4} of {len(tags.ids)} body tags found in the flipped image; "
             f"error {np.linalg.norm(e_img[3:]) * 1e3:.1f} mm / {np.degrees(np.linalg.norm(e_img[:3])):.2f} deg "
             f"(reported std {np.linalg.norm(cal_img.std_translation) * 1e3:.1f} mm).")
    for s in rep_img.sections:
        if s.title.startswith("Images"):
            report.extend([s], prefix="ArUco")
    report.write(out_dir / "report.html")
    summary = {
        "1 image error": f"{np.linalg.norm(e1[3:]) * 1e3:.1f} mm / {np.degrees(np.linalg.norm(e1[:3])):.2f} deg",
        "4 placements error": f"{np.linalg.norm(e4[3:]) * 1e3:.1f} mm / {np.degrees(np.linalg.norm(e4[:3])):.2f} deg",
        "4 placements std": f"{np.linalg.norm(joint.std_translation) * 1e3:.1f} mm / "
                            f"{np.degrees(np.linalg.norm(joint.std_rotation)):.2f} deg",
        "ArUco image error": f"{np.linalg.norm(e_img[3:]) * 1e3:.1f} mm",
        "time": f"{time.perf_counter() - t0:.1f} s",
    }
    return DemoOutcome(summary=summary, passed=passed, sections=list(report.sections), result=result)


