"""Command line of the ``projector`` rig: ``robocal projector simulate | calibrate | evaluate | path``.

Each command is thin wiring over :mod:`robocal.rigs.projector.workflow`.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
from pathlib import Path

import numpy as np
import yaml

from robocal.cli import DemoContext, DemoOutcome, Rig
from robocal.cli._common import RawHelp, add_out_argument, add_seed_argument, examples_epilog, prepare_out_dir, write_run
from robocal.errors import FileFormatError, InputError, RobocalError
from robocal.io import atomic_write_text, load_result
from robocal.report import Section

__all__ = ["RIG"]

EXAMPLES = Path("examples/projector")
#: ``simulate --points`` cap: the pairwise-distance check is O(N^2) in memory (1e8 points were killed, OOM).
MAX_SIM_POINTS = 10_000


def _add_commands(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND")

    p = sub.add_parser("simulate", help="write a simulated calibration input (with its ground truth)",
                       formatter_class=RawHelp,
                       epilog=examples_epilog("robocal projector simulate --out sim",
                                              "robocal projector simulate --points 10 --noise 2 --out sim --seed 4",
                                              "robocal projector calibrate sim/projector.yaml --out cal"))
    p.add_argument("--points", type=int, default=8, help="number of floor points")
    p.add_argument("--noise", type=float, default=5.0, help="world measurement noise sigma [mm]")
    p.add_argument("--theta-noise", type=float, default=0.0, help="encoder noise sigma [deg]")
    add_seed_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("calibrate", help="estimate R_0_W, t_0_W (and h, tilt offset): result.json + report.html",
                       formatter_class=RawHelp,
                       description="Input format: see docs/rigs/projector.md or robocal.rigs.projector.files.",
                       epilog=examples_epilog(f"robocal projector calibrate {EXAMPLES}/seed_projector_A.yaml --out out",
                                              f"robocal projector calibrate {EXAMPLES}/room_A.yaml --out out",
                                              f"robocal projector calibrate {EXAMPLES}/room_A_csv.yaml --strict --out out"))
    p.add_argument("input", type=Path, help="calibration input (YAML/JSON)")
    p.add_argument("--strict", action="store_true", help="inconsistent pairwise distances are an error")
    add_out_argument(p)
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("evaluate", help="seed Table 2 protocol on a simulated rig: table + floor error map",
                       formatter_class=RawHelp,
                       epilog=examples_epilog(f"robocal projector evaluate {EXAMPLES}/room_A.yaml --out ev",
                                              f"robocal projector evaluate {EXAMPLES}/room_A.yaml --result out/result.json"
                                              " --spacing 1.5 --out ev"))
    p.add_argument("input", type=Path, help="calibration input with a 'truth' section (as written by simulate)")
    p.add_argument("--result", type=Path, default=None, help="use this calibration result instead of calibrating")
    p.add_argument("--spacing", type=float, default=2.0, help="Table 2 grid spacing [m]")
    p.add_argument("--center", type=float, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"),
                   help="Table 2 grid centre in {W} [m]")
    add_out_argument(p)
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("path", help="world path -> timed joint commands over one or more projectors",
                       formatter_class=RawHelp,
                       epilog=examples_epilog(f"robocal projector path {EXAMPLES}/path_room.yaml --out path",
                                              f"robocal projector path {EXAMPLES}/path_timed.yaml --out path",
                                              f"robocal projector path {EXAMPLES}/path_timed.yaml --retime --out path",
                                              f"robocal projector path {EXAMPLES}/path_nadir.yaml --out path"))
    p.add_argument("input", type=Path, help="path input (YAML/JSON)")
    p.add_argument("--nadir-margin", type=float, default=2.0, help="keep this far from the nadir [deg]; with the "
                   "projector's tilt_min < 0 a path may pass through it (constant pan, tilt through zero)")
    p.add_argument("--limit-margin", type=float, default=2.0, help="keep this far below the tilt limit [deg]")
    p.add_argument("--retime", action="store_true",
                   help="slow the spot down where the joint rate limits require it (instead of infeasible rows)")
    add_out_argument(p)
    p.set_defaults(func=_cmd_path)


# ------------------------------------------------------------------ commands
def _cmd_simulate(args) -> int:
    from robocal.rigs.projector.simulate import simulate_calibration
    from robocal.rigs.projector.workflow import scenario_document

    if not 3 <= args.points <= MAX_SIM_POINTS:
        raise InputError(f"--points must be in [3, {MAX_SIM_POINTS}], got {args.points}")
    if args.noise <= 0 or args.theta_noise < 0:
        raise InputError(f"--noise must be > 0 and --theta-noise >= 0, got {args.noise}, {args.theta_noise}")
    rng = np.random.default_rng(args.seed)
    sc = simulate_calibration(rng, n_points=args.points, sigma=args.noise * 1e-3,
                              theta_sigma=math.radians(args.theta_noise))
    out = prepare_out_dir(args.out, "projector-simulate")
    doc = scenario_document(sc)
    text = (f"# robocal projector simulate --points {args.points} --noise {args.noise} --seed {args.seed}\n"
            "# Calibration input; 'truth' holds the simulated projector (used by `evaluate`).\n"
            + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120))
    path = atomic_write_text(out / "projector.yaml", text)
    print(f"wrote {path}")
    return 0


def _cmd_calibrate(args) -> int:
    from robocal.rigs.projector.files import load_calibration_input
    from robocal.rigs.projector.workflow import calibration_report, calibration_result, run_calibration

    inp = load_calibration_input(args.input)
    if args.strict:
        inp.strict = True
    run = run_calibration(inp)
    result = calibration_result(run, inputs=inp.files, truth=inp.truth)
    report = calibration_report(run, title=f"projector calibration: {args.input.name}", truth=inp.truth)
    out = prepare_out_dir(args.out, "projector-calibrate")
    write_run(out, result, report)
    b = run.best
    print(f"{run.primary}: yaw {math.degrees(b.yaw):.4f} deg"
          + (f" +- {math.degrees(b.std['yaw']):.4f}" if b.std.get("yaw") else "")
          + f", t = [{b.t_0_W[0]:.4f}, {b.t_0_W[1]:.4f}, {b.t_0_W[2]:.4f}] m, residual RMS {1000 * b.rms:.2f} mm")
    return 0


def _model_from_result(path: Path, nominal):
    res = load_result(path)
    if res.rig != "projector":
        raise FileFormatError(f"result of rig {res.rig!r}, expected 'projector'", source=str(path))
    e = res.estimate
    try:
        m = nominal.with_(R_0_W=np.asarray(e["R_0_W"], float), t_0_W=np.asarray(e["t_0_W"], float))
        if "h" in e:
            m = m.with_(d1=m.H - float(e["h"]), offsets=tuple(float(v) for v in e["offsets"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"not a projector result ({exc})", source=str(path)) from None
    return m


def _cmd_evaluate(args) -> int:
    from robocal.rigs.projector.files import load_calibration_input
    from robocal.rigs.projector.workflow import calibration_report, calibration_result, run_calibration, run_evaluation

    inp = load_calibration_input(args.input)
    if inp.truth is None:
        raise FileFormatError("evaluate needs a 'truth' section (a simulated rig, see `robocal projector simulate`)",
                              source=str(args.input))
    if args.spacing <= 0:
        raise InputError(f"--spacing must be > 0, got {args.spacing}")
    run = None
    if args.result is not None:
        calibrated = _model_from_result(args.result, inp.model)
    else:
        run = run_calibration(inp)
        calibrated = run.calibrated_model()
    ev = run_evaluation(inp.truth, calibrated, center=tuple(args.center), spacing=args.spacing)
    e = ev.evaluation
    if not np.any(e.reached):
        n0 = calibrated.nadir_world
        raise InputError(f"--center {args.center[0]:g} {args.center[1]:g} --spacing {args.spacing:g}: no Table 2 grid "
                         f"point is on the reachable floor (nadir ({n0[0]:.3g}, {n0[1]:.3g}) m, radius "
                         f"{calibrated.floor_radius:.3g} m)")
    out = prepare_out_dir(args.out, "projector-evaluate")
    if run is not None:
        result = calibration_result(run, inputs=inp.files, truth=inp.truth)
        result.diagnostics["evaluation"] = ev.evaluation.to_dict()
        report = calibration_report(run, title=f"projector evaluation: {args.input.name}", truth=inp.truth,
                                    evaluation=ev)
    else:
        from robocal.report import Report

        result = None
        report = Report(f"projector evaluation: {args.input.name}", subtitle=f"calibration {args.result}")
        report.sections.extend(ev.sections())
        text = json.dumps(_jsonable(e.to_dict()), indent=2) + "\n"
        print(f"wrote {atomic_write_text(out / 'evaluation.json', text)}")
    write_run(out, result, report)
    if not np.all(e.reached):
        print(f"warning: Table 2 grid point(s) {[int(i) + 1 for i in np.flatnonzero(~e.reached)]} (numbered as in the "
              f"table) are outside the reachable floor and not evaluated", file=sys.stderr)
    print(f"Table 2 grid: {int(e.reached.sum())}/{len(e.reached)} reached, spot error RMS {1000 * e.rms:.2f} mm, "
          f"max {1000 * e.max:.2f} mm")
    return 0


def _safe(name: str) -> str:
    """A projector name usable in a file name."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in str(name)) or "projector"


def _require_distinct_file_names(names, *, source: str) -> None:
    """Raise InputError when two projector names give the same ``commands_<name>.csv``.

    :func:`_safe` maps e.g. ``A/1`` and ``A 1`` both to ``A_1``; names differing only in case collide on
    case-insensitive file systems. Either would silently overwrite one head's command stream with another's.
    """
    seen = {}
    for n in names:
        key = _safe(n).casefold()
        if key in seen:
            raise InputError(f"projectors[].name: {seen[key]!r} and {n!r} would both be written to "
                             f"commands_{_safe(n)}.csv (names must differ in letters, digits, '-' or '_', "
                             f"not only in case or other characters)", source=source)
        seen[key] = n


def _jsonable(d):
    from robocal.io import to_jsonable

    return to_jsonable(d)


def _cmd_path(args) -> int:
    from robocal.rigs.projector.files import load_path_input
    from robocal.rigs.projector.path import plan_multi, require_reachable_path, retime
    from robocal.rigs.projector.workflow import path_report

    inp = load_path_input(args.input)
    _require_distinct_file_names([q.name for q in inp.projectors], source=str(args.input))
    try:  # exit 2: a point no projector reaches is wrong input; exit 1 is kept for a plan that fails its checks
        require_reachable_path(inp.projectors, inp.t, inp.points)
    except RobocalError as exc:
        raise type(exc)(exc.message, source=str(args.input)) from None
    kw = dict(walls=inp.walls, nadir_margin=math.radians(args.nadir_margin),
              limit_margin=math.radians(args.limit_margin))
    if args.retime:
        t_new, _, plan = retime(inp.projectors, inp.t, inp.points, inp.velocity, **kw)
        print(f"retimed: {inp.t[-1] - inp.t[0]:.3f} s -> {t_new[-1] - t_new[0]:.3f} s")
    else:
        plan = plan_multi(inp.projectors, inp.t, inp.points, inp.velocity, **kw)
    out = prepare_out_dir(args.out, "projector-path")
    cmd = plan.commands()
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["t [s]", "x [m]", "y [m]", "projector", "theta1 [rad]", "theta2 [rad]", "theta1_dot [rad/s]",
                "theta2_dot [rad/s]", "status"])
    for i in range(len(cmd["t"])):
        k = int(cmd["projector"][i])
        w.writerow([f"{cmd['t'][i]:.6f}", f"{cmd['x'][i]:.6f}", f"{cmd['y'][i]:.6f}", plan.names[k] if k >= 0 else "",
                    *(f"{v:.9f}" if np.isfinite(v) else "" for v in (*cmd["theta"][i], *cmd["theta_dot"][i])),
                    cmd["status"][i]])
    print(f"wrote {atomic_write_text(out / 'commands.csv', buf.getvalue())}")
    streams, _ = plan.projector_commands()
    for st in streams:  # one stream per head: the idle ones pre-aim at their next hand-over pose
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["t [s]", "theta1 [rad]", "theta2 [rad]", "theta1_dot [rad/s]", "theta2_dot [rad/s]", "laser_on",
                    "mode"])
        for i in range(len(st["t"])):
            w.writerow([f"{st['t'][i]:.6f}", *(f"{v:.9f}" for v in (*st["theta"][i], *st["theta_dot"][i])),
                        int(st["laser_on"][i]), st["mode"][i]])
        fname = f"commands_{_safe(st['name'])}.csv"
        print(f"wrote {atomic_write_text(out / fname, buf.getvalue())}")
    print(f"wrote {atomic_write_text(out / 'plan.json', json.dumps(_jsonable(plan.to_dict()), indent=2) + chr(10))}")
    write_run(out, None, path_report(plan, inp.projectors, inp.walls, title=f"projector path: {args.input.name}"))
    print(f"{len(plan.t)} samples, {len(plan.handovers)} hand-over(s), "
          + ("all feasible" if plan.ok else f"{len(plan.infeasible)} infeasible stretch(es)"))
    for bad in plan.infeasible[:10]:
        print(f"  infeasible t = {bad['t0']:.2f} .. {bad['t1']:.2f} s: "
              + "; ".join(f"{k}: {v}" for k, v in bad["reasons"].items()))
    return 0 if plan.ok else 1


# ---------------------------------------------------------------------- demo
def _demo(ctx: DemoContext) -> DemoOutcome:
    from robocal.rigs.projector.calibrate import calibrate, seed_method, yaw_of
    from robocal.rigs.projector.path import plan_multi, sample_polyline
    from robocal.rigs.projector.published import SEED_A_POINTS_0, SEED_A_POINTS_W, SEED_A_R_INIT, SEED_A_R_OPT
    from robocal.rigs.projector.simulate import seed_room_projectors, simulate_calibration
    from robocal.rigs.projector.workflow import calibration_result, run_evaluation

    sc = simulate_calibration(ctx.rng, n_points=8, sigma=0.005)
    run = calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"), sigma=sc.sigma)
    best = run.best
    yaw_err = best.yaw - float(yaw_of(sc.truth.R_0_W))
    z = abs(yaw_err) / best.std["yaw"]
    ev = run_evaluation(sc.truth, run.calibrated_model(), map_n=31)
    result = calibration_result(run, truth=sc.truth)
    result.diagnostics["evaluation"] = ev.evaluation.to_dict()
    # the seed's published numbers
    pub = seed_method(SEED_A_POINTS_W, SEED_A_POINTS_0, order=[2, 1, 0])
    trunc = lambda R: np.trunc(np.asarray(R) * 1e4) / 1e4  # noqa: E731 - the paper truncates to 4 decimals
    reproduced = bool(np.array_equal(trunc(pub.extra["R_init"]), SEED_A_R_INIT)
                      and np.array_equal(trunc(pub.R_0_W), SEED_A_R_OPT))
    pub_run = calibrate(SEED_A_POINTS_W, points_0=SEED_A_POINTS_0, methods=("seed",), seed_order=[2, 1, 0])
    # a path across the seed's room, served by A and B
    A, B = seed_room_projectors()
    t, p, v = sample_polyline([[-2.0, -1.5], [-2.0, 1.0], [1.5, 1.5], [3.5, -1.0], [1.0, -4.0]], 0.3, 0.1)
    plan = plan_multi([A, B], t, p, v, walls=[[-0.5, -3.0, -0.5, 0.5]])
    from robocal.rigs.projector.plots import calibration_sections, plot_path
    from robocal.report import new_figure

    secs = calibration_sections(run, truth=sc.truth) + ev.sections()
    s = Section("Seed 000 published numbers (projector A)")
    s.status(reproduced, "published R (init and optimised) reproduced to the printed 4 decimals (truncated), with "
                         "the world-origin point as eq. (12)'s reference" if reproduced else "published R NOT reproduced")
    s.diagnostics(pub_run.consistency.warnings)
    s.text(f"seed method: init yaw {math.degrees(yaw_of(pub.extra['R_init'])):.4f} deg, optimised "
           f"{math.degrees(pub.yaw):.4f} deg, t = {np.round(pub.t_0_W * 100, 2).tolist()} cm")
    secs.append(s)
    s = Section("Spot path over projectors A and B")
    fig, ax = new_figure(size=(6.4, 5.2))
    plot_path(plan, ax, walls=[[-0.5, -3.0, -0.5, 0.5]], projectors=[A, B])
    s.figure(fig, f"{len(plan.handovers)} hand-over(s); all samples served: {plan.ok}")
    secs.append(s)
    passed = bool(z < 4 and reproduced and ev.evaluation.rms < 0.01 and plan.ok)
    summary = {"yaw error": f"{1000 * yaw_err:.3f} mrad ({z:.1f} sigma)",
               "Table 2 RMS": f"{1000 * ev.evaluation.rms:.2f} mm",
               "published R": "reproduced" if reproduced else "NOT reproduced",
               "path hand-overs": str(len(plan.handovers))}
    return DemoOutcome(summary=summary, passed=passed, sections=secs, result=result)


RIG = Rig(
    name="projector",
    help="ceiling pan-tilt laser projector: D-H model, IK, world extrinsics, spot paths (seed 000)",
    description=(
        "Ceiling pan-tilt laser projector (seed 000).\n"
        "  simulate   write a simulated calibration input with its ground truth\n"
        "  calibrate  R_0_W, t_0_W by the seed's method, the closed form and nonlinear LS\n"
        "  evaluate   the seed's Table 2 protocol + floor error map on a simulated rig\n"
        "  path       world path -> timed joint commands, several projectors, hand-overs\n\n"
        + examples_epilog(f"robocal projector calibrate {EXAMPLES}/seed_projector_A.yaml --out out",
                          "robocal projector simulate --out sim && robocal projector evaluate sim/projector.yaml --out ev",
                          f"robocal projector path {EXAMPLES}/path_room.yaml --out path")
    ),
    add_commands=_add_commands,
    demo=_demo,
)
