"""Command line of the ``humanoid`` rig: ``robocal humanoid simulate | calibrate | plan | report``.

Each command is thin wiring over the library: :mod:`.simulate`, :mod:`.dataset`,
:mod:`.calibrate`, :mod:`.plan`, :mod:`.report`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

from robocal.cli import DemoContext, DemoOutcome, Rig
from robocal.cli._common import RawHelp, add_accept_implausible_argument, add_out_argument, add_seed_argument, examples_epilog, prepare_out_dir, write_run
from robocal.errors import InputError
from robocal.io import atomic_write_text, load_result
from robocal.report import Report, new_figure

__all__ = ["RIG", "simulate_files"]

EXAMPLES = Path("examples/humanoid")


def _add_commands(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND")

    p = sub.add_parser("simulate", help="render a simulated run: data-set YAML + PNG images (+ truth)",
                       formatter_class=RawHelp,
                       description="True offsets ~0.5 deg, poses within the joint limits with the board fully "
                                   "visible, joint readings quantised to 0.1 deg, rendered images with blur and "
                                   "noise.",
                       epilog=examples_epilog("robocal humanoid simulate --out humanoid-sim",
                                              "robocal humanoid simulate --views 12 --seed 3 --out humanoid-sim",
                                              "robocal humanoid calibrate humanoid-sim/run.yaml --out humanoid-cal"))
    p.add_argument("--views", type=int, default=8, help="views per foot")
    p.add_argument("--blur", type=float, default=0.8, help="image blur sigma [px]")
    p.add_argument("--image-noise", type=float, default=2.0, help="image noise sigma [grey levels]")
    p.add_argument("--offset-scale", type=float, default=0.5, help="std of the true joint/camera offsets [deg]")
    p.add_argument("--tie", action="store_true", help="one HipYawPitch motor (tied joints) in the model")
    add_seed_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("calibrate", help="detect corners, estimate offsets: result.json, report.html, "
                                         "offsets.yaml, corrected URDF",
                       formatter_class=RawHelp,
                       description="Input format: docs/rigs/humanoid.md (format robocal.humanoid-data/1).\n"
                                   "Parameter sets: seed (21, default), seed+camera_xy, legs, all, or a "
                                   "comma list of names (LKneePitch, camera.roll, board.left.x, ...).",
                       epilog=examples_epilog(f"robocal humanoid calibrate {EXAMPLES}/run.yaml --out humanoid-cal",
                                              "robocal humanoid calibrate humanoid-sim/run.yaml --tie --out humanoid-cal   "
                                              "# data from one HipYawPitch motor",
                                              f"robocal humanoid calibrate {EXAMPLES}/run.yaml "
                                              "--params seed+camera_xy --out cal"))
    p.add_argument("input", type=Path, help="data-set file (YAML/JSON)")
    p.add_argument("--params", default="seed", help="parameters to estimate")
    p.add_argument("--tie", action="store_true",
                   help="one offset for both HipYawPitch joints (one motor); wrong for data whose two "
                        "offsets differ, such as examples/humanoid (simulated untied)")
    p.add_argument("--fd", action="store_true", help="finite-difference Jacobian instead of the analytic one")
    p.add_argument("--corner-sigma", type=float, default=None,
                   help="corner noise [px] (default: measured from the data)")
    p.add_argument("--reject-outliers", action="store_true",
                   help="remove the corners beyond 3 sigma (a view with > 25 %% of its corners flagged: the "
                        "whole view) and re-solve once; what was removed is listed in result.json and the report")
    p.add_argument("--consistency-px", type=float, default=60.0,
                   help="refuse a view whose corners lie further [px, median] from where its joint record and "
                        "foot label put them than max(this, --consistency-ratio x the median view's); raise it "
                        "for a robot with offsets beyond ~1 deg")
    p.add_argument("--consistency-ratio", type=float, default=4.0,
                   help="see --consistency-px")
    add_accept_implausible_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("plan", help="choose leg poses that make the calibration well conditioned",
                       formatter_class=RawHelp,
                       description="Greedy D-optimal design: from random candidate poses (within the joint "
                                   "limits, whole board in view and facing the camera, feet apart) add the one "
                                   "that most increases log det of the Fisher information. Writes plan.yaml "
                                   "(joint angles to command) and report.html (predicted stds after each pose).",
                       epilog=examples_epilog("robocal humanoid plan --poses 12 --out humanoid-plan",
                                              "robocal humanoid plan --poses 20 --candidates 100 --out humanoid-plan",
                                              f"robocal humanoid plan --data {EXAMPLES}/run.yaml --corner-sigma 0.1 "
                                              "--out plan"))
    p.add_argument("--poses", type=int, default=12, help="poses to choose")
    p.add_argument("--candidates", type=int, default=60, help="random candidate poses per foot")
    p.add_argument("--params", default="seed", help="parameters to plan for")
    p.add_argument("--data", type=Path, default=None,
                   help="plan for the robot of this data-set file (URDF, camera, board, tie, joint resolution; "
                        "its images are not read)")
    p.add_argument("--tie", action="store_true",
                   help="one HipYawPitch motor (tied joints) in the default model (with --data, the file's "
                        "tie_hip_yaw_pitch decides)")
    p.add_argument("--corner-sigma", type=float, default=0.3, help="expected corner noise [px]")
    add_seed_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_cmd_plan)

    p = sub.add_parser("report", help="rebuild report.html from a result.json",
                       formatter_class=RawHelp,
                       epilog=examples_epilog("robocal humanoid report humanoid-cal/result.json --out humanoid-report"))
    p.add_argument("result", type=Path, help="result.json written by 'robocal humanoid calibrate'")
    add_out_argument(p)
    p.set_defaults(func=_cmd_report)


# ------------------------------------------------------------------ library-level helpers
def simulate_files(out_dir, rng: np.random.Generator, *, views: int = 8, blur: float = 0.8,
                   image_noise: float = 2.0, offset_scale: float = 0.5, tie: bool = False,
                   progress: bool = False):
    """Simulate a run and write ``run.yaml`` + ``images/*.png`` (+ ``truth.yaml``); returns
    ``(path of run.yaml, model, data)``."""
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


# ------------------------------------------------------------------ commands
def _cmd_simulate(args) -> int:
    out = prepare_out_dir(args.out, "humanoid-simulate")
    run, _, data = simulate_files(out, np.random.default_rng(args.seed), views=args.views, blur=args.blur,
                                  image_noise=args.image_noise, offset_scale=args.offset_scale, tie=args.tie,
                                  progress=True)
    for m in data.messages:
        print(m, file=sys.stderr)
    print(f"wrote {run} ({data.n_views} views, images in {out / 'images'}) and {out / 'truth.yaml'}")
    return 0


def _truth_of(path: Path, model):
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


def _cmd_calibrate(args) -> int:
    from robocal.rigs.humanoid.calibrate import calibrate, check_options
    from robocal.rigs.humanoid.dataset import load_dataset
    from robocal.rigs.humanoid.detect import detect_views
    from robocal.rigs.humanoid.report import write_outputs

    model, data, info = load_dataset(args.input, detect=False)
    # refuse bad options before the detection (seconds for a few dozen images)
    check_options(model, parameters=args.params, corner_sigma=args.corner_sigma,
                  joint_resolution=info["joint_resolution"], consistency_px=args.consistency_px,
                  consistency_ratio=args.consistency_ratio)
    detect_views(model, data, progress=True)
    for m in data.messages:
        print(m, file=sys.stderr)
    cal = calibrate(model, data, parameters=args.params, tie=args.tie, jac="2-point" if args.fd else "analytic",
                    corner_sigma=args.corner_sigma, joint_resolution=info["joint_resolution"],
                    reject_outliers=args.reject_outliers, consistency_px=args.consistency_px,
                    consistency_ratio=args.consistency_ratio, accept_implausible=args.accept_implausible,
                    progress=True,
                    declared=info["declared"])
    out = prepare_out_dir(args.out, "humanoid-calibrate")
    truth = _truth_of(args.input, model)
    write_outputs(cal, out, inputs=info["inputs"], truth=truth)
    print(cal.summary())
    if truth is not None:
        z = [(abs(r["error/std"]), r["parameter"]) for r in cal.parameter_rows(truth) if r["error/std"] is not None]
        if z:
            worst = max(z)
            print(f"simulation truth in {args.input.name}: {len(z)} parameters, worst |error|/std "
                  f"{worst[0]:.2f} ({worst[1]}); {sum(v <= 3 for v, _ in z)} within 3 std (table in the report)")
    return 0


def _cmd_plan(args) -> int:
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.plan import plan_poses
    from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION

    if args.poses < 1 or args.candidates < 1:
        raise InputError("--poses and --candidates must be >= 1")
    if not (np.isfinite(args.corner_sigma) and args.corner_sigma > 0):
        raise InputError(f"--corner-sigma must be a finite number > 0 px, got {args.corner_sigma}")
    resolution = JOINT_RESOLUTION
    if args.data is not None:
        from robocal.rigs.humanoid.dataset import load_dataset

        model, _, info = load_dataset(args.data, detect=False)
        resolution = info["joint_resolution"]
    else:
        model = default_model(tie_hip_yaw_pitch=args.tie)
    plan = plan_poses(model, args.poses, np.random.default_rng(args.seed), parameters=args.params,
                      n_candidates=args.candidates, corner_sigma=args.corner_sigma, joint_resolution=resolution,
                      progress=True)
    out = prepare_out_dir(args.out, "humanoid-plan")
    doc = {"description": "leg poses chosen greedily for D-optimality (joint angles to command)",
           "feet": plan.feet,
           "joints": {"unit": "deg", "names": list(model.joint_names),
                      "records": [[round(float(np.degrees(v)), 2) for v in row] for row in plan.theta]},
           "predicted_std_deg_after_each_pose": [r["worst joint std [deg]"] for r in plan.table()],
           "assumed": {"model": str(args.data) if args.data else "default", "tied": bool(model.tied),
                       "corner_sigma_px": args.corner_sigma,
                       "joint_resolution_deg": round(float(np.degrees(resolution)), 6)}}
    atomic_write_text(out / "plan.yaml", yaml.safe_dump(doc, sort_keys=False, width=200))
    rep = Report("NAO calibration pose plan", subtitle=f"{args.poses} poses from {2 * args.candidates} candidates")
    sec = rep.section("Predicted uncertainty as poses are added")
    fig, ax = new_figure(size=(7, 4))
    plan.plot(ax=ax)
    sec.figure(fig, "worst predicted joint-offset std (planned vs random order)")
    sec.table(plan.table(), digits=4)
    write_run(out, None, rep)
    print(f"wrote {out / 'plan.yaml'}")
    for r in plan.table():
        w = r["worst joint std [deg]"]
        print(f"  {r['poses']:3d} poses ({r['foot added']:>5s}): worst joint std "
              f"{'undetermined' if w is None else f'{w:.4f} deg'}")
    return 0


def _cmd_report(args) -> int:
    from robocal.rigs.humanoid.report import report_from_result

    result = load_result(args.result)
    if result.rig != "humanoid":
        raise InputError(f"{args.result}: a result of rig {result.rig!r}, not 'humanoid'")
    out = prepare_out_dir(args.out, "humanoid-report")
    write_run(out, None, report_from_result(result))
    return 0


# ------------------------------------------------------------------ demo
def _demo(ctx: DemoContext) -> DemoOutcome:
    """simulate (rendered images) -> detect -> calibrate -> check against the truth."""
    from robocal.rigs.humanoid.calibrate import calibrate
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.report import build_report, write_outputs
    from robocal.rigs.humanoid.simulate import simulate_dataset

    model = default_model()
    data = simulate_dataset(model, ctx.rng, n_per_foot=6, render=True, progress=ctx.progress)
    cal = calibrate(model, data)
    truth = data.truth.params
    rows = cal.parameter_rows(truth)
    z = np.array([abs(r["error/std"]) for r in rows if r["error/std"] is not None])
    joints = [r for r in rows if r["unit"] == "deg" and not r["parameter"].startswith(("camera.", "board."))]
    err = np.array([abs(r["value"] - r["truth"]) for r in joints if r["value"] is not None])
    passed = bool(len(z) == len(rows) and np.all(z < 3.5))
    rep = build_report(cal, title="humanoid: NAO legs + camera from foot checkerboards", truth=truth, n_overlays=2)
    write_outputs(cal, ctx.out_dir, truth=truth, report=rep, quiet=True)
    summary = {
        "views": f"{cal.data.n_views}",
        "RMS x/y": f"{cal.rms_xy[0]:.3f}/{cal.rms_xy[1]:.3f} px",
        "max joint error": f"{err.max():.3f} deg",
        "max |error|/std": f"{z.max():.2f}",
    }
    return DemoOutcome(summary=summary, passed=passed, sections=rep.sections, result=cal.to_result())


RIG = Rig(
    name="humanoid",
    help="NAO leg joint offsets + head camera mounting from checkerboards under the feet (seed 001)",
    description="Kinematic calibration of a NAO-class humanoid: the lower head camera watches a checkerboard "
                "pinned under each foot; Levenberg-Marquardt over joint offsets, camera and board mounting "
                "(the seed's 21 parameters), with uncertainties, identifiability and outliers.\n\n"
                + examples_epilog("robocal humanoid simulate --out humanoid-sim",
                                  "robocal humanoid calibrate humanoid-sim/run.yaml --out humanoid-cal",
                                  f"robocal humanoid calibrate {EXAMPLES}/run.yaml --out humanoid-cal",
                                  "robocal humanoid plan --poses 12 --out humanoid-plan",
                                  "robocal humanoid report humanoid-cal/result.json --out humanoid-report"),
    add_commands=_add_commands,
    demo=_demo,
)
