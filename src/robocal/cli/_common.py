"""Small helpers shared by the rigs' command-line wiring.

CLI code stays thin: parse arguments, call a library function that returns a
result object, write files with these helpers, print a short summary.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
from pathlib import Path

from robocal.io import CalibrationResult, claim_folder, write_result
from robocal.report import Report

__all__ = [
    "add_out_argument",
    "add_seed_argument",
    "prepare_out_dir",
    "write_run",
    "examples_epilog",
    "RawHelp",
    "OneLineErrorParser",
    "add_accept_implausible_argument",
]


class OneLineErrorParser(argparse.ArgumentParser):
    """Argument parser whose usage errors are one stderr line and exit status 2.

    argparse's default prints the whole usage block first; the CLI contract
    (one line naming the problem, status 2) holds for usage mistakes too.
    Sub-parsers inherit the class, so every rig's commands behave the same.
    """

    def error(self, message: str):  # noqa: D102 - argparse hook
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


class RawHelp(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps example blocks as written and shows defaults that say something.

    No "(default: None)" or "(default: False)" for options and flags whose
    absence is their meaning, and none appended to a help text that already
    states its default.
    """

    def _get_help_string(self, action):  # noqa: D102 - argparse hook
        text = action.help or ""
        if action.default is None or action.default is False or action.default == argparse.SUPPRESS \
                or "default" in text:
            return text
        return super()._get_help_string(action)


def examples_epilog(*lines: str) -> str:
    """An ``Examples:`` block for a parser's epilog."""
    return "examples:\n" + "\n".join(f"  {ln}" for ln in lines)


FORCE_HELP = ("replace the files of another command's run in the --out folder (files robocal did not write "
              "and this command's inputs are never removed)")


def add_out_argument(parser: argparse.ArgumentParser, *, help: str | None = None) -> None:
    """``--out DIR`` and ``--force`` (see ``docs/results.md``, "Output folders")."""
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help=help or "output directory (default: a fresh robocal-out-<command>-<time> folder)",
    )
    parser.add_argument("--force", action="store_true", help=FORCE_HELP)


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    if value < 0:  # numpy's SeedSequence takes non-negative entropy only
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {value}")
    return value


def add_seed_argument(parser: argparse.ArgumentParser, default: int = 0) -> None:
    parser.add_argument("--seed", type=_seed, default=default, help="seed of the random generator (>= 0)")


def prepare_out_dir(out: Path | None, label: str, *, force: bool | None = None) -> Path:
    """Create ``out`` (or a fresh time-stamped folder named after ``label``) as this run's output folder.

    ``label`` names the command (``"flow-simulate"``). Inside a command run
    (:class:`robocal.io.CommandRun`, which ``robocal``'s ``main`` opens) the
    folder is checked and marked: an earlier run of the same command is
    removed first, another command's run or unknown files are refused unless
    ``force`` (default: the run's ``--force``), and ``INCOMPLETE`` stays until
    the command finishes (see ``docs/results.md``, "Output folders"). From
    the Python API without a run it only makes the folder.
    """
    if out is None:
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        out = Path(f"robocal-out-{label}-{stamp}")
        n = 1
        while out.exists():
            n += 1
            out = Path(f"robocal-out-{label}-{stamp}-{n}")
    return claim_folder(Path(out), label, force=force)


def write_run(out_dir: Path, result: CalibrationResult | None, report: Report | None, *, quiet: bool = False):
    """Write ``out_dir/result.json`` and ``out_dir/report.html`` (atomically)."""
    paths = []
    if result is not None:
        paths.append(write_result(Path(out_dir) / "result.json", result))
    if report is not None:
        paths.append(report.write(Path(out_dir) / "report.html"))
    if not quiet:
        for p in paths:
            print(f"wrote {p}")
        if result is not None:
            for w in result.warnings:
                print(f"warning: {w}", file=sys.stderr)
    return paths


def add_accept_implausible_argument(parser: argparse.ArgumentParser) -> None:
    """``--accept-implausible``: go on when the answer is implausible (see :mod:`robocal.plausibility`)."""
    parser.add_argument(
        "--accept-implausible", action="store_true",
        help="when the answer is physically implausible (a likely unit slip, a transposed board, ...), "
             "write it with an implausible_input warning instead of stopping with exit status 2")
