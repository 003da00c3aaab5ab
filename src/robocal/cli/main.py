"""``robocal`` command-line entry point.

Errors a user can cause (:class:`~robocal.errors.RobocalError`, and the
failures user data provokes in NumPy and the runtime: memory, singular
matrices, undecodable text, overflowing numbers) print one line on stderr and
exit with status 2; anything else is a bug and keeps its traceback.

Every command runs inside a :class:`robocal.io.CommandRun`: its ``--out``
folder is checked and marked ``INCOMPLETE`` at the start, and the mark is
removed only when the command finishes (see ``docs/results.md``).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
import warnings
import zlib
from pathlib import Path

import numpy as np

import robocal
from robocal.cli._bag import add_bag_command
from robocal.cli._common import (FORCE_HELP, LazySubParsers, OneLineErrorParser, RawHelp, examples_epilog,
                                prepare_out_dir)
from robocal.cli._rig import DemoContext, demo_of, discover_rigs, registered_rig_names
from robocal.cli._batch import add_batch_command
from robocal.cli._workflow import add_report_command, add_workflow_commands
from robocal.errors import InputError, RobocalError
from robocal.io import CommandRun, preflight, set_command_line, write_result
from robocal.workflow import seed_value

__all__ = ["main", "build_parser", "run_demo"]

EXIT_USER_ERROR = 2


def build_parser(rigs=None) -> argparse.ArgumentParser:
    rigs = discover_rigs() if rigs is None else rigs
    parser = OneLineErrorParser(
        prog="robocal",
        description=(
            "Robot geometric calibration and sensor dead reckoning.\n"
            "Each rig is a complete workflow: simulate data, calibrate, evaluate, report."
        ),
        formatter_class=RawHelp,
        epilog=examples_epilog(
            "robocal demo                      # every rig on embedded data, HTML report",
            "robocal demo --out demo-out --seed 3",
            "robocal projector --help          # one rig's commands",
            "robocal projector calibrate examples/projector/seed_projector_A.yaml --out projector-cal",
        ),
    )
    parser.add_argument("--version", action="version", version=f"robocal {robocal.__version__}")
    # each command's parser is built when it is parsed or its help shown (LazySubParsers): a rig command
    # builds its own parser, not every command's (issue 16, start-up); `robocal --help` lists them all
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", action=LazySubParsers)

    with_demo = [r.name for r in rigs if r.demo is not None]

    def build_demo(demo):
        demo.add_argument("--out", type=Path, default=None, metavar="DIR",
                          help="report directory (default: a fresh robocal-out-demo-<time> folder)")
        demo.add_argument("--force", action="store_true", help=FORCE_HELP)
        demo.add_argument("--seed", type=seed_value, default=2026,
                          help="seed of the random generator; each rig draws from its own stream keyed by its name, "
                               "so a rig's figures do not depend on which other rigs run")
        demo.add_argument("--rigs", default=None, metavar="NAMES",
                          help=f"comma-separated subset of rigs to run, of: {', '.join(with_demo) or 'none installed'} "
                               "(default: all)")
        demo.add_argument("--no-progress", action="store_true", help="never show progress bars")
        demo.set_defaults(func=lambda a: run_demo(a, rigs))

    sub.add_parser(
        "demo",
        help="run every rig end to end on embedded default data and write one HTML report",
        description=(
            "Simulate each rig's default data, calibrate, and check the result against the simulated truth.\n"
            "Writes DIR/report.html (one self-contained page with every rig's figures) and\n"
            "DIR/<rig>/result.json (the shared result schema). Takes 10-30 s.\n"
            "Exit status 0 when every rig's check passed, 1 when one failed."
        ),
        formatter_class=RawHelp,
        epilog=examples_epilog("robocal demo", "robocal demo --out demo-out --rigs projector,flow"),
        build=build_demo,
    )

    sub.add_parser("rigs", help="list the installed rigs",
                   build=lambda lst: lst.set_defaults(func=lambda a: _list_rigs(rigs)))

    # `robocal report` reads the rig from the result file: it loads every rig when it runs
    add_report_command(sub, lambda: {w.name: w for w in discover_rigs()})
    add_batch_command(sub, registered_rig_names)  # robocal batch RIG MANIFEST (issue 17)
    add_bag_command(sub)

    def build_rig(p, rig):
        add_workflow_commands(p, rig)
        p.set_defaults(func=lambda a, p=p: (p.print_help(), 0)[1])

    for rig in rigs:
        sub.add_parser(rig.name, help=rig.help, description=rig.description, formatter_class=RawHelp,
                       build=lambda p, rig=rig: build_rig(p, rig))
    return parser


def _list_rigs(rigs) -> int:
    for rig in rigs:
        print(f"{rig.name:14s} {rig.help}")
    return 0


def run_demo(args, rigs) -> int:
    """Run each rig's demo, print a summary table, write ``report.html`` and per-rig results."""
    wanted = None if args.rigs is None else [r.strip() for r in args.rigs.split(",") if r.strip()]
    chosen = [r for r in rigs if r.demo is not None and (wanted is None or r.name in wanted)]
    if wanted is not None:
        with_demo = [r.name for r in rigs if r.demo is not None]
        unknown = sorted(set(wanted) - set(with_demo))
        if unknown or not wanted:
            raise InputError(f"--rigs: {', '.join(unknown) or repr(args.rigs)} "
                             f"{'is not a rig with a demo' if len(unknown) == 1 else 'are not rigs with a demo'}"
                             f" (have: {', '.join(with_demo)})")
    # after the rigs, a small fleet of the cheapest one through robocal batch (robocal.batch._demo)
    from robocal.batch._demo import fleet_demo_workflows
    chosen = chosen + fleet_demo_workflows(chosen)
    from robocal.report import Report  # the demo's page; no other command needs it at start-up

    out = prepare_out_dir(args.out, "demo")
    report = Report("robocal demo", subtitle=f"seed {args.seed}; rigs: {', '.join(r.name for r in chosen) or 'none'}")
    overview = report.section("Summary")
    rows = []
    failed = 0
    for rig in chosen:
        print(f"[{rig.name}] running ...", flush=True)
        t0 = time.perf_counter()
        ctx = DemoContext(out_dir=out / rig.name, rng=np.random.default_rng(demo_seed(args.seed, rig.name)),
                          progress=not args.no_progress)
        ctx.out_dir.mkdir(parents=True, exist_ok=True)
        try:
            outcome = demo_of(rig)(ctx)
        except RobocalError as exc:
            failed += 1
            rows.append({"rig": rig.name, "status": "error", "time [s]": time.perf_counter() - t0, "figures": str(exc)})
            continue
        dt = time.perf_counter() - t0
        if outcome.result is not None:
            write_result(ctx.out_dir / "result.json", outcome.result)
        report.extend(outcome.sections, prefix=rig.name)
        figures = "; ".join(f"{k}: {v}" for k, v in outcome.summary.items())
        rows.append({"rig": rig.name, "status": "ok" if outcome.passed else "CHECK FAILED", "time [s]": dt, "figures": figures})
        if not outcome.passed:
            failed += 1
    overview.table(rows, ["rig", "status", "time [s]", "figures"], digits=3)
    if not chosen:
        overview.text("No rig with a demo is installed.")
    path = report.write(out / "report.html")
    _print_table(rows)
    print(f"report: {path}")
    return 0 if failed == 0 else 1


def demo_seed(seed: int, rig: str) -> np.random.SeedSequence:
    """The seed sequence of ``rig``'s demo: keyed by the rig's name, not by its place in the run.

    ``SeedSequence(seed).spawn(n)`` hands out streams by position, so adding
    or leaving out a rig shifted every later rig's data (issue 18: the
    mirror's "1 image error" read 254, 206 or 120 mm for three ``--rigs``
    choices). CRC-32 of the name is stable across runs and platforms (unlike
    ``hash``); as a spawn key it gives the child ``SeedSequence(seed).spawn``
    would give at that index, independent of every other rig's.
    """
    return np.random.SeedSequence(int(seed), spawn_key=(zlib.crc32(rig.encode("utf-8")),))


def _print_table(rows) -> None:
    if not rows:
        print("no rigs ran")
        return
    w_rig = max(4, *(len(r["rig"]) for r in rows))
    w_st = max(6, *(len(r["status"]) for r in rows))
    print(f"{'rig':{w_rig}s}  {'status':{w_st}s}  {'time':>7s}  figures")
    for r in rows:
        print(f"{r['rig']:{w_rig}s}  {r['status']:{w_st}s}  {r['time [s]']:6.1f}s  {r['figures']}")


def _invoked_rig(argv) -> list[str] | None:
    """``[name]`` when the command is a registered rig, else None (load every rig).

    The top-level options (``-h``, ``--version``) take no value, so the first
    word not starting with ``-`` is the command.
    """
    command = next((a for a in argv if not a.startswith("-")), None)
    return [command] if command in registered_rig_names() else None


def _command_words(argv) -> list[str]:
    """``["flow", "simulate"]``: the words naming the command (up to two, before any option)."""
    words = []
    for a in argv:
        if a.startswith("-") or len(words) == 2 or Path(a).exists():
            break
        words.append(a)
    return words


def _input_files(args) -> list[Path]:
    """The existing files named by the parsed arguments: the command's inputs, first the positional one."""
    found = []
    values = [getattr(args, "input", None), *vars(args).values()]
    for v in values:
        for item in (v if isinstance(v, (list, tuple)) else [v]):
            if isinstance(item, (str, Path)) and str(item) and not str(item).startswith("-"):
                try:
                    if Path(item).is_file() and Path(item) not in found:
                        found.append(Path(item))
                except (OSError, ValueError):  # a name too long or with a NUL byte is no input file
                    pass
    return found


def _data_error(exc: BaseException, args) -> str:
    """One line for a failure user data provoked outside robocal's own checks, naming the input file."""
    inputs = _input_files(args) if args is not None else []
    where = f"{inputs[0]}: " if inputs else ""
    if isinstance(exc, MemoryError):
        what = str(exc).strip() or "the input needs more memory than this machine has"
        return f"{where}out of memory: {what}"
    if isinstance(exc, np.linalg.LinAlgError):
        return f"{where}the data give a singular or ill-conditioned problem ({exc}); check for extreme or repeated values"
    if isinstance(exc, UnicodeDecodeError):
        return (f"{where}not UTF-8 text: byte 0x{exc.object[exc.start]:02x} at offset {exc.start} "
                "(a binary file, or text saved in another encoding)")
    return f"{where}a computation overflowed or became undefined ({exc}); check for extreme values (e.g. 1e300) or wrong units"


def main(argv=None) -> int:
    args = None
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv == ["--version"]:  # answered before the rigs are imported (~1 s)
        print(f"robocal {robocal.__version__}")
        return 0
    set_command_line(argv)
    run = None
    try:
        parser = build_parser(discover_rigs(_invoked_rig(argv)))
        args = parser.parse_args(argv)
        if getattr(args, "func", None) is None:
            parser.print_help()
            return 0
        words = _command_words(argv)
        run = CommandRun(command=shlex.join(["robocal", *words]), command_line=shlex.join(["robocal", *argv]),
                         rig=words[0] if words and words[0] not in ("demo", "rigs", "report", "batch") else None,
                         force=bool(getattr(args, "force", False)), inputs=tuple(_input_files(args)))
        with run:
            preflight(getattr(args, "out", None))  # refuse a wrong --out before the work, not after it
            # Warnings are held back while the command runs: when it then fails (the
            # numeric warnings before fx: 1e300's LinAlgError), the one error line is
            # the whole answer; when it succeeds they are shown as usual.
            with warnings.catch_warnings(record=True) as held:
                code = int(args.func(args) or 0)
            for w in held:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
            # a command that returns has finished its files: 1 is a verdict ("a rig's check
            # failed" in demo, "infeasible" in projector path) written into them, not an error
            run.finish("complete")
        return code
    except RobocalError as exc:
        msg = str(exc).replace("\n", " ")
        # an error raised deep in a library call may not know the file it came from
        # (a command with several input files and no `input`, like `handeye calibrate
        # GRIPPER TARGET`, gets them all: the message is about their combination)
        src = getattr(args, "input", None)
        if src is None and args is not None:
            files = _input_files(args)
            src = " + ".join(map(str, files)) if 0 < len(files) <= 3 else None
        if exc.source is None and src is not None and not any(
                n in msg for n in {str(src), *(Path(p).name for p in str(src).split(" + "))}):
            msg = f"{src}: {msg}"
        print(f"robocal: error: {msg}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as exc:  # a file that cannot be read or written: the user's to fix, not a bug
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"robocal: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except (MemoryError, np.linalg.LinAlgError, UnicodeDecodeError, FloatingPointError, RuntimeWarning) as exc:
        # These come from the user's data, not from a bug: a size beyond the machine's
        # memory, a singular system from repeated or extreme values, a binary file where
        # text was expected, numbers that overflow. The rigs' own checks catch the
        # common cases with a precise message; what slips past them still deserves one
        # line naming the input, not a traceback a user cannot act on.
        print(f"robocal: error: {_data_error(exc, args)}".replace("\n", " "), file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("robocal: interrupted", file=sys.stderr)
        return 130
    finally:
        set_command_line(None)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
