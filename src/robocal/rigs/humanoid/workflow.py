"""The humanoid rig's steps of the rig contract (:mod:`robocal.workflow`).

``simulate_files`` -> ``load_input`` -> ``calibrate_input`` -> ``to_result``
-> :func:`robocal.rigs.humanoid.report.build_report`, with :func:`summary`
and :func:`demo`. The core builds ``robocal humanoid simulate | calibrate |
report`` from them (:mod:`robocal.rigs.humanoid.cli` declares the options).
Besides ``result.json`` and ``report.html`` (written by the core), a
calibration writes ``offsets.yaml`` and the corrected URDF into its output
folder (:func:`robocal.rigs.humanoid.report.write_offsets`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from robocal.errors import InputError
from robocal.io import atomic_write_text, hash_inputs
from robocal.workflow import DemoContext, DemoOutcome

__all__ = ["HumanoidInput", "simulate_run", "simulate_files", "load_input", "calibrate_input", "to_result",
           "summary", "demo"]


@dataclass
class HumanoidInput:
    """A loaded data-set file, corners not yet detected (:func:`load_input`).

    Attributes
    ----------
    path : Path
        The data-set file.
    model : HumanoidModel
    data : HumanoidDataset
        Joint records, feet and image paths (``corners`` None until detection).
    info : dict
        ``load_dataset``'s info: joint resolution [rad], input files, declared units.
    truth : ndarray (P,) or None
        The simulation truth the file carries (``simulation_truth``), full parameter vector
        [rad, m]; None for recorded data.
    """

    path: Path
    model: object
    data: object
    info: dict
    truth: np.ndarray | None = None


def simulate_run(out_dir, rng: np.random.Generator, *, views: int = 8, blur: float = 0.8,
                 image_noise: float = 2.0, offset_scale: float = 0.5, tie: bool = False,
                 progress: bool = False):
    """Simulate a run and write ``run.yaml`` + ``images/*.png`` + ``truth.yaml`` into ``out_dir``.

    True offsets of std ``offset_scale`` [deg] (joints, camera and board rotation), ``views``
    poses per foot within the joint limits with the board fully visible, readings quantised to
    0.1 deg, images rendered with ``blur`` [px] and ``image_noise`` [grey levels]. Returns
    ``(path of run.yaml, model, data)``.
    """
    from robocal.rigs.humanoid.dataset import write_dataset
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.simulate import draw_truth, save_images, simulate_dataset

    if views < 1:
        raise InputError(f"--views must be >= 1, got {views}")
    for name, val in (("--offset-scale", offset_scale), ("--blur", blur), ("--image-noise", image_noise)):
        if not (np.isfinite(val) and val >= 0):
            raise InputError(f"{name} must be a finite number >= 0, got {val}")
    model = default_model(tie_hip_yaw_pitch=tie)
    truth = draw_truth(model, rng, joint_deg=offset_scale, camera_deg=offset_scale, board_deg=offset_scale)
    data = simulate_dataset(model, rng, n_per_foot=views, truth=truth, render=True, blur_sigma=blur,
                            image_noise=image_noise, progress=progress)
    out_dir = Path(out_dir)
    paths = save_images(data, out_dir / "images")
    run = write_dataset(out_dir / "run.yaml", model, data, paths, truth=truth.params)
    atomic_write_text(out_dir / "truth.yaml", yaml.safe_dump(
        {"units": "rad for angles, m for lengths", "truth": truth.as_dict()}, sort_keys=False))
    return run, model, data


def simulate_files(out_dir, rng: np.random.Generator, *, progress: bool = False, **options) -> list[Path]:
    """The ``simulate`` step: :func:`simulate_run`; returns ``run.yaml``, the image folder and ``truth.yaml``."""
    run, _, _ = simulate_run(out_dir, rng, progress=progress, **options)
    out_dir = Path(out_dir)
    return [Path(run), out_dir / "images", out_dir / "truth.yaml"]


def load_input(path=None, *, bag=None, joints: str = "/joint_states", images: str | None = None,
               camera_info: str | None = None, camera=None, joint_map=None, **_) -> HumanoidInput:
    """The ``load_input`` step: the data-set file read and checked, its images not yet read; or, with
    ``bag``, the views taken from a recording (:func:`robocal.rigs.humanoid.bag.load_bag_input`)."""
    if bag is not None:
        if path is not None:
            raise InputError(f"give a data-set file or --bag, not both (got {path} and --bag {bag})")
        from robocal.rigs.humanoid.bag import load_bag_input

        return load_bag_input(bag, joints=joints, images=images, camera_info=camera_info, camera=camera,
                              joint_map=joint_map)
    if path is None:
        raise InputError("give a data-set file (run.yaml) or a recording with --bag FILE --images TOPIC")
    from robocal.rigs.humanoid.dataset import load_dataset

    path = Path(path)
    model, data, info = load_dataset(path, detect=False)
    return HumanoidInput(path, model, data, info, _truth_of(path, model))


def _truth_of(path: Path, model) -> np.ndarray | None:
    """The simulation truth stored in a data-set file, as a full parameter vector (or None)."""
    from robocal.io import load_document

    doc = load_document(path)
    if "simulation_truth" not in doc:
        return None
    vals = doc.raw("simulation_truth").get("values", {})
    labels = model.parameter_labels()
    if not all(k in vals for k in labels):
        return None
    return np.array([float(vals[k]) for k in labels])


def calibrate_input(inp: HumanoidInput, *, out_dir=None, progress: bool = False, accept_implausible: bool = False,
                    params: str = "seed", tie: bool = False, fd: bool = False, corner_sigma: float | None = None,
                    reject_outliers: bool = False, consistency_px: float | None = None,
                    consistency_ratio: float | None = None, **_):
    """The ``calibrate`` step: check the options, detect the corners, calibrate (:func:`calibrate`).

    The options are those of ``robocal humanoid calibrate`` (``fd``: finite-difference Jacobian).
    With ``out_dir``, ``offsets.yaml`` and the corrected URDF are written there (their names go
    into the result's ``diagnostics["files"]``). Returns the :class:`HumanoidCalibration`.
    """
    from robocal.rigs.humanoid.calibrate import NOMINAL_MIN_PX, NOMINAL_RATIO, calibrate, check_options
    from robocal.rigs.humanoid.detect import detect_views

    model, data, info = inp.model, inp.data, inp.info
    consistency_px = NOMINAL_MIN_PX if consistency_px is None else consistency_px
    consistency_ratio = NOMINAL_RATIO if consistency_ratio is None else consistency_ratio
    # refuse bad options before the detection (seconds for a few dozen images)
    check_options(model, parameters=params, corner_sigma=corner_sigma, joint_resolution=info["joint_resolution"],
                  consistency_px=consistency_px, consistency_ratio=consistency_ratio)
    detect_views(model, data, progress=progress)
    cal = calibrate(model, data, parameters=params, tie=tie, jac="2-point" if fd else "analytic",
                    corner_sigma=corner_sigma, joint_resolution=info["joint_resolution"],
                    reject_outliers=reject_outliers, consistency_px=consistency_px,
                    consistency_ratio=consistency_ratio, accept_implausible=accept_implausible,
                    progress=progress, declared=info["declared"])
    if out_dir is not None:
        from robocal.rigs.humanoid.report import write_offsets

        written = write_offsets(cal, out_dir, inputs=hash_inputs(info["inputs"]))
        cal.files = [p.name for p in written]
    return cal


def to_result(cal, inp: HumanoidInput | None = None):
    """The ``to_result`` step: :meth:`HumanoidCalibration.to_result` with the input's file hashes and,
    for a simulated input, its truth (``diagnostics["simulation_truth"]``, ``["truth_check"]``)."""
    if inp is None:
        return cal.to_result()
    return cal.to_result(inputs=hash_inputs(inp.info["inputs"]), truth=inp.truth)


def summary(result) -> str:
    """The ``summary`` step: :func:`robocal.rigs.humanoid.calibration.summary_text`."""
    from robocal.rigs.humanoid.calibration import summary_text

    return summary_text(result)


def demo(ctx: DemoContext) -> DemoOutcome:
    """simulate (rendered images) -> detect -> calibrate -> check against the truth (NEES).

    The rendered images are written into ``ctx.out_dir/images`` so that the result names them and
    its report (also written there, with ``offsets.yaml`` and the URDF) can be rebuilt."""
    from robocal.rigs.humanoid.calibrate import calibrate
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.report import build_report, write_offsets
    from robocal.rigs.humanoid.simulate import save_images, simulate_dataset

    out = Path(ctx.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model = default_model()
    data = simulate_dataset(model, ctx.rng, n_per_foot=6, render=True, progress=ctx.progress)
    data.images = save_images(data, out / "images")
    cal = calibrate(model, data)
    truth = data.truth.params
    check = cal.truth_check(truth)
    cal.files = [p.name for p in write_offsets(cal, out)]
    result = cal.to_result(truth=truth)
    rep = build_report(result, base_dir=out, title="humanoid: NAO legs + camera from foot checkerboards",
                       n_overlays=2)
    rep.write(out / "report.html")
    rows = cal.parameter_rows(truth)
    joints = [r for r in rows if r["unit"] == "deg" and not r["parameter"].startswith(("camera.", "board."))]
    err = np.array([abs(r["value"] - r["truth"]) for r in joints if r["value"] is not None])
    d = result.diagnostics
    summary_row = {
        "views": f"{cal.data.n_views}",
        "RMS x/y": f"{d['rms_x_px']:.3f}/{d['rms_y_px']:.3f} px",
        "max joint error": f"{err.max():.3f} deg",
        "NEES": f"{check.nees:.1f} (limit {check.threshold:.1f}, {check.dof} parameters)",
    }
    # every free parameter must be determined and the errors consistent with the covariance
    passed = bool(check.passed and check.dof == len(cal.free))
    return DemoOutcome(summary=summary_row, passed=passed, sections=rep.sections, result=result)
