"""Command line of the ``humanoid`` rig, declared: ``robocal humanoid simulate | calibrate | plan | report``.

The steps live in :mod:`.workflow` (simulate, load, calibrate, result, summary,
demo), :mod:`.report` (the report, from the result alone) and :mod:`.commands`
(``plan``); the core builds the commands from this declaration.
"""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Command, Option, Workflow, seed_value

__all__ = ["RIG"]

EXAMPLES = Path("examples/humanoid")
_WF = "robocal.rigs.humanoid.workflow"

RIG = Workflow(
    name="humanoid",
    help="NAO leg joint offsets + head camera mounting from checkerboards under the feet (Fan and Lou, seed 001 [S1])",
    description="Kinematic calibration of a NAO-class humanoid: the lower head camera watches a checkerboard "
                "pinned under each foot; Levenberg-Marquardt over joint offsets, camera and board mounting "
                "(the seed's 21 parameters), with uncertainties, identifiability and outliers.\n\n"
                + examples_epilog("robocal humanoid simulate --out humanoid-sim",
                                  "robocal humanoid calibrate humanoid-sim/run.yaml --out humanoid-cal",
                                  f"robocal humanoid calibrate {EXAMPLES}/run.yaml --out humanoid-cal",
                                  "robocal humanoid plan --poses 12 --out humanoid-plan",
                                  "robocal humanoid report humanoid-cal/result.json --out humanoid-report"),
    simulate=f"{_WF}:simulate_files",
    load_input=f"{_WF}:load_input",
    calibrate=f"{_WF}:calibrate_input",
    to_result=f"{_WF}:to_result",
    build_report="robocal.rigs.humanoid.report:build_report",
    summary=f"{_WF}:summary",
    demo=f"{_WF}:demo",
    fleet="robocal.rigs.humanoid.fleet:fleet_member",
    simulate_help="render a simulated run: data-set YAML + PNG images (+ truth)",
    simulate_description="True offsets ~0.5 deg, poses within the joint limits with the board fully visible, joint "
                         "readings quantised to 0.1 deg, rendered images with blur and noise.",
    simulate_examples=("robocal humanoid simulate --out humanoid-sim",
                       "robocal humanoid simulate --views 12 --seed 3 --out humanoid-sim",
                       "robocal humanoid calibrate humanoid-sim/run.yaml --out humanoid-cal"),
    simulate_options=(
        Option("--views", type=int, default=8, help="views per foot"),
        Option("--blur", type=float, default=0.8, help="image blur sigma [px]"),
        Option("--image-noise", type=float, default=2.0, help="image noise sigma [grey levels]"),
        Option("--offset-scale", type=float, default=0.5, help="std of the true joint/camera offsets [deg]"),
        Option("--tie", action="store_true", help="one HipYawPitch motor (tied joints) in the model"),
    ),
    calibrate_help="detect corners, estimate offsets: result.json, report.html, offsets.yaml, corrected URDF",
    calibrate_description="Input format: docs/rigs/humanoid.md (format robocal.humanoid-data/1).\n"
                          "Parameter sets: seed (21, default), seed+camera_xy, legs, all, or a "
                          "comma list of names (LKneePitch, camera.roll, board.left.x, ...).",
    calibrate_examples=(f"robocal humanoid calibrate {EXAMPLES}/run.yaml --out humanoid-cal",
                        "robocal humanoid calibrate humanoid-sim/run.yaml --tie --out humanoid-cal   "
                        "# data from one HipYawPitch motor",
                        f"robocal humanoid calibrate {EXAMPLES}/run.yaml --params seed+camera_xy --out cal",
                        "robocal humanoid calibrate --bag nao.bag --images /nao/camera/bottom/image_raw --out cal"),
    # optional (none with --bag: the default [] hands load_input no path); not named `input`, which the
    # CLI's error line would print as the file of a run without one
    input_arguments=(Option("dataset", type=Path, nargs="?", default=[], metavar="INPUT",
                            help="data-set file (YAML/JSON); none with --bag"),),
    calibrate_options=(
        Option("--bag", type=Path, default=None, to="load_input",
               help="a ROS 1 .bag, ROS 2 bag folder / .db3 or .mcap recording to take the views from "
                    "(with --images)"),
        Option("--joints", default="/joint_states", to="load_input", help="the recording's JointState topic"),
        Option("--images", default=None, to="load_input", help="the recording's lower-camera image topic"),
        Option("--camera-info", default=None, to="load_input",
               help="CameraInfo topic of the camera (default: camera_info beside --images)"),
        Option("--camera", type=Path, default=None, to="load_input", help="camera file instead of --camera-info"),
        Option("--joint-map", nargs="+", default=None, metavar="MODEL=RECORDED", to="load_input",
               help="recorded names of model joints that differ from NAOqi's (e.g. LKneePitch=l_knee)"),
        Option("--params", default="seed", help="parameters to estimate"),
        Option("--tie", action="store_true",
               help="one offset for both HipYawPitch joints (one motor); wrong for data whose two "
                    "offsets differ, such as examples/humanoid (simulated untied)"),
        Option("--fd", action="store_true", help="finite-difference Jacobian instead of the analytic one"),
        Option("--corner-sigma", type=float, default=None,
               help="corner noise [px] (default: measured from the data)"),
        Option("--reject-outliers", action="store_true",
               help="remove the outlier corners (beyond the Bonferroni threshold over all corners, ~4.2 sigma "
                    "for 400; a view with > 25 %% of its corners flagged: the whole view) and re-solve once; "
                    "what was removed is listed in result.json and the report"),
        Option("--consistency-px", type=float, default=60.0,
               help="refuse a view whose corners lie further [px, median] from where its joint record and "
                    "foot label put them than max(this, --consistency-ratio x the median view's); raise it "
                    "for a robot with offsets beyond ~1 deg"),
        Option("--consistency-ratio", type=float, default=4.0, help="see --consistency-px"),
    ),
    commands=(
        Command(
            "plan", help="choose leg poses that make the calibration well conditioned",
            run="robocal.rigs.humanoid.commands:run_plan",
            description="Greedy D-optimal design: from random candidate poses (within the joint limits, whole "
                        "board in view and facing the camera, feet apart) add the one that most increases "
                        "log det of the Fisher information. Writes plan.yaml (joint angles to command) and "
                        "report.html (predicted stds after each pose).",
            examples=("robocal humanoid plan --poses 12 --out humanoid-plan",
                      "robocal humanoid plan --poses 20 --candidates 100 --out humanoid-plan",
                      f"robocal humanoid plan --data {EXAMPLES}/run.yaml --corner-sigma 0.1 --out plan"),
            options=(
                Option("--poses", type=int, default=12, help="poses to choose"),
                Option("--candidates", type=int, default=60, help="random candidate poses per foot"),
                Option("--params", default="seed", help="parameters to plan for"),
                Option("--data", type=Path, default=None,
                       help="plan for the robot of this data-set file (URDF, camera, board, tie, joint "
                            "resolution; its images are not read)"),
                Option("--tie", action="store_true",
                       help="one HipYawPitch motor (tied joints) in the default model (with --data, the file's "
                            "tie_hip_yaw_pitch decides)"),
                Option("--corner-sigma", type=float, default=0.3, help="expected corner noise [px]"),
                # the type every other --seed has (robocal.workflow.seed_value) (a whole number >= 0)
                Option("--seed", type=seed_value, default=0, help="seed of the random generator (>= 0)"),
            ),
        ),
    ),
    simulated_inputs=("run.yaml",),
    quick_simulate=("--views", "3"),
)
