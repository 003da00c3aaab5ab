"""``robocal lineprofiler``, declared (:mod:`robocal.workflow`).

The steps live in the library: :mod:`.calibrate` (load, calibrate, result),
:mod:`.report`, :mod:`.workflow` (simulate, summary, demo, ``compare``).
``robocal handeye`` is the core's (:mod:`robocal.handeye.cli`).
"""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Command, Option, Workflow, accept_implausible_option, number_at_least, seed_value

__all__ = ["RIG"]

EXAMPLES = Path("examples/lineprofiler")
_LP = "robocal.rigs.lineprofiler"


_POSES = Option("--poses", type=number_at_least(int, 5, why="FPDP fits X and the sphere centre from 5 or more"), default=16,
                help="number of arm poses of the FPDP sphere scan")
_NOISE_FREE = Option("--noise-free", action="store_true", help="no measurement noise")
_SEED = Option("--seed", type=seed_value, default=0, help="seed of the random generator (>= 0)")


RIG = Workflow(
    name="lineprofiler",
    help="hand-eye calibration of an arm-mounted line laser (Jing, Hu and Guo, seed 004 [S4]: FPDP, MCT)",
    description="Line-laser profiler hand-eye calibration: FPDP (sphere, linear), geometric refinement on all "
                "profile points, MCT (laser tracker and standard block), FPDP vs MCT re-run in simulation.\n\n"
                + examples_epilog("robocal lineprofiler simulate --out lineprofiler-sim",
                            f"robocal lineprofiler calibrate {EXAMPLES}/fpdp_input.yaml --out lineprofiler-cal",
                            f"robocal lineprofiler calibrate {EXAMPLES}/mct_input.yaml --out lineprofiler-mct",
                            "robocal lineprofiler report lineprofiler-cal/result.json --out lineprofiler-report",
                            "robocal lineprofiler compare --out lineprofiler-compare"),
    simulate=f"{_LP}.workflow:simulate_files",
    load_input=f"{_LP}.workflow:load_input",
    calibrate=f"{_LP}.workflow:calibrate_input",
    to_result=f"{_LP}.calibrate:to_result",
    build_report=f"{_LP}.report:build_report",
    summary=f"{_LP}.workflow:summary",
    demo=f"{_LP}.workflow:demo",
    fleet=f"{_LP}.fleet:fleet_member",
    simulate_help="write simulated FPDP and MCT input files (and hand-eye pose lists)",
    simulate_options=(
        _POSES, _NOISE_FREE,
        Option("--scan-profiles", type=number_at_least(int, 3, why="MCT's block scan needs a P3 stroke of 3 or more"),
               default=31, help="profiles in the MCT block scan"),
        Option("--encoder-sigma", type=number_at_least(float, 0.0, unit="mm"), default=0.0, metavar="MM",
               help="P3 encoder read-out noise of the MCT scan and line readings, in mm (default 0: exact)"),
        _SEED,
    ),
    simulate_examples=("robocal lineprofiler simulate --out lineprofiler-sim --seed 1",),
    calibrate_help="FPDP + geometric refinement, or MCT, from an input YAML",
    # optional with --bag (the default [] hands load_input no path); not named `input`, which the CLI's error
    # line would print as the file of a run without one
    input_arguments=(Option("input_file", type=Path, nargs="?", default=[], metavar="INPUT",
                            help="input YAML: sphere radius, arm, profiles CSV (FPDP); or 'method: mct' with "
                                 "tracker, heights, block and scan files (see docs/rigs/lineprofiler.md); with "
                                 "--bag optional (arm, sphere_radius, sign)"),),
    calibrate_options=(
        Option("--bag", type=Path, default=None, to="load_input",
               help="a ROS 1 .bag, ROS 2 bag folder / .db3 or .mcap recording of an FPDP sphere scan"),
        Option("--profiles", default=None, to="load_input",
               help="the recording's profile topic (sensor_msgs/PointCloud2 in the profiler's frame)"),
        Option("--joints", default=None, to="load_input", help="the arm's JointState topic"),
        Option("--joint-names", nargs="+", default=None, metavar="NAME", to="load_input",
               help="the arm's joints as named on --joints, in chain order (default: the chain's names)"),
        Option("--base", default=None, to="load_input", help="tf frame of the arm's base (with --flange)"),
        Option("--flange", default=None, to="load_input", help="tf frame of the flange E (with --base)"),
        Option("--sphere-radius", dest="sphere_radius_mm", type=number_at_least(float, 0.0, strict=True, unit="mm"),
               default=None, metavar="MM", to="load_input",
               help="the sphere's radius in mm (default: INPUT's sphere_radius)"),
    ),
    calibrate_examples=(f"robocal lineprofiler calibrate {EXAMPLES}/fpdp_input.yaml --out lineprofiler-cal",
                        f"robocal lineprofiler calibrate {EXAMPLES}/mct_input.yaml --out lineprofiler-mct",
                        "robocal lineprofiler calibrate --bag scan.bag --profiles /profiler/points --joints "
                        "/joint_states --sphere-radius 25.4 --out lineprofiler-bag"),
    commands=(
        Command("compare", help="simulated re-run of the seed's FPDP vs MCT comparison",
                run=f"{_LP}.workflow:run_compare",
                options=(
                    _SEED,
                    Option("--runs", type=number_at_least(int, 2, why="the spread of repeated calibrations needs 2 or more"),
                           default=3, help="repeated experiments (the seed's 3); e_v, e_theta, e_p against their "
                                           "mean"),
                    Option("--poses", type=number_at_least(int, 5, why="FPDP fits X and the sphere centre from 5 or more"),
                           default=16, help="arm poses per FPDP experiment (the seed's 16)"),
                ),
                examples=("robocal lineprofiler compare --out lineprofiler-compare",)),
    ),
    simulated_inputs=("fpdp_input.yaml",),
    quick_simulate=("--poses", "8", "--scan-profiles", "5"),
)


def __getattr__(name: str):
    # the hand-eye declaration moved to the core (robocal.handeye.cli); the old entry point
    # "robocal.rigs.lineprofiler.cli:HANDEYE" of an older install keeps resolving for one release
    if name == "HANDEYE":
        import warnings

        from robocal._deprecation import REMOVED_IN
        from robocal.handeye.cli import HANDEYE

        warnings.warn(f"robocal.rigs.lineprofiler.cli.HANDEYE is deprecated and will be removed in {REMOVED_IN}; "
                      "use robocal.handeye.cli.HANDEYE instead", DeprecationWarning, stacklevel=2)
        return HANDEYE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
