"""The projector's extra commands, ``evaluate`` and ``path``: their run functions (``Command.run(args) -> int``).

Declared in :mod:`robocal.rigs.projector.cli`; the numerical work is in
:mod:`.workflow`, :mod:`.evaluate` and :mod:`.path`. A command writes its
folder through the core's :func:`robocal.io.prepare_out_dir` and
:func:`robocal.io.write_run` (library level: nothing here imports the CLI).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, InputError, RobocalError
from robocal.io import atomic_write_text, load_result, prepare_out_dir, to_jsonable, write_run
from robocal.rigs.projector.files import extrinsics_from_result

__all__ = ["run_evaluate", "run_path", "model_from_result"]


def model_from_result(path: Path, nominal):
    """``nominal`` with the pose (and ``h``, offsets) of the result file ``path``."""
    x = extrinsics_from_result(load_result(path), source=str(path))
    m = nominal.with_(R_0_W=x["R_0_W"], t_0_W=x["t_0_W"])
    if "h" in x:
        m = m.with_(d1=m.H - x["h"], offsets=x["offsets"])
    return m


def run_evaluate(args) -> int:
    """``robocal projector evaluate``: the seed's Table 2 protocol on a simulated rig, with or without ``--result``."""
    if not (math.isfinite(args.spacing) and args.spacing > 0):
        raise InputError(f"--spacing must be a finite distance > 0 [m], got {args.spacing:g}")
    if not all(math.isfinite(c) for c in args.center):
        raise InputError(f"--center must be two finite coordinates [m], got {args.center[0]:g} {args.center[1]:g}")
    from robocal.rigs.projector.files import load_calibration_input
    from robocal.rigs.projector.report import build_report
    from robocal.rigs.projector.workflow import calibration_result, run_calibration, run_evaluation

    inp = load_calibration_input(args.input)
    if inp.truth is None:
        raise FileFormatError("evaluate needs a 'truth' section (a simulated rig, see `robocal projector simulate`)",
                              source=str(args.input))
    run = None
    if args.result is not None:
        calibrated = model_from_result(args.result, inp.model)
    else:
        run = run_calibration(inp, accept_implausible=args.accept_implausible)
        calibrated = run.calibrated_model()
    ev = run_evaluation(inp.truth, calibrated, center=tuple(args.center), spacing=args.spacing)
    e = ev.evaluation
    if not np.any(e.reached):
        n0 = calibrated.nadir_world
        raise InputError(f"--center {args.center[0]:g} {args.center[1]:g} --spacing {args.spacing:g}: no Table 2 grid "
                         f"point is on the reachable floor (nadir ({n0[0]:.3g}, {n0[1]:.3g}) m, radius "
                         f"{calibrated.floor_radius:.3g} m)")
    out = prepare_out_dir(args.out, "projector-evaluate")
    title = f"projector evaluation: {Path(args.input).name}"
    if run is not None:
        result = calibration_result(run, inputs=inp.files, truth=inp.truth, title=title)
        result.diagnostics["evaluation"] = ev.record()
        report = build_report(result, base_dir=out)
    else:
        from robocal.report import Report

        result = None
        report = Report(title, subtitle=f"calibration {args.result}")
        report.sections.extend(ev.sections())
        text = json.dumps(to_jsonable(e.to_dict()), indent=2) + "\n"
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


def _csv_field(x) -> str:
    """A text CSV field, quoted as :mod:`csv` does (``QUOTE_MINIMAL``) when it holds a comma, quote or newline."""
    x = str(x)
    return '"' + x.replace('"', '""') + '"' if ("," in x or '"' in x or "\n" in x or "\r" in x) else x


def _csv_text(header, columns) -> str:
    """CSV text from a header and columns ``(values, fmt)``: numbers by the %-format ``fmt`` (non-finite -> blank
    field), text (``fmt`` None) quoted where needed. Formats column by column: the per-field ``csv.writer`` loop
    took 10 of the 12 s of a 219 000-sample path."""
    cols = []
    for values, fmt in columns:
        if fmt is None:  # few distinct texts ('ok', 'serve', a name): quote each once
            quoted = {v: _csv_field(v) for v in set(values)}
            cols.append([quoted[v] for v in values])
        else:
            a = np.asarray(values)
            ok = np.isfinite(a).tolist() if a.dtype.kind == "f" else [True] * len(a)
            cols.append([fmt % v if g else "" for v, g in zip(a.tolist(), ok)])
    lines = [",".join(_csv_field(h) for h in header)]
    lines += [",".join(row) for row in zip(*cols)]
    return "\n".join(lines) + "\n"


def _check_path_options(args) -> None:
    """Validate ``path``'s numeric options before any file is read (one line naming the option, exit 2)."""
    from robocal.rigs.projector.path import MAX_NADIR_SNAP

    for name, val, lo, hi, unit in (("--nadir-margin", args.nadir_margin, 0.0, 45.0, "deg"),
                                    ("--limit-margin", args.limit_margin, 0.0, 45.0, "deg"),
                                    ("--nadir-snap", args.nadir_snap, 0.0, 1000 * MAX_NADIR_SNAP, "mm")):
        if not (math.isfinite(val) and lo <= val <= hi):
            raise InputError(f"{name} must be in [{lo:g}, {hi:g}] {unit}, got {val:g}")


def run_path(args) -> int:
    """``robocal projector path``: commands.csv, one commands_<name>.csv per head, plan.json, report.html."""
    _check_path_options(args)
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
              limit_margin=math.radians(args.limit_margin), nadir_snap=args.nadir_snap * 1e-3)
    if args.retime:
        t_new, _, plan = retime(inp.projectors, inp.t, inp.points, inp.velocity, **kw)
        print(f"retimed: {inp.t[-1] - inp.t[0]:.3f} s -> {t_new[-1] - t_new[0]:.3f} s")
    else:
        plan = plan_multi(inp.projectors, inp.t, inp.points, inp.velocity, **kw)
    out = prepare_out_dir(args.out, "projector-path")
    cmd = plan.commands()
    names = np.array([*plan.names, ""], dtype=object)[cmd["projector"]]  # index -1 -> "" (unserved)
    text = _csv_text(["t [s]", "x [m]", "y [m]", "projector", "theta1 [rad]", "theta2 [rad]", "theta1_dot [rad/s]",
                      "theta2_dot [rad/s]", "status"],
                     [(cmd["t"], "%.6f"), (cmd["x"], "%.6f"), (cmd["y"], "%.6f"), (names, None),
                      (cmd["theta"][:, 0], "%.9f"), (cmd["theta"][:, 1], "%.9f"), (cmd["theta_dot"][:, 0], "%.9f"),
                      (cmd["theta_dot"][:, 1], "%.9f"), (cmd["status"], None)])
    print(f"wrote {atomic_write_text(out / 'commands.csv', text)}")
    streams, preaim = plan.projector_commands()  # once: plan.json and the report reuse preaim
    for st in streams:  # one stream per head: the idle ones pre-aim at their next hand-over pose
        text = _csv_text(["t [s]", "theta1 [rad]", "theta2 [rad]", "theta1_dot [rad/s]", "theta2_dot [rad/s]",
                          "laser_on", "mode"],
                         [(st["t"], "%.6f"), (st["theta"][:, 0], "%.9f"), (st["theta"][:, 1], "%.9f"),
                          (st["theta_dot"][:, 0], "%.9f"), (st["theta_dot"][:, 1], "%.9f"),
                          (np.asarray(st["laser_on"]).astype(int), "%d"), (st["mode"], None)])
        fname = f"commands_{_safe(st['name'])}.csv"
        print(f"wrote {atomic_write_text(out / fname, text)}")
    options = {"nadir_margin [deg]": args.nadir_margin, "limit_margin [deg]": args.limit_margin,
               "nadir_snap [mm]": args.nadir_snap, "retime": bool(args.retime)}
    doc = dict(plan.to_dict(preaim=preaim), options=options)
    print(f"wrote {atomic_write_text(out / 'plan.json', json.dumps(to_jsonable(doc), indent=2) + chr(10))}")
    write_run(out, None, path_report(plan, inp.projectors, inp.walls, title=f"projector path: {args.input.name}",
                                     preaim=preaim))
    print(f"{len(plan.t)} samples, {len(plan.handovers)} hand-over(s), "
          + ("all feasible" if plan.ok else f"{len(plan.infeasible)} infeasible stretch(es)"))
    for bad in plan.infeasible[:10]:
        print(f"  infeasible t = {bad['t0']:.2f} .. {bad['t1']:.2f} s: "
              + "; ".join(f"{k}: {v}" for k, v in bad["reasons"].items()))
    if len(plan.infeasible) > 10:
        print(f"  ... {len(plan.infeasible) - 10} more in plan.json 'infeasible'")
    serving = [k for k in range(len(plan.names)) if np.any(plan.assignment == k)] or range(len(plan.names))
    for k in serving:  # the IK branch per stretch between nadir crossings, when there is a choice to report
        br = plan.trajectories[k].branches
        if len(br) > 1 or any(b["branch"] for b in br):
            print(f"  {plan.names[k]}: IK branch per stretch between nadir crossings (plan.json 'branches'):")
            for b in br:
                print(f"    t = {b['t0']:.2f} .. {b['t1']:.2f} s: {b['ik']}: {b['why']}")
    return 0 if plan.ok else 1
