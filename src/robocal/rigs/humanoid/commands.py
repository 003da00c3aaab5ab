"""The humanoid rig's extra command: ``robocal humanoid plan`` (greedy D-optimal pose planning).

:func:`plan_files` is the work (library, no argument parsing); :func:`run_plan`
is the command's ``Command.run(args)``: it claims the output folder the way
every command does and prints what it wrote.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from robocal.errors import InputError
from robocal.io import atomic_write_text

__all__ = ["plan_files", "run_plan"]


def plan_files(out_dir, rng: np.random.Generator, *, poses: int = 12, candidates: int = 60, params: str = "seed",
               data=None, tie: bool = False, corner_sigma: float = 0.3, progress: bool = False):
    """Plan ``poses`` leg poses (:func:`robocal.rigs.humanoid.plan.plan_poses`) and write ``plan.yaml``
    (joint angles to command [deg]) and ``report.html`` (predicted stds after each pose) into ``out_dir``.

    ``data``: a data-set file whose robot (URDF, camera, board, tie, joint resolution) to plan for
    (its images are not read); default the default model (``tie``: one HipYawPitch motor).
    ``corner_sigma``: expected corner noise [px]. Returns ``(paths written, PosePlan)``.
    """
    from robocal.report import Report, new_figure
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.plan import plan_poses
    from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION

    if poses < 1 or candidates < 1:
        raise InputError("--poses and --candidates must be >= 1")
    if not (np.isfinite(corner_sigma) and corner_sigma > 0):
        raise InputError(f"--corner-sigma must be a finite number > 0 px, got {corner_sigma}")
    resolution = JOINT_RESOLUTION
    if data is not None:
        from robocal.rigs.humanoid.dataset import load_dataset

        model, _, info = load_dataset(data, detect=False)
        resolution = info["joint_resolution"]
    else:
        model = default_model(tie_hip_yaw_pitch=tie)
    plan = plan_poses(model, poses, rng, parameters=params, n_candidates=candidates, corner_sigma=corner_sigma,
                      joint_resolution=resolution, progress=progress)
    out_dir = Path(out_dir)
    doc = {"description": "leg poses chosen greedily for D-optimality (joint angles to command)",
           "feet": plan.feet,
           "joints": {"unit": "deg", "names": list(model.joint_names),
                      "records": [[round(float(np.degrees(v)), 2) for v in row] for row in plan.theta]},
           "predicted_std_deg_after_each_pose": [r["worst joint std [deg]"] for r in plan.table()],
           "assumed": {"model": str(data) if data else "default", "tied": bool(model.tied),
                       "corner_sigma_px": corner_sigma,
                       "joint_resolution_deg": round(float(np.degrees(resolution)), 6)}}
    paths = [atomic_write_text(out_dir / "plan.yaml", yaml.safe_dump(doc, sort_keys=False, width=200))]
    rep = Report("NAO calibration pose plan", subtitle=f"{poses} poses from {2 * candidates} candidates")
    sec = rep.section("Predicted uncertainty as poses are added")
    fig, ax = new_figure(size=(7, 4))
    plan.plot(ax=ax)
    sec.figure(fig, "worst predicted joint-offset std (planned vs random order)")
    sec.table(plan.table(), digits=4)
    paths.append(rep.write(out_dir / "report.html"))
    return paths, plan


def run_plan(args) -> int:
    """``robocal humanoid plan``: :func:`plan_files` into ``--out``, then the predicted std per pose."""
    if args.poses < 1 or args.candidates < 1:
        raise InputError("--poses and --candidates must be >= 1")
    if not (np.isfinite(args.corner_sigma) and args.corner_sigma > 0):
        raise InputError(f"--corner-sigma must be a finite number > 0 px, got {args.corner_sigma}")
    from robocal.io import prepare_out_dir

    out = prepare_out_dir(args.out, "humanoid-plan")  # --force: read by the command run (claim_folder)
    paths, plan = plan_files(out, np.random.default_rng(args.seed), poses=args.poses, candidates=args.candidates,
                             params=args.params, data=args.data, tie=args.tie, corner_sigma=args.corner_sigma,
                             progress=True)
    for p in paths:
        print(f"wrote {p}")
    for r in plan.table():
        w = r["worst joint std [deg]"]
        print(f"  {r['poses']:3d} poses ({r['foot added']:>5s}): worst joint std "
              f"{'undetermined' if w is None else f'{w:.4f} deg'}")
    return 0

