"""Command line of the ``projector`` rig, declared: ``robocal projector simulate | calibrate | report | evaluate | path``.

Declarations only (:class:`robocal.workflow.Workflow`): the core builds
``simulate``, ``calibrate`` and ``report``; the steps live in
:mod:`robocal.rigs.projector.workflow` and :mod:`.report`, the extra commands'
run functions in :mod:`.commands`. Declaring imports none of them.
"""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import examples_epilog
from robocal.workflow import Command, Option, Workflow, accept_implausible_option, seed_value

__all__ = ["RIG"]

EXAMPLES = Path("examples/projector")
#: :data:`robocal.rigs.projector.path.NADIR_SNAP` and ``MAX_NADIR_SNAP`` [m], repeated for the ``path`` parser so
#: that ``--help`` does not import the path planner (its model pulls in scipy.spatial, ~0.4 s); a test
#: (tests/rigs/projector/test_projector_cli_commands.py) asserts that they equal path's.
NADIR_SNAP = 1e-3
MAX_NADIR_SNAP = 0.1
#: ``simulate --points`` cap, repeated from :data:`robocal.rigs.projector.workflow.MAX_SIM_POINTS` for the help text.
MAX_SIM_POINTS = 10_000

_W = "robocal.rigs.projector.workflow"

EVALUATE = Command(
    "evaluate", help="seed Table 2 protocol on a simulated rig: table + floor error map",
    run="robocal.rigs.projector.commands:run_evaluate",
    description=("Commands a 3 x 3 grid of floor points with the calibrated model and measures\n"
                 "where the true head (the input's 'truth') lands the spot. Writes\n"
                 "OUT/report.html (and result.json, or evaluation.json with --result)."),
    examples=(f"robocal projector evaluate {EXAMPLES}/room_A.yaml --out projector-eval",
              f"robocal projector evaluate {EXAMPLES}/room_A.yaml --result projector-cal/result.json"
              " --spacing 1.5 --out ev"),
    options=(
        Option("input", type=Path, help="calibration input with a 'truth' section (as written by simulate)"),
        Option("--result", type=Path, default=None, help="use this calibration result instead of calibrating"),
        Option("--spacing", type=float, default=2.0, metavar="M", help="Table 2 grid spacing [m]"),
        Option("--center", type=float, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"),
               help="Table 2 grid centre in {W} [m]"),
        accept_implausible_option(),
    ),
)

PATH = Command(
    "path", help="world path -> timed joint commands over one or more projectors",
    run="robocal.rigs.projector.commands:run_path",
    description=("Writes OUT/commands.csv (the serving head per sample, with a status column),\n"
                 "OUT/commands_<name>.csv per head (pre-aimed between its segments), plan.json\n"
                 "and report.html.\n"
                 "Exit 0: every sample served; 1: a stretch is infeasible (its reason and fix\n"
                 "are printed); 2: bad input (e.g. a point no projector reaches)."),
    examples=(f"robocal projector path {EXAMPLES}/path_room.yaml --out projector-path",
              f"robocal projector path {EXAMPLES}/path_timed.yaml --out projector-path",
              f"robocal projector path {EXAMPLES}/path_timed.yaml --retime --out projector-path",
              f"robocal projector path {EXAMPLES}/path_nadir.yaml --out projector-path",
              f"robocal projector path {EXAMPLES}/path_near_nadir.yaml --nadir-snap 15 --out path"),
    options=(
        Option("input", type=Path, help="path input (YAML/JSON)"),
        Option("--nadir-margin", type=float, default=2.0, metavar="DEG",
               help="keep this far from the nadir [deg]; with the projector's tilt_min < 0 a path may pass "
                    "through it (constant pan, tilt through zero)"),
        Option("--limit-margin", type=float, default=2.0, metavar="DEG", help="keep this far below the tilt limit [deg]"),
        Option("--nadir-snap", type=float, default=1000 * NADIR_SNAP, metavar="MM",
               help=f"path samples closer than this to a projector's nadir are aimed at the nadir itself, and a "
                    f"path passing that close goes through it (needs tilt_min < 0) instead of swinging the pan "
                    f"180 deg; the spot error there is up to this distance [mm, 0..{1000 * MAX_NADIR_SNAP:g}]"),
        Option("--retime", action="store_true",
               help="slow the spot down where the joint rate limits require it (instead of infeasible rows)"),
    ),
)

RIG = Workflow(
    name="projector",
    help="ceiling pan-tilt laser projector: D-H model, IK, world extrinsics, spot paths (seed 000)",
    description=(
        "Ceiling pan-tilt laser projector (seed 000).\n"
        "  simulate   write a simulated calibration input with its ground truth\n"
        "  calibrate  the pose T_0_W by the seed's method, the closed form and nonlinear LS\n"
        "  report     rebuild report.html from a result.json\n"
        "  evaluate   the seed's Table 2 protocol + floor error map on a simulated rig\n"
        "  path       world path -> timed joint commands, several projectors, hand-overs\n\n"
        + examples_epilog(f"robocal projector calibrate {EXAMPLES}/seed_projector_A.yaml --out projector-cal",
                          "robocal projector simulate --out projector-sim && robocal projector evaluate "
                          "projector-sim/projector.yaml --out projector-eval",
                          f"robocal projector path {EXAMPLES}/path_room.yaml --out projector-path")
    ),
    simulate=f"{_W}:simulate_files",
    load_input=f"{_W}:load_input",
    calibrate=f"{_W}:calibrate_input",
    to_result=f"{_W}:to_result",
    build_report="robocal.rigs.projector.report:build_report",
    summary=f"{_W}:summary",
    demo=f"{_W}:demo",
    fleet="robocal.rigs.projector.fleet:fleet_member",
    simulate_help="write a simulated calibration input (with its ground truth)",
    simulate_description=("Writes OUT/projector.yaml: projector A of the seed's room, N floor points with\n"
                          "world noise and the joint angles read there, and a 'truth' section (the true\n"
                          "head) that `evaluate` uses."),
    simulate_examples=("robocal projector simulate --out projector-sim",
                       "robocal projector simulate --points 10 --noise 2 --out projector-sim --seed 4",
                       "robocal projector calibrate projector-sim/projector.yaml --out projector-cal"),
    simulate_options=(
        Option("--points", type=int, default=8, metavar="N", help=f"number of floor points [3..{MAX_SIM_POINTS}]"),
        Option("--noise", type=float, default=5.0, metavar="MM", help="world measurement noise sigma [mm], > 0"),
        Option("--theta-noise", type=float, default=0.0, metavar="DEG",
               help="encoder noise sigma [deg], >= 0 (written to the input as joint_noise, which calibrate uses)"),
        # the core's --seed, declared here so that the step gets it too (written into projector.yaml's header)
        Option("--seed", type=seed_value, default=0, help="seed of the random generator (>= 0)"),
    ),
    calibrate_help="estimate the pose T_0_W (and h, tilt offset): result.json + report.html",
    calibrate_description=("Input format: see docs/rigs/projector.md or robocal.rigs.projector.files.\n"
                           "Writes OUT/result.json and OUT/report.html; exit 2 on bad input."),
    calibrate_examples=(f"robocal projector calibrate {EXAMPLES}/seed_projector_A.yaml --out projector-cal",
                        f"robocal projector calibrate {EXAMPLES}/room_A.yaml --out projector-cal",
                        f"robocal projector calibrate {EXAMPLES}/room_A_csv.yaml --strict --out projector-cal"),
    calibrate_options=(
        Option("--strict", action="store_true",
               help="inconsistent pairwise distances, spots beyond the tilt limit and estimates outside their "
                    "physical bounds are errors (exit 2) instead of warnings"),
    ),
    input_arguments=(Option("input", type=Path, help="calibration input (YAML/JSON)"),),
    commands=(EVALUATE, PATH),
    simulated_inputs=("projector.yaml",),
    quick_simulate=("--points", "8"),
)
