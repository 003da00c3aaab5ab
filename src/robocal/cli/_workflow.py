"""The commands the core builds from a :class:`robocal.workflow.Workflow`, the same for every rig.

``robocal <rig> simulate | calibrate | report`` and ``robocal report
RESULT.json``: one implementation each, so the output folder, the error's
source file, atomic writing, the summary line and the exit status cannot drift
apart between rigs. A rig's extra commands are added from their declarations.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from robocal.cli._common import (LazySubParsers, RawHelp, add_command, add_out_argument, add_seed_argument,
                                 examples_epilog, prepare_out_dir, write_run)
from robocal.errors import InputError, RobocalError
from robocal.workflow import Command, Option, Workflow, accept_implausible_option, number_at_least

__all__ = ["add_workflow_commands", "add_report_command", "run_simulate", "run_calibrate", "rebuild_report",
           "calibrate_files"]


def _options_for(options, args, step: str) -> dict:
    return {o.dest: getattr(args, o.dest) for o in options if o.to == step}


def _with_step(options, default: str) -> tuple:
    """The options with ``to`` filled in (``Option(to="")`` means the command's main step)."""
    out = []
    for o in options:
        if o.to == "":
            o = Option(*o.flags, to=default, **o.kwargs)
        out.append(o)
    return tuple(out)


def add_workflow_commands(parser: argparse.ArgumentParser, wf: Workflow) -> None:
    """Add ``simulate``, ``calibrate``, ``report`` (those the workflow has) and its extra commands.

    Each command's arguments are added when it is parsed or its help is shown (:class:`LazySubParsers`):
    a command builds its own parser, not its rig's dozen.
    """
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND", action=LazySubParsers)
    if wf.simulate is not None:
        opts = _with_step(wf.simulate_options, "simulate")

        def build_simulate(p, opts=opts):
            for o in opts:
                o.add_to(p)
            if not any(o.dest == "seed" for o in opts):
                add_seed_argument(p)
            if wf.fleet is not None:
                p.add_argument("--fleet", type=number_at_least(int, 1), default=None, metavar="N",
                               help="N robots instead of one (OUT/robot-000, ...), true parameters scattered as "
                                    "across a real fleet, a few with a planted fault; OUT/fleet.yaml is the manifest "
                                    f"for 'robocal batch {wf.name}', OUT/fleet_truth.json names the planted robots")
            add_out_argument(p)
            p.set_defaults(func=lambda a, wf=wf, opts=opts: run_simulate(wf, a, opts))

        _add_step(sub, "simulate", wf.simulate_help, wf.simulate_description, wf.simulate_examples, build_simulate)
    if wf.calibrate is not None:
        opts = _with_step(wf.calibrate_options, "calibrate")

        def build_calibrate(p, opts=opts):
            for o in wf.inputs:
                o.add_to(p)
            for o in opts:
                o.add_to(p)
            accept_implausible_option().add_to(p)
            add_out_argument(p)
            p.set_defaults(func=lambda a, wf=wf, opts=opts: run_calibrate(wf, a, opts))

        _add_step(sub, "calibrate", wf.calibrate_help, wf.calibrate_description, wf.calibrate_examples,
                  build_calibrate)
    if wf.build_report is not None:
        def build_report(p):
            p.add_argument("result", type=Path, help=f"result.json written by 'robocal {wf.name} calibrate'")
            add_out_argument(p)
            p.set_defaults(func=lambda a, wf=wf: _report_command(a, {wf.name: wf}, label=f"{wf.name}-report"))

        sub.add_parser("report", help="rebuild report.html from a result.json", formatter_class=RawHelp,
                       epilog=examples_epilog(f"robocal {wf.name} report {wf.name}-cal/result.json "
                                              f"--out {wf.name}-report"),
                       build=build_report)
    for cmd in wf.commands:
        _add_command(sub, wf, cmd)


def _add_command(sub, wf: Workflow, cmd: Command) -> None:
    def build(p):
        for o in cmd.options:
            o.add_to(p)
        if cmd.out:
            add_out_argument(p)
        p.set_defaults(func=lambda a, run=cmd.run: _call(run, a))

    _add_step(sub, cmd.name, cmd.help, cmd.description, cmd.examples, build)


def _add_step(sub, name: str, help_line: str, description: str | None, examples, build) -> None:
    """A rig command's parser (built by ``build`` when the command is parsed), its examples as the epilog."""
    sub.add_parser(name, help=help_line, description=description or None, formatter_class=RawHelp,
                   epilog=examples_epilog(*examples) if examples else None, build=build)


def _call(run, args) -> int:
    from robocal.workflow import resolve

    return int(resolve(run)(args) or 0)


def run_simulate(wf: Workflow, args, options=()) -> int:
    """``robocal <rig> simulate``: the rig's simulated input in a fresh folder."""
    out = prepare_out_dir(args.out, f"{wf.name}-simulate")
    rng = np.random.default_rng(args.seed)
    if getattr(args, "fleet", None):
        from robocal.batch import simulate_fleet

        fleet = simulate_fleet(wf, out, args.fleet, rng, progress=True, **_options_for(options, args, "simulate"))
        print(f"wrote {fleet.manifest}\nwrote {fleet.truth}\n{fleet.summary()}")
        return 0
    paths = wf.step("simulate")(out, rng, progress=True, **_options_for(options, args, "simulate"))
    for p in paths or ():
        print(f"wrote {p}")
    return 0


def calibrate_files(wf: Workflow, paths, *, out_dir: Path, input_options=None, calibrate_options=None,
                    accept_implausible: bool = False, progress: bool = False):
    """``load_input`` -> ``calibrate`` -> ``to_result`` -> ``build_report``: the calibrate command as a function.

    Returns ``(result, report)``; the result's ``inputs`` get the content hash
    of every path given when the rig recorded none. A :class:`RobocalError`
    raised without a file gets the first input's name.
    """
    from robocal.io import hash_inputs

    # an input argument with nargs (IMAGES...) arrives as a list: each of its values is one input
    paths = [Path(p) for v in paths for p in (v if isinstance(v, (list, tuple)) else [v])]
    try:
        inp = wf.step("load_input")(*paths, **(input_options or {}))
        cal = wf.step("calibrate")(inp, out_dir=Path(out_dir), progress=progress,
                                   accept_implausible=accept_implausible, **(calibrate_options or {}))
        result = wf.step("to_result")(cal, inp)
        if not result.inputs:
            result.inputs = hash_inputs(paths)
        report = None
        if wf.build_report is not None:
            report = wf.step("build_report")(result, base_dir=Path(out_dir))
    except RobocalError as exc:
        if exc.source is None and paths:
            raise exc.with_source(" + ".join(map(str, paths)) if len(paths) > 1 else str(paths[0])) from None
        raise
    return result, report


def run_calibrate(wf: Workflow, args, options=()) -> int:
    """``robocal <rig> calibrate INPUT --out DIR``: ``DIR/result.json`` and ``DIR/report.html``."""
    out = prepare_out_dir(args.out, f"{wf.name}-calibrate")
    paths = [getattr(args, o.dest) for o in wf.inputs]
    result, report = calibrate_files(
        wf, paths, out_dir=out, input_options=_options_for(options, args, "load_input"),
        calibrate_options=_options_for(options, args, "calibrate"),
        accept_implausible=args.accept_implausible, progress=True)
    write_run(out, result, report)
    extra = wf.step("write_outputs")
    for p in (extra(result, out) if extra is not None else None) or ():
        print(f"wrote {p}")
    print(summary_text(wf, result))
    return 0


def summary_text(wf: Workflow, result) -> str:
    """The lines printed after a calibration: the rig's ``summary`` or the residual RMS and warning count."""
    fn = wf.step("summary")
    if fn is not None:
        return str(fn(result))
    rms = "—" if result.residual_rms is None else f"{result.residual_rms:.4g} {result.residual_unit or ''}".strip()
    return f"{wf.name}: residual RMS {rms}; {len(result.warnings)} warning(s)"


def rebuild_report(path, workflows) -> "object":
    """The report of the result file ``path``, rebuilt by the workflow named in its ``rig`` field."""
    from robocal.io import load_result

    path = Path(path)
    result = load_result(path)
    wf = workflows.get(result.rig)
    if wf is None or wf.build_report is None:
        have = ", ".join(sorted(n for n, w in workflows.items() if w.build_report is not None)) or "none"
        if len(workflows) == 1:
            raise InputError(f"a result of rig {result.rig!r}, not {next(iter(workflows))!r}", source=str(path))
        raise InputError(f"rig: {result.rig!r} has no report builder installed (rigs with reports: {have})",
                         source=str(path))
    try:
        return wf.step("build_report")(result, base_dir=path.parent)
    except RobocalError as exc:
        raise exc.with_source(str(path)) if exc.source is None else exc from None


def _report_command(args, workflows, *, label: str) -> int:
    report = rebuild_report(args.result, workflows)
    out = prepare_out_dir(args.out, label)
    write_run(out, None, report)
    return 0


def add_report_command(sub, workflows_loader) -> None:
    """``robocal report RESULT.json``: any rig's report, rebuilt from its result file."""
    def build(p):
        p.add_argument("result", type=Path, help="a result.json written by any 'robocal <rig> calibrate'")
        add_out_argument(p)
        p.set_defaults(func=lambda a: _report_command(a, workflows_loader(), label="report"))

    add_command(
        sub, "report", build, help="rebuild any rig's report.html from its result.json", formatter_class=RawHelp,
        description="Reads the result file, finds the rig named in its 'rig' field and rebuilds the report\n"
                    "that 'robocal <rig> calibrate' wrote beside it.",
        epilog=examples_epilog("robocal report mirror-cal/result.json --out mirror-report"))
