"""``robocal lineprofiler`` and ``robocal handeye``, declared (:mod:`robocal.workflow`).

The steps live in the library: :mod:`.calibrate` (load, calibrate, result),
:mod:`.report`, :mod:`.workflow` (simulate, summary, demo, ``compare``) and
:mod:`.handeye_workflow` (the two pose lists, AX = XB, ``robot-world``).
"""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Command, Option, Workflow, accept_implausible_option, number_at_least, seed_value

__all__ = ["RIG", "HANDEYE"]

EXAMPLES = Path("examples/lineprofiler")
_LP = "robocal.rigs.lineprofiler"
_HE = f"{_LP}.handeye_workflow"


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
    load_input=f"{_LP}.calibrate:load_input",
    calibrate=f"{_LP}.calibrate:calibrate_input",
    to_result=f"{_LP}.calibrate:to_result",
    build_report=f"{_LP}.report:build_report",
    summary=f"{_LP}.workflow:summary",
    demo=f"{_LP}.workflow:demo",
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
    input_arguments=(Option("input", type=Path, help="input YAML: sphere radius, arm, profiles CSV (FPDP); or "
                                                     "'method: mct' with tracker, heights, block and scan files "
                                                     "(see docs/rigs/lineprofiler.md)"),),
    calibrate_examples=(f"robocal lineprofiler calibrate {EXAMPLES}/fpdp_input.yaml --out lineprofiler-cal",
                        f"robocal lineprofiler calibrate {EXAMPLES}/mct_input.yaml --out lineprofiler-mct"),
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


_PAIR = (Option("gripper_poses", type=Path, help="T_base_gripper list (CSV/YAML, scalar-last quaternions)"),
         Option("target_poses", type=Path, help="T_cam_target list (CSV/YAML)"))

HANDEYE = Workflow(
    name="handeye",
    help="AX = XB hand-eye solvers (Tsai, Park, Horaud, Andreff, Daniilidis) and robot-world AX = ZB, "
         "with refinement",
    description="Classic hand-eye calibration from pose lists (see docs/rigs/lineprofiler.md).\n\n"
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
    build_report=f"{_HE}:build_report",
    summary=f"{_HE}:summary",
    simulate_help="write two simulated pose lists (gripper, target) and their truth",
    simulate_options=(_POSES, _NOISE_FREE),
    simulate_examples=("robocal handeye simulate --out handeye-sim --seed 1",),
    calibrate_help="eye-in-hand X = T_gripper_cam from two pose lists",
    input_arguments=_PAIR,
    calibrate_options=(
        Option("--method", default="tsai", choices=["tsai", "park", "horaud", "andreff", "daniilidis"],
               help="closed-form AX = XB solver (then refined unless --no-refine)"),
        Option("--no-refine", action="store_true", help="closed form only (no covariance)"),
    ),
    calibrate_examples=(f"robocal handeye calibrate {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                        "--method park --out he",),
    commands=(
        Command("robot-world", help="A X = Z B: T_gripper_cam and T_base_target together (Shah + refinement)",
                run=f"{_HE}:run_robot_world",
                options=(*_PAIR,
                         Option("--no-refine", action="store_true", help="Shah's closed form only (no covariance)"),
                         accept_implausible_option()),
                examples=(f"robocal handeye robot-world {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                          "--out rw",)),
    ),
    simulated_inputs=("gripper_poses.csv", "target_poses.csv"),
    quick_simulate=("--poses", "8"),
)
