"""``robocal handeye``, declared (:mod:`robocal.workflow`): the steps live in :mod:`.workflow`."""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Command, Option, Workflow, accept_implausible_option, number_at_least

__all__ = ["HANDEYE"]

EXAMPLES = Path("examples/lineprofiler")
_HE = "robocal.handeye.workflow"

_PAIR = (Option("gripper_poses", type=Path, help="T_base_gripper list (CSV/YAML, scalar-last quaternions)"),
         Option("target_poses", type=Path, help="T_cam_target list (CSV/YAML)"))

_SETUP = Option("--setup", default="eye-in-hand", choices=["eye-in-hand", "eye-to-hand"],
                help="eye-in-hand (camera on the gripper, fixed target): X = T_gripper_cam, target pose "
                     "T_base_target; eye-to-hand (fixed camera, target on the gripper): X = T_base_cam, "
                     "target pose T_gripper_target")
_PAIRS_HELP = ("pose pairs of the closed form's relative motions: all (every pair, n^2/2), consecutive "
               "(i, i+1), auto (default: all up to 200 poses, else consecutive plus at most 20,000 longer "
               "pairs turning 10-150 deg; memory linear in the number of poses)")

#: ``calibrate``'s inputs: the two lists, or none with ``--bag`` (an absent one is ``[]``: no input file).
_PAIR_OR_BAG = (Option("gripper_poses", type=Path, nargs="?", default=[],
                       help="T_base_gripper list (CSV/YAML, scalar-last quaternions); by default none: --bag"),
                Option("target_poses", type=Path, nargs="?", default=[],
                       help="T_cam_target list (CSV/YAML); by default none: --bag"))

#: A recording instead of the lists (robocal.handeye.bag_input); every default None: given or not.
_BAG = (
    Option("--bag", type=Path, default=None, to="load_input",
           help="a ROS 1 .bag, ROS 2 bag folder / .db3 or .mcap recording (no ROS install needed): the robot "
                "poses from its tf at the header stamps of --images or --target-poses"),
    Option("--base", default=None, to="load_input", help="tf frame of the robot base (e.g. base_link)"),
    Option("--gripper", default=None, to="load_input", help="tf frame of the gripper / flange (e.g. tool0)"),
    Option("--images", default=None, to="load_input",
           help="the target's images: with --bag an image topic (sensor_msgs/Image or CompressedImage); without, "
                "a folder of images, one per robot pose of GRIPPER in name order; with --target and a camera"),
    Option("--camera-info", default=None, to="load_input",
           help="CameraInfo topic (default: the camera_info beside the image topic)"),
    Option("--camera", type=Path, default=None, to="load_input",
           help="camera file instead of --camera-info (OpenCV YAML/XML, ROS camera_info, robocal JSON/YAML)"),
    Option("--target", type=Path, default=None, to="load_input",
           help="target file (chessboard, ChArUco, ArUco/AprilTag grid) of --images"),
    Option("--target-poses", dest="target_pose_topic", default=None, to="load_input",
           help="instead of --images: a topic of the target's pose in the camera (PoseStamped, "
                "PoseWithCovarianceStamped, TransformStamped)"),
    Option("--every", type=number_at_least(int, 1), default=None, to="load_input",
           help="take every N-th frame of the topic"),
)

_SHARED = (
    Option("--method", default="tsai", choices=["tsai", "park", "horaud", "andreff", "daniilidis"],
           help="closed-form AX = XB solver (then refined unless --no-refine)"),
    Option("--no-refine", action="store_true", help="closed form only (no covariance)"),
    _SETUP,
    Option("--pairs", default="auto", choices=["auto", "consecutive", "all"], help=_PAIRS_HELP),
)

#: ``calibrate`` of two timed streams (read by ``load_pose_pair``).
_CLOCK = Option("--clock-offset", default="none", metavar="auto|none|SECONDS", to="load_input",
                help="two timed streams on two clocks: none (default: one clock), SECONDS (added to the camera's "
                     "stamps to put them on the robot's clock), or auto (from the two rotation rates by "
                     "cross-correlation, then refined with X: reported with its std). Timed streams: samples "
                     "whose stamp does not advance are dropped and counted, the streams cropped to their "
                     "overlap")

HANDEYE = Workflow(
    name="handeye",
    help="AX = XB hand-eye solvers (Tsai, Park, Horaud, Andreff, Daniilidis) and robot-world AX = ZB, "
         "with refinement",
    description="Classic hand-eye calibration from pose lists (see docs/handeye.md).\n\n"
                + examples_epilog("robocal handeye simulate --out handeye-sim",
                            f"robocal handeye calibrate {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                            "--method park --out he",
                            f"robocal handeye robot-world {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                            "--out rw",
                            "robocal handeye report he/result.json --out he-report"),
    simulate=f"{_HE}:simulate_files",
    load_input=f"{_HE}:load_pose_pair",
    calibrate=f"{_HE}:calibrate",
    to_result=f"{_HE}:to_result",
    build_report="robocal.handeye.report:build_report",
    summary=f"{_HE}:summary",
    fleet="robocal.handeye.fleet:fleet_member",
    simulate_help="write two simulated pose lists (gripper, target) and their truth",
    simulate_options=(
        Option("--poses", type=number_at_least(int, 3, why="AX = XB needs 2 motions, i.e. 3 poses or more"),
               default=16, help="number of simulated views of the target"),
        Option("--noise-free", action="store_true", help="no measurement noise"),
        Option("--setup", default="eye-in-hand", choices=["eye-in-hand", "eye-to-hand"],
               help="eye-in-hand: a camera on the gripper views a fixed target; eye-to-hand: a fixed camera "
                    "views a target on the gripper"),
    ),
    simulate_examples=("robocal handeye simulate --out handeye-sim --seed 1",),
    calibrate_help="X = T_gripper_cam (eye-in-hand) or T_base_cam (eye-to-hand) from two pose lists, from the "
                   "robot poses and a folder of images (--images DIR --camera --target), or from a ROS 1 / ROS 2 / "
                   "MCAP recording (--bag: tf + images or a target-pose topic)",
    input_arguments=_PAIR_OR_BAG,
    calibrate_options=(*_SHARED, _CLOCK, *_BAG),
    calibrate_examples=(f"robocal handeye calibrate {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                        "--method park --out he",
                        "robocal handeye calibrate examples/handeye/robot_poses.csv --images examples/handeye/images "
                        "--camera examples/handeye/camera.yaml --target examples/handeye/target.yaml --out he-img",
                        "robocal handeye calibrate --bag examples/bags/handeye.bag --base base_link --gripper tool0 "
                        "--images /camera/image_raw/compressed --target examples/bags/handeye_target.yaml "
                        "--out he-bag"),
    commands=(
        Command("calibrate-images", help="X from images of a target and the robot poses: each view's pose with its "
                                         "covariance, ambiguous / badly conditioned views named and down-weighted",
                run="robocal.handeye.commands:run_images",
                options=(Option("--images", type=Path, required=True,
                                help="folder of images (.png/.jpg/...), one per robot pose, in name order"),
                         Option("--robot", type=Path, required=True, help="T_base_gripper list, one pose per image"),
                         Option("--camera", type=Path, required=True,
                                help="camera file (OpenCV YAML/XML, ROS camera_info, robocal JSON/YAML)"),
                         Option("--target", type=Path, required=True,
                                help="target file (chessboard, ChArUco, ArUco/AprilTag grid)"),
                         *_SHARED, accept_implausible_option()),
                examples=("robocal handeye simulate-images --out he-img",
                          "robocal handeye calibrate-images --images he-img/images --robot he-img/robot_poses.csv "
                          "--camera he-img/camera.yaml --target he-img/target.yaml --out he-img-cal")),
        Command("simulate-images", help="render views of a chessboard with the robot poses, camera, target, truth",
                run="robocal.handeye.commands:run_simulate_images",
                options=(Option("--poses", type=number_at_least(int, 3, why="AX = XB needs 3 poses"), default=8,
                                help="number of views"),
                         Option("--seed", type=int, default=0, help="random seed"),
                         Option("--setup", default="eye-in-hand", choices=["eye-in-hand", "eye-to-hand"],
                                help="eye-in-hand or eye-to-hand")),
                examples=("robocal handeye simulate-images --out he-img",)),
        Command("robot-world", help="A X = Z B: T_gripper_cam and T_base_target together (Shah + refinement)",
                run=f"{_HE}:run_robot_world",
                options=(*_PAIR,
                         Option("--no-refine", action="store_true", help="Shah's closed form only (no covariance)"),
                         Option("--setup", default="eye-in-hand", choices=["eye-in-hand", "eye-to-hand"],
                                help="eye-in-hand: X = T_target_base, Z = T_cam_gripper (and their inverses "
                                     "T_base_target, T_gripper_cam); eye-to-hand (fixed camera, target on the "
                                     "gripper): X = T_target_gripper, Z = T_cam_base (T_gripper_target, "
                                     "T_base_cam)"),
                         Option("--pairs", default="auto", choices=["auto", "consecutive", "all"],
                                help="pose pairs of the excitation check's gripper motions (Shah's closed form "
                                     "and the refinement use every pose): " + _PAIRS_HELP.split(": ", 1)[1]),
                         Option("--clock-offset", default="none", metavar="auto|none|SECONDS", to=None,
                                help="two timed streams on two clocks, as for calibrate; auto: the rotation-rate "
                                     "correlation only (not refined with X and Z: no std)"),
                         accept_implausible_option()),
                examples=(f"robocal handeye robot-world {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                          "--out rw",)),
    ),
    simulated_inputs=("gripper_poses.csv", "target_poses.csv"),
    quick_simulate=("--poses", "8"),
)
