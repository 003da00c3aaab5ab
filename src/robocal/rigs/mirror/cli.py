"""Command line of the ``mirror`` rig: ``robocal mirror simulate | calibrate | report``.

Thin wiring over :mod:`robocal.rigs.mirror.workflow`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from robocal.cli import DemoContext, DemoOutcome, Rig
from robocal.cli._common import RawHelp, add_accept_implausible_argument, add_out_argument, add_seed_argument, examples_epilog, prepare_out_dir, write_run
from robocal.errors import InputError, RobocalError
from robocal.io import load_result

__all__ = ["RIG"]

EXAMPLES = Path("examples/mirror")


def _number(kind, minimum, strict):
    """argparse type: a ``kind`` (int/float) >= minimum (> minimum when strict); bad values -> usage error."""
    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not np.isfinite(v) or v < minimum or (strict and v == minimum):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {minimum}, got {text}")
        return v
    parse.__name__ = kind.__name__
    return parse


def _add_commands(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND")
    p = sub.add_parser(
        "simulate", help="write simulated mirror observations of the patent's example (with ground truth)",
        formatter_class=RawHelp,
        description="The default scene reproduces the patent's published T_cm, T_cri and T_rc and distortion; "
                    "see docs/rigs/mirror.md for what had to be assumed.",
        epilog=examples_epilog("robocal mirror simulate --out mirror-sim",
                               "robocal mirror simulate --placements 4 --sigma 0.5 --seed 3 --out mirror-sim",
                               "robocal mirror simulate --images --out mirror-sim   # rendered images, ArUco body tags",
                               "robocal mirror calibrate mirror-sim/mirror_input.yaml --out mirror-cal"))
    p.add_argument("--placements", type=_number(int, 1, False), default=1, help="number of mirror placements (images)")
    p.add_argument("--sigma", type=_number(float, 0.0, False), default=0.5,
                   help="pixel noise sigma [px] of point files; 0 = noise-free, sigma_px then left out of the file "
                        "(not used with --images: images get 0.6 px blur and grey-level noise 2)")
    p.add_argument("--images", action="store_true",
                   help="render images with ArUco tags on the body instead of writing image points")
    add_seed_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser(
        "calibrate", help="estimate the camera pose in the robot frame: result.json + report.html",
        formatter_class=RawHelp,
        description="Input: intrinsics, mirror marker rectangle, body point model and, per image, the marker "
                    "and reflected body image points (or an image with ArUco tags). Format: docs/rigs/mirror.md "
                    "or robocal.rigs.mirror.files. Your own camera: 'camera: {file: my_camera.yaml}' (an OpenCV "
                    "calibration: camera_matrix, dist_coeffs, image size; cv2.FileStorage YAML/XML, ROS or JSON); "
                    "the example files use the patent scene's assumed 768 x 576, f = 800 px camera.",
        epilog=examples_epilog(f"robocal mirror calibrate {EXAMPLES}/published_single.yaml --out mirror-cal",
                               f"robocal mirror calibrate {EXAMPLES}/four_placements.yaml --out mirror-cal",
                               f"robocal mirror calibrate {EXAMPLES}/aruco_images.yaml --out mirror-cal",
                               f"robocal mirror calibrate {EXAMPLES}/own_camera.yaml --out mirror-cal   # OpenCV camera file",
                               f"robocal mirror calibrate {EXAMPLES}/published_single.yaml --no-refine --out mirror-cal"))
    p.add_argument("input", type=Path, help="calibration input (YAML/JSON)")
    p.add_argument("--no-refine", action="store_true",
                   help="patent's single-image estimates only (averaged over images), no joint least squares; "
                        "the std is that of the average")
    add_accept_implausible_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser(
        "report", help="redraw report.html from a result.json", formatter_class=RawHelp,
        epilog=examples_epilog("robocal mirror report mirror-cal/result.json --out mirror-report"))
    p.add_argument("result", type=Path, help="result.json written by 'robocal mirror calibrate'")
    add_out_argument(p)
    p.set_defaults(func=_cmd_report)


def _cmd_simulate(args) -> int:
    from robocal.rigs.mirror import workflow

    out = prepare_out_dir(args.out, "mirror-simulate")
    paths = workflow.simulate_files(out, placements=args.placements, sigma_px=args.sigma, seed=args.seed,
                                    images=args.images)
    for p in paths:
        print(f"wrote {p}")
    return 0


def _cmd_calibrate(args) -> int:
    from robocal.rigs.mirror import workflow

    out = prepare_out_dir(args.out, "mirror-calibrate")
    cal, result, report = workflow.calibrate_file(args.input, refine=not args.no_refine, out_dir=out,
                                                  accept_implausible=args.accept_implausible, progress=True)
    write_run(out, result, report)
    t = cal.T_r_c[:3, 3] * 1e3
    s = cal.std_translation * 1e3
    print(f"t_r_c = [{t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}] mm  (std {s[0]:.1f}, {s[1]:.1f}, {s[2]:.1f} mm); "
          f"rotation std {np.degrees(cal.std_rotation).max():.3g} deg")
    line = workflow.planar_summary(cal)
    if line:
        print(line)
    return 0


def _cmd_report(args) -> int:
    from robocal.rigs.mirror.report import build_report

    result = load_result(args.result)
    if result.rig != "mirror":
        raise InputError(f"{args.result}: a result of rig {result.rig!r}, not 'mirror'")
    try:
        report = build_report(result, base_dir=Path(args.result).parent)
    except RobocalError as exc:
        raise exc.with_source(str(args.result)) from None
    out = prepare_out_dir(args.out, "mirror-report")
    write_run(out, None, report)
    return 0


def _demo(ctx: DemoContext) -> DemoOutcome:
    from robocal.rigs.mirror import workflow

    return workflow.demo(ctx.out_dir, ctx.rng, progress=ctx.progress)


RIG = Rig(
    name="mirror",
    help="camera-to-robot-body calibration from one image of a plane mirror (seed 002)",
    description=(
        "Foot-eye calibration of a mobile robot: a plane mirror with four markers (a known rectangle) in front\n"
        "of the robot; the camera sees the markers and the reflection of feature points on the body.\n"
        "One image gives the camera pose in the robot frame (the patent's method); several mirror\n"
        "placements are refined jointly with uncertainty.\n\n"
        + examples_epilog("robocal mirror simulate --placements 4 --out mirror-sim",
                          f"robocal mirror calibrate {EXAMPLES}/published_single.yaml --out mirror-cal",
                          "robocal mirror report mirror-cal/result.json --out mirror-report")
    ),
    add_commands=_add_commands,
    demo=_demo,
)
