"""``robocal flow ...``, declared: simulate | calibrate | report (built by the core), odometry | evaluate |
convert-mavlink, and the demo.

Declarations only: every step is a ``"module:attr"`` string imported when the
command runs, so ``robocal flow --help`` imports none of the rig's library
(numba, OpenCV, matplotlib, scipy).
"""

from __future__ import annotations

from pathlib import Path

from robocal.workflow import Command, Option, Workflow, accept_implausible_option

__all__ = ["RIG", "TEXTURES"]

#: :data:`robocal.rigs.flow.simulate.TEXTURES` (the ``--texture`` choices), repeated here so that ``--help``
#: does not import the simulator (numba, ~0.3 s); a test (tests/rigs/flow/test_flow_cli.py) asserts that
#: they are equal.
TEXTURES = ("gravel", "grass", "brick", "moon")

DESCRIPTION = """Dead reckoning from several downward optical-flow sensors (Li, Guan and Chu 2017, PX4FLOW-class):
SAD block matching + sub-pixel refinement + gyro compensation per sensor, the rigid-body
least squares A u = b over the array, pose integration, array calibration, ATE/RPE.
Log format: see docs/rigs/flow.md (run.yaml + per-sensor flow.csv or raw frames.npz).

examples:
  robocal flow simulate --out flow-sim
  robocal flow odometry examples/flow/loop/run.yaml --out flow-odo
  robocal flow odometry examples/flow/frames/run.yaml --out flow-odo-frames     (raw frames)
  robocal flow calibrate examples/flow/calibration/run.yaml --out flow-cal
  robocal flow evaluate examples/flow/loop/run.yaml --array flow-cal/array_calibrated.yaml --out flow-eval
  robocal flow report flow-cal/result.json --out flow-cal-report      (any flow result.json)
  robocal flow convert-mavlink flow.tlog --array array.yaml --sensor-map 0:s60,1:s120,2:s270 --out flow-conv"""

def _kernel_options(*, simulate: bool = False, debias: bool = True) -> tuple:
    """The block matcher's options (raw frames only; for ``simulate``: the kernel of the written flow.csv)."""
    scope = "; for the flow written to flow.csv" if simulate else "; raw frames only"
    opts = (
        Option("--subpixel", default=None, choices=("none", "half", "quarter", "parabolic", "equiangular"),
               help=f"sub-pixel method of the block matcher (half = PX4FLOW; default equiangular){scope}"),
        Option("--refine", default=None, choices=("none", "lk"),
               help=f"frame-level Gauss-Newton refinement (default none){scope}"),
        Option("--search", type=int, default=None, help=f"integer search range, +/- px (default 4){scope}"),
        Option("--aggregate", default=None, choices=("trimmed", "tensor"),
               help="how the blocks make a frame's flow: trimmed mean (default), or tensor = weighted by each "
                    "block's gradient structure tensor (fewer wrong frames on repeating patterns such as "
                    f"bricks, ~30 %% slower){scope}"),
    )
    if debias:
        opts += (Option("--debias", action="store_true",
                        help="remove the kernel's sub-pixel bias (pixel locking), measured on the run's frames (a flow "
                             "log: on gravel frames), from every displacement"),)
    return opts + (Option("--no-progress", action="store_true", help="never show progress bars"),)


#: ``--bag FILE --map topics.yaml`` (issue 15; robocal.rigs.flow.bag): calibrate and odometry from a recording.
_BAG_OPTIONS = (
    Option("--bag", type=Path, default=None, to="load_input",
           help="a ROS 1 .bag, ROS 2 bag folder / .db3 or .mcap recording: each sensor's "
                "mavros_msgs/OpticalFlowRad topic and a nav_msgs/Odometry reference (with --map)"),
    Option("--map", type=Path, default=None, to="load_input",
           help="with --bag: YAML of the array (as run.yaml) and 'topics: {flow: {SENSOR: TOPIC}, reference: "
                "TOPIC}' (docs/rigs/flow.md, 'From a recording')"),
)

_RUN_COMMAND_OPTIONS = _kernel_options() + (
    accept_implausible_option(),)

RIG = Workflow(
    name="flow",
    help="dead reckoning from several optical-flow sensors (Li, Guan and Chu 2017)",
    description=DESCRIPTION,
    simulate="robocal.rigs.flow.commands:simulate_files",
    load_input="robocal.rigs.flow.inputs:load_input",
    calibrate="robocal.rigs.flow.workflow:calibrate_input",
    to_result="robocal.rigs.flow.workflow:calibration_result",
    build_report="robocal.rigs.flow.report:build_report",
    summary="robocal.rigs.flow.workflow:summary",
    demo="robocal.rigs.flow.demo:demo",
    simulate_help="simulate a drive: frames, flow log, gyro, height, truth, wheel odometry",
    simulate_options=(
        Option("--trajectory", default="loop", choices=("loop", "calibration", "straight"),
               help="loop = smooth random curves; calibration = straights, turns on the spot and arcs (for "
                    "'calibrate'); straight = constant speed"),
        Option("--duration", type=float, default=8.0, help="s"),
        Option("--rate", type=float, default=400.0, help="frame rate, Hz"),
        Option("--speed", type=float, default=0.4, help="typical forward speed, m/s"),
        Option("--texture", default="gravel", choices=TEXTURES + ("procedural",),
               help="floor photograph (scikit-image): gravel, grass = good floors; brick = repeating pattern "
                    "(aliasing); moon = low texture; procedural = band-limited noise"),
        Option("--supersample", type=int, default=2, help="sub-rays per pixel side (binning area average)"),
        Option("--gap", action="append", help="low-texture disc on the floor: X,Y,RADIUS in m (repeatable)"),
        Option("--no-frames", action="store_true", help="write only the flow log, not frames.npz"),
        *_kernel_options(simulate=True, debias=False),
    ),
    simulate_examples=(
        "robocal flow simulate --out flow-sim",
        "robocal flow simulate --trajectory calibration --duration 8 --out flow-sim-cal",
        "robocal flow simulate --texture brick --gap 0.5,0.2,0.05 --no-frames --out flow-sim-brick",
    ),
    calibrate_help="calibrate R, psi, phi, scale of every sensor from a run with a reference",
    # optional (none with --bag: the default [] hands load_input no path); not named `input` (humanoid's reason)
    input_arguments=(Option("run", type=Path, nargs="?", default=[], metavar="INPUT",
                            help="run.yaml with a 'reference' trajectory; none with --bag"),),
    calibrate_options=(
        *_BAG_OPTIONS,
        Option("--window", type=float, default=0.1, help="window length, s"),
        Option("--loss", default="linear", choices=("linear", "soft_l1", "huber", "cauchy"),
               help="robust loss of the window residuals (scipy least_squares names)"),
        *_kernel_options(),
    ),
    calibrate_examples=("robocal flow calibrate examples/flow/calibration/run.yaml --out flow-cal",
                        "robocal flow calibrate --bag drive.bag --map topics.yaml --out flow-cal-bag"),
    commands=(
        Command(
            "odometry", help="dead reckoning from a run (flow log or raw frames, or a recording)",
            run="robocal.rigs.flow.commands:run_odometry",
            options=(
                Option("input", type=Path, nargs="?", default=None, help="run.yaml; none with --bag"),
                *_BAG_OPTIONS,
                Option("--allow-missing", action="store_true", help="treat missing sensor records as invalid frames"),
                Option("--no-robust", action="store_true", help="do not drop disagreeing sensors"),
                Option("--integration", default="exact", choices=("exact", "euler"),
                       help="euler = the seed's eq. 12 literally"),
                Option("--no-report", action="store_true",
                       help="write trajectory.csv and result.json only (no report.html: 'robocal flow report "
                            "OUT/result.json' draws it later); for batches of logs, about 2 s less a log"),
                *_RUN_COMMAND_OPTIONS,
            ),
            examples=("robocal flow odometry examples/flow/loop/run.yaml --out flow-odo",
                      "robocal flow odometry flow-sim/run.yaml --no-report --out flow-odo   (report later: "
                      "robocal flow report flow-odo/result.json --out flow-odo-report)",
                      "robocal flow odometry examples/flow/frames/run.yaml --subpixel quarter --out flow-odo-frames",
                      "robocal flow odometry flow-sim/run.yaml --refine lk --out flow-odo",
                      "robocal flow odometry --bag drive.bag --map topics.yaml --out flow-odo-bag"),
        ),
        Command(
            "evaluate", help="ATE / RPE of flow (and wheel) odometry against the reference",
            run="robocal.rigs.flow.commands:run_evaluate",
            options=(
                Option("input", type=Path, help="run.yaml with a 'reference' trajectory"),
                Option("--array", type=Path, default=None,
                       help="a calibrated array (YAML) to compare with the nominal one"),
                *_RUN_COMMAND_OPTIONS,
            ),
            examples=("robocal flow evaluate examples/flow/loop/run.yaml --out flow-eval",
                      "robocal flow evaluate examples/flow/loop/run.yaml --array flow-cal/array_calibrated.yaml "
                      "--out flow-eval"),
        ),
        Command(
            "convert-mavlink", help="MAVLink telemetry log (.tlog, OPTICAL_FLOW_RAD) -> flow log + run.yaml",
            run="robocal.rigs.flow.commands:run_convert_mavlink",
            options=(
                Option("input", type=Path,
                       help=".tlog: records of an 8-byte big-endian timestamp (us) + one MAVLink 1/2 frame"),
                Option("--array", type=Path, required=True,
                       help="YAML with the array's 'sensors' (name, R, psi, phi, scale; as in run.yaml)"),
                Option("--sensor-map", required=True, metavar="ID:NAME,...",
                       help="OPTICAL_FLOW_RAD sensor_id -> sensor name of the array, e.g. 0:s60,1:s120,2:s270"),
                Option("--focal-px", type=float, default=None,
                       help="focal length written to run.yaml, px (flow is logged in rad: it only sets the flow-error "
                            "scale; default the array file's camera.focal_px, else 666.7 = PX4FLOW, 16 mm lens)"),
                Option("--sigma-px", type=float, default=0.16,
                       help="the sensors' flow error per camera frame, px (default 0.16: PX4FLOW half-pixel "
                            "firmware); run.yaml gets it times sqrt(frames per interval)"),
                Option("--frame-rate", type=float, default=400.0,
                       help="the sensors' camera frame rate, Hz (default 400: PX4FLOW), to count the frames a "
                            "record integrates"),
                Option("--clock", default="log", choices=("log", "message"),
                       help="record end times: log = the tlog's timestamps (one clock for all sensors); message = "
                            "time_usec (only when every sensor stamps on one clock, e.g. one autopilot)"),
                Option("--rate", type=float, default=None,
                       help="resample onto a uniform grid at this rate, Hz (default: the first mapped sensor's "
                            "records)"),
                Option("--sysid", type=int, default=None, help="use only messages from this MAVLink system id"),
            ),
            examples=("robocal flow convert-mavlink examples/flow/mavlink/flow.tlog --array "
                      "examples/flow/mavlink/array.yaml \\\n      --sensor-map 0:s60,1:s120,2:s270 --out conv",
                      "robocal flow odometry flow-conv/run.yaml --out flow-odo",
                      "robocal flow convert-mavlink my.tlog --array array.yaml --sensor-map 0:left,1:right "
                      "--rate 100 --out flow-conv"),
        ),
    ),
    simulated_inputs=("run.yaml",),
    quick_simulate=("--trajectory", "calibration", "--duration", "1.5", "--supersample", "1", "--no-frames",
                    "--no-progress"),
)
