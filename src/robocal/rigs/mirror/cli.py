"""Command line of the ``mirror`` rig, declared: ``robocal mirror simulate | calibrate | report``.

The core (:mod:`robocal.cli._workflow`) builds the commands from this
declaration; the steps are in :mod:`robocal.rigs.mirror.workflow` and
:mod:`robocal.rigs.mirror.report`, named as strings so that ``robocal mirror
--help`` imports none of them.
"""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Option, Workflow, number_at_least

__all__ = ["RIG"]

EXAMPLES = Path("examples/mirror")
_WF = "robocal.rigs.mirror.workflow"


RIG = Workflow(
    name="mirror",
    help="camera-to-robot-body calibration from one image of a plane mirror (patent CN 101096101, seed 002 [S2])",
    description=(
        "Foot-eye calibration of a mobile robot: a plane mirror with four markers (a known rectangle) in front\n"
        "of the robot; the camera sees the markers and the reflection of feature points on the body.\n"
        "One image gives the camera pose in the robot frame (the patent's method); several mirror\n"
        "placements are refined jointly with uncertainty.\n\n"
        + examples_epilog("robocal mirror simulate --placements 4 --out mirror-sim",
                          f"robocal mirror calibrate {EXAMPLES}/published_single.yaml --out mirror-cal",
                          "robocal mirror report mirror-cal/result.json --out mirror-report")
    ),
    simulate=f"{_WF}:simulate_files",
    load_input=f"{_WF}:load_input",
    calibrate=f"{_WF}:calibrate_input",
    to_result=f"{_WF}:to_result",
    build_report="robocal.rigs.mirror.report:build_report",
    summary=f"{_WF}:summary",
    demo=f"{_WF}:demo",
    fleet="robocal.rigs.mirror.fleet:fleet_member",
    simulate_help="write simulated mirror observations of the patent's example (with ground truth)",
    simulate_description="The default scene reproduces the patent's published T_cm, T_cri and T_rc and distortion; "
                         "see docs/rigs/mirror.md for what had to be assumed.",
    simulate_examples=("robocal mirror simulate --out mirror-sim",
                       "robocal mirror simulate --placements 4 --sigma 0.5 --seed 3 --out mirror-sim",
                       "robocal mirror simulate --images --out mirror-sim   # rendered images, ArUco body tags",
                       "robocal mirror simulate --markerless --mirrors 4 --points 3 --out mirror-sim   # no markers",
                       "robocal mirror calibrate mirror-sim/mirror_input.yaml --out mirror-cal"),
    simulate_options=(
        Option("--placements", type=number_at_least(int, 1), default=1, help="number of mirror placements (images)"),
        Option("--sigma", dest="sigma_px", type=number_at_least(float, 0.0), default=0.5,
               help="pixel noise sigma [px] of point files; 0 = noise-free, sigma_px then left out of the file "
                    "(not used with --images: images get 0.6 px blur and grey-level noise 2)"),
        Option("--images", action="store_true",
               help="render images with ArUco tags on the body instead of writing image points (with "
                    "--markerless: a chessboard on the body seen in the mirror)"),
        Option("--markerless", action="store_true",
               help="the markerless form: no markers on the mirror, reference points seen in --mirrors poses "
                    "(Takahashi et al. 2012; docs/rigs/mirror.md, 'Markerless input')"),
        Option("--mirrors", type=number_at_least(int, 3), default=3,
               help="with --markerless: number of mirror poses (>= 3)"),
        Option("--points", type=number_at_least(int, 3), default=20,
               help="with --markerless: number of reference points (3..20, well spread body points)"),
    ),
    calibrate_help="estimate the camera pose in the robot frame: result.json + report.html",
    calibrate_description=(
        "Input: intrinsics, mirror marker rectangle, body point model and, per image, the marker "
        "and reflected body image points (or an image with ArUco tags). Format: docs/rigs/mirror.md "
        "or robocal.rigs.mirror.files. Your own camera: 'camera: {file: my_camera.yaml}' (an OpenCV "
        "calibration: camera_matrix, dist_coeffs, image size; cv2.FileStorage YAML/XML, ROS or JSON); "
        "the example files use the patent scene's assumed 768 x 576, f = 800 px camera."),
    calibrate_examples=(f"robocal mirror calibrate {EXAMPLES}/published_single.yaml --out mirror-cal",
                        f"robocal mirror calibrate {EXAMPLES}/four_placements.yaml --out mirror-cal",
                        f"robocal mirror calibrate {EXAMPLES}/aruco_images.yaml --out mirror-cal",
                        f"robocal mirror calibrate {EXAMPLES}/own_camera.yaml --out mirror-cal   # OpenCV camera file",
                        f"robocal mirror calibrate {EXAMPLES}/markerless.yaml --out mirror-cal   # no mirror markers",
                        f"robocal mirror calibrate {EXAMPLES}/published_single.yaml --no-refine --out mirror-cal"),
    calibrate_options=(
        Option("--no-refine", action="store_true",
               help="patent's single-image estimates only (averaged over images), no joint least squares; "
                    "the std is that of the average"),
    ),
    input_arguments=(Option("input", type=Path, help="calibration input (YAML/JSON)"),),
    simulated_inputs=("mirror_input.yaml",),
    quick_simulate=("--placements", "2"),
)
