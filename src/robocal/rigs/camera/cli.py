"""Command line of the ``camera`` rig, declared: ``robocal camera simulate | calibrate | report``.

The steps live in :mod:`.files` (images and target in), :mod:`.workflow`
(calibrate, result, camera files, summary, demo), :mod:`.simulate` and
:mod:`.report`; the core builds the commands from this declaration.
"""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Option, Workflow, number_at_least

__all__ = ["RIG"]

EXAMPLES = Path("examples/camera")
_WF = "robocal.rigs.camera.workflow"
#: The camera models of ``--model`` (robocal.camera.INTRINSIC_MODELS, spelled out: the declaration imports no OpenCV).
MODELS = ("opencv4", "opencv5", "opencv8", "opencv12", "fisheye")

RIG = Workflow(
    name="camera",
    help="camera intrinsics and distortion from images of a chessboard, ChArUco board or AprilTag grid",
    description=(
        "Intrinsic calibration, the first step of every camera rig: the target is detected in each image\n"
        "(views without enough corners, blurred or duplicate views are named and skipped), then one joint\n"
        "least-squares problem over the intrinsics and every view's pose, started from cv2.calibrateCamera,\n"
        "gives the camera with its covariance; corner outliers are removed one by one and named. Writes\n"
        "result.json, report.html and the camera as camera.yaml (OpenCV), camera_info.yaml (ROS), camera.json.\n\n"
        + examples_epilog("robocal camera simulate --out cam-sim",
                          "robocal camera calibrate cam-sim/camera_input.yaml --out cam-cal",
                          f"robocal camera calibrate {EXAMPLES}/images --target {EXAMPLES}/target.yaml --out cam-cal",
                          "robocal camera calibrate 'shots/*.jpg' --target board.yaml --model opencv8 --out cam-cal",
                          "robocal camera report cam-cal/result.json --out cam-report")
    ),
    simulate=f"{_WF}:simulate_files",
    load_input="robocal.rigs.camera.files:load_input",
    calibrate=f"{_WF}:calibrate_input",
    to_result=f"{_WF}:to_result",
    build_report="robocal.rigs.camera.report:build_report",
    write_outputs=f"{_WF}:write_outputs",
    summary=f"{_WF}:summary",
    demo=f"{_WF}:demo",
    fleet="robocal.rigs.camera.fleet:fleet_member",
    simulate_help="render images of a target seen by a known camera (blur, noise, vignetting), with the truth",
    simulate_description=(
        "Writes images/view_NNN.png, target.yaml, camera_truth.yaml (the true camera, OpenCV format) and the\n"
        "session file camera_input.yaml that 'robocal camera calibrate' takes (the report then checks the\n"
        "estimate against the truth). The camera: 640 x 480 px (scaled with --width), ~65 deg field of view,\n"
        "a webcam's barrel distortion. ChArUco and grid views may be partial; chessboard views are whole."),
    simulate_examples=("robocal camera simulate --out cam-sim",
                       "robocal camera simulate --target charuco --views 20 --out cam-sim",
                       "robocal camera simulate --defects --blur 1.2 --noise 4 --seed 3 --out cam-sim",
                       "robocal camera simulate --lens fisheye --out fish-sim   # then calibrate with --model fisheye"),
    simulate_options=(
        Option("--views", type=number_at_least(int, 3, why="a calibration needs 3 views or more"), default=12,
               help="number of rendered views"),
        Option("--target", choices=("chessboard", "charuco", "aruco_grid"), default="chessboard",
               help="9x6 chessboard (inner corners, 25 mm), 7x5 ChArUco (40/30 mm, DICT_5X5_100) or 6x4 "
                    "AprilTag 36h11 grid (40/10 mm)"),
        Option("--width", type=number_at_least(int, 64), default=640, help="image width [px]"),
        Option("--height", type=number_at_least(int, 48), default=480, help="image height [px]"),
        Option("--blur", type=number_at_least(float, 0.0), default=0.7, help="Gaussian blur sigma [px]"),
        Option("--noise", type=number_at_least(float, 0.0), default=2.0, help="grey-level noise std (0-255)"),
        Option("--vignetting", type=float, default=0.3, help="brightness loss at the image corners, 0-1"),
        Option("--lens", choices=("pinhole", "fisheye"), default="pinhole",
               help="pinhole with OpenCV's 5-term distortion, or an equidistant fisheye (~150 deg; calibrate it "
                    "with --model fisheye)"),
        Option("--image-format", choices=("png", "jpg"), default="png",
               help="lossless PNG or JPEG (quality 90, a quarter of the size)"),
        Option("--defects", action="store_true",
               help="add a defocused view and a duplicate shot (calibrate names and skips both)"),
    ),
    calibrate_help="intrinsics + distortion from images: result.json, report.html, camera.yaml, camera_info.yaml, "
                   "camera.json",
    calibrate_description=(
        "IMAGES: image files, folders (their .png/.jpg/... files) or quoted glob patterns, with --target; or one\n"
        "session file (camera_input.yaml: target, images, optional truth). Target files (YAML): chessboard\n"
        "(rows x cols INNER corners, square), charuco (rows x cols squares, square, marker, dictionary),\n"
        "aruco_grid (rows x cols markers, marker, separation, dictionary incl. DICT_APRILTAG_36h11); lengths\n"
        "with units ({value: 25, unit: mm}). Format and models: docs/rigs/camera.md."),
    calibrate_examples=("robocal camera calibrate cam-sim/camera_input.yaml --out cam-cal",
                        f"robocal camera calibrate {EXAMPLES}/images --target {EXAMPLES}/target.yaml --out cam-cal",
                        "robocal camera calibrate shots/ --target board.yaml --model opencv8 --fix k6 --out cam-cal",
                        "robocal camera calibrate 'fish/*.png' --target board.yaml --model fisheye --out cam-cal",
                        "robocal camera calibrate --bag run.bag --topic /camera/image_raw --every 10 "
                        "--target board.yaml --out cam-cal"),
    input_arguments=(Option("images", nargs="*", type=Path,
                            help="image files, folders or glob patterns (quoted), or one session file (YAML); "
                                 "none with --bag"),),
    calibrate_options=(
        Option("--target", type=Path, default=None, to="load_input",
               help="the target file (YAML/JSON); a session file names its own"),
        Option("--bag", type=Path, default=None, to="load_input",
               help="a ROS 1 .bag, ROS 2 bag folder / .db3 or .mcap recording to take the images from "
                    "(with --topic; no ROS install needed)"),
        Option("--topic", default=None, to="load_input",
               help="the recording's image topic (sensor_msgs/Image or CompressedImage); "
                    "'robocal bag inspect FILE' lists them"),
        Option("--every", type=number_at_least(int, 1), default=1, to="load_input",
               help="take every N-th frame of the topic (video frames a few ms apart are near-duplicates)"),
        Option("--model", choices=MODELS, default="opencv5",
               help="opencv5: k1 k2 p1 p2 k3 (default); opencv4: k3 = 0; opencv8: + rational k4 k5 k6; "
                    "opencv12: + thin prism s1..s4; fisheye: equidistant k1..k4 (cv2.fisheye)"),
        Option("--fix", nargs="+", default=(), metavar="TERM",
               help="distortion terms held at zero (e.g. --fix k3)"),
        Option("--max-outliers", type=number_at_least(int, 0), default=None,
               help="corners that may be removed as outliers (default 5 %% of all corners)"),
        Option("--min-corners", type=number_at_least(int, 4), default=None,
               help="views with fewer usable corners are skipped (default 6)"),
        Option("--noise", choices=("per_view", "pooled"), default="per_view",
               help="per_view: each view weighted by its own pixel noise when a test (Cochran's, 5 %%) finds the "
                    "views' levels unequal (default); pooled: one level for all (cv2.calibrateCamera's objective)"),
        Option("--blur-limit", type=number_at_least(float, 0.0, strict=True), default=None, to="load_input",
               help="edge blur [px] above which a view is named blurred and skipped (default 2.5)"),
        Option("--duplicate-limit", type=number_at_least(float, 0.0), default=None, to="load_input",
               help="two views within this corner RMS [px] are duplicates, the second skipped (default 2)"),
    ),
    simulated_inputs=("camera_input.yaml",),
    quick_simulate=("--views", "6", "--width", "480", "--height", "360"),
)
